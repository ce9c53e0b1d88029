"""The cached pipeline: stages rerun only when stale, full-size outputs, cancellation."""

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import (
    STAGES,
    Cancelled,
    Pipeline,
    PolarsegError,
    SegmentParams,
    diffuse_dop,
    intensity_baseline,
    segment,
)

ANGLES = np.deg2rad([0, 30, 60, 90, 120, 150, 180])


def two_material_stack(shape=(57, 63), seed=0):
    """Left half n = 1.3, right half n = 1.8; the same dome-shaped surface and albedo."""
    rng = np.random.default_rng(seed)
    h, w = shape
    yy, xx = np.mgrid[:h, :w]
    # a rippled surface gives every block a spread of normals
    zen = 0.15 + 1.1 * (0.5 + 0.5 * np.sin(xx / 2.3) * np.cos(yy / 3.1))
    azi = np.mod(np.arctan2(np.sin(yy / 4.0), np.cos(xx / 5.0)), np.pi)
    n = np.where(xx < w // 2, 1.3, 1.8)
    rho = np.where(n == 1.3, diffuse_dop(zen, 1.3), diffuse_dop(zen, 1.8))
    intensity = 0.6 * np.cos(zen) + 0.2
    stack = intensity * (1 + rho * np.cos(2 * ANGLES[:, None, None] - 2 * azi))
    stack = stack + rng.normal(0, 1e-3, stack.shape)
    truth = (xx >= w // 2).astype(int)
    return stack, truth


def test_run_produces_full_size_outputs_and_summary():
    stack, truth = two_material_stack()
    pipe = Pipeline(stack, ANGLES, SegmentParams(window=10, degree=4, n_segments=2))
    res = pipe.run()
    for name in ("intensity", "dop", "phase", "zenith", "labels", "reconstruction_error"):
        assert getattr(res, name).shape == (57, 63), name
    assert res.block_labels.shape == (5, 6)
    assert res.labels.dtype.kind == "i" and res.labels.min() == 0
    assert res.n_segments == 2
    s = res.summary()
    assert set(s["stage_seconds"]) == set(STAGES)
    assert 0.95 <= s["explained_variance"] <= 1.0
    assert s["n_segments"] == 2 and sum(s["segment_pixels"]) == 57 * 63
    assert s["mean_reconstruction_error"] == pytest.approx(res.reconstruction_error.mean())


def test_two_materials_separate_where_intensity_does_not():
    stack, truth = two_material_stack((60, 80))
    res = segment(stack, ANGLES, SegmentParams(window=10, degree=4, n_segments=2))
    assert adjusted_rand_score(truth.ravel(), res.labels.ravel()) > 0.9


def test_changing_segments_reuses_everything_upstream():
    stack, _ = two_material_stack()
    pipe = Pipeline(stack, ANGLES, SegmentParams(window=10, degree=4, n_segments=2))
    pipe.run()
    assert all(pipe.calls[s] == 1 for s in STAGES)
    three = pipe.params.replace(n_segments=3)
    assert pipe.stale_stages(params=three) == ["labels"]
    res = pipe.run(three)
    assert pipe.calls["harmonics"] == 1 and pipe.calls["cut"] == 1
    assert pipe.calls["reconstruction"] == 1 and pipe.calls["labels"] == 2
    assert res.n_segments == 3


@pytest.mark.parametrize(
    ("change", "stale"),
    [
        ({"scale": 2.0}, ["affinity", "cut", "labels"]),
        ({"variance": 0.9}, ["pca", "affinity", "cut", "labels"]),
        ({"refractive_index": 1.6}, list(STAGES[1:])),
        ({"window": 8}, ["harmonics", "pca", "affinity", "cut", "labels", "reconstruction"]),
        ({"coefficients": "ridge"}, ["harmonics", "pca", "affinity", "cut", "labels"]),
        ({"specular_branch": "above-brewster"}, []),  # irrelevant under the diffuse model
    ],
)
def test_stale_stages_follow_dependencies(change, stale):
    stack, _ = two_material_stack()
    pipe = Pipeline(stack, ANGLES, SegmentParams(window=10, degree=3))
    pipe.run()
    assert pipe.stale_stages(params=pipe.params.replace(**change)) == stale


def test_cancel_between_stages_keeps_cache_valid():
    stack, _ = two_material_stack()
    pipe = Pipeline(stack, ANGLES, SegmentParams(window=10, degree=3))
    seen = []

    def progress(stage, i, n):
        seen.append(stage)

    with pytest.raises(Cancelled):
        pipe.run(progress=progress, cancel=lambda: len(seen) >= 3)
    assert seen == list(STAGES[:3])
    assert pipe.calls["pca"] == 0
    pipe.run()
    assert pipe.calls["harmonics"] == 1  # not recomputed after the cancel


def test_run_iter_yields_each_stage():
    stack, _ = two_material_stack()
    pipe = Pipeline(stack, ANGLES, SegmentParams(window=10, degree=3))
    steps = list(pipe.run_iter(reconstruction=False))
    assert [s for s, _, _ in steps] == list(STAGES[:-1])
    assert steps[-1][1:] == (len(STAGES) - 1, len(STAGES) - 1)
    assert pipe.result(reconstruction=False).reconstruction_error is None


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"window": 100}, "larger than the image"),
        ({"refractive_index": 1.0}, "refractive index"),
        ({"degree": -1}, "degree"),
        ({"degree": 99}, "degree"),
        ({"variance": 0.0}, "variance"),
        ({"n_segments": 0}, "segments"),
        ({"model": "metal"}, "model"),
    ],
)
def test_bad_parameters_raise_clear_errors(params, match):
    stack, _ = two_material_stack()
    with pytest.raises(PolarsegError, match=match):
        Pipeline(stack, ANGLES, SegmentParams(degree=2).replace(**params)).run()


