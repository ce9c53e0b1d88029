"""A physical check on a real capture: four linear polariser discs at 45° steps.

``polarizer_IMX250MZR.png`` (Sony IMX250MZR, polanalyser, MIT licence; see
``../shared/data/polanalyser/SOURCES.md``) shows four polarising filters held in a row
against a window, turned by 45° from one to the next. Decoded with the sensor's mosaic
layout, each disc must show one angle of linear polarisation (AoLP coherence |mean
e^{2iφ}| > 0.95), neighbouring discs must differ by 45° (modulo 180°), and the discs must
be more strongly polarised than the scene around them.

The filters are held by hand, so their angles are not exact multiples of 45°: measured
(super-pixel decoding, least-squares fit, saturated samples left out) the discs sit at
83.3°, 43.7°, 175.2° and 135.5° from left to right, steps of −39.6°, −48.5° and −39.7°.
So each disc is asked to lie within 5° of one ladder of 45° steps (fitted offset), and a
neighbouring step, the difference of two such deviations, 45° ± 6° (45° ± 5° fails on
this frame by 0.4°). A wrong mosaic layout fails: with two neighbouring angles of the
super-pixel swapped (45°, 90°, 135°, 0° instead of 90°, 45°, 135°, 0°) the four discs
are still found but step by −13°, −90° and +13°. Swapping 0° ↔ 90° or 45° ↔ 135° only
mirrors every AoLP (φ → 90° − φ or −φ: the steps keep their size and change sense), which
no test without the filters' true orientations can tell apart.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage
from skimage import io as skio
from skimage.filters import threshold_otsu
from skimage.measure import label, regionprops

from napari_polarseg.engine import polarisation_image, validity_mask
from napari_polarseg.engine.physics.mosaic import IMX250MZR_LAYOUT, demosaic_superpixel

REPO = Path(__file__).resolve().parents[1]
RELATIVE_DIR = "../shared/data/polanalyser"
FRAME = (REPO / RELATIVE_DIR / "polarizer_IMX250MZR.png").resolve()
#: Largest deviation (degrees) of a disc from the fitted ladder of 45° steps.
LADDER_TOLERANCE_DEG = 5.0
#: Largest deviation (degrees) of a neighbouring step from 45°.
STEP_TOLERANCE_DEG = 6.0

pytestmark = pytest.mark.skipif(
    not FRAME.is_file(),
    reason=f"real polarisation-camera frame polarizer_IMX250MZR.png not found in {RELATIVE_DIR} "
    "(relative to the repository: put the shared data folder beside it as ../shared)",
)


def circular_step_deg(a: float, b: float) -> float:
    """b − a for axial angles (degrees modulo 180), in [−90, 90)."""
    return float(np.mod(b - a + 90.0, 180.0) - 90.0)


def find_discs(dop: np.ndarray, usable: np.ndarray, n: int = 4) -> list[np.ndarray]:
    """Masks of the ``n`` largest round, strongly polarised regions, left to right.

    ρ smoothed (Gaussian, σ = 3 px) and thresholded by Otsu's method; connected regions
    with holes filled, kept if round (4π area / perimeter² > 0.6, solidity > 0.9).
    """
    smooth = ndimage.gaussian_filter(np.where(usable, dop, 0.0), 3.0)
    regions = label(smooth > threshold_otsu(smooth))
    round_ones = []
    for region in regionprops(regions):
        if region.area < 1000 or region.perimeter == 0:
            continue
        if 4 * np.pi * region.area / region.perimeter**2 > 0.6 and region.solidity > 0.9:
            round_ones.append(region)
    round_ones.sort(key=lambda r: -r.area)
    chosen = sorted(round_ones[:n], key=lambda r: r.centroid[1])
    return [ndimage.binary_fill_holes(regions == r.label) for r in chosen]


def disc_measures(layout_deg=IMX250MZR_LAYOUT) -> dict[str, list[float]]:
    """AoLP (degrees), coherence and ρ inside each disc, ρ around it, left to right."""
    raw = skio.imread(FRAME)
    stack, angles_deg = demosaic_superpixel(raw, layout_deg)
    mask = validity_mask(stack)
    pol = polarisation_image(stack, np.deg2rad(angles_deg), weights=mask.sample_weights)
    usable = mask.valid & ~pol.invalid
    out: dict[str, list[float]] = {"aolp": [], "coherence": [], "dop_in": [], "dop_around": []}
    for disc in find_discs(pol.dop, usable):
        radius = np.sqrt(disc.sum() / np.pi)
        inner = ndimage.binary_erosion(disc, iterations=int(0.1 * radius)) & usable
        outside = ndimage.distance_transform_edt(~disc)
        ring = (outside > 0.15 * radius) & (outside < 0.45 * radius) & usable
        z = np.mean(np.exp(2j * pol.phase[inner]))
        out["aolp"].append(float(np.rad2deg(np.angle(z) / 2) % 180.0))
        out["coherence"].append(float(np.abs(z)))
        out["dop_in"].append(float(np.median(pol.dop[inner])))
        out["dop_around"].append(float(np.percentile(pol.dop[ring], 90)))
    return out


@pytest.fixture(scope="module")
def discs() -> dict[str, list[float]]:
    return disc_measures()


def test_four_discs_are_found(discs):
    assert len(discs["aolp"]) == 4, discs


def test_each_disc_has_one_angle_of_polarisation(discs):
    assert len(discs["coherence"]) == 4
    assert min(discs["coherence"]) > 0.95, discs["coherence"]


def test_neighbouring_discs_step_by_45_degrees(discs):
    aolp = discs["aolp"]
    assert len(aolp) == 4
    steps = [circular_step_deg(a, b) for a, b in zip(aolp[:-1], aolp[1:], strict=True)]
    assert all(abs(abs(s) - 45.0) <= STEP_TOLERANCE_DEG for s in steps), steps
    assert len({np.sign(s) for s in steps}) == 1, steps  # the filters turn one way
    # every disc within the tolerance of one ladder a0 + k · 45° (a0 fitted)
    sense = float(np.sign(steps[0]))
    offsets = np.deg2rad([a - sense * 45.0 * k for k, a in enumerate(aolp)])
    a0 = np.angle(np.mean(np.exp(2j * offsets))) / 2
    deviation = [abs(circular_step_deg(np.rad2deg(a0), np.rad2deg(o))) for o in offsets]
    assert max(deviation) <= LADDER_TOLERANCE_DEG, deviation


def test_discs_are_more_polarised_than_the_scene_around_them(discs):
    assert len(discs["dop_in"]) == 4
    for inside, around in zip(discs["dop_in"], discs["dop_around"], strict=True):
        # the median inside above the 90th percentile of a ring around the disc
        assert inside > around, (inside, around)
    assert min(discs["dop_in"]) > 0.3
