"""Rasterise the hand-labelled truth files and draw previews for checking them.

For every truth JSON (default: the bundled ``napari_polarseg/sample_data/truth/*.json``)
this writes into ``--out``:

- ``<stem>_truth.png``: uint8 labels, 0 = unlabelled / ignored, k = class k (1-based, in
  the file's class order);
- ``<stem>_strokes.png``: uint8 labels of the strokes, same convention;

and prints the pixels per class. With ``--preview`` it also writes ``<stem>_preview.png``:
the polygons (outlines) and strokes (thick lines) over the frame's smoothed degree of
polarisation ρ and its intensity Î, with a coordinate grid, so a reviewer can check that
every polygon sits inside its object. ``--crop`` zooms the preview on one region.

Usage::

    .venv/bin/python scripts/rasterise_truth.py --out /tmp/truth [--preview]
        [--frames DIR] [--crop R0,R1,C0,C1] [--grid 50] [FILE.json ...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from skimage import io as skio

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from napari_polarseg.engine.errors import PolarsegError  # noqa: E402
from napari_polarseg.truth import (  # noqa: E402
    TruthFile,
    frame_polarisation_image,
    read_truth_file,
    truth_files,
)

#: Where the raw polanalyser frames are found by default (as in the tests).
FRAMES_DIR = (ROOT / ".." / "shared" / "data" / "polanalyser").resolve()

#: Outline colours of the classes, in class order (matplotlib "tab10").
COLOURS = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
)


def parse_crop(text: str) -> tuple[int, int, int, int]:
    """``"r0,r1,c0,c1"`` → a tuple of 4 ints (half-open row and column ranges)."""
    try:
        r0, r1, c0, c1 = (int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--crop must be R0,R1,C0,C1, not {text!r}") from None
    if r1 <= r0 or c1 <= c0:
        raise argparse.ArgumentTypeError(f"--crop {text}: empty range")
    return r0, r1, c0, c1


def write_labels(truth: TruthFile, out: Path) -> tuple[Path, Path]:
    """Write the truth and stroke label images of ``truth`` as uint8 PNGs into ``out``."""
    stem = Path(truth.path).stem
    paths = (out / f"{stem}_truth.png", out / f"{stem}_strokes.png")
    for path, labels in zip(paths, (truth.truth, truth.strokes), strict=True):
        skio.imsave(path, labels.astype(np.uint8), check_contrast=False)
    return paths


def count_table(truth: TruthFile) -> str:
    """Pixels per class (polygons and strokes) as a small text table."""
    regions = truth.pixel_counts("truth")
    strokes = truth.pixel_counts("strokes")
    lines = [f"{Path(truth.path).name} ({truth.frame}, {truth.shape[0]} x {truth.shape[1]})"]
    lines.append(f"  {'label':>5}  {'class':<12} {'truth px':>9} {'stroke px':>9}")
    for k, name in enumerate(truth.classes, start=1):
        lines.append(f"  {k:>5}  {name:<12} {regions[name]:>9} {strokes[name]:>9}")
    unlabelled = int(np.count_nonzero(truth.truth == 0))
    lines.append(f"  {0:>5}  {'(ignored)':<12} {unlabelled:>9}")
    return "\n".join(lines)


def write_preview(
    truth: TruthFile,
    frames: Path,
    out: Path,
    crop: tuple[int, int, int, int] | None = None,
    grid: int = 50,
) -> Path:
    """Draw the polygons and strokes over ρ (5 × 5 mean) and Î of the real frame."""
    from matplotlib import colormaps
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from scipy import ndimage as ndi

    pim = frame_polarisation_image(truth, frames)
    bad = np.asarray(pim.invalid, bool) | ~np.isfinite(pim.dop) | ~np.isfinite(pim.intensity)
    rho = ndi.uniform_filter(np.where(bad, 0.0, np.asarray(pim.dop, float)), 5)
    weight = ndi.uniform_filter((~bad).astype(float), 5)
    rho = np.ma.masked_where(weight < 0.5, rho / np.maximum(weight, 1e-9))
    intensity = np.ma.masked_where(bad, np.asarray(pim.intensity, float))
    height, width = truth.shape
    r0, r1, c0, c1 = crop if crop is not None else (0, height, 0, width)
    r0, c0 = max(r0, 0), max(c0, 0)
    r1, c1 = min(r1, height), min(c1, width)
    rows, cols = r1 - r0, c1 - c0
    panel_w = 9.0
    panel_h = panel_w * rows / cols
    fig = Figure(figsize=(2 * panel_w + 0.6, panel_h + 0.9), dpi=110)
    FigureCanvasAgg(fig)
    views = (
        (rho, "magma", 0.0, float(np.percentile(rho.compressed(), 99.5)), "ρ (5×5 mean)"),
        (
            intensity,
            "gray",
            float(np.percentile(intensity.compressed(), 0.5)),
            float(np.percentile(intensity.compressed(), 99.5)),
            "intensity Î",
        ),
    )
    extent = (c0 - 0.5, c1 - 0.5, r1 - 0.5, r0 - 0.5)
    for i, (img, cmap, vmin, vmax, title) in enumerate(views):
        ax = fig.add_subplot(1, 2, i + 1)
        colours = colormaps[cmap].with_extremes(bad="#00c0ff")
        ax.imshow(
            img[r0:r1, c0:c1], cmap=colours, vmin=vmin, vmax=vmax, extent=extent,
            interpolation="nearest",
        )  # fmt: skip
        ticks_r = np.arange((r0 // grid + 1) * grid, r1, grid)
        ticks_c = np.arange((c0 // grid + 1) * grid, c1, grid)
        for t in ticks_c:
            ax.axvline(t, color="cyan", lw=0.3, alpha=0.5)
        for t in ticks_r:
            ax.axhline(t, color="cyan", lw=0.3, alpha=0.5)
        ax.set_xticks(ticks_c)
        ax.set_yticks(ticks_r)
        ax.tick_params(labelsize=5)
        for label in ax.get_xticklabels():
            label.set_rotation(90)
        for k, name in enumerate(truth.classes):
            colour = COLOURS[k % len(COLOURS)]
            for j, poly in enumerate(truth.regions.get(name, ())):
                closed = np.vstack([poly, poly[:1]])
                ax.plot(
                    closed[:, 1], closed[:, 0], "-", color=colour, lw=0.9,
                    label=name if j == 0 else None,
                )  # fmt: skip
            for path in truth.stroke_paths.get(name, ()):
                ax.plot(path[:, 1], path[:, 0], "-", color=colour, lw=2.2)
                ax.plot(path[:, 1], path[:, 0], "-", color="white", lw=0.5)
        ax.set_xlim(c0 - 0.5, c1 - 0.5)
        ax.set_ylim(r1 - 0.5, r0 - 0.5)
        ax.set_title(f"{truth.frame}: {title}; light blue = no valid fit (saturated)", fontsize=8)
        if i == 0:
            ax.legend(fontsize=6, loc="lower left", framealpha=0.7)
    fig.tight_layout()
    suffix = "" if crop is None else f"_{r0}-{r1}_{c0}-{c1}"
    path = out / f"{Path(truth.path).stem}_preview{suffix}.png"
    fig.savefig(path)
    return path


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="*", type=Path, help="truth JSONs (default: bundled)")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--preview", action="store_true", help="also draw preview PNGs")
    parser.add_argument(
        "--frames", type=Path, default=FRAMES_DIR, help=f"raw frames folder ({FRAMES_DIR})"
    )
    parser.add_argument("--crop", type=parse_crop, help="preview only rows R0:R1, cols C0:C1")
    parser.add_argument("--grid", type=int, default=50, help="preview grid step (px)")
    args = parser.parse_args(argv)
    files = args.files or truth_files()
    if not files:
        print("no truth files found", file=sys.stderr)
        return 1
    args.out.mkdir(parents=True, exist_ok=True)
    try:
        for file in files:
            truth = read_truth_file(file)
            truth_png, strokes_png = write_labels(truth, args.out)
            print(count_table(truth))
            print(f"  wrote {truth_png} and {strokes_png}")
            if args.preview:
                preview = write_preview(truth, args.frames, args.out, args.crop, args.grid)
                print(f"  wrote {preview}")
    except PolarsegError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