def test_params_json_round_trip_and_unknown_keys():
    p = SegmentParams(window=12, degree=8, refractive_index=1.6, n_segments=4)
    assert SegmentParams.from_json(p.to_json()) == p
    with pytest.raises(PolarsegError, match="unknown"):
        SegmentParams.from_dict({"windw": 3})


def test_intensity_baseline_full_size():
    stack, _ = two_material_stack()
    labels = intensity_baseline(stack.mean(0), 10, 2)
    assert labels.shape == (57, 63) and set(np.unique(labels)) == {0, 1}


def test_known_normals_come_back_through_the_pipeline():
    """A dome rendered with known normals and n gives its zenith and azimuth back."""
    from napari_polarseg.engine.synthetic.optics import (
        diffuse_dop_from_transmission,
        render_stack,
    )

    h = w = 96
    yy, xx = np.mgrid[:h, :w] - 47.5
    r2 = (xx**2 + yy**2) / 60.0**2
    # hemisphere-like cap: slopes from its height field z = 60 sqrt(1 - r^2)
    inside = r2 < 0.95
    root = np.sqrt(np.clip(1 - r2, 0.05, None))
    # dz/dcol, dz/drow of the cap; flat board outside it
    p = np.where(inside, -xx / 60.0 / root, 0.0)
    q = np.where(inside, -yy / 60.0 / root, 0.0)
    zenith = np.arctan(np.hypot(p, q))
    azimuth = np.mod(np.arctan2(-q, -p), np.pi)
    n = 1.5
    rho = diffuse_dop_from_transmission(zenith, n)
    intensity = 0.3 + 0.3 * np.cos(zenith)
    stack = render_stack(intensity, rho, azimuth, ANGLES, noise_sigma=0.001, bit_depth=12, rng=1)
    pipe = Pipeline(stack, ANGLES, SegmentParams(window=8, degree=2, refractive_index=n))
    nrm = pipe.get("normals")
    strong = rho > 0.05
    assert strong.sum() > 1000
    err = np.abs(nrm.zenith - zenith)[strong]
    assert np.rad2deg(np.median(err)) < 1.0
    dphi = np.abs(np.angle(np.exp(2j * (nrm.azimuth - azimuth)))) / 2
    assert np.rad2deg(np.median(dphi[strong])) < 1.0


