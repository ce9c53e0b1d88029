"""benchmarks/family_variants.py: a variant's score does not depend on the variants run
before it on the same frame (``truth size`` once gave every later variant the truth's
object size)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import family_variants  # noqa: E402
from families import Frame  # noqa: E402

from napari_polarseg.engine.methods import unregister_method  # noqa: E402
from napari_polarseg.engine.synthetic.scenes import make_scene  # noqa: E402


def test_a_variant_scores_the_same_after_truth_size():
    """Small leaves (about 12 px) whose true size, given, changes the default's scales:
    ``frame-share scales`` scores the same alone and after ``truth size``."""
    sc = make_scene("scattered_leaves", shape=(120, 160), seed=1, object_size=12.0)
    truth = sc.labels.astype(np.int32) + 1  # 0 = not scored
    frame = Frame("leaves", sc.stack, sc.angles, truth, int(truth.max()), 12.0, "diffuse", "dev")
    chosen = {n: family_variants.VARIANTS[n] for n in ("truth size", "frame-share scales")}
    methods = {n: family_variants.register(n, v) for n, v in chosen.items()}
    try:
        both = family_variants.frame_scores(frame, chosen, methods)
        alone = family_variants.frame_scores(
            frame, {"frame-share scales": chosen["frame-share scales"]}, methods
        )
    finally:
        for name in methods.values():
            unregister_method(name)
    assert both["frame-share scales"] == alone["frame-share scales"]
    assert both["truth size"] != both["frame-share scales"]  # the size given matters here
    assert np.isfinite(list(both.values())).all()
