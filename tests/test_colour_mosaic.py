"""Colour-polarisation mosaics (Sony IMX250MYR: 2 x 2 polariser super-pixels under an
RGGB Bayer filter, 4 x 4 period): decodings against a rendered scene with known Î, ρ, φ
per colour and against an independent slicing of the 4 x 4 pattern; reading and
segmenting sensor-named files; per-colour features of the pixel classifier."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
import tifffile
from skimage import io as skio

from napari_polarseg import cli
from napari_polarseg import io as pio
from napari_polarseg.engine import SegmentParams
from napari_polarseg.engine.classifier.pixel_classifier import ClassifierParams
from napari_polarseg.engine.classifier.pixel_segmentation import PixelSegmenter
from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.physics.colour_mosaic import (
    BAYER_ORDERS,
    LUMINANCE_WEIGHTS,
    colour_mosaic,
    colour_polarisation_images,
    demosaic_colour,
    demosaic_colour_flags,
    demosaic_colour_interpolated,
    demosaic_colour_superpixel,
    luminance,
)
from napari_polarseg.engine.physics.polarimage import polarisation_image
from napari_polarseg.engine.pipeline import Pipeline

SONY = (90.0, 45.0, 135.0, 0.0)
LAYOUTS = [SONY, (0.0, 45.0, 90.0, 135.0), (135.0, 0.0, 45.0, 90.0)]


# -- the forward model, written here independently of the package ------------------------


def render(s0, rho, phi, layout=SONY, bayer="RGGB"):
    """Raw colour-polarisation frame of a scene known per colour at every raw pixel.

    ``s0, rho, phi``: (3, H, W) arrays for R, G, B (total intensity, degree and angle of
    linear polarisation in radians). Pixel (r, c) sees the colour of Bayer cell
    (r//2 % 2, c//2 % 2) and the polariser of cell (r % 2, c % 2):
    I(θ) = S0/2 · (1 + ρ cos(2θ − 2φ)).
    """
    _, h, w = s0.shape
    r, c = np.mgrid[0:h, 0:w]
    letter = np.array(list(bayer))[2 * ((r // 2) % 2) + (c // 2) % 2]
    colour = np.select([letter == "R", letter == "G"], [0, 1], 2)
    theta = np.deg2rad(np.asarray(layout))[2 * (r % 2) + c % 2]
    pick = (colour, r, c)
    return s0[pick] / 2 * (1 + rho[pick] * np.cos(2 * theta - 2 * phi[pick]))


def slice_period(raw, layout=SONY, bayer="RGGB"):
    """Independent super-pixel decoding: walk the 16 positions of the 4 x 4 period.

    Returns {(colour letter, angle in degrees): (H/4, W/4) image}, G averaged."""
    out: dict[tuple[str, float], list[np.ndarray]] = {}
    for dr, dc in itertools.product(range(4), range(4)):
        letter = bayer[2 * (dr // 2) + dc // 2]
        angle = float(layout[2 * (dr % 2) + dc % 2])
        out.setdefault((letter, angle), []).append(raw[dr::4, dc::4].astype(float))
    return {key: np.mean(v, axis=0) for key, v in out.items()}


def scene_per_period(h, w, seed=0):
    """S0, ρ, φ per colour, constant over every 4 x 4 period (raw size 4h x 4w)."""
    rng = np.random.default_rng(seed)
    small = (
        rng.uniform(50, 200, (3, h, w)),
        rng.uniform(0.05, 0.6, (3, h, w)),
        rng.uniform(0, np.pi, (3, h, w)),
    )
    big = tuple(np.kron(a, np.ones((1, 4, 4))) for a in small)
    return small, big


def smooth_scene(h, w):
    """S0, ρ, φ per colour varying slowly (periods of 100+ pixels), raw size h x w."""
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    s0 = np.stack([150 + 40 * np.sin(2 * np.pi * (x + k * y) / 1.5) for k in (0.2, 0.5, 0.8)])
    rho = np.stack([0.3 + 0.15 * np.cos(2 * np.pi * (y - k * x) / 1.7) for k in (0.1, 0.4, 0.7)])
    phi = np.stack([0.4 + k + 0.5 * np.sin(2 * np.pi * (x + y) / 2.0) for k in (0.0, 0.9, 1.8)])
    return s0, rho, phi


def fit_angle(a, b):
    """Smallest difference of two angles modulo π."""
    d = np.mod(a - b, np.pi)
    return np.minimum(d, np.pi - d)


# -- decodings ------------------------------------------------------------------------------


@pytest.mark.parametrize("bayer", BAYER_ORDERS)
@pytest.mark.parametrize("layout", LAYOUTS)
def test_superpixel_decoding_recovers_the_rendered_scene_exactly(bayer, layout):
    (s0, rho, phi), big = scene_per_period(6, 7)
    raw = render(*big, layout=layout, bayer=bayer)
    stack, angles = demosaic_colour_superpixel(raw, layout, bayer)
    assert stack.shape == (3, 4, 6, 7) and angles.tolist() == sorted(layout)
    theta = np.deg2rad(angles)[None, :, None, None]
    expected = s0[:, None] / 2 * (1 + rho[:, None] * np.cos(2 * theta - 2 * phi[:, None]))
    np.testing.assert_allclose(stack, expected, rtol=1e-12)
    for c, pol in enumerate(colour_polarisation_images(stack, np.deg2rad(angles))):
        np.testing.assert_allclose(pol.intensity, s0[c] / 2, rtol=1e-10)  # mean = S0/2
        np.testing.assert_allclose(pol.dop, rho[c], atol=1e-10)
        assert fit_angle(pol.phase, phi[c]).max() < 1e-9


@pytest.mark.parametrize("bayer", BAYER_ORDERS)
@pytest.mark.parametrize("layout", LAYOUTS)
def test_superpixel_decoding_matches_an_independent_slicing(bayer, layout):
    raw = np.random.default_rng(1).integers(0, 4096, (20, 24)).astype(np.uint16)
    stack, angles = demosaic_colour_superpixel(raw, layout, bayer)
    sliced = slice_period(raw, layout, bayer)
    for c, letter in enumerate("RGB"):
        for k, angle in enumerate(angles):
            np.testing.assert_array_equal(stack[c, k], sliced[(letter, float(angle))])
    # and the mosaic of the decoded stack is the raw frame again where R and B are, and
    # holds the mean of the two G samples where G is
    again = colour_mosaic(stack, layout, bayer)
    np.testing.assert_array_equal(slice_period(again, layout, bayer)[("R", 0.0)], stack[0, 0])
    rerendered = demosaic_colour_superpixel(again, layout, bayer)[0]
    np.testing.assert_allclose(rerendered, stack)


@pytest.mark.parametrize("bayer", BAYER_ORDERS)
def test_interpolated_decoding_keeps_every_sample_where_it_was_measured(bayer):
    raw = np.random.default_rng(2).uniform(0, 1000, (16, 20))
    stack, angles = demosaic_colour_interpolated(raw, SONY, bayer)
    assert stack.shape == (3, 4, 16, 20)
    for dr, dc in itertools.product(range(4), range(4)):
        c = "RGB".index(bayer[2 * (dr // 2) + dc // 2])
        k = list(angles).index(SONY[2 * (dr % 2) + dc % 2])
        np.testing.assert_array_equal(stack[c, k, dr::4, dc::4], raw[dr::4, dc::4])


def test_interpolated_decoding_is_close_to_the_truth_of_a_smooth_scene():
    h, w = 96, 128
    s0, rho, phi = smooth_scene(h, w)
    raw = render(s0, rho, phi)
    stack, angles = demosaic_colour(raw, SONY, "RGGB", method="interpolated")
    theta = np.deg2rad(angles)[None, :, None, None]
    truth = s0[:, None] / 2 * (1 + rho[:, None] * np.cos(2 * theta - 2 * phi[:, None]))
    inner = (slice(None), slice(None), slice(4, -4), slice(4, -4))
    rel = np.abs(stack - truth)[inner] / truth[inner]
    assert rel.max() < 0.01  # bilinear on a lattice of period 4
    for c, pol in enumerate(colour_polarisation_images(stack, np.deg2rad(angles))):
        core = (slice(4, -4), slice(4, -4))
        np.testing.assert_allclose(pol.intensity[core], s0[c][core] / 2, rtol=0.005)
        assert np.abs(pol.dop - rho[c])[core].max() < 0.005
        assert fit_angle(pol.phase, phi[c])[core].max() < 0.01
    # the wrong Bayer order is far off: the comparison can tell decodings apart
    wrong = demosaic_colour(raw, SONY, "BGGR", method="interpolated")[0]
    assert (np.abs(wrong - truth)[inner] / truth[inner]).max() > 0.1


def test_interpolated_decoding_averages_to_the_superpixel_one_on_a_constant_scene():
    (_, _, _), big = scene_per_period(1, 1, seed=3)
    raw = render(*(np.tile(a, (1, 8, 8)) for a in big))  # one constant colour scene
    inter, _ = demosaic_colour_interpolated(raw)
    sup, _ = demosaic_colour_superpixel(raw)
    np.testing.assert_allclose(inter, np.broadcast_to(sup[..., :1, :1], inter.shape), rtol=1e-12)


def test_flags_follow_the_samples_that_draw_on_a_flagged_pixel():
    flags = np.zeros((16, 16), dtype=bool)
    flags[5, 6] = True  # pixel (1, 2) of its period: Bayer cell (0, 1) = G, polariser (1, 0)
    sup = demosaic_colour_flags(flags, SONY, "RGGB", "superpixel")
    k = sorted(SONY).index(135.0)
    assert sup.sum() == 1 and sup[1, k, 1, 1]
    inter = demosaic_colour_flags(flags, SONY, "RGGB", "interpolated")
    assert inter[[0, 2]].sum() == 0 and inter[1, k, 5, 6]
    assert inter[1, k].sum() == 7 * 7 and inter[1].sum() == inter[1, k].sum()


def test_luminance_is_a_polarisation_stack_with_the_weighted_stokes_vector():
    (s0, rho, phi), big = scene_per_period(5, 5, seed=4)
    stack, angles = demosaic_colour_superpixel(render(*big))
    lum = polarisation_image(luminance(stack), np.deg2rad(angles))
    wts = np.asarray(LUMINANCE_WEIGHTS)[:, None, None]
    assert abs(float(np.sum(LUMINANCE_WEIGHTS)) - 1.0) < 1e-12
    s1 = np.sum(wts * s0 / 2 * rho * np.cos(2 * phi), axis=0)
    s2 = np.sum(wts * s0 / 2 * rho * np.sin(2 * phi), axis=0)
    np.testing.assert_allclose(lum.intensity, np.sum(wts * s0 / 2, axis=0), rtol=1e-10)
    np.testing.assert_allclose(lum.intensity * lum.dop * np.cos(2 * lum.phase), s1, atol=1e-8)
    np.testing.assert_allclose(lum.intensity * lum.dop * np.sin(2 * lum.phase), s2, atol=1e-8)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: demosaic_colour_superpixel(np.zeros((6, 8))), "multiples of 4"),
        (lambda: demosaic_colour_superpixel(np.zeros((8, 8)), bayer="RGBG"), "Bayer order"),
        (lambda: demosaic_colour_interpolated(np.zeros((8, 8)), (0, 45, 90)), "4 finite"),
        (lambda: demosaic_colour(np.zeros((8, 8)), method="cubic"), "demosaic method"),
    ],
)
def test_bad_colour_mosaics_are_refused(call, message):
    with pytest.raises(PolarsegError, match=message):
        call()


# -- files: the reader and the command line -------------------------------------------------


def two_material_colour_scene(h=32, w=40, seed=0):
    """Raw 4h x 4w colour frame: left and right halves of one luminance but another
    colour of polarisation (left: only R polarised, right: only B, with the same
    luminance Stokes vector), plus noise. Returns (raw uint16, truth at h x w)."""
    rng = np.random.default_rng(seed)
    truth = np.zeros((h, w), dtype=np.uint8)
    truth[:, w // 2 :] = 1
    w_r, _, w_b = LUMINANCE_WEIGHTS
    rho_left, rho_right = 0.25, 0.25 * w_r / w_b
    s0 = np.full((3, h, w), 1600.0)
    rho = np.zeros((3, h, w))
    rho[0][truth == 0] = rho_left
    rho[2][truth == 1] = rho_right
    phi = np.full((3, h, w), 0.7)
    big = tuple(np.kron(a, np.ones((1, 4, 4))) for a in (s0, rho, phi))
    raw = render(*big) + rng.normal(0, 8.0, (4 * h, 4 * w))
    return np.clip(np.round(raw), 0, 65535).astype(np.uint16), truth


def test_a_sensor_named_file_reads_as_colour_with_the_sensor_defaults(tmp_path):
    raw, _ = two_material_colour_scene(8, 10)
    named = tmp_path / "scene_IMX250MYR.png"
    skio.imsave(named, raw, check_contrast=False)
    data = pio.read_stack(named)
    assert data.metadata["sensor"] == "IMX250MYR" and data.metadata["bayer"] == "RGGB"
    assert data.metadata["mosaic_layout_deg"] == list(SONY)
    assert data.colour_stack.shape == (3, 4, 8, 10) and data.stack.shape == (4, 8, 10)
    sliced = slice_period(raw)
    for c, letter in enumerate("RGB"):
        for k, angle in enumerate(data.angles_deg):
            np.testing.assert_array_equal(data.colour_stack[c, k], sliced[(letter, angle)])
    np.testing.assert_allclose(data.stack, luminance(data.colour_stack))
    # the same frame under another name needs the layout and order given
    plain = tmp_path / "scene.tif"
    tifffile.imwrite(plain, raw)
    given = pio.read_stack(plain, mosaic=SONY, bayer="rggb")
    np.testing.assert_array_equal(given.colour_stack, data.colour_stack)
    with pytest.raises(PolarsegError, match="Bayer order needs a mosaic"):
        pio.read_stack(plain, bayer="RGGB")
    full = pio.read_stack(named, demosaic="interpolated")
    assert full.colour_stack.shape == (3, 4, 32, 40) and full.stack.shape == (4, 32, 40)
    # a mono sensor's name still means a 2 x 2 mosaic, without colour
    mono = tmp_path / "scene_IMX250MZR.png"
    skio.imsave(mono, raw, check_contrast=False)
    data = pio.read_stack(mono)
    assert data.colour_stack is None and data.stack.shape == (4, 16, 20)
    # a multi-page stack named after a sensor is still an angle stack
    stack_file = tmp_path / "stack_IMX250MYR.tif"
    pio.write_stack_tiff(stack_file, given.stack, given.angles_deg)
    assert pio.read_stack(stack_file).metadata["format"] != "mosaic"


def test_a_saturated_raw_pixel_flags_the_luminance_samples_it_feeds(tmp_path):
    raw = np.random.default_rng(6).integers(900, 1100, (8, 8)).astype(np.uint16)
    raw[4, 7] = 65535  # period (1, 1), Bayer cell (0, 1) = G, polariser cell (0, 1) = 45
    path = tmp_path / "x_IMX253MYR.tif"
    tifffile.imwrite(path, raw)
    data = pio.read_stack(path)
    k = list(data.angles_deg).index(45.0)
    assert data.saturated.sum() == 1 and data.saturated[k, 1, 1]


def test_segment_on_a_sensor_named_colour_frame(tmp_path, capsys):
    raw, truth = two_material_colour_scene()
    named = tmp_path / "bench_IMX250MYR.png"
    skio.imsave(named, raw, check_contrast=False)
    scribbles = np.zeros(truth.shape, dtype=np.uint8)
    scribbles[4:8, 3:15] = 1
    scribbles[24:28, 25:37] = 2
    skio.imsave(tmp_path / "scribbles.png", scribbles, check_contrast=False)
    out = tmp_path / "out"
    code = cli.main(
        ["segment", str(named), "--out", str(out), "--window", "4", "--degree", "4"]
        + ["--scribbles", str(tmp_path / "scribbles.png")]
    )
    assert code == 0, capsys.readouterr().err
    labels = tifffile.imread(out / "labels.tif")
    assert labels.shape == truth.shape
    # labels.tif holds the scribble values (1, 2) of the truth's materials (0, 1)
    assert np.mean(labels == truth + 1) > 0.95  # the colour of the polarisation separates them
    params = json.loads((out / "params.json").read_text())
    assert params["bayer"] == "RGGB" and params["sensor"] == "IMX250MYR"
    assert params["raw_shape"] == [128, 160] and params["angles_deg"] == sorted(SONY)
    summary = json.loads((out / "summary.json").read_text())
    top = summary["classifier"]["top_features"]
    assert any(name.split(":")[0] in ("R", "B") for name in top)
    # --mosaic --bayer on a file without the sensor's name gives the same stack
    plain = tmp_path / "bench.png"
    skio.imsave(plain, raw, check_contrast=False)
    out2 = tmp_path / "out2"
    code = cli.main(
        ["segment", str(plain), "--out", str(out2), "--mosaic", "90,45,135,0", "--bayer", "RGGB"]
        + ["--window", "4", "--degree", "4", "--segments", "2"]
    )
    assert code == 0, capsys.readouterr().err
    np.testing.assert_allclose(
        tifffile.imread(out2 / "intensity.tif"), tifffile.imread(out / "intensity.tif")
    )
    code = cli.main(["segment", str(plain), "--out", str(tmp_path / "o3"), "--bayer", "RGGB"])
    assert code != 0 and "--bayer applies to a raw mosaic frame" in capsys.readouterr().err


def test_colour_features_separate_materials_of_one_luminance():
    raw, truth = two_material_colour_scene(seed=5)
    stack, angles = demosaic_colour_superpixel(raw)
    pipe = Pipeline(luminance(stack), np.deg2rad(angles), SegmentParams(window=4, degree=4))
    scribbles = np.zeros(truth.shape, dtype=np.int64)
    scribbles[4:8, 3:15] = 1
    scribbles[24:28, 25:37] = 2
    # without the region walk: a loaded classifier then labels as the trained one did
    alone = ClassifierParams(region_walk=0.0)
    mono = PixelSegmenter(pipe).segment(scribbles, params=alone, reconstruction=False)
    colour = PixelSegmenter(pipe, colour_stack=stack).segment(scribbles, reconstruction=False)
    names = colour.classifier.feature_names
    assert set(mono.classifier.feature_names) < set(names)
    assert {n.split(":")[0] for n in names if ":" in n} >= {"R", "G", "B"}
    # the two halves have one luminance polarisation, their R (and B) ones differ
    lum = pipe.get("polarisation")
    red = PixelSegmenter(pipe, colour_stack=stack).colour_images()[0]
    left, right = truth == 0, truth == 1
    assert abs(lum.dop[left].mean() - lum.dop[right].mean()) < 0.01
    assert red.dop[left].mean() - red.dop[right].mean() > 0.2
    accuracy = np.mean(colour.result.labels == truth)
    assert accuracy > 0.95 and accuracy > np.mean(mono.result.labels == truth) + 0.1
    # a classifier trained without colour still applies to the colour segmenter (its own
    # features; no walk, so the labels of training)
    again = PixelSegmenter(pipe, colour_stack=stack).segment(classifier=mono.classifier)
    np.testing.assert_array_equal(again.result.labels, mono.result.labels)


def test_shift_frames_moves_every_colour_as_the_registration_moved_the_luminance():
    from scipy import ndimage

    from napari_polarseg.engine.physics.registration import register_stack, shift_frames

    texture = ndimage.gaussian_filter(np.random.default_rng(7).normal(0, 1, (48, 48)), 3)
    s0 = np.stack([(150 + 800 * texture) * k for k in (1.0, 0.8, 0.6)])
    colour, _ = demosaic_colour_interpolated(render(s0, np.full_like(s0, 0.1), 0.5 + 0 * s0))
    moved = colour.copy()
    moved[:, 2] = ndimage.shift(colour[:, 2], (0, 1.5, -2.0), order=3, mode="nearest")
    registered, shifts = register_stack(luminance(moved))
    assert np.allclose(shifts[2], (-1.5, 2.0), atol=0.1) and not np.any(shifts[[0, 1, 3]])
    aligned = shift_frames(moved, shifts)
    np.testing.assert_allclose(luminance(aligned), registered, atol=1e-9)
    np.testing.assert_array_equal(aligned[:, [0, 1, 3]], moved[:, [0, 1, 3]])
    with pytest.raises(PolarsegError, match="do not match"):
        shift_frames(moved, shifts[:3])


def test_a_raw_size_mask_reduces_to_the_colour_super_pixels(tmp_path):
    keep = np.ones((16, 20), dtype=np.uint8)
    keep[5, 6] = 0  # in period (1, 1)
    skio.imsave(tmp_path / "m.png", keep, check_contrast=False)
    mask = pio.read_mask(tmp_path / "m.png", (4, 5), raw_shape=(16, 20))
    assert mask.shape == (4, 5) and mask.sum() == 19 and not mask[1, 1]
