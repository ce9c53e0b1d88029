"""Figures of the time-series change map on the synthetic growing bruise.

The renderer (``render_fruit_days``) and the figures (``figures``) are those of
``tests/test_timeseries.py``: the bruised fruit of ``make_scene("fruit")`` (120 × 130)
whose bruise grows by 10 px between two days, segmented with RECOMMENDED at 2 segments.
Also runs two days with the same truth and independent noise (nothing changed).

    .venv/bin/python benchmarks/bench_timeseries.py               # 10 seeds, ~1 min
    .venv/bin/python benchmarks/bench_timeseries.py --seeds 5 --methods tracked
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_timeseries import PARAMS, figures, render_fruit_days  # noqa: E402

from napari_polarseg.engine.analysis.timeseries import METHODS, segment_timeseries  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--false-alarm", type=float, default=1e-3)
    ap.add_argument("--change-window", type=int, default=None)
    ap.add_argument("--change-from", default="all")
    args = ap.parse_args(argv)
    rows: dict[str, list[dict[str, float]]] = {m: [] for m in args.methods}
    nulls: dict[str, list[dict[str, float]]] = {m: [] for m in args.methods}
    t_start = time.perf_counter()
    for seed in range(args.seeds):
        angles, stacks, truths = render_fruit_days(seed=seed)
        _, null_stacks, _ = render_fruit_days(seed=seed, grow_px=(0.0, 0.0))
        for method in args.methods:
            kw = dict(
                method=method,
                false_alarm=args.false_alarm,
                change_window=args.change_window,
                change_from=args.change_from,
            )
            t0 = time.perf_counter()
            res = segment_timeseries(stacks, angles, PARAMS, **kw)
            fig = figures(res, truths)
            fig["seconds"] = time.perf_counter() - t0
            rows[method].append(fig)
            null = segment_timeseries(null_stacks, angles, PARAMS, **kw)
            nulls[method].append(
                {
                    "null_changed_pixels": float(null.changes[0].mean()),
                    "null_significant_blocks": float(null.change_significant[0].sum()),
                    "null_blocks": float(null.change_significant[0].size),
                    "null_inflation": null.change_statistics[0].inflation,
                }
            )
            print(
                f"seed {seed} {method:9s} "
                + " ".join(f"{k} {v:.3f}" for k, v in fig.items())
                + f" | null flagged {nulls[method][-1]['null_significant_blocks']:.0f}",
                flush=True,
            )
    print(
        f"\n{args.seeds} seeds, false alarm {args.false_alarm}, "
        f"{time.perf_counter() - t_start:.0f} s"
    )
    for method in args.methods:
        keys = list(rows[method][0]) + list(nulls[method][0])
        merged = [dict(**a, **b) for a, b in zip(rows[method], nulls[method], strict=True)]
        print(f"{method}:")
        for k in keys:
            vals = np.array([m[k] for m in merged])
            print(f"  {k:26s} mean {vals.mean():.4f}  min {vals.min():.4f}  max {vals.max():.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
