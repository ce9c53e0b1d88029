"""The named starting points of the CLI's ``--preset`` and the plugin's preset menu.

They hold the thesis method's own parameters (:class:`~.methods.thesis.ThesisParams`:
the thesis method's, and the thesis maps' of any run), so this module imports that
method's module; :mod:`.params` hands them out on first use.
"""

from __future__ import annotations

from .methods.thesis import ThesisBlocks, ThesisParams
from .params import DEFAULT_METHOD, SegmentParams

#: Parameters that beat the thesis defaults on the bundled synthetic scenes (chosen with
#: ``benchmarks/evaluate.py --sweep``; docs/quality.md has the table).
#: The thesis's absolute affinity scale s = 1 with 10-20 PCA components gives affinities
#: near e^-30: the graph falls apart and the cut peels off single blocks, so the scale is
#: relative to the median distance here; the azimuth-invariant zonal coefficients drop
#: the surface-azimuth variation that dominates the raw coefficients; a minimum segment
#: size stops the cut from isolating a few odd blocks.
RECOMMENDED = SegmentParams(
    method=ThesisBlocks.name,
    method_params={
        ThesisBlocks.name: ThesisParams(
            window=12,
            degree=8,
            features="zonal",
            scale=2.0,
            scale_mode="median",
            min_segment_blocks=4,
        )
    },
)


#: The default of ``segment``, ``demo`` and the plugin (preset ``auto``): the superpixel
#: method on the valid pixels, k + 1 clusters merged to k across the weakest border,
#: the node features diffused over whole surfaces (``method="surface_superpixels"``),
#: the best unsupervised method measured on the rendered development scenes and the
#: hand-labelled real frames together (``benchmarks/evaluate_unsupervised.py``, figures
#: in ``docs/quality.md``; it replaced ``"valid_superpixels"``, which replaced
#: ``"superpixels"``); the recommended block parameters give the thesis maps when
#: asked for.
AUTO = RECOMMENDED.replace(method=DEFAULT_METHOD)

#: The named starting points of the CLI's ``--preset`` and the plugin's preset menu.
PRESETS: dict[str, SegmentParams] = {
    "auto": AUTO,
    "thesis": SegmentParams(method=ThesisBlocks.name),
    "recommended": RECOMMENDED,
}
