"""Hand-labelled ground truth of real polarisation-camera frames (napari_polarseg.truth).

The bundled truth files must rasterise to the committed pixel counts (a regression check of
the polygons and of the rasteriser), keep their strokes inside their own class's polygons
and never let two classes share a pixel. Malformed files must fail with one-line
:class:`PolarsegError` messages naming the file. The physical checks need the real frames in
``<repo>/../shared/data/polanalyser`` and are skipped, with the path in the reason, when
that folder is absent.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from napari_polarseg.engine import PolarsegError
from napari_polarseg.truth import (
    TRUTH_DIR,
    TruthFile,
    frame_polarisation_image,
    read_truth_file,
    real_frame_path,
    truth_files,
)

REPO = Path(__file__).resolve().parents[1]
REAL_DIR = (REPO / ".." / "shared" / "data" / "polanalyser").resolve()

needs_real_data = pytest.mark.skipif(
    not REAL_DIR.is_dir(),
    reason="real polarisation-camera frames not found in ../shared/data/polanalyser "
    "(beside the repository; docs/data.md, 'Optional real data')",
)

#: Pixels per class as measured when the polygons and strokes were drawn (regression check).
EXPECTED_TRUTH = {
    "fruits_IMX250MZR.json": {
        "background": 281162,
        "apple": 217559,
        "orange": 106623,
        "banana": 217695,
    },
    "camera_IMX250MZR.json": {"mat": 586867, "body": 29190, "lens_cap": 7405},
    "carps_IMX250MZR.json": {"water": 180905, "tree_reflection": 37557, "fish": 6367},
    "polarizer_IMX250MZR.json": {"outdoor_scene": 182075, "filter": 87909, "interior": 195690},
}
EXPECTED_STROKES = {
    "fruits_IMX250MZR.json": {"background": 404, "apple": 324, "orange": 233, "banana": 304},
    "camera_IMX250MZR.json": {"mat": 384, "body": 284, "lens_cap": 142},
    "carps_IMX250MZR.json": {"water": 273, "tree_reflection": 273, "fish": 175},
    "polarizer_IMX250MZR.json": {"outdoor_scene": 283, "filter": 274, "interior": 303},
}
BUNDLED = sorted(EXPECTED_TRUTH)


@pytest.fixture(scope="module", params=BUNDLED)
def bundled(request) -> TruthFile:
    return read_truth_file(TRUTH_DIR / request.param)


def test_truth_files_lists_the_bundled_files():
    names = [p.name for p in truth_files()]
    assert names == BUNDLED
    assert all(p.is_file() and p.parent == TRUTH_DIR for p in truth_files())


def test_bundled_header(bundled):
    assert bundled.frame == bundled.path.stem + ".png"
    assert bundled.mosaic == (90.0, 45.0, 135.0, 0.0)
    assert bundled.shape == (1024, 1224)
    assert bundled.truth.shape == bundled.strokes.shape == bundled.shape
    assert bundled.truth.dtype == bundled.strokes.dtype == np.int32
    assert not bundled.truth.flags.writeable and not bundled.strokes.flags.writeable
    assert set(bundled.regions) == set(bundled.classes) == set(bundled.stroke_paths)


def test_bundled_pixel_counts(bundled):
    name = bundled.path.name
    assert bundled.pixel_counts() == EXPECTED_TRUTH[name]
    assert bundled.pixel_counts("strokes") == EXPECTED_STROKES[name]
    assert list(bundled.pixel_counts()) == list(bundled.classes)
    assert int(bundled.truth.max()) == len(bundled.classes)
    assert int(bundled.truth.min()) == 0  # boundaries stay unlabelled


def test_bundled_classes_do_not_overlap(bundled):
    """Each class's polygons, rasterised alone, share no pixel with another class's."""
    from skimage.draw import polygon

    owner = np.zeros(bundled.shape, np.int32)
    for k, name in enumerate(bundled.classes, start=1):
        mine = np.zeros(bundled.shape, bool)
        for poly in bundled.regions[name]:
            rr, cc = polygon(poly[:, 0], poly[:, 1], shape=bundled.shape)
            mine[rr, cc] = True
        assert not np.any(mine & (owner != 0)), name
        owner[mine] = k
    np.testing.assert_array_equal(owner, bundled.truth)


def test_bundled_strokes_inside_their_polygons(bundled):
    for k, name in enumerate(bundled.classes, start=1):
        stroke = bundled.strokes == k
        assert stroke.any(), name
        assert np.all(bundled.truth[stroke] == k), name


def test_bundled_drawing_rules(bundled):
    """≤ 40 vertices per polygon; 2–4 strokes of 30–120 px per class; margins to the frame."""
    height, width = bundled.shape
    for name in bundled.classes:
        assert bundled.regions[name], name
        for poly in bundled.regions[name]:
            assert 3 <= len(poly) <= 40
            assert poly[:, 0].min() >= 15 and poly[:, 0].max() <= height - 1 - 13
            assert poly[:, 1].min() >= 15 and poly[:, 1].max() <= width - 1 - 13
        paths = bundled.stroke_paths[name]
        assert 2 <= len(paths) <= 4, name
        for path in paths:
            length = float(np.sum(np.hypot(*np.diff(path, axis=0).T)))
            assert 30 <= length <= 120, (name, length)


def test_label_and_real_frame_path(bundled, tmp_path):
    assert [bundled.label(c) for c in bundled.classes] == list(range(1, len(bundled.classes) + 1))
    with pytest.raises(PolarsegError, match="unknown class"):
        bundled.label("no such class")
    path = real_frame_path(bundled, tmp_path, must_exist=False)
    assert path == tmp_path / bundled.frame
    with pytest.raises(PolarsegError, match="not found") as info:
        real_frame_path(bundled, tmp_path)
    assert "\n" not in str(info.value)
    with pytest.raises(PolarsegError, match="layer"):
        bundled.pixel_counts("labels")


# --- malformed files -------------------------------------------------------------------------


def _valid_doc() -> dict:
    return {
        "frame": "scene.png",
        "mosaic": [90, 45, 135, 0],
        "shape": [40, 50],
        "coordinates": "superpixel frame, (row, col) pixels",
        "classes": ["background", "thing"],
        "regions": {
            "background": [[[2, 2], [2, 15], [15, 15], [15, 2]]],
            "thing": [[[20, 20], [20, 45], [35, 45], [35, 20]]],
        },
        "strokes": {"background": [[[5, 5], [5, 12]]], "thing": [[[25, 25], [30, 40], [28, 42]]]},
    }


def _write(tmp_path: Path, doc, name: str = "truth.json") -> Path:
    path = tmp_path / name
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc), encoding="utf-8")
    return path


def test_small_valid_file(tmp_path):
    truth = read_truth_file(_write(tmp_path, _valid_doc()), expected_shape=(40, 50))
    assert truth.classes == ("background", "thing")
    assert truth.pixel_counts() == {"background": 14 * 14, "thing": 16 * 26}
    assert truth.strokes[5, 5:13].tolist() == [1] * 8
    assert truth.strokes[25, 25] == 2 and truth.strokes[28, 42] == 2
    assert truth.pixel_counts("strokes")["background"] == 8
    # the optional "coordinates" key may be left out; strokes may be empty
    doc = _valid_doc()
    del doc["coordinates"]
    doc["strokes"] = {}
    assert not read_truth_file(_write(tmp_path, doc)).strokes.any()


def _broken(**changes):
    doc = _valid_doc()
    for key, value in changes.items():
        if value is KeyError:
            del doc[key]
        else:
            doc[key] = value
    return doc


MALFORMED = {
    "bad JSON": ('{"frame": "scene.png", "shape": [40, 50],', "not valid JSON"),
    "not UTF-8": (b"\xff\xfe{}", "not UTF-8"),
    "top level array": ("[1, 2, 3]", "top level must be a JSON object"),
    "duplicate key": ('{"frame": "a.png", "frame": "b.png"}', "appears twice"),
    "missing key": (_broken(regions=KeyError), "missing key(s) regions"),
    "unknown key": (_broken(labels=[1]), "unknown key(s) 'labels'"),
    "frame not a string": (_broken(frame=3), "'frame' must be a non-empty file name"),
    "frame with a folder": (_broken(frame="../x/scene.png"), "without folders"),
    "wrong coordinates": (_broken(coordinates="full frame"), "'coordinates' must be"),
    "mosaic of 3": (_broken(mosaic=[0, 45, 90]), "'mosaic' must be a list of 4 angles"),
    "mosaic of strings": (_broken(mosaic=["0", "45", "90", "135"]), "'mosaic' must be"),
    "shape as string": (_broken(shape="40x50"), "'shape' must be [rows, columns]"),
    "shape of floats": (_broken(shape=[40.0, 50.0]), "'shape' must be [rows, columns]"),
    "shape with bool": (_broken(shape=[True, 50]), "'shape' must be [rows, columns]"),
    "deeply nested": ("[" * 200000 + "]" * 200000, "nested too deeply"),
    "classes not a list": (_broken(classes="background"), "'classes' must be a non-empty"),
    "class name with a newline": (_broken(classes=["back\nground", "thing"]), "printable"),
    "empty class name": (_broken(classes=["background", ""]), "non-empty string"),
    "duplicate class": (_broken(classes=["thing", "thing"]), "unique"),
    "regions not an object": (_broken(regions=[[[1, 1], [1, 5], [5, 5]]]), "'regions' must be"),
    "polygons not a list": (_broken(regions={"thing": "square"}), "must be a list of polygons"),
    "polygon with 2 points": (
        _broken(regions={"thing": [[[20, 20], [30, 30]]]}),
        "polygon 1 of class 'thing' has 2 point(s); it needs at least 3",
    ),
    "point as string": (
        _broken(regions={"thing": [[[20, 20], "30, 30", [30, 20]]]}),
        "every point must be [row, col]",
    ),
    "point with NaN": (
        '{"frame": "s.png", "mosaic": [90, 45, 135, 0], "shape": [40, 50], "classes": ["a"], '
        '"regions": {"a": [[[1, 1], [1, NaN], [5, 5]]]}, "strokes": {}}',
        "every point must be [row, col]",
    ),
    "point outside the frame": (
        _broken(regions={"thing": [[[20, 20], [20, 60], [30, 30]]]}),
        "point [20, 60] lies outside the 40 x 50 frame",
    ),
    "unknown class in regions": (
        _broken(regions={"stone": [[[20, 20], [20, 30], [30, 30]]]}),
        "'regions' names unknown class 'stone'",
    ),
    "unknown class in strokes": (
        _broken(strokes={"stone": [[[20, 20], [20, 30]]]}),
        "'strokes' names unknown class 'stone'",
    ),
    "stroke of one point": (
        _broken(strokes={"thing": [[[25, 25]]]}),
        "stroke 1 of class 'thing' has 1 point(s); it needs at least 2",
    ),
    "overlapping classes": (
        _broken(
            regions={
                "background": [[[2, 2], [2, 30], [30, 30], [30, 2]]],
                "thing": [[[20, 20], [20, 45], [35, 45], [35, 20]]],
            }
        ),
        "polygons of classes 'background' and 'thing' overlap",
    ),
    "stroke in another class": (
        _broken(strokes={"background": [[[5, 5], [25, 30]]]}),
        "stroke 1 of class 'background' crosses a polygon of class 'thing'",
    ),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_file_raises_one_line(tmp_path, case):
    doc, expected = MALFORMED[case]
    if isinstance(doc, bytes):
        path = tmp_path / "truth.json"
        path.write_bytes(doc)
    else:
        path = _write(tmp_path, doc)
    with pytest.raises(PolarsegError) as info:
        read_truth_file(path)
    message = str(info.value)
    assert expected in message
    assert "\n" not in message
    assert str(path) in message


def test_shape_mismatch_with_the_frame(tmp_path):
    path = _write(tmp_path, _valid_doc())
    with pytest.raises(PolarsegError) as info:
        read_truth_file(path, expected_shape=(1024, 1224))
    message = str(info.value)
    assert "'shape' is 40 x 50 but the frame is 1024 x 1224" in message
    assert str(path) in message and "\n" not in message


def test_missing_and_huge_files(tmp_path, monkeypatch):
    missing = tmp_path / "nope.json"
    with pytest.raises(PolarsegError, match="cannot be read") as info:
        read_truth_file(missing)
    assert str(missing) in str(info.value)
    monkeypatch.setattr("napari_polarseg.truth.MAX_FILE_BYTES", 10)
    with pytest.raises(PolarsegError, match="more than the 10"):
        read_truth_file(_write(tmp_path, _valid_doc()))


def test_memory_limit(tmp_path, monkeypatch):
    monkeypatch.setenv("POLARSEG_MAX_BYTES", "1000")
    with pytest.raises(PolarsegError, match="rasterising truth file"):
        read_truth_file(_write(tmp_path, _valid_doc()))


def test_rasterise_script(tmp_path, capsys):
    import importlib.util

    from skimage import io as skio

    spec = importlib.util.spec_from_file_location(
        "rasterise_truth", REPO / "scripts" / "rasterise_truth.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    for name, counts in EXPECTED_TRUTH.items():
        stem = Path(name).stem
        labels = skio.imread(tmp_path / f"{stem}_truth.png")
        assert labels.dtype == np.uint8 and labels.shape == (1024, 1224)
        assert np.bincount(labels.ravel())[1:].tolist() == list(counts.values())
        strokes = skio.imread(tmp_path / f"{stem}_strokes.png")
        assert np.bincount(strokes.ravel())[1:].tolist() == list(EXPECTED_STROKES[name].values())
        for cls, n in counts.items():
            assert f"{cls}" in out and f"{n}" in out
    bad = _write(tmp_path, "{", "bad.json")
    assert module.main(["--out", str(tmp_path), str(bad)]) == 2
    assert "not valid JSON" in capsys.readouterr().err


# --- physics on the real frames --------------------------------------------------------------


def _class_medians(name: str) -> tuple[dict[str, float], dict[str, float]]:
    truth = read_truth_file(TRUTH_DIR / name)
    pim = frame_polarisation_image(truth, REAL_DIR)
    ok = ~np.asarray(pim.invalid) & np.isfinite(pim.dop) & np.isfinite(pim.intensity)
    med_i, med_rho = {}, {}
    for k, cls in enumerate(truth.classes, start=1):
        mask = (truth.truth == k) & ok
        assert mask.sum() > 0.95 * (truth.truth == k).sum()  # few saturated pixels
        med_i[cls] = float(np.median(pim.intensity[mask]))
        med_rho[cls] = float(np.median(pim.dop[mask]))
    return med_i, med_rho


@needs_real_data
def test_fruits_physics():
    """Measured: median Î 98 / 29 / 66 / 77 and ρ 0.031 / 0.131 / 0.065 / 0.118 for
    background / apple / orange / banana (8-bit Î, super-pixel demosaicing)."""
    med_i, med_rho = _class_medians("fruits_IMX250MZR.json")
    # Î: the white background is brightest, the dark red apple darkest
    assert med_i["background"] > 1.15 * med_i["banana"]
    assert med_i["banana"] > 1.08 * med_i["orange"]
    assert med_i["orange"] > 1.8 * med_i["apple"]
    # ρ: the matte paper is least polarised, the orange's rough peel next, the smooth
    # waxy apple and banana skins most
    assert med_rho["background"] < 0.6 * med_rho["orange"]
    assert med_rho["orange"] < 0.7 * min(med_rho["apple"], med_rho["banana"])
    assert med_rho["background"] < 0.05


@needs_real_data
def test_camera_physics():
    """Measured: median Î 148 / 16 / 20 and ρ 0.022 / 0.275 / 0.760 for mat / body /
    lens_cap."""
    med_i, med_rho = _class_medians("camera_IMX250MZR.json")
    # Î: the lit woven mat is far brighter than the black camera
    assert med_i["mat"] > 5 * max(med_i["body"], med_i["lens_cap"])
    # ρ: the rough mat is nearly unpolarised; the glossy cap polarises most
    assert med_rho["mat"] < 0.25 * med_rho["body"]
    assert med_rho["lens_cap"] > 2 * med_rho["body"]
    assert med_rho["lens_cap"] > 0.6 and med_rho["mat"] < 0.05


@needs_real_data
def test_carps_physics():
    """Measured: median Î 72 / 17 / 151 and ρ 0.644 / 0.286 / 0.409 for water /
    tree_reflection / fish."""
    med_i, med_rho = _class_medians("carps_IMX250MZR.json")
    # Î: the pale koi outshine the water; where the surface mirrors the dark tree it is darkest
    assert med_i["fish"] > 1.8 * med_i["water"]
    assert med_i["water"] > 3 * med_i["tree_reflection"]
    # ρ: the sky's reflection off the surface polarises most; where it mirrors the dark tree
    # the unpolarised light from below dominates
    assert med_rho["water"] > 1.3 * med_rho["fish"]
    assert med_rho["fish"] > 1.2 * med_rho["tree_reflection"]


@needs_real_data
def test_polarizer_physics():
    """Measured: median Î 129 / 63 / 22 and ρ 0.026 / 0.437 / 0.113 for outdoor_scene /
    filter / interior."""
    med_i, med_rho = _class_medians("polarizer_IMX250MZR.json")
    # Î: the filters pass about half the window's light; the room below is dark
    assert med_i["outdoor_scene"] > 1.6 * med_i["filter"]
    assert med_i["filter"] > 2 * med_i["interior"]
    # ρ: the linear polariser film polarises what it passes; the scene through the glass hardly
    assert med_rho["filter"] > 10 * med_rho["outdoor_scene"]
    assert med_rho["filter"] > 3 * med_rho["interior"]
    assert med_rho["outdoor_scene"] < 0.05


@needs_real_data
@pytest.mark.parametrize("name", BUNDLED)
def test_truth_matches_the_frame(name):
    truth = read_truth_file(TRUTH_DIR / name)
    from napari_polarseg.io import read_stack

    data = read_stack(real_frame_path(truth, REAL_DIR), mosaic=list(truth.mosaic))
    assert data.stack.shape == (4, *truth.shape)
    read_truth_file(TRUTH_DIR / name, expected_shape=data.stack.shape[1:])
