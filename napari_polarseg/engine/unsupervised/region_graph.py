"""The graph between the superpixels of the unsupervised segmentation.

The superpixels themselves are
:func:`~napari_polarseg.engine.features.superpixels.polarisation_superpixels`;
:func:`region_adjacency` is the shared-border graph of the regions.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps


def region_adjacency(regions: np.ndarray) -> sps.csr_matrix:
    """Shared border length (4-neighbour pixel pairs) between every two regions, (n, n)."""
    n = int(regions.max()) + 1
    pairs = []
    for a, b in ((regions[:, :-1], regions[:, 1:]), (regions[:-1], regions[1:])):
        differ = a != b
        pairs.append((a[differ], b[differ]))
    rows = np.concatenate([p[0] for p in pairs])
    cols = np.concatenate([p[1] for p in pairs])
    m = sps.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n)).tocsr()
    return (m + m.T).tocsr()
