"""Speed and memory of the engine against baselines, measured side by side in one run.

Builds the reference inputs from the synthetic generator, runs every target of issue 5
("Interactive speed") and every baseline, and prints ONE table: stage, seconds (median of
repeats), peak memory (RSS of a fresh subprocess, ``resource.getrusage``), ratio to the
baseline (baseline seconds / ours), target and met/missed.

Reference input: ``make_scene("leaves", shape=(720, 660), angles_deg=0..180 step 10)``
(19 angles), thesis parameters w = 10, L = 12, 3 segments (4,752 blocks). Camera frame:
``make_scene("leaves", shape=(1024, 1224), angles_deg=(0, 45, 90, 135))`` (one
2448 × 2048 polarisation-camera frame after super-pixel demosaicing), w = 8 (19,584
blocks). The inputs are rendered once and cached (``--cache``; the camera frame takes a
few minutes to render the first time).

Baselines
---------
- *straightforward*: the thesis-era implementation — a Python loop over blocks calling
  ``scipy.special.sph_harm_y`` for every (l, m), scikit-learn PCA, a dense affinity from
  ``scipy.spatial.distance.cdist``, and ``scipy.linalg.eigh`` of the full generalized
  problem (D − W) y = λ D y for every cut (the same greedy split rule as the engine). The
  harmonic and reconstruction loops are timed on a subset of blocks and extrapolated to
  all blocks (marked "extrapolated").
- ``scipy.special.sph_harm_y_all`` and the previous engine's ``sph_legendre_p_all`` plus
  trigonometry, for the harmonic stage.
- ``skimage.graph.cut_normalized`` and ``sklearn.cluster.SpectralClustering(affinity=
  "precomputed")`` on the same affinity as the engine's normalized cut: time and
  agreement (adjusted Rand index, ARI) with it.

Bounded cuts (issue 13)
-----------------------
- The thesis preset (w = 10, L = 12, s = 1, 3 segments) on the real 1224 × 1024 frames
  of ``../shared/data/polanalyser`` (IMX250MZR mosaics, layout 90,45,135,0; 12,444 blocks,
  sparse kNN graph), the whole pipeline in a fresh process as ``polarseg segment`` runs
  it; target 15 s each. Their graphs have fallen apart: before the work limits, the cut
  of the camera and carps frames took 455 and 737 s. Skipped with a message when the
  folder is absent.
- A constructed fallen-apart frame: the synthetic 1224 × 1024 camera frame with
  :data:`PLANTED_BLOCKS` blocks replaced by unique noise (isolated blocks, Ncut values
  near 0), same preset and target.
- A constructed fallen-apart affinity: 2,400 groups of 5 strongly tied nodes joined in a
  chain by weak links (12,000 nodes, sparse), whose smallest eigenvalues lie close
  together; the cut of 3 segments with the default product cap; target 15 s.

Usage::

    .venv/bin/python benchmarks/bench_speed.py              # the table, ~5-8 minutes
    .venv/bin/python benchmarks/bench_speed.py --repeats 5
    .venv/bin/python benchmarks/bench_speed.py --bounded    # only the bounded-cut rows
    .venv/bin/python benchmarks/bench_speed.py --auto       # only the default preset's rows

Not part of the test suite; ``tests/test_speed_equivalence.py`` imports the
straightforward baseline from here to check that the fast path gives the same labels.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.linalg
import scipy.special

REF_SHAPE = (720, 660)
REF_ANGLES = tuple(range(0, 181, 10))
CAM_SHAPE = (1024, 1224)
CAM_ANGLES = (0, 45, 90, 135)
SCENE = "leaves"
#: The real polarisation-camera frames beside the repository (``../shared``).
SHARED_FRAMES = Path(__file__).resolve().parents[2] / "shared" / "data" / "polanalyser"
FRAME_NAMES = ("fruits", "camera", "carps", "polarizer")
FRAME_MOSAIC = (90, 45, 135, 0)
#: Blocks of the synthetic camera frame replaced by unique noise (isolated blocks).
PLANTED_BLOCKS = 12
#: The thesis preset's whole run on a 1224 × 1024 frame may take this long (issue 13).
BOUNDED_TARGET = 15.0
#: Seconds allowed for the default preset's whole cold run (issue 13), by frame size.
AUTO_TARGET = {"720x660": 1.5, "1224x1024": 5.0}

# -- the straightforward baseline (thesis-era implementation) ------------------------------


def straightforward_harmonics(zenith: np.ndarray, azimuth: np.ndarray, degree: int) -> np.ndarray:
    """(M, (L+1)²) real harmonics at M points: one ``sph_harm_y`` call per (l, m)."""
    out = np.empty((zenith.size, (degree + 1) ** 2))
    for l in range(degree + 1):  # noqa: E741
        for m in range(-l, l + 1):
            c = scipy.special.sph_harm_y(l, abs(m), zenith, azimuth)
            if m > 0:
                v = np.sqrt(2.0) * (-1.0) ** m * c.real
            elif m < 0:
                v = np.sqrt(2.0) * (-1.0) ** m * c.imag
            else:
                v = c.real
            out[:, l * l + l + m] = v
    return out


def _block_pixels(a: np.ndarray, b: int, nbx: int, window: int) -> np.ndarray:
    r, c = divmod(b, nbx)
    return a[r * window : (r + 1) * window, c * window : (c + 1) * window].ravel()


def straightforward_coefficients(
    intensity: np.ndarray,
    zenith: np.ndarray,
    azimuth: np.ndarray,
    window: int,
    degree: int,
    blocks: np.ndarray | None = None,
) -> np.ndarray:
    """Eq. 4.21 block means by a Python loop over blocks (and (l, m) per block).

    Returns (n_blocks, (L+1)²); only ``blocks`` (default all) are filled, the rest NaN.
    """
    nby, nbx = intensity.shape[0] // window, intensity.shape[1] // window
    out = np.full((nby * nbx, (degree + 1) ** 2), np.nan)
    for b in range(nby * nbx) if blocks is None else blocks:
        f = _block_pixels(intensity, b, nbx, window)
        Y = straightforward_harmonics(
            _block_pixels(zenith, b, nbx, window), _block_pixels(azimuth, b, nbx, window), degree
        )
        out[b] = f @ Y / f.size
    return out


def straightforward_reconstruction(
    intensity: np.ndarray,
    zenith: np.ndarray,
    azimuth: np.ndarray,
    window: int,
    degree: int,
    ridge: float = 1e-3,
    blocks: np.ndarray | None = None,
) -> np.ndarray:
    """Per-block ridge fit and reconstruction by a loop over blocks (whole blocks only)."""
    nby, nbx = intensity.shape[0] // window, intensity.shape[1] // window
    m = window * window
    lam = ridge * m / (4 * np.pi)
    out = np.full((nby * nbx, m), np.nan)
    for b in range(nby * nbx) if blocks is None else blocks:
        f = _block_pixels(intensity, b, nbx, window)
        Y = straightforward_harmonics(
            _block_pixels(zenith, b, nbx, window), _block_pixels(azimuth, b, nbx, window), degree
        )
        a = np.linalg.solve(Y.T @ Y + lam * np.eye(Y.shape[1]), Y.T @ f)
        out[b] = Y @ a
    return out


def straightforward_affinity(
    coefficients: np.ndarray, variance: float, scale: float, scale_mode: str = "absolute"
) -> np.ndarray:
    """scikit-learn PCA, Mahalanobis distances from ``cdist``, exp(−D / s): dense."""
    from scipy.spatial.distance import cdist
    from sklearn.decomposition import PCA

    x = coefficients.reshape(-1, coefficients.shape[-1])
    pca = PCA(n_components=min(x.shape), svd_solver="full")
    scores = pca.fit_transform(x)
    keep = int(np.searchsorted(np.cumsum(pca.explained_variance_ratio_), variance - 1e-12) + 1)
    feats = scores[:, :keep]
    cov = np.cov(feats, rowvar=False, bias=True).reshape(keep, keep)
    d = cdist(feats, feats, "mahalanobis", VI=np.linalg.pinv(cov)) ** 2
    if scale_mode == "median":
        scale = scale * np.median(d[~np.eye(d.shape[0], dtype=bool)])
    return np.exp(-d / scale)


def straightforward_ncut(
    W: np.ndarray,
    n_segments: int,
    min_size: int = 1,
    history: list[tuple[np.ndarray, float]] | None = None,
) -> np.ndarray:
    """Greedy recursive Ncut with ``scipy.linalg.eigh`` of the full (D − W, D) problem.

    ``history``, if given, receives (labels, seconds since the start) after every split,
    so that one run gives the labels and times of every smaller number of segments.
    """
    from napari_polarseg.engine.graph.ncut import best_split

    t_start = time.perf_counter()
    n = W.shape[0]
    segments = [np.arange(n)]
    cache: dict[bytes, tuple[np.ndarray | None, float]] = {}

    def candidate(idx: np.ndarray) -> tuple[np.ndarray | None, float]:
        key = idx.tobytes()
        if key not in cache:
            if idx.size < max(2, 2 * min_size):
                cache[key] = (None, np.inf)
            else:
                sub = W[np.ix_(idx, idx)]
                D = np.diag(sub.sum(axis=1))
                _, vecs = scipy.linalg.eigh(D - sub, D)
                cache[key] = best_split(sub, vecs[:, 1], min_size)
        return cache[key]

    while len(segments) < n_segments:
        vals = [candidate(s)[1] for s in segments]
        best = int(np.argmin(vals))
        mask = candidate(segments[best])[0]
        if mask is None:
            break
        seg = segments[best]
        segments[best] = seg[mask]
        segments.append(seg[~mask])
        if history is not None:
            history.append((_labels_of(segments, n), time.perf_counter() - t_start))
    return _labels_of(segments, n)


def _labels_of(segments: list[np.ndarray], n: int) -> np.ndarray:
    from napari_polarseg.engine.graph.ncut import first_appearance_order

    labels = np.empty(n, dtype=np.int32)
    for lab, seg in enumerate(segments):
        labels[seg] = lab
    return first_appearance_order(labels)


def straightforward_segment(stack: np.ndarray, angles: np.ndarray, params) -> np.ndarray:
    """Block labels of the straightforward pipeline (no spatial term, dense, eigh)."""
    from napari_polarseg.engine import Pipeline
    from napari_polarseg.engine.features.pca import harmonic_features

    pipe = Pipeline(stack, angles, params)
    pol, nrm = pipe.get("polarisation"), pipe.get("normals")
    coef = straightforward_coefficients(
        pol.intensity, nrm.zenith, nrm.azimuth, params.window, params.degree
    )
    coef = harmonic_features(coef, params.features)  # a selection, not a speed matter
    W = straightforward_affinity(coef, params.variance, params.scale, params.scale_mode)
    return straightforward_ncut(W, params.n_segments, params.min_segment_blocks)


# -- measuring -------------------------------------------------------------------------------


def median_time(fn: Callable[[], object], repeats: int) -> tuple[float, object]:
    """Median wall-clock seconds of ``repeats`` calls, and the last call's result."""
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def peak_rss_mb() -> float:
    """Peak resident set size of this process, MiB.

    Linux: ``VmHWM`` of /proc/self/status, the high-water mark of this process's own
    memory. (``getrusage``'s ``ru_maxrss`` is kept across fork and exec, so a child
    started by a large parent would report the parent's peak.) Elsewhere ``ru_maxrss``.
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 2**20 if sys.platform == "darwin" else rss / 1024.0  # bytes / KiB


def ari(a: np.ndarray, b: np.ndarray) -> float:
    from sklearn.metrics import adjusted_rand_score

    return float(adjusted_rand_score(np.ravel(a), np.ravel(b)))


@dataclass
class Row:
    stage: str
    seconds: float | None
    peak_mb: float | None = None
    baseline: str = ""
    baseline_seconds: float | None = None
    target: float | None = None
    target_mb: float | None = None
    note: str = ""

    def ratio(self) -> str:
        if self.seconds is None or self.baseline_seconds is None or self.seconds <= 0:
            return ""
        return f"{self.baseline_seconds / self.seconds:,.1f}x"

    def verdict(self) -> str:
        if self.target is None and self.target_mb is None:
            return ""
        ok = self.seconds is not None
        if self.target is not None and self.seconds is not None:
            ok = ok and self.seconds <= self.target
        if self.target_mb is not None:
            ok = ok and self.peak_mb is not None and self.peak_mb <= self.target_mb
        if ok:
            return "met"
        over = []
        if self.target is not None and self.seconds is not None and self.seconds > self.target:
            over.append(f"{self.seconds - self.target:.3f} s")
        if self.target_mb is not None and self.peak_mb is not None:
            if self.peak_mb > self.target_mb:
                over.append(f"{self.peak_mb - self.target_mb:,.0f} MB")
        return "MISSED" + (f" by {', '.join(over)}" if over else "")


def print_table(rows: list[Row]) -> None:
    head = ["stage", "seconds", "peak MB", "baseline", "base s", "ratio", "target", "result"]
    lines = []
    for r in rows:
        target = []
        if r.target is not None:
            target.append(f"<= {r.target:g} s")
        if r.target_mb is not None:
            target.append(f"< {r.target_mb:,.0f} MB")
        lines.append(
            [
                r.stage,
                "" if r.seconds is None else f"{r.seconds:.3f}",
                "" if r.peak_mb is None else f"{r.peak_mb:,.0f}",
                r.baseline,
                "" if r.baseline_seconds is None else f"{r.baseline_seconds:,.2f}",
                r.ratio(),
                ", ".join(target),
                r.verdict() + (f" ({r.note})" if r.note else ""),
            ]
        )
    widths = [max(len(h), *(len(x[i]) for x in lines)) for i, h in enumerate(head)]
    fmt = " | ".join(f"{{:<{w}}}" for w in widths)
    print(fmt.format(*head))
    print("-+-".join("-" * w for w in widths))
    for x in lines:
        print(fmt.format(*x))


# -- inputs ----------------------------------------------------------------------------------


def build_inputs(cache: Path) -> dict[str, Path]:
    """Render (or reuse) the reference stack and the camera frame; return their paths."""
    from napari_polarseg.engine.synthetic.scenes import make_scene

    cache.mkdir(parents=True, exist_ok=True)
    paths = {}
    for key, shape, angles in (("ref", REF_SHAPE, REF_ANGLES), ("cam", CAM_SHAPE, CAM_ANGLES)):
        path = cache / f"{SCENE}_{key}_{shape[0]}x{shape[1]}_{len(angles)}.npz"
        if not path.exists():
            t0 = time.perf_counter()
            sc = make_scene(SCENE, shape=shape, angles_deg=angles)
            tmp = path.with_suffix(".tmp.npz")
            np.savez(tmp, stack=sc.stack, angles=np.deg2rad(sc.angles_deg), labels=sc.labels)
            os.replace(tmp, path)
            print(f"rendered {path.name} in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        paths[key] = path
    return paths


def load(path: Path) -> tuple[np.ndarray, np.ndarray]:
    with np.load(path) as f:
        return f["stack"], f["angles"]


# -- child processes (one per memory measurement) --------------------------------------------


def planted_isolated(
    stack: np.ndarray, window: int = 10, n: int = PLANTED_BLOCKS, seed: int = 0
) -> np.ndarray:
    """``stack`` with ``n`` w × w blocks (seeded) replaced by unique uniform noise: their
    polarisation fits nothing else, so at the thesis scale they are isolated blocks of
    the affinity (less than 1e-6 of their degree leaves them) and the cut's Ncut values
    are ~0."""
    rng = np.random.default_rng(seed)
    out = stack.copy()
    rows, cols = stack.shape[1] // window, stack.shape[2] // window
    top = float(np.iinfo(out.dtype).max) if out.dtype.kind in "ui" else float(out.max())
    for b in rng.choice(rows * cols, size=n, replace=False):
        r, c = divmod(int(b), cols)
        patch = rng.uniform(0.05, 0.9, size=(stack.shape[0], window, window)) * top
        out[:, r * window : (r + 1) * window, c * window : (c + 1) * window] = patch
    return out


def chain_of_groups(n_groups: int = 2_400, size: int = 5, eps: float = 1e-2, seed: int = 0):
    """A fallen-apart sparse affinity: groups of ``size`` strongly tied nodes, joined in
    a chain by one weak link (~``eps``) each; the smallest Laplacian eigenvalues are a
    long chain's, close together, and the Jacobi preconditioner cannot separate them."""
    import scipy.sparse as sps

    rng = np.random.default_rng(seed)
    blocks = [0.5 + 0.5 * rng.random((size, size)) for _ in range(n_groups)]
    W = sps.block_diag(blocks, format="csr")
    ends = np.arange(size - 1, (n_groups - 1) * size, size)
    weak = eps * (0.5 + rng.random(ends.size))
    link = sps.csr_matrix((weak, (ends, ends + 1)), shape=W.shape)
    W = W.maximum(W.T) + link + link.T
    W.setdiag(1.0)
    return W.tocsr()


