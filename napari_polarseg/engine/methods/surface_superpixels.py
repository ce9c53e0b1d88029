"""Superpixels on the valid pixels whose features are spread over whole surfaces: the
valid-superpixel method (:mod:`.valid_superpixels`) with a wider edge-aware diffusion.

Everything is as in :class:`~.valid_superpixels.ValidSuperpixels` (invalid pixels left
out, k + 1 clusters merged to k, ``n_segments = 0`` finds k) but the node features'
diffusion over the region graph (:mod:`~napari_polarseg.engine.unsupervised.region_diffusion`)
reaches further and crosses weaker borders:

- **reach** (``diffusion_range``) :data:`REACH` of the image side instead of 7 %: a lazy
  walk of t = ⌈reach² · n / λ⌉ steps (at most
  :data:`~napari_polarseg.engine.unsupervised.region_diffusion.MAX_STEPS`) over the n
  superpixels, so a superpixel carries the features of the whole surface it lies on;
- **border scale** (``diffusion_tau``) :data:`BORDER_SCALE` × the median border strength
  instead of 0.75: the border weights exp(−(e / τ)²) let the walk across the faint
  borders inside one surface (a shading gradient, the rim of a soft shadow) and still
  stop at the strong ones between objects;
- **gated intensity borders** (``border_gate``) :data:`BORDER_GATE`: a border's log Î
  edges count only as far as the two superpixels' polarisation differs
  (:func:`~napari_polarseg.engine.unsupervised.region_diffusion.gated_strength`), so the
  walk and the merge cross a cast shadow's edge, where Î steps and ρ and φ run on, as
  they cross a shading gradient; its Stokes edges count in full.

What it is for: on a large surface seen under a changing angle (a floor, a table, a
wall) ρ and the shading drift across the frame, and a short diffusion leaves that drift
in the features, so k-means cuts the surface in two along it and merges two materials
elsewhere.

Two node-feature groups, and the object size:

- **texture** (:mod:`~napari_polarseg.engine.unsupervised.texture`): how grainy ρ, the
  AoLP and log Î are at the scale of one pixel, each less its image-wide fit on the
  regions' brightness. These columns are not diffused (the walk's borders follow the
  mean maps, which do not change where only the relief does) and weigh
  :data:`TEXTURE_WEIGHT` against the diffused mean ones: coatings of one lacquer that
  differ only in their relief, or a moulded leaf among waxy ones, are told apart where
  the means are alike;
- **object size**: the estimated size is followed (superpixels of side D / 8, a reach of
  :data:`REACH_OBJECTS` · D, never coarser than the frame-share scales) where it is at
  least :data:`ESTIMATE_FLOOR` of the short side; a smaller estimate, more often the
  grain of a texture or a net than an object, keeps the frame-share scales.

Of the k + 1 clusters, the two merged are those whose shared border is **weakest on
average** (:func:`~napari_polarseg.engine.unsupervised.merge.weakest_border`), not the
two closest in feature space: where the clustering still cuts one surface along its
shading or a soft shadow, the two parts meet along a border with no edge. A segment
with more border to the others than within itself (a scatter of superpixels straddling
edges, :data:`~napari_polarseg.engine.unsupervised.merge.COHESION_FLOOR`) goes first.

With ``n_segments = 0`` the number of segments is the fewest among 2..6 whose
silhouette comes within :data:`K_TOLERANCE` of the best one: the diffused features
form smooth continua that more clusters always cut a little better, so the best
silhouette alone overshoots.

The figures that chose these values, and their neighbours, are in ``docs/quality.md``
(*A default chosen on the development half*).
"""

from __future__ import annotations

from ..unsupervised.merge import weakest_border
from ..unsupervised.params import UnsupervisedParams
from ..unsupervised.texture import TEXTURE_FEATURES
from .valid_superpixels import ValidSuperpixels

#: Reach of the node features' diffusion, a share of the image side √(H·W).
REACH = 0.20
#: Reach of that diffusion in object sizes (``SegmentParams.object_size``), never beyond
#: :data:`REACH` of the side (:meth:`~.valid_superpixels.ValidSuperpixels.scaled_params`).
REACH_OBJECTS = 0.5
#: τ of the diffusion's border weights, in units of the median border strength.
BORDER_SCALE = 1.25
#: K of the gate on the log Î edges of those borders
#: (``UnsupervisedParams.border_gate``): a step of Î weighs as a border only where the
#: two superpixels' polarisation differs by about K × its median difference or more.
BORDER_GATE = 0.5
#: Weight of the polarisation-texture node features (:mod:`..unsupervised.texture`)
#: against the mean ones, which are diffused; the texture ones are not.
TEXTURE_WEIGHT = 0.3
#: The estimated object size is followed where it is at least this share of the short
#: side (:attr:`~.valid_superpixels.ValidSuperpixels.estimate_floor`).
ESTIMATE_FLOOR = 0.10
#: With ``n_segments = 0``: the fewest k whose silhouette is within this share of the
#: best (:func:`~napari_polarseg.engine.unsupervised.choose_k.estimate_k`).
K_TOLERANCE = 0.10


class SurfaceSuperpixels(ValidSuperpixels):
    """:class:`~.valid_superpixels.ValidSuperpixels` with the node features diffused over
    whole surfaces (module docstring); ``n_segments = 0`` finds k."""

    name = "surface_superpixels"
    title = "superpixels on valid pixels, features spread over surfaces (unsupervised)"
    k_tolerance = K_TOLERANCE
    reach_objects = REACH_OBJECTS
    merge_rule = staticmethod(weakest_border)
    follows_estimate = True
    estimate_floor = ESTIMATE_FLOOR

    def __init__(self, params: UnsupervisedParams | None = None) -> None:
        super().__init__(
            params
            or UnsupervisedParams(
                diffusion_range=REACH,
                diffusion_tau=BORDER_SCALE,
                border_gate=BORDER_GATE,
                texture=TEXTURE_FEATURES,
                texture_weight=TEXTURE_WEIGHT,
            )
        )