def test_summary_separates_recomputed_stages_from_cached_ones():
    stack, _ = two_material_stack()
    pipe = Pipeline(stack, ANGLES, SegmentParams(window=10, degree=3, n_segments=2))
    first = pipe.run().summary()
    assert first["recomputed_stages"] == list(STAGES)
    again = pipe.run(pipe.params.replace(n_segments=3)).summary()
    assert again["recomputed_stages"] == ["labels"]
    assert again["total_seconds"] == pytest.approx(again["stage_seconds"]["labels"], abs=1e-6)
    assert again["total_seconds"] < first["total_seconds"]


def test_params_are_read_only_and_each_run_takes_its_own():
    stack, _ = two_material_stack()
    base = SegmentParams(window=10, degree=3)
    pipe = Pipeline(stack, ANGLES, base)
    assert pipe.params is base
    with pytest.raises(AttributeError):
        pipe.params = base.replace(degree=5)
    assert not hasattr(pipe, "update")
    other = base.replace(n_segments=3)
    assert pipe.run(other).params is other and pipe.params is other  # the last run's


def test_runs_a_then_b_then_a_reuse_the_upstream_stages():
    """Params A, then B (another number of segments), then A again: A's labels again,
    and no stage upstream of the labels recomputed after the first run."""
    stack, _ = two_material_stack()
    a = SegmentParams(window=10, degree=4, n_segments=2)
    b = a.replace(n_segments=3)
    pipe = Pipeline(stack, ANGLES, a)
    first = pipe.run(a)
    second = pipe.run(b)
    again = pipe.run(a)
    assert first.n_segments == 2 and second.n_segments == 3
    np.testing.assert_array_equal(again.labels, first.labels)
    upstream = [s for s in STAGES if s != "labels"]
    assert all(pipe.calls[s] == 1 for s in upstream), dict(pipe.calls)
    assert pipe.calls["labels"] == 3
    assert again.recomputed == ["labels"] and again.params is a


def test_two_threads_with_different_params_get_their_own_results():
    import threading

    stack, _ = two_material_stack()
    a = SegmentParams(window=10, degree=3, n_segments=2)
    b = SegmentParams(window=8, degree=5, n_segments=3)
    ref = {p: Pipeline(stack, ANGLES, p).run() for p in (a, b)}
    pipe = Pipeline(stack, ANGLES, a)
    results: dict[SegmentParams, list] = {a: [], b: []}
    errors: list[BaseException] = []

    def work(p: SegmentParams) -> None:
        try:
            for _ in range(3):
                results[p].append(pipe.run(p))
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(p,)) for p in (a, b)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    for p in (a, b):
        assert len(results[p]) == 3
        for res in results[p]:
            assert res.params is p
            assert res.coefficients.shape == ref[p].coefficients.shape
            np.testing.assert_array_equal(res.labels, ref[p].labels)


def test_masked_out_blocks_are_no_graph_nodes_and_take_their_neighbours_label():
    stack, truth = two_material_stack((70, 100))
    region = np.ones((70, 100), dtype=bool)
    region[40:, :] = False  # the user restricts the segmentation to the top 40 rows
    params = SegmentParams(window=10, degree=4, n_segments=2, scale_mode="median")
    pipe = Pipeline(stack, ANGLES, params, mask=region)
    res = pipe.run()
    valid = pipe.block_valid().reshape(res.block_labels.shape)
    assert valid[:4].all() and not valid[4:].any()
    assert pipe.get("cut").W.shape == (40, 40)  # 4 x 10 blocks, not 7 x 10
    # the masked blocks copy the label of the nearest segmented block (row 3)
    np.testing.assert_array_equal(res.block_labels[4:], np.repeat(res.block_labels[3:4], 3, 0))
    # and the two materials inside the region are still told apart
    assert adjusted_rand_score(truth[region], res.labels[region]) > 0.8
    assert res.summary()["mask"]  # counts reported