def thesis_frame_child(task: str, path: Path) -> dict:
    """The thesis preset's whole run on a 1224 × 1024 frame (a real mosaic PNG, or the
    synthetic camera frame with planted isolated blocks)."""
    from napari_polarseg import io as pio
    from napari_polarseg.engine import Pipeline, SegmentParams

    if task == "thesis-frame":
        data = pio.read_stack(str(path), mosaic=np.array(FRAME_MOSAIC))
        stack, angles = data.stack, data.angles_rad
    else:
        stack, angles = load(path)
        stack = planted_isolated(stack)
    t0 = time.perf_counter()
    res = Pipeline(stack, angles, SegmentParams(method="thesis", n_segments=3)).run()
    seconds = time.perf_counter() - t0
    check = res.degenerate()
    return {
        "seconds": seconds,
        "peak_mb": peak_rss_mb(),
        "n_blocks": int(res.block_labels.size),
        "stage_seconds": res.timings,
        "cut_limits": res.cut_limits,
        "ncut_values": [float(v) for v in res.ncut_values],
        "largest_share": check.largest_share,
        "degenerate": check.degenerate,
    }


def bounded_rows(cache: Path) -> tuple[list[Row], list[str]]:
    """The rows of issue 13's bounded cuts (module docstring) and their details
    (``cache``: the folder of the rendered inputs, :func:`build_inputs`)."""
    from napari_polarseg.engine.graph import ncut

    rows: list[Row] = []
    notes: list[str] = []

    def add(label: str, out: dict) -> None:
        limits = out["cut_limits"]
        rows.append(
            Row(
                label,
                out["seconds"],
                out["peak_mb"],
                target=BOUNDED_TARGET,
                note=(
                    f"labels {out['stage_seconds']['labels']:.2f} s, "
                    f"{limits['products']} products, capped {limits['eigensolver_capped']}, "
                    f"isolated {limits['isolated_skipped']}"
                ),
            )
        )
        ncuts = ", ".join(f"{v:.2g}" for v in out["ncut_values"])
        notes.append(
            f"  {label}: Ncut values {ncuts}; largest segment "
            f"{100 * out['largest_share']:.2f} % (degenerate: {out['degenerate']}); stages "
            + ", ".join(f"{k} {v:.2f}" for k, v in out["stage_seconds"].items())
        )

    frames = [SHARED_FRAMES / f"{name}_IMX250MZR.png" for name in FRAME_NAMES]
    if not SHARED_FRAMES.is_dir():
        notes.append(f"  real frames skipped: {SHARED_FRAMES} is absent")
    for path in (f for f in frames if f.is_file()):
        out = run_child("thesis-frame", path)
        add(f"thesis preset, real {path.stem} 1224x1024 ({out['n_blocks']} blocks)", out)
    out = run_child("thesis-planted", build_inputs(cache)["cam"])
    add(f"thesis preset, synthetic frame + {PLANTED_BLOCKS} isolated blocks", out)

    W = chain_of_groups()
    t0 = time.perf_counter()
    tree = ncut.CutTree(W)
    tree.labels(3)
    seconds = time.perf_counter() - t0
    limits = tree.cut_limits()
    rows.append(
        Row(
            f"Ncut k=3, chain-of-groups affinity ({W.shape[0]} nodes, sparse)",
            seconds,
            target=BOUNDED_TARGET,
            note=(
                f"{limits['products']} products, capped {limits['eigensolver_capped']}, "
                f"cap {limits['max_products']} per solve"
            ),
        )
    )
    notes.append(f"  chain-of-groups Ncut values {', '.join(f'{v:.2g}' for v in tree.ncut_values)}")
    return rows, notes


