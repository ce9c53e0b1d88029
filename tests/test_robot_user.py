"""benchmarks/robot_user.py: the simulated user paints where it should and, with an
oracle classifier, drives the ARI up."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]


def load(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there (the
    # module puts its folder on sys.path itself, for its sibling imports)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def robot():
    return load("robot_user")


def planted():
    """Truth (0 = unlabelled strip) and a feature with one value per planted region.

    Material 1 is the background (feature 0) plus patch B (feature 3, 18 × 22 px) and
    patch C (feature 2.4, 8 × 10 px); material 2 a block (feature 1), material 3 another
    (feature 2). A classifier that knows only one disc per material calls B and C
    material 3, so B is the largest wrong region and C the next.
    """
    truth = np.ones((96, 120), dtype=np.int32)
    feature = np.zeros(truth.shape)
    truth[:, :4] = 0  # unlabelled
    truth[10:40, 60:110] = 2
    feature[10:40, 60:110] = 1
    truth[55:90, 70:115] = 3
    feature[55:90, 70:115] = 2
    feature[50:68, 10:32] = 3  # patch B, material 1
    feature[12:20, 20:30] = 2.4  # patch C, material 1: nearer 2 than 3
    feature += np.random.default_rng(0).uniform(-0.05, 0.05, truth.shape)
    return truth, feature


def nearest_neighbour(feature):
    """Oracle: every pixel takes the class of the scribbled pixel of nearest feature."""

    def update(scribbles):
        marked = scribbles > 0
        values, classes = feature[marked], scribbles[marked]
        order = np.argsort(values)
        values, classes = values[order], classes[order]
        i = np.clip(np.searchsorted(values, feature), 1, len(values) - 1)
        left_closer = np.abs(feature - values[i - 1]) <= np.abs(values[i] - feature)
        return np.where(left_closer, classes[i - 1], classes[i])

    return update


def test_first_discs_at_the_deepest_points_and_restricted_to_their_class(robot):
    truth, _ = planted()
    radius = robot.disc_radius(truth.shape)
    assert radius == 3  # max(3, 96 // 80)
    scribbles, centres = robot.initial_scribbles(truth, radius)
    for value, centre in zip((1, 2, 3), centres, strict=True):
        depth = ndimage.distance_transform_edt(np.pad(truth == value, 1))[1:-1, 1:-1]
        assert depth[centre] == depth.max()
        assert truth[centre] == value
        assert scribbles[centre] == value
    assert set(np.unique(scribbles)) == {0, 1, 2, 3}
    assert np.all((scribbles == 0) | (scribbles == truth))  # never across a class edge
    # the block of material 2 is 30 x 50: its deepest points lie on its middle rows
    assert centres[1][0] in (24, 25)


def test_corrections_land_in_the_largest_wrong_region_and_reach_the_target(robot):
    truth, feature = planted()
    update = nearest_neighbour(feature)
    scribbles, _ = robot.initial_scribbles(truth, robot.disc_radius(truth.shape))
    first = update(scribbles)
    region = robot.largest_wrong_region(first, truth)
    assert region[50:68, 10:32].all() and region.sum() == 18 * 22  # patch B
    run = robot.run_robot(truth, update, rounds=5)
    assert run.corrections[0] == robot.deepest_point(region)
    assert region[run.corrections[0]]
    assert 50 <= run.corrections[0][0] < 68 and 10 <= run.corrections[0][1] < 32
    assert 12 <= run.corrections[1][0] < 20 and 20 <= run.corrections[1][1] < 30  # patch C
    assert len(run.ari) == 6 and len(run.corrections) == 2  # nothing left to correct
    assert run.ari[0] < 0.9 < run.ari[2] and run.ari[-1] == pytest.approx(1.0)
    assert run.corrections_to() == "1"  # patch C is small: B alone lifts it past 0.9
    assert robot.RobotRun([0.1, 0.5], [], [], []).corrections_to() == ">1"


def test_the_three_methods_run_on_a_small_scene(robot):
    from napari_polarseg.engine.synthetic.scenes import make_scene

    sc = make_scene("leaves", shape=(48, 64), angles_deg=(0, 45, 90, 135))
    scene = robot.Scene("leaves", sc.stack, sc.angles, sc.labels.astype(np.int32) + 1, "dev")
    rows = robot.evaluate_scene(scene, rounds=2, bound=True)
    assert [r["method"] for r in rows] == ["product", "plain RF", "ilastik RF"]
    for r in rows:
        assert len(r["ari"]) == 3 and all(-1 <= a <= 1 for a in r["ari"])
        assert -1 <= r["bound"] <= 1
    assert "dev (1 scenes)" in robot.half_means(rows, 2)[0]


def test_the_bound_is_marked_when_the_halves_hold_other_materials(robot):
    truth = np.ones((10, 20), dtype=np.int32)
    truth[:, 3] = 2
    truth[:, 15] = 2
    assert robot.halves_comparable(truth)
    truth[:, 3] = 1  # material 2 only on the right: the left half cannot teach it
    assert not robot.halves_comparable(truth)
    truth[:, 15] = 1  # one material everywhere
    assert not robot.halves_comparable(truth)


def test_setbacks_count_the_corrections_that_lowered_the_ari(robot):
    """A run's setbacks: the corrections after which the ARI fell by more than the
    tolerance, and the largest fall."""
    run = robot.RobotRun([0.5, 0.7, 0.65, 0.695, 0.9, 0.6], [0.0] * 6, [], [])
    assert run.setbacks() == (2, pytest.approx(0.3))
    assert robot.RobotRun([0.5, 0.6, 0.6], [0.0] * 3, [], []).setbacks() == (0, 0.0)


def test_half_means_of_frames_without_a_bound(robot):
    """The real frames have no truth-trained bound: their summary line has none and does
    not fail (``robot_user.py --real`` alone)."""
    rows = [
        {
            "half": "real",
            "scene": s,
            "method": "product",
            "ari": [0.5] * 16,
            "comparable": True,
            "bound": None,
            "to": "1",
        }
        for s in ("a", "b")
    ]
    (line,) = robot.half_means(rows, 15)
    assert "product 0.500" in line and "bound" not in line
