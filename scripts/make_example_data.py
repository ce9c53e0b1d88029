#!/usr/bin/env python
"""Write the example inputs that README.md's commands use, from the bundled samples.

    examples/data/leaves_stack.tif    the bundled synthetic leaves scene
                                      (napari_polarseg/sample_data/leaves.npz) as a
                                      multi-page uint16 TIFF, 7 frames at 0..180 degrees,
                                      the angles in its JSON ImageDescription
    examples/data/leaves_strokes.tif  a few painted strokes on it (uint8, 0 = unpainted,
                                      k + 1 = true material k), for --scribbles
    napari_polarseg/sample_data/<scene>_strokes.tif
                                      the same kind of strokes on each bundled synthetic
                                      scene, which `polarseg demo` trains on

The raw polarisation-camera frame the README uses is the bundled
napari_polarseg/sample_data/fruits_IMX250MZR_crop.png itself
(scripts/make_real_sample.py). Deterministic: rerunning writes the same pixels.

Usage::

    python scripts/make_example_data.py [--out DIR]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import tifffile
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from napari_polarseg.io import write_stack_tiff  # noqa: E402

SAMPLES = ROOT / "napari_polarseg" / "sample_data"
SAMPLE = SAMPLES / "leaves.npz"
#: The sample scenes that get bundled strokes (``sample_data/<scene>_strokes.tif``).
SAMPLE_SCENES = ("leaves", "camouflage", "fruit")
DEFAULT_OUT = ROOT / "examples" / "data"
#: Strokes: every STROKE_ROWS-th row, in runs of STROKE_LENGTH columns of every
#: STROKE_PERIOD, inside each material eroded by ERODE pixels.
STROKE_ROWS, STROKE_LENGTH, STROKE_PERIOD, ERODE = 16, 12, 32, 3


def strokes(truth: np.ndarray) -> np.ndarray:
    """Short horizontal strokes well inside every true material (label k + 1)."""
    rows, cols = np.indices(truth.shape)
    on_grid = (rows % STROKE_ROWS == STROKE_ROWS // 2) & (cols % STROKE_PERIOD < STROKE_LENGTH)
    out = np.zeros(truth.shape, dtype=np.uint8)
    for k in np.unique(truth):
        inside = ndimage.binary_erosion(truth == k, iterations=ERODE)
        out[inside & on_grid] = k + 1
    return out


def main(argv: list[str] | None = None) -> int:
    """Write the stack and the strokes; print their sizes."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    with np.load(SAMPLE) as data:
        stack, angles, truth = data["stack"], data["angles"], data["labels"]
    written = [args.out / "leaves_stack.tif", args.out / "leaves_strokes.tif"]
    write_stack_tiff(written[0], stack.astype(np.uint16), angles)
    tifffile.imwrite(written[1], strokes(truth), compression="zlib")
    # the demo's bundled strokes, one file per sample scene (polarseg demo trains on them)
    for scene in SAMPLE_SCENES:
        with np.load(SAMPLES / f"{scene}.npz") as data:
            written.append(SAMPLES / f"{scene}_strokes.tif")
            tifffile.imwrite(written[-1], strokes(data["labels"]), compression="zlib")
    for path in written:
        print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