def auto_child(task: str, path: Path) -> dict:
    """The default preset's (``auto``) whole run, cold, in this fresh process: on the
    720 × 660 reference, the synthetic 1224 × 1024 camera frame, or a real frame."""
    from napari_polarseg import io as pio
    from napari_polarseg.engine import Scene
    from napari_polarseg.engine.params import AUTO

    if task == "auto-frame":
        data = pio.read_stack(str(path), mosaic=np.array(FRAME_MOSAIC))
        stack, angles = data.stack, data.angles_rad
    else:
        stack, angles = load(path)
    t0 = time.perf_counter()
    res = Scene(stack, angles).segment(AUTO.replace(n_segments=3))
    seconds = time.perf_counter() - t0
    return {
        "seconds": seconds,
        "peak_mb": peak_rss_mb(),
        "shape": list(res.labels.shape),
        "stage_seconds": res.timings,
        "degenerate": res.degenerate().degenerate,
    }


def auto_rows(cache: Path) -> tuple[list[Row], list[str]]:
    """Rows of the default preset ``auto`` (issue 13): whole cold runs in fresh processes
    (:data:`AUTO_TARGET`), and their stage seconds."""
    rows: list[Row] = []
    notes: list[str] = []
    paths = build_inputs(cache)
    runs = [("auto-ref", paths["ref"], "720x660"), ("auto-cam", paths["cam"], "1224x1024")]
    runs += [
        ("auto-frame", SHARED_FRAMES / f"{name}_IMX250MZR.png", "1224x1024")
        for name in FRAME_NAMES[:2]
        if (SHARED_FRAMES / f"{name}_IMX250MZR.png").is_file()
    ]
    for task, path, size in runs:
        out = run_child(task, path)
        where = "synthetic" if task != "auto-frame" else f"real {path.stem}"
        label = f"auto preset (default), cold, {where} {'x'.join(map(str, out['shape']))}"
        rows.append(Row(label, out["seconds"], out["peak_mb"], target=AUTO_TARGET[size]))
        notes.append(
            f"  {label}: degenerate {out['degenerate']}; stages "
            + ", ".join(f"{k} {v:.2f}" for k, v in out["stage_seconds"].items())
        )
    return rows, notes


