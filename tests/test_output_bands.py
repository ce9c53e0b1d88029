"""Large results' output images made band by band (issue 39): the same files and values
as the whole-image functions, checked on small images with tiny bands."""

from __future__ import annotations

import numpy as np
import pytest
import tifffile
from PIL import Image

from napari_polarseg import io as pio
from napari_polarseg.engine.analysis.evaluation import segment_statistics
from napari_polarseg.engine.analysis.views import (
    CompositeParams,
    aolp_dolp_composite,
    auto_dolp_max,
)
from napari_polarseg.engine.physics.stokes import stokes_components
from napari_polarseg.outputs import band_statistics, bands

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # NaN and inf inputs


@pytest.fixture
def small_bands(monkeypatch: pytest.MonkeyPatch) -> None:
    """Bands of 7 rows, and every image counted as large (made band by band)."""
    monkeypatch.setattr(bands, "BAND_ROWS", 7)
    monkeypatch.setattr(bands, "TILED_PIXELS", 1)
    monkeypatch.setattr("napari_polarseg.io.tiff_tiles.TILED_PIXELS", 1)


def _maps(seed: int = 0, shape: tuple[int, int] = (45, 38)) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    maps = {
        "intensity": rng.uniform(-5, 200, shape),
        "dop": rng.uniform(0, 0.6, shape),
        "zenith": rng.uniform(0, 1.5, shape),
        "phase": rng.uniform(0, np.pi, shape),
    }
    maps["intensity"][3, 4] = np.nan
    maps["phase"][10, 2] = np.inf
    maps["dop"][30, 30] = np.nan
    return maps


def test_map_written_in_bands_equals_whole(small_bands: None, tmp_path) -> None:
    value = _maps()["dop"]
    meta = {"quantity": "degree of polarisation", "unit": "1"}
    lazy = bands.as_dtype(value, np.float32)
    assert pio.is_lazy(lazy)
    pio.write_tiff(tmp_path / "bands.tif", lazy, meta)
    pio.write_tiff(tmp_path / "whole.tif", np.asarray(value, np.float32), meta)
    assert (tmp_path / "bands.tif").read_bytes() == (tmp_path / "whole.tif").read_bytes()
    read = tifffile.imread(tmp_path / "bands.tif")
    assert np.array_equal(read, value.astype(np.float32), equal_nan=True)


def test_stokes_labels_mask_in_bands(small_bands: None) -> None:
    m = _maps(1)
    whole = stokes_components(m["intensity"], m["dop"], m["phase"]).astype(np.float32)
    banded = np.asarray(bands.stokes_image(m["intensity"], m["dop"], m["phase"]))
    assert np.array_equal(banded, whole, equal_nan=True)
    labels = np.random.default_rng(2).integers(0, 5, (45, 38))
    assert bands.labels_image_banded(labels).dtype == np.uint16
    assert np.array_equal(np.asarray(bands.labels_image_banded(labels)), labels)
    valid = labels > 1
    assert np.array_equal(np.asarray(bands.used_pixels_banded(valid, labels.shape)), valid)
    assert np.asarray(bands.used_pixels_banded(None, labels.shape)).all()


@pytest.mark.parametrize("mode", ["intensity", "light", "dark"])
def test_composite_in_bands(small_bands: None, mode: str) -> None:
    m = _maps(3)
    rho_max = bands.auto_dolp_max_banded(m["dop"])
    assert rho_max == auto_dolp_max(m["dop"])
    params = CompositeParams(dolp_max=rho_max, mode=mode)
    whole = aolp_dolp_composite(m["intensity"], m["dop"], m["phase"], params)
    picture = bands.composite_image(m["intensity"], m["dop"], m["phase"], params)
    assert np.array_equal(np.asarray(picture), whole)