def test_scale_change_reuses_the_distances_and_large_graphs_are_float32():
    """The squared distances are kept with the block features: a change of the affinity
    scale recomputes only the exponential. From dense_graph.FLOAT32_MIN_NODES blocks the
    distances and the affinity are float32, and the labels equal those of the float64
    affinity (the issue's condition for float32)."""
    from napari_polarseg.engine.graph import affinity as feat
    from napari_polarseg.engine.graph import dense_graph, ncut
    from napari_polarseg.engine.synthetic.scenes import make_scene

    scene = make_scene("camouflage", shape=(200, 208), angles_deg=np.arange(0, 180, 30))
    p = SegmentParams(window=4, degree=4, n_segments=3, scale=2.0, scale_mode="median")
    pipe = Pipeline(scene.stack, scene.angles, p)
    pipe.run(reconstruction=False)
    W = pipe.get("affinity")
    n = W.shape[0]
    assert n >= dense_graph.FLOAT32_MIN_NODES and W.dtype == np.float32
    D = pipe.distances.matrix
    assert D.dtype == np.float32
    features = pipe.get("pca").features.reshape(n, -1)
    W64 = feat.affinity_matrix(features, 2.0, "median")
    np.testing.assert_allclose(W, W64, rtol=2e-5, atol=1e-7)
    want = ncut.CutTree(W64, min_size=p.min_segment_blocks).labels(3)
    np.testing.assert_array_equal(pipe.get("labels")[0].ravel(), want)

    pipe.run(pipe.params.replace(scale=3.0), reconstruction=False)
    assert pipe.distances.matrix is D  # kept: only exp(−D/s) was recomputed
    np.testing.assert_allclose(
        pipe.get("affinity"), feat.affinity_matrix(features, 3.0, "median"), rtol=2e-5, atol=1e-7
    )
    pipe.run(pipe.params.replace(variance=0.9), reconstruction=False)  # other distances
    assert pipe.distances.matrix is not D


def test_prefetch_makes_one_more_segment_free():
    from napari_polarseg.engine.graph import ncut

    stack, _ = two_material_stack(shape=(96, 100))
    pipe = Pipeline(stack, ANGLES, SegmentParams(window=4, degree=4, n_segments=2))
    pipe.run()
    assert list(pipe.prefetch())  # the two segments' candidate splits
    tree = pipe.get("cut")
    assert set(tree._candidates) == set(tree._ids)
    pipe.run(pipe.params.replace(n_segments=3))
    assert pipe.get("labels")[0].max() == 2
    fresh = Pipeline(stack, ANGLES, pipe.params).run()
    np.testing.assert_array_equal(pipe.get("labels")[0], fresh.block_labels)
    # the prefetch also left a touched buffer for the next affinity: a scale change
    # writes into it
    pool = pipe.matrices
    size = pipe.get("affinity").size
    spare = [id(b) for b in pool._buffers if b.size == size and pool._free(b)]
    assert len(spare) == 1
    pipe.run(pipe.params.replace(scale=1.5), reconstruction=False)
    assert id(pipe.get("affinity").base) == spare[0]
    # nothing to do: stale labels, a tree already deeper than k, or k-way clustering
    scale2 = pipe.params.replace(scale=2.0)
    assert list(pipe.prefetch(scale2)) == []
    pipe.run(scale2)
    pipe.run(pipe.params.replace(n_segments=2))
    assert [pos for pos in pipe.prefetch() if pos >= 0] == []  # no eigensolve
    pipe.run(pipe.params.replace(clustering="kway"))
    assert not isinstance(pipe.get("cut"), ncut.CutTree)
    assert list(pipe.prefetch()) == []


