"""Issue 25: a frame given as a raw mosaic is checked: colour images are refused, a frame
without a 2 x 2 pixel pattern gets a warning."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from napari_polarseg import cli
from napari_polarseg.io.mosaic_checks import MIN_NYQUIST_SHARE, nyquist_share

REPO = Path(__file__).resolve().parents[1]
CROP = REPO / "napari_polarseg" / "sample_data" / "fruits_IMX250MZR_crop.png"
REAL_DIR = REPO / ".." / "shared" / "data" / "polanalyser"
LAYOUT = "90,45,135,0"


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def raw():
    """The bundled raw crop, cut to 128 x 128 (even offset) to keep the runs quick."""
    return np.asarray(Image.open(CROP))[128:256, 128:256]


def test_a_colour_image_given_as_a_mosaic_is_refused(tmp_path, capsys, raw):
    rgb = np.stack([raw, raw // 2, raw // 3], axis=-1).astype(np.uint8)
    for name, image in (("rgb.png", rgb), ("rgba.png", np.dstack([rgb, np.full_like(raw, 255)]))):
        Image.fromarray(image).save(tmp_path / name)
        code, out, err = run(
            capsys, "segment", tmp_path / name, "--out", tmp_path / "o", "--mosaic", LAYOUT
        )
        assert code == 2 and out == ""
        assert err.count("\n") == 1 and err.startswith("polarseg: error: ")
        assert name in err and "colour image" in err and "raw" in err
        assert not (tmp_path / "o").exists()


def test_a_grey_frame_saved_as_rgb_is_read_as_its_grey_channel(tmp_path, capsys, raw):
    Image.fromarray(np.stack([raw] * 3, axis=-1)).save(tmp_path / "grey.png")
    code, _, err = run(
        capsys, "segment", tmp_path / "grey.png", "--out", tmp_path / "o", "--mosaic", LAYOUT, "-q"
    )
    assert code == 0, err
    assert "warning" not in err


def test_a_frame_without_a_2x2_pattern_gets_a_warning(tmp_path, capsys, raw):
    smooth = ndimage.gaussian_filter(raw.astype(float), 2).astype(np.uint8)  # blurred
    assert nyquist_share(smooth) < MIN_NYQUIST_SHARE
    Image.fromarray(smooth).save(tmp_path / "smooth.png")
    code, _, err = run(
        capsys, "segment", tmp_path / "smooth.png", "--out", tmp_path / "o", "--mosaic", LAYOUT
    )
    assert code == 0, err
    (line,) = [line for line in err.splitlines() if "warning" in line]
    assert line.startswith("polarseg: warning: smooth.png shows no 2 x 2 pixel pattern")


def test_the_bundled_raw_frame_gets_no_warning(tmp_path, capsys, raw):
    assert nyquist_share(np.asarray(Image.open(CROP))) > 3 * MIN_NYQUIST_SHARE
    Image.fromarray(raw).save(tmp_path / "raw.png")
    code, _, err = run(
        capsys, "segment", tmp_path / "raw.png", "--out", tmp_path / "o", "--mosaic", LAYOUT
    )
    assert code == 0, err
    assert "warning" not in err


@pytest.mark.skipif(
    not REAL_DIR.is_dir(),
    reason="real polarisation-camera frames not found in ../shared/data/polanalyser "
    "(beside the repository; docs/data.md, 'Optional real data')",
)
def test_the_real_raw_frames_show_their_2x2_pattern():
    frames = sorted(REAL_DIR.glob("*_IMX250MZR.png"))
    assert frames
    for path in frames:
        share = nyquist_share(np.asarray(Image.open(path)))
        assert share > 2 * MIN_NYQUIST_SHARE, (path.name, share)
