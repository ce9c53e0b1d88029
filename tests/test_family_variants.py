"""benchmarks/family_variants.py: a variant's score does not depend on the variants run
before it on the same frame (``truth size`` once gave every later variant the truth's
object size)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from sklearn.metrics import adjusted_rand_score

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import family_variants  # noqa: E402
from families import Frame  # noqa: E402

from napari_polarseg.engine import Pipeline, Scene  # noqa: E402
from napari_polarseg.engine.features.object_size import estimate_object_size  # noqa: E402
from napari_polarseg.engine.methods import unregister_method  # noqa: E402
from napari_polarseg.engine.params import PRESETS  # noqa: E402
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


def test_size_from_polarisation_uses_rho_and_phi_only_and_leaves_the_scene_as_it_was():
    """``size from polarisation`` runs at the estimate of ρ cos 2φ, ρ sin 2φ alone (the
    estimate given a constant Î), and the default run after it on the same scene uses
    the scene's own estimate again and scores as it does alone."""
    sc = make_scene("fruit", shape=(120, 160), seed=2)  # estimates 38 px and 52 px
    truth = sc.labels.astype(np.int32) + 1
    frame = Frame("fruit", sc.stack, sc.angles, truth, int(truth.max()), np.nan, "diffuse", "dev")
    chosen = {n: family_variants.VARIANTS[n] for n in ("size from polarisation", "default")}
    methods = {n: family_variants.register(n, v) for n, v in chosen.items()}
    try:
        pipe = Pipeline(frame.stack, frame.angles, PRESETS["auto"].replace(n_segments=frame.k))
        scene, params = Scene(pipeline=pipe), pipe.params
        polarised = scene.segment(params.replace(method=methods["size from polarisation"]))
        assert "object_size" not in vars(scene)  # the scene's own method is back
        default = scene.segment(params.replace(method=methods["default"]))
        pol = scene.polarisation(params)
        flat = np.ones(pol.intensity.shape, dtype=np.float32)
        want = estimate_object_size(flat, pol.dop, pol.phase, ~pol.invalid).size_px
        own = estimate_object_size(pol.intensity, pol.dop, pol.phase, ~pol.invalid).size_px
        both = family_variants.frame_scores(frame, chosen, methods)
        alone = family_variants.frame_scores(frame, {"default": chosen["default"]}, methods)
    finally:
        for name in methods.values():
            unregister_method(name)
    assert polarised.method_record["object_size"] == round(want, 1)
    assert default.method_record["object_size"] == round(own, 1)
    assert abs(want - own) > 5.0  # the two estimates differ on this scene
    assert both["default"] == alone["default"]


def test_steadier_size_keeps_the_size_whose_labels_change_least_when_nudged():
    """``steadier size`` on a scene whose two estimates differ (38 and 52 px): its labels
    are the default's at whichever of the two sizes agrees more with its own labels at
    0.9 and 1.1 times it, computed here run by run."""
    sc = make_scene("fruit", shape=(120, 160), seed=2)
    chosen = {"steadier size": family_variants.VARIANTS["steadier size"]}
    methods = {n: family_variants.register(n, v) for n, v in chosen.items()}
    try:
        pipe = Pipeline(sc.stack, sc.angles, PRESETS["auto"].replace(n_segments=2))
        scene, params = Scene(pipeline=pipe), pipe.params
        steady = scene.segment(params.replace(method=methods["steadier size"])).labels
        pol = scene.polarisation(params)
        flat = np.ones(pol.intensity.shape, dtype=np.float32)
        sizes = [
            estimate_object_size(pol.intensity, pol.dop, pol.phase, ~pol.invalid).size_px,
            estimate_object_size(flat, pol.dop, pol.phase, ~pol.invalid).size_px,
        ]
        runs = [
            [scene.segment(params.replace(object_size=f * d)).labels.ravel() for f in (1, 0.9, 1.1)]
            for d in sizes
        ]
    finally:
        for name in methods.values():
            unregister_method(name)
    agree = [
        np.mean([adjusted_rand_score(r[0], r[1]), adjusted_rand_score(r[0], r[2])]) for r in runs
    ]
    assert abs(sizes[1] / sizes[0] - 1) > 0.1 and min(sizes) > 12  # both count, and differ
    assert agree[0] != agree[1]
    np.testing.assert_array_equal(steady.ravel(), runs[int(np.argmax(agree))][0])


def test_the_oracle_takes_each_frames_best_variant(capsys):
    """``--oracle``: by family, the mean over frames of the best variant's score, and its
    paired difference to the default."""
    results = {
        "default": {"small": [0.1, 0.5, 0.3]},
        "other": {"small": [0.4, 0.2, 0.3]},
    }
    family_variants.print_oracle(results, ["small"])
    row = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| small")]
    # best per frame 0.4, 0.5, 0.3: mean 0.4; minus default 0.3, 0, 0: +0.100 ± 0.100
    assert row == ["| small | 0.400 | +0.100 ± 0.100 |"]


def test_the_medoid_is_the_labelling_the_others_agree_with():
    """``texture weight medoid`` keeps the label image closest (mean ARI) to the others:
    of a cut into halves, the same cut with a corner changed and a checkerboard (read on
    every second pixel: one label, agreeing with neither), the two cuts agree best; a
    tie keeps the preferred one."""
    cut = np.zeros((40, 40), dtype=int)
    cut[:, 20:] = 1
    nudged = cut.copy()
    nudged[:6, :6] = 1
    noise = np.indices((40, 40)).sum(axis=0) % 2
    assert family_variants.medoid([noise, nudged, cut]) in (1, 2)
    assert family_variants.medoid([noise, cut, cut.copy()], prefer=2) == 2
    assert family_variants.medoid([cut, cut.copy(), cut.copy()], prefer=1) == 1


def test_read_rounds_join_the_development_halves_only(monkeypatch):
    """``--read-rounds``: the test halves of rounds read before follow a rendered
    family's development half; the real frames and a checked test half get none."""

    def halves(family, half, test_base=0):
        yield (family, half, test_base)

    monkeypatch.setattr(family_variants, "frames", halves)
    dev = list(family_variants.development_frames("small", "dev", 0, [18, 19]))
    assert dev == [("small", "dev", 0), ("small", "test", 18), ("small", "test", 19)]
    assert list(family_variants.development_frames("real", "dev", 0, [18])) == [("real", "dev", 0)]
    assert list(family_variants.development_frames("small", "test", 17, [18])) == [
        ("small", "test", 17)
    ]