def test_matrix_pool_reuses_memory_but_never_an_array_still_held():
    from napari_polarseg.engine.matrix_pool import MatrixPool

    pool = MatrixPool(keep=3)
    a = pool.take((6, 6), np.float32)
    b = pool.take((6, 6), np.float32)
    assert not np.shares_memory(a, b)
    a_buffer = id(a.base)
    del a
    c = pool.take((6, 6), np.float32)
    assert id(c.base) == a_buffer  # a's memory again: nothing of it was alive
    view = c.T
    del c
    assert not np.shares_memory(pool.take((6, 6), np.float32), view)  # a view keeps it

    # in the pipeline: reruns write new affinities into freed memory, never into an
    # affinity the caller still holds
    stack, _ = two_material_stack(shape=(96, 100))
    pipe = Pipeline(stack, ANGLES, SegmentParams(window=4, degree=4, n_segments=2))
    pipe.run(reconstruction=False)
    held = pipe.get("affinity")
    kept = held.copy()
    for s in (2.0, 3.0, 4.0, 5.0):
        pipe.run(pipe.params.replace(scale=s), reconstruction=False)
        assert pipe.get("affinity").base is not held.base
    np.testing.assert_array_equal(held, kept)
    del held
    used = []  # ids only: a reference to a buffer would keep it from being reused
    for s in (6.0, 7.0, 8.0, 9.0):
        pipe.run(pipe.params.replace(scale=s), reconstruction=False)
        used.append(id(pipe.get("affinity").base))
    # nothing held any more: two pooled buffers take turns (one holds the affinity in
    # use while the next is written)
    pooled = {id(b) for b in pipe.matrices._buffers}
    assert set(used) <= pooled and used[0] == used[2] != used[1] == used[3]
    fresh = Pipeline(stack, ANGLES, pipe.params)
    fresh.run(reconstruction=False)
    np.testing.assert_array_equal(pipe.get("affinity"), fresh.get("affinity"))
    np.testing.assert_array_equal(pipe.get("labels")[0], fresh.get("labels")[0])


@pytest.mark.parametrize("coefficients", ["thesis", "ridge"])
def test_run_iter_reports_progress_within_the_chunked_stages(coefficients):
    # 160 x 170 pixels in 10 x 10 blocks: 272 blocks, several chunks per chunked stage
    stack, _ = two_material_stack(shape=(160, 170))
    params = SegmentParams(window=10, degree=8, coefficients=coefficients)
    pipe = Pipeline(stack, ANGLES, params)
    reports: list[tuple[str, float, int]] = []
    steps = list(pipe.run_iter(progress=lambda *r: reports.append(r)))
    names = [s for s, _, _ in steps]
    n = len(names)
    by_stage = {name: [i for s, i, _ in reports if s == name] for name in names}
    for name in ("harmonics", "reconstruction"):
        i = names.index(name)
        values = by_stage[name]
        inside = [v for v in values if i < v < i + 1]
        assert len(inside) >= 2, (name, values)  # strictly between the stage boundaries
        assert values == sorted(values) and values[-1] == i + 1
    # the chunked stages report within; polarisation and normals (pixel chunks) and pca
    # (a checkpoint) may too, where Cancel is checked
    assert {"harmonics", "reconstruction"} <= {s for s, _, _ in reports}
    chunked = {"polarisation", "normals", "harmonics", "pca", "reconstruction"}
    assert {s for s, _, _ in reports} <= chunked
    assert all(total == n for _, _, total in reports)
    # the yields and the result are those of a run without progress
    ref = Pipeline(stack, ANGLES, params)
    assert [s[:2] for s in ref.run_iter()] == [s[:2] for s in steps]
    np.testing.assert_array_equal(pipe.result().labels, ref.result().labels)
    # get(stage, progress): only that stage reports, not one computed on the way to it
    fresh = Pipeline(stack, ANGLES, params)
    shares: list[float] = []
    fresh.get("pca", progress=shares.append)  # computes the (chunked) harmonics first
    assert fresh.is_fresh("harmonics") and shares == [0.5]  # pca's checkpoint only
    shares.clear()
    fresh.get("reconstruction", progress=shares.append)
    assert len(shares) >= 2 and shares[-1] == 1 and all(0 < s <= 1 for s in shares)
