"""Make the bundled real polarisation-camera sample reproducibly.

Crops a 512 x 512 region of the raw 2448 x 2048 Sony IMX250MZR mosaic
``fruits_IMX250MZR.png`` (apple, background and orange; MIT licence, see
``napari_polarseg/sample_data/LICENSE-polanalyser.md``) at an even offset, so that the
2 x 2 polariser super-pixels keep their layout (90, 45 / 135, 0 degrees), and saves it
as an 8-bit PNG into ``napari_polarseg/sample_data/``. The napari sample
"Fruits (polarisation camera)" demosaics it into a 4-angle stack (0/45/90/135).

Usage::

    .venv/bin/python scripts/make_real_sample.py [--source DIR]
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
#: The real frames beside the repository: ../shared/data/polanalyser (docs/data.md, "Optional
#: real data", says where they come from).
SOURCE_DIR = ROOT / ".." / "shared" / "data" / "polanalyser"
SOURCE_NAME = "fruits_IMX250MZR.png"
SOURCE_SHA256 = "8e9c22aa2ab0c4b48374a3fa27330fc4800daeb178e3a4bfd513d7e0f5d4fa49"
OUT = ROOT / "napari_polarseg" / "sample_data" / "fruits_IMX250MZR_crop.png"
LICENSE_OUT = ROOT / "napari_polarseg" / "sample_data" / "LICENSE-polanalyser.md"

#: Top-left corner (row, column) of the crop in the raw mosaic; both even.
OFFSET = (256, 1088)
#: Side of the square crop in raw pixels (even).
SIZE = 512


def crop_mosaic(raw: np.ndarray, offset: tuple[int, int] = OFFSET, size: int = SIZE) -> np.ndarray:
    """Crop a raw 2 x 2 mosaic at an even offset so the super-pixel layout is kept."""
    r0, c0 = offset
    if r0 % 2 or c0 % 2 or size % 2:
        raise ValueError(f"offset {offset} and size {size} must be even")
    if r0 + size > raw.shape[0] or c0 + size > raw.shape[1]:
        raise ValueError(f"crop {offset} + {size} does not fit the {raw.shape} frame")
    return np.ascontiguousarray(raw[r0 : r0 + size, c0 : c0 + size])


def licence_notice(sources_md: str) -> str:
    """The licence part of the data's SOURCES.md, with a header naming the crop."""
    start = sources_md.index("## MIT License")
    return (
        "# Licence of `fruits_IMX250MZR_crop.png`\n\n"
        f"`fruits_IMX250MZR_crop.png` is a {SIZE} x {SIZE} crop (rows {OFFSET[0]} to "
        f"{OFFSET[0] + SIZE - 1}, columns {OFFSET[1]} to {OFFSET[1] + SIZE - 1}) of the raw\n"
        f"Sony IMX250MZR frame `{SOURCE_NAME}` (2448 x 2048, 8-bit, 2 x 2 polariser\n"
        "super-pixels 90/45 over 135/0 degrees) from the GitHub repository elerac/polanalyser,\n"
        "commit 4bb8edd778a3787f303344263637e908924cf3d6, folder images/. It is made by\n"
        "`scripts/make_real_sample.py`. The original licence follows.\n\n"
        + sources_md[start:].rstrip()
        + "\n"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--source",
        type=Path,
        default=SOURCE_DIR,
        help="polanalyser data folder [../shared/data/polanalyser beside the repository]",
    )
    args = parser.parse_args(argv)
    src = args.source / SOURCE_NAME
    if not src.is_file():
        print(
            f"error: {SOURCE_NAME} not found in {args.source} (the real frames go in "
            "../shared/data/polanalyser beside the repository; see docs/data.md)",
            file=sys.stderr,
        )
        return 1
    digest = hashlib.sha256(src.read_bytes()).hexdigest()
    if digest != SOURCE_SHA256:
        print(f"error: {src} has SHA-256 {digest}, expected {SOURCE_SHA256}", file=sys.stderr)
        return 1
    raw = np.asarray(Image.open(src))
    if raw.shape != (2048, 2448) or raw.dtype != np.uint8:
        print(f"error: expected a 2048 x 2448 uint8 frame, got {raw.shape} {raw.dtype}")
        return 1
    crop = crop_mosaic(raw)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(crop).save(OUT, optimize=True)
    LICENSE_OUT.write_text(licence_notice((args.source / "SOURCES.md").read_text()))
    pixels = hashlib.sha256(crop.tobytes()).hexdigest()
    print(f"wrote {OUT.relative_to(ROOT)} ({OUT.stat().st_size} bytes, pixel SHA-256 {pixels})")
    print(f"wrote {LICENSE_OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
