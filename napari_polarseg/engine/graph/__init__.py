"""The block graph and its cuts.

Affinities S = exp(−D/s) (:mod:`.affinity`), the eigensolver of the normalised Laplacian
(:mod:`.eigensolver`), the recursive normalized cut (:mod:`.ncut`) and k-way spectral
clustering (:mod:`.spectral`).
"""