def child(task: str, path: Path) -> dict:
    """Run one task in this (fresh) process; report seconds and peak RSS."""
    from napari_polarseg.engine import Pipeline, SegmentParams

    if task in ("thesis-frame", "thesis-planted"):
        return thesis_frame_child(task, path)
    if task.startswith("auto-"):
        return auto_child(task, path)
    stack, angles = load(path)
    params = {
        "cold": SegmentParams(method="thesis", window=10, degree=12, n_segments=3),
        "l30": SegmentParams(method="thesis", window=10, degree=30, n_segments=3),
        "camera": SegmentParams(method="thesis", window=8, degree=12, n_segments=3),
    }[task]
    t0 = time.perf_counter()
    res = Pipeline(stack, angles, params).run()
    seconds = time.perf_counter() - t0
    return {
        "seconds": seconds,
        "peak_mb": peak_rss_mb(),
        "n_blocks": int(res.block_labels.size),
        "stage_seconds": res.timings,
    }


def run_child(task: str, path: Path) -> dict:
    out = subprocess.run(
        [sys.executable, __file__, "--child", task, "--input", str(path)],
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


# -- the benchmark ---------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="repeats per timing [3]")
    parser.add_argument(
        "--cache",
        type=Path,
        default=Path(tempfile.gettempdir()) / "napari-polarseg-bench",
        help="folder for the rendered inputs [%(default)s]",
    )
    parser.add_argument("--subset", type=int, default=240, help="blocks timed for loops [240]")
    parser.add_argument(
        "--bounded", action="store_true", help="only the bounded-cut rows of issue 13"
    )
    parser.add_argument(
        "--auto", action="store_true", help="only the rows of the default preset auto"
    )
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--input", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.input)))
        return 0
    if args.bounded or args.auto:
        t_start = time.perf_counter()
        rows, notes = (auto_rows if args.auto else bounded_rows)(args.cache)
        what = "default preset auto" if args.auto else "bounded cuts"
        print(f"napari-polarseg {what} — {os.cpu_count()} CPUs, load {_load()}")
        print_table(rows)
        print("details:")
        print("\n".join(notes))
        print(f"total benchmark time {time.perf_counter() - t_start:.0f} s")
        return 0

    from napari_polarseg.engine import Pipeline, SegmentParams
    from napari_polarseg.engine.features import harmonics
    from napari_polarseg.engine.graph import affinity as feat
    from napari_polarseg.engine.graph import ncut
    from napari_polarseg.engine.params import RECOMMENDED

    t_start = time.perf_counter()
    reps = max(1, args.repeats)
    paths = build_inputs(args.cache)
    stack, angles = load(paths["ref"])
    params = SegmentParams(method="thesis", window=10, degree=12, n_segments=3)
    rows: list[Row] = []

    # ---- ours: the whole pipeline and its interactive changes -----------------------------
    cold = run_child("cold", paths["ref"])  # memory of a fresh process, first run
    t_cold, res = median_time(lambda: Pipeline(stack, angles, params).run(), reps)
    ours_labels = res.block_labels.ravel()
    pipe = Pipeline(stack, angles, params)
    pipe.run()
    pol, nrm = pipe.get("polarisation"), pipe.get("normals")
    I, Z, A = pol.intensity, nrm.zenith, nrm.azimuth  # noqa: E741

    change_stages: dict[str, dict[str, float]] = {}  # stage seconds of each change's runs

    def timed_change(base: Pipeline, prefetch: bool = False, **kw) -> float:
        """Median seconds of a run after changing ``kw``, from the state after ``base``
        (with ``prefetch``: after the plugin's idle-time ``Pipeline.prefetch``)."""
        times, splits = [], []
        for _ in range(reps):
            p = Pipeline(stack, angles, base.params)
            # the state right after a cold run (the cut tree copied: it grows in place)
            p._cache = {
                k: (v[0], copy.deepcopy(v[1]) if k == "cut" else v[1])
                for k, v in base._cache.items()
            }
            p.distances = base.distances
            if prefetch:
                list(p.prefetch())
            params = p.params.replace(**kw)
            t0 = time.perf_counter()
            result = p.run(params)
            times.append(time.perf_counter() - t0)
            splits.append({k: result.timings[k] for k in result.recomputed})
        label = f"{base.params.features} w{base.params.window} " + ", ".join(
            f"{k} {v:g}" for k, v in kw.items()
        )
        label += " after prefetch" if prefetch else ""
        change_stages[label] = {k: float(np.median([s[k] for s in splits])) for k in splits[0]}
        return float(np.median(times))

    t_k2 = timed_change(pipe, n_segments=2)
    t_k4 = timed_change(pipe, n_segments=4)
    t_k4p = timed_change(pipe, prefetch=True, n_segments=4)
    t_s2 = timed_change(pipe, scale=2.0)
    t_n = timed_change(pipe, refractive_index=1.6)
    t_w = timed_change(pipe, window=12)
    # the same interactions with the recommended preset (w 12, L 8, zonal, median scale)
    t_rcold, _ = median_time(lambda: Pipeline(stack, angles, RECOMMENDED).run(), reps)
    rpipe = Pipeline(stack, angles, RECOMMENDED)
    rpipe.run()
    r_k4 = timed_change(rpipe, n_segments=4)
    r_s = timed_change(rpipe, scale=3.0)
    r_n = timed_change(rpipe, refractive_index=1.6)
    r_w = timed_change(rpipe, window=14)
    t_h12, _ = median_time(lambda: harmonics.block_coefficients(I, Z, A, 10, 12), reps)
    t_h30, _ = median_time(lambda: harmonics.block_coefficients(I, Z, A, 10, 30), reps)
    t_rec, _ = median_time(lambda: harmonics.reconstruct_intensity(I, Z, A, 10, 12), reps)
    l30 = run_child("l30", paths["ref"])
    cam = run_child("camera", paths["cam"])

    # ---- baselines ------------------------------------------------------------------------
    nb = ours_labels.size
    subset = np.linspace(0, nb - 1, min(args.subset, nb)).astype(int)
    scale_up = nb / subset.size
    t0 = time.perf_counter()
    straightforward_coefficients(I, Z, A, 10, 12, subset)
    b_h12 = (time.perf_counter() - t0) * scale_up
    sub30 = subset[:: max(1, subset.size // 60)]
    t0 = time.perf_counter()
    straightforward_coefficients(I, Z, A, 10, 30, sub30)
    b_h30 = (time.perf_counter() - t0) * nb / sub30.size
    t0 = time.perf_counter()
    straightforward_reconstruction(I, Z, A, 10, 12, blocks=subset)
    b_rec = (time.perf_counter() - t0) * scale_up
    # library evaluation of all harmonics at every pixel, on a tenth of the pixels
    pts = slice(0, I.size // 10)
    zf, af = Z.ravel()[pts], A.ravel()[pts]
    t0 = time.perf_counter()
    scipy.special.sph_harm_y_all(12, 12, zf, af)
    b_all12 = (time.perf_counter() - t0) * 10
    t0 = time.perf_counter()
    scipy.special.sph_legendre_p_all(12, 12, zf)
    ms = np.arange(1, 13)[:, None]
    np.cos(ms * af[None]), np.sin(ms * af[None])
    b_leg12 = (time.perf_counter() - t0) * 10
    coef = pipe.get("harmonics")
    # as the pipeline stores it from dense_graph.FLOAT32_MIN_NODES blocks (each entry computed
    # in float64); the cut tree multiplies with it directly
    t_aff_ours, W = median_time(
        lambda: feat.affinity_matrix(pipe.get("pca").features, 1.0, "absolute", np.float32),
        reps,
    )
    t0 = time.perf_counter()
    W_sf = straightforward_affinity(coef, params.variance, params.scale)
    b_aff = time.perf_counter() - t0
    t_cut_ours, labels_cut = median_time(lambda: ncut.CutTree(W).labels(3), reps)
    tree = ncut.CutTree(W)
    tree.labels(3)
    t0 = time.perf_counter()
    labels_cut4 = tree.labels(4)
    t_cut4 = time.perf_counter() - t0
    # eigh per cut up to 4 segments; the 3-segment labels and time from the same run
    steps: list[tuple[np.ndarray, float]] = []
    straightforward_ncut(W_sf, 4, history=steps)
    (labels_sf, b_cut), (labels_sf4, b_cut4) = steps[1], steps[2]
    b_cut4 -= b_cut
    b_total = b_h12 + b_aff + b_cut + b_rec + pipe.stage_seconds("polarisation")
    b_scale = b_aff + b_cut

    # other normalized-cut / spectral implementations on the same affinity
    from sklearn.cluster import SpectralClustering

    t_sc, sc_labels = median_time(
        lambda: SpectralClustering(3, affinity="precomputed", random_state=0).fit_predict(W), 1
    )
    knn = feat.knn_affinity(pipe.get("pca").features)
    t_knn_cut, knn_labels = median_time(lambda: ncut.CutTree(knn).labels(3), reps)
    knn_tree = ncut.CutTree(knn)
    knn_tree.labels(3)
    thresh = max(knn_tree.ncut_values) * 1.01
    t_sk, sk_labels = median_time(lambda: _skimage_ncut(knn, thresh), 1)

    # ---- the table ------------------------------------------------------------------------
    sf = "straightforward"
    rows += [
        Row(
            "cold run 720x660x19, w10 L12 k3 (stack -> labels + error map)",
            t_cold,
            cold["peak_mb"],
            sf + " (loops extrapolated)",
            b_total,
            1.5,
            note=f"fresh process {cold['seconds']:.2f} s",
        ),
        Row("  change n_segments 3 -> 2 (cached tree)", t_k2, target=0.2),
        Row("  change n_segments 3 -> 4 (one more split)", t_k4, target=0.2),
        Row("  same, after the plugin's idle-time prefetch", t_k4p, target=0.2),
        Row("  change affinity scale 1 -> 2", t_s2, None, sf, b_scale, 0.5),
        Row(
            "  change refractive index 1.45 -> 1.6",
            t_n,
            None,
            sf + " (loops extrapolated)",
            b_total - pipe.stage_seconds("polarisation"),
            1.0,
        ),
        Row("  change window 10 -> 12", t_w, None, "", None, 1.0),
        Row("cold run, RECOMMENDED preset (w12 L8 zonal, median s=2)", t_rcold, target=1.5),
        Row("  change n_segments 3 -> 4", r_k4, target=0.2),
        Row("  change affinity scale 2 -> 3", r_s, target=0.5),
        Row("  change refractive index 1.45 -> 1.6", r_n, target=1.0),
        Row("  change window 12 -> 14", r_w, target=1.0),
        Row("harmonic stage L=12 (eq. 4.21)", t_h12, None, sf + " (extrapolated)", b_h12, 0.15),
        Row("  same, L=12", t_h12, None, "sph_harm_y_all, all pixels (1/10 x10)", b_all12),
        Row("  same, L=12", t_h12, None, "sph_legendre_p_all + trig (1/10 x10)", b_leg12),
        Row("harmonic stage L=30", t_h30, None, sf + " (extrapolated)", b_h30, 1.0),
        Row("reconstruction + error map L=12", t_rec, None, sf + " (extrapolated)", b_rec),
        Row(
            "affinity (dense float32, 4752 blocks)",
            t_aff_ours,
            None,
            sf + " (sklearn PCA+cdist)",
            b_aff,
        ),
        Row(
            "Ncut tree k=3 (dense, 4752 blocks)",
            t_cut_ours,
            None,
            "scipy.linalg.eigh per cut",
            b_cut,
            note=f"ARI vs eigh {ari(labels_sf, labels_cut):.3f}",
        ),
        Row(
            "  one more cut, k=4",
            t_cut4,
            None,
            "scipy.linalg.eigh",
            b_cut4,
            note=f"ARI vs eigh {ari(labels_sf4, labels_cut4):.3f}",
        ),
        Row(
            "  same affinity",
            t_cut_ours,
            None,
            "sklearn SpectralClustering",
            t_sc,
            note=f"ARI vs our Ncut {ari(labels_cut, sc_labels):.3f}",
        ),
        Row(
            "Ncut tree k=3 (kNN graph, 4752 blocks)",
            t_knn_cut,
            None,
            "skimage cut_normalized",
            t_sk,
            note=(
                f"ARI vs our Ncut {ari(knn_labels, sk_labels):.3f}, "
                f"{np.unique(sk_labels).size} segments; kNN vs dense ARI "
                f"{ari(knn_labels, labels_cut):.3f}"
            ),
        ),
        Row(
            "L=30 whole pipeline (fresh process)",
            l30["seconds"],
            l30["peak_mb"],
            target=6.0,
            target_mb=1.5 * 1024,
        ),
        Row(
            f"camera frame 1224x1024x4, w8 ({cam['n_blocks']} blocks, sparse kNN)",
            cam["seconds"],
            cam["peak_mb"],
            "straightforward Ncut (eigh, n^3 extrap.)",
            b_cut * (cam["n_blocks"] / nb) ** 3,
            15.0,
        ),
    ]
    bounded, bounded_notes = bounded_rows(args.cache)
    rows += bounded
    auto, auto_notes = auto_rows(args.cache)
    rows += auto
    print(
        f"napari-polarseg speed benchmark — {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPUs, numpy {np.__version__}, scipy {scipy.__version__}; "
        f"median of {reps} (fresh-process rows: 1 run); ratio = baseline s / ours; "
        f"load {_load()}"
    )
    print_table(rows)
    print("bounded cuts (issue 13):")
    print("\n".join(bounded_notes))
    print("default preset auto (issue 13):")
    print("\n".join(auto_notes))
    for name, stages in (("in-process", res.timings), ("fresh process", cold["stage_seconds"])):
        print(
            f"cold-run stage seconds ({name}): "
            + ", ".join(f"{k} {v:.3f}" for k, v in stages.items())
            + f"; without the polarisation fit {sum(stages.values()) - stages['polarisation']:.3f}"
        )
    print("stage seconds of the changes (median over the repeats; what a miss is made of):")
    for label, stages in change_stages.items():
        print(f"  {label}: " + ", ".join(f"{k} {v:.3f}" for k, v in stages.items()))
    print(
        "camera-frame stage seconds: "
        + ", ".join(f"{k} {v:.3f}" for k, v in cam["stage_seconds"].items())
    )
    print(f"total benchmark time {time.perf_counter() - t_start:.0f} s")
    return 0


def _load() -> str:
    """The host's load averages (other processes slow every row down)."""
    try:
        return "/".join(f"{v:.1f}" for v in os.getloadavg()) + " (1/5/15 min)"
    except OSError:  # pragma: no cover - not on Linux
        return "n/a"


def _skimage_ncut(W, thresh: float) -> np.ndarray:
    """``skimage.graph.cut_normalized`` on a sparse affinity (nodes = blocks).

    Its recursion stops on an Ncut threshold, not a number of segments; we pass the
    largest Ncut value of our own splits plus 1 % (so it may stop at another count).
    Building its networkx graph is included in the time.
    """
    import scipy.sparse as sps
    from skimage import graph

    W = sps.triu(sps.csr_matrix(W), k=1).tocoo()
    rag = graph.RAG()
    n = W.shape[0]
    for i in range(n):
        rag.add_node(i, labels=[i])
    rag.add_weighted_edges_from(zip(W.row.tolist(), W.col.tolist(), W.data.tolist(), strict=True))
    labels = np.arange(n)
    return graph.cut_normalized(labels, rag, thresh=thresh, num_cuts=10, rng=0)


if __name__ == "__main__":
    raise SystemExit(main())
