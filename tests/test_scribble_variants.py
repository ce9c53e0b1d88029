"""benchmarks/scribble_variants.py: a variant's score does not depend on the variants
run before it on the same frame (the walk-superpixel and unsure-walk variants patch
the walk for their own run only), and the variants that should differ on small objects do."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import scribble_variants  # noqa: E402
from families import Frame  # noqa: E402

from napari_polarseg.engine.classifier import pixel_segmentation, region_walk  # noqa: E402
from napari_polarseg.engine.classifier.region_walk import walk, walk_region_area  # noqa: E402
from napari_polarseg.engine.synthetic.scenes import make_scene  # noqa: E402


def test_a_variant_scores_the_same_after_the_others():
    """Small leaves (about 12 px): ``default`` scores the same alone and after the
    variants that patch the walk or cap the scales otherwise."""
    sc = make_scene("scattered_leaves", shape=(120, 160), seed=1, object_size=12.0)
    truth = sc.labels.astype(np.int32) + 1  # 0 = not scored
    frame = Frame("leaves", sc.stack, sc.angles, truth, int(truth.max()), 12.0, "diffuse", "dev")
    names = (
        "walk superpixels 0.25 D",
        "classifier where the walk is unsure by 0.5",
        "every scale",
        "default",
    )
    chosen = {n: scribble_variants.VARIANTS[n] for n in names}
    after = scribble_variants.frame_scores(frame, chosen, 1)
    alone = scribble_variants.frame_scores(frame, {"default": chosen["default"]}, 1)
    assert after["default"] == alone["default"]
    assert pixel_segmentation.walk_region_area is walk_region_area  # the patch is undone
    assert region_walk.walk is walk
    assert after["every scale"] != after["default"]  # σ = 16 is dropped at 12 px
    assert np.isfinite(np.ravel(list(after.values()))).all()
