"""Speed of the pixel classifier (issue 12 targets), printed with the stage seconds.

Rows (each the median of ``--repeats`` runs in this process; whole-process figures for
the CLI row):

- pixel features + prediction on the 720 × 660 reference stack (target ≤ 1.0 s): the
  polarisation image is computed first and not counted;
- retraining on 5,000 scribbled pixels (target ≤ 0.5 s);
- a 1224 × 1024 polarisation-camera frame end to end, ``polarseg segment FRAME --mosaic
  90,45,135,0 --scribbles STROKES`` as a fresh process (target ≤ 5 s): the real fruits
  frame with its bundled strokes when ``../shared`` is beside the repository, else a
  rendered frame of that size.

Usage::

    .venv/bin/python benchmarks/bench_pixel.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_speed import median_time
from scipy import ndimage

from napari_polarseg.engine import polarisation_image
from napari_polarseg.engine.classifier.pixel_classifier import (
    ClassifierParams,
    predict_pixels,
    train_pixel_classifier,
)
from napari_polarseg.engine.features.pixel_features import EPS_INTENSITY, pixel_features
from napari_polarseg.engine.synthetic.scenes import make_scene, scribble_strokes

REPO = Path(__file__).resolve().parents[1]
REAL = REPO.parent / "shared" / "data" / "polanalyser" / "fruits_IMX250MZR.png"
TARGETS = {"features + prediction": 1.0, "retraining": 0.5, "camera frame end to end": 5.0}


def verdict(name: str, seconds: float) -> str:
    target = TARGETS[name]
    if seconds <= target:
        return f"met (target {target} s)"
    return f"MISSED by {seconds - target:.2f} s (target {target} s)"


def strokes_of(labels: np.ndarray, pixels: int) -> np.ndarray:
    """Long strokes, 3 px wide, until about ``pixels`` scribbled pixels."""
    s = scribble_strokes(labels, seed=0, per_material=12, length=90)
    s = ndimage.grey_dilation(s, size=(3, 3))
    index = np.flatnonzero(s.ravel())
    keep = np.zeros(s.size, dtype=bool)
    keep[index[:: max(1, index.size // pixels)]] = True
    return np.where(keep.reshape(s.shape), s, 0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    sc = make_scene("leaves", shape=(720, 660), angles_deg=np.arange(0, 181, 10))
    pol = polarisation_image(sc.stack, sc.angles)
    guide = np.log(np.maximum(pol.intensity, EPS_INTENSITY)).astype(np.float32)
    strokes = strokes_of(sc.labels, 5000)
    feats = pixel_features(pol.intensity, pol.dop, pol.phase)
    clf = train_pixel_classifier(feats, strokes)

    def features_and_prediction():
        f = pixel_features(pol.intensity, pol.dop, pol.phase)
        return predict_pixels(clf, f, guide=guide)

    t_feat, _ = median_time(lambda: pixel_features(pol.intensity, pol.dop, pol.phase), args.repeats)
    t_pred, _ = median_time(lambda: predict_pixels(clf, feats, guide=guide), args.repeats)
    t_both, _ = median_time(features_and_prediction, args.repeats)
    t_train, trained = median_time(
        lambda: train_pixel_classifier(feats, strokes, ClassifierParams()), args.repeats
    )
    print(
        f"reference stack 720 x 660, {feats.n_features} features, {trained.n_training_pixels} "
        "scribbled pixels"
    )
    print(
        f"  features + prediction      {t_both:6.3f} s  {verdict('features + prediction', t_both)}"
        f"  (features {t_feat:.3f}, prediction + smoothing {t_pred:.3f})"
    )
    print(f"  retraining                 {t_train:6.3f} s  {verdict('retraining', t_train)}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if REAL.is_file():
            from napari_polarseg.truth import read_truth_file, truth_files

            truth = read_truth_file([p for p in truth_files() if "fruits" in p.name][0])
            frame, what = REAL, "real fruits frame with its bundled strokes"
            stroke_img = truth.strokes
        else:
            cam = make_scene("leaves", shape=(1024, 1224), angles_deg=(0, 45, 90, 135))
            from napari_polarseg.engine.physics.mosaic import mosaic_superpixel

            frame = tmp / "frame.npy"
            np.save(frame, mosaic_superpixel(cam.stack, (90, 45, 135, 0)))
            what = "rendered 1224 x 1024 frame"
            stroke_img = scribble_strokes(cam.labels, seed=0)
        np.save(tmp / "strokes.npy", stroke_img.astype(np.int32))
        cmd = [
            sys.executable,
            "-m",
            "napari_polarseg.cli",
            "segment",
            str(frame),
            "--mosaic",
            "90,45,135,0",
            "--scribbles",
            str(tmp / "strokes.npy"),
            "--out",
            str(tmp / "o"),
        ]
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True)
            times.append(time.perf_counter() - t0)
        t_cam = float(np.median(times))
        import json

        summary = json.loads((tmp / "o" / "summary.json").read_text())
    stages = summary["stage_seconds"]
    print(f"camera frame end to end ({what}, a fresh process)")
    print(
        f"  polarseg segment --scribbles {t_cam:6.3f} s  "
        f"{verdict('camera frame end to end', t_cam)}"
    )
    print(
        "  stage seconds: "
        + ", ".join(f"{k} {v:.2f}" for k, v in stages.items())
        + f"; classifier {summary['classifier']['seconds']}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