def test_composite_png_same_file(small_bands: None, tmp_path) -> None:
    m = _maps(4)
    params = CompositeParams(dolp_max=0.5)
    whole = aolp_dolp_composite(m["intensity"], m["dop"], m["phase"], params)
    pio.write_png(tmp_path / "whole.png", whole)
    bands.write_picture(tmp_path / "bands.png", Image.fromarray(whole))
    assert (tmp_path / "whole.png").read_bytes() == (tmp_path / "bands.png").read_bytes()


def test_percentile_without_copy_on_disk(small_bands: None) -> None:
    from napari_polarseg.engine import disk_arrays

    values = disk_arrays.disk_empty((45, 38))
    values[...] = _maps(5)["intensity"]
    expected = np.percentile(values[np.isfinite(values)], 99.0)
    assert bands.finite_percentile(values, 99.0) == expected
    assert bands.finite_percentile(np.full((3, 3), np.nan), 50.0) is None


@pytest.mark.parametrize("with_valid", [False, True])
def test_segment_statistics_in_bands(small_bands: None, with_valid: bool) -> None:
    m = _maps(6)
    rng = np.random.default_rng(7)
    labels = rng.integers(0, 4, (45, 38))
    labels[labels == 2] = 3  # a segment without pixels
    valid = rng.random((45, 38)) > 0.2 if with_valid else None
    block_labels = rng.integers(0, 5, (5, 4))
    features = rng.normal(size=(20, 4))
    kwargs = {"valid": valid, "block_labels": block_labels, "features": features}
    whole = segment_statistics(labels, *m.values(), **kwargs)
    banded = band_statistics.banded_segment_statistics(labels, *m.values(), **kwargs)
    assert banded == whole or _same_rows(banded, whole)


def _same_rows(a: list[dict], b: list[dict]) -> bool:
    """Rows equal, NaN equal to NaN."""
    return len(a) == len(b) and all(
        ra.keys() == rb.keys()
        and all(ra[k] == rb[k] or (ra[k] != ra[k] and rb[k] != rb[k]) for k in ra)
        for ra, rb in zip(a, b, strict=True)
    )


def _folder_files(out) -> dict[str, bytes]:
    """Every file of a result folder but summary.json (it holds the seconds)."""
    return {
        str(p.relative_to(out)): p.read_bytes()
        for p in sorted(out.rglob("*"))
        if p.is_file() and p.name != "summary.json"
    }


def test_result_folder_in_bands_same_files(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The whole folder (thesis maps, overview, NaN and excluded pixels) written with
    every image made band by band is the folder written whole, byte for byte."""
    import dataclasses

    from napari_polarseg.engine import Pipeline, SegmentParams
    from napari_polarseg.engine.synthetic.scenes import make_scene
    from napari_polarseg.outputs import write_result_folder

    scene = make_scene("leaves", shape=(40, 48))
    result = Pipeline(scene.stack, scene.angles, SegmentParams(window=8, n_segments=3)).run()
    valid = np.ones(result.labels.shape, bool)
    valid[5:9, 3:20] = False
    intensity = result.intensity.copy()
    intensity[2, 2] = np.nan
    result = dataclasses.replace(result, valid=valid, intensity=intensity)
    common = {"stack": scene.stack, "angles_deg": scene.angles_deg, "result": result}
    # both written as tiled BigTIFF (a large image's files); then made whole, or in bands
    monkeypatch.setattr("napari_polarseg.io.tiff_tiles.TILED_PIXELS", 1)
    write_result_folder(tmp_path / "whole", **common, overview=True)
    monkeypatch.setattr(bands, "BAND_ROWS", 6)
    monkeypatch.setattr(bands, "TILED_PIXELS", 1)
    write_result_folder(tmp_path / "bands", **common, overview=True)
    whole, banded = _folder_files(tmp_path / "whole"), _folder_files(tmp_path / "bands")
    assert "aolp_dolp.png" in whole and "stokes.tif" in whole
    assert banded.keys() == whole.keys()
    assert [name for name in whole if banded[name] != whole[name]] == []
