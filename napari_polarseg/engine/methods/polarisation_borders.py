"""The surface-superpixel method with its borders weighed on the polarisation edges alone
(``--method polarisation_borders``; a peer of the default for scenes crossed by cast
shadows, not the default).

Everything of :class:`~.surface_superpixels.SurfaceSuperpixels` is kept (valid pixels
only, the node features diffused over whole surfaces, k + 1 clusters merged to k across
the weakest border, ``n_segments = 0`` finds k), and the superpixels still follow the
edges of log Î and of the Stokes components. What changes is the map the borders
between superpixels are weighed on, by the diffusion and by the merge: the Stokes edges
|∇(G * (s1, s2))| alone (``UnsupervisedParams.border_intensity_weight = 0``).

What it is for: a cast shadow multiplies Î by a factor and leaves ρ and φ as they are.
The default weighs its borders on the log Î edges too, so a shadow's edge stops its
diffusion and its merge as a material's border does, and below about half the light
the shadow becomes a segment of its own (``docs/quality.md``, *A cast shadow is not a
material*; ``benchmarks/cast_shadow.py``). Here the walk and the merge cross any step
of Î across which ρ and φ run on, so the shadowed and the lit parts of one material
join.

What it costs: where objects differ from their neighbours by their shading and hardly by
their polarisation (many small leaves of one albedo, the small-object family), the walk
then crosses their borders too and they run together; on the development halves the
small family falls from the default's 0.339 to 0.195 and the real frames from 0.955 to
0.909, few large objects rise from 0.496 to 0.522 (``docs/quality.md``). The default's
own border gate crosses a shadow that leaves 70 % of the light, not deeper ones; choose
this method for scenes under a sun or a lamp that casts hard shadows across the
materials.
"""

from __future__ import annotations

from .surface_superpixels import SurfaceSuperpixels


class PolarisationBorders(SurfaceSuperpixels):
    """:class:`~.surface_superpixels.SurfaceSuperpixels` with the diffusion's and the
    merge's borders weighed on the Stokes edges alone (module docstring)."""

    name = "polarisation_borders"
    title = "superpixels, borders of polarisation only: cast shadows crossed (unsupervised)"

    def __init__(self) -> None:
        super().__init__()
        self.params = self.params.replace(border_intensity_weight=0.0)
