"""The scribbles method's watershed grid on large frames: the robot user
(:mod:`robot_user`: one disc per material, then one on the largest wrong region each
round) on the hand-labelled camera frames upsampled ``F`` times, with the superpixels'
watershed on the grid of :func:`~napari_polarseg.engine.features.superpixels.watershed_grid`
and on a fixed grid for comparison.

A frame of 1.25 MP has regions of 417 px (watershed on the 2× coarser grid); upsampled
2× or 3× (5 or 11 MP, as a 5 MP sensor or a DSLR sees the same scene) its regions are of
1024 px, where the rule's grid is 4. The stack is upsampled bilinearly
(``scipy.ndimage.zoom``, order 1), the truth by repetition. Printed per frame and grid:
ARI (over the labelled pixels) after the discs and after each correction, the
corrections to ARI 0.9, the seconds; then the means over the frames.

Usage::

    cd benchmarks && OMP_NUM_THREADS=1 PYTHONPATH=.. python watershed_grid.py \\
        [--upsample 2] [--compare 2] [--rounds 5]
"""

from __future__ import annotations

import argparse
import time
from unittest import mock

import numpy as np
from robot_user import product_update, real_scenes, run_robot
from scipy import ndimage

from napari_polarseg.engine import Pipeline
from napari_polarseg.engine.classifier import pixel_segmentation
from napari_polarseg.engine.features.superpixels import watershed_grid


def upsampled(stack: np.ndarray, truth: np.ndarray, factor: int) -> tuple[np.ndarray, np.ndarray]:
    """(stack, truth) ``factor`` times larger: bilinear per angle, truth repeated."""
    big = np.stack([ndimage.zoom(a.astype(np.float32), factor, order=1) for a in stack])
    return big, np.repeat(np.repeat(truth, factor, axis=0), factor, axis=1)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--upsample", type=int, default=2)
    ap.add_argument("--compare", type=int, default=2, help="the fixed grid compared")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args(argv)
    grids = {"rule": watershed_grid, f"grid {args.compare}": lambda area: args.compare}
    rows: dict[str, list[tuple[float, float, int]]] = {n: [] for n in grids}
    for scene in real_scenes():
        stack, truth = upsampled(scene.stack, scene.truth, args.upsample)
        for name, grid in grids.items():
            t0 = time.perf_counter()
            with mock.patch.object(pixel_segmentation, "watershed_grid", grid):
                update = product_update(Pipeline(stack, scene.angles_rad))
                run = run_robot(truth, update, args.rounds)
            to_09 = next((i for i, a in enumerate(run.ari) if a >= 0.9), args.rounds + 1)
            rows[name].append((run.ari[0], run.ari[-1], to_09))
            print(
                f"{scene.name} {stack.shape[1]}x{stack.shape[2]} {name} (area grid "
                f"{grid(1024)}): ARI by round {[round(a, 3) for a in run.ari]}, "
                f"corrections to 0.9: {to_09}, {time.perf_counter() - t0:.0f} s",
                flush=True,
            )
    print(f"\n| watershed | discs | after {args.rounds} | corrections to 0.9 (sum) |")
    print("|---|---:|---:|---:|")
    for name, values in rows.items():
        a = np.asarray(values, dtype=float)
        print(f"| {name} | {a[:, 0].mean():.3f} | {a[:, 1].mean():.3f} | {int(a[:, 2].sum())} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
