"""Normalized cuts: generalized eigenproblem, best split, recursion on planted partitions."""

import numpy as np
import pytest
import scipy.linalg
from sklearn.metrics import adjusted_rand_score

from napari_polarseg.engine import CutTree, best_split, fiedler_vector, recursive_ncut


def planted(sizes, p_in=0.9, p_out=0.05, noise=0.04, seed=0):
    rng = np.random.default_rng(seed)
    truth = np.repeat(np.arange(len(sizes)), sizes)
    rng.shuffle(truth)
    W = np.where(truth[:, None] == truth[None, :], p_in, p_out)
    W = W + noise * rng.random(W.shape)
    W = (W + W.T) / 2
    return W, truth


@pytest.mark.parametrize("n", [40, 600])  # dense eigh and Lanczos paths
def test_fiedler_vector_solves_generalized_problem(n):
    W, _ = planted([n // 2, n - n // 2], seed=1)
    y = fiedler_vector(W)
    D = np.diag(W.sum(1))
    vals = scipy.linalg.eigh(D - W, D, eigvals_only=True)
    lam = y @ (D - W) @ y / (y @ D @ y)
    assert lam == pytest.approx(vals[1], rel=1e-6)
    np.testing.assert_allclose((D - W) @ y, lam * D @ y, atol=1e-6 * np.abs(D @ y).max())


@pytest.mark.parametrize(
    ("sizes", "seed"), [((30, 50), 0), ((100, 80, 60), 1), ((200, 150, 120, 90, 60), 2)]
)
def test_recovers_planted_partition_exactly(sizes, seed):
    W, truth = planted(sizes, seed=seed)
    labels = recursive_ncut(W, len(sizes))
    assert adjusted_rand_score(truth, labels) == 1.0
    assert labels[0] == 0  # numbered in order of first appearance


def test_best_split_minimises_ncut_by_brute_force():
    rng = np.random.default_rng(3)
    W = rng.random((9, 9))
    W = (W + W.T) / 2
    y = rng.normal(size=9)
    mask, value = best_split(W, y)
    order = np.argsort(y)
    d = W.sum(1)
    best = np.inf
    for k in range(1, 9):
        a = np.zeros(9, bool)
        a[order[:k]] = True
        cut = W[a][:, ~a].sum()
        best = min(best, cut / d[a].sum() + cut / d[~a].sum())
    assert value == pytest.approx(best, rel=1e-12)
    cut = W[mask][:, ~mask].sum()
    assert cut / d[mask].sum() + cut / d[~mask].sum() == pytest.approx(value)


def test_min_size_and_threshold_stop_splitting():
    W, truth = planted((50, 50, 4), seed=4)
    labels = recursive_ncut(W, 3, min_size=10)
    assert np.bincount(labels).min() >= 10
    tree = CutTree(W, threshold=1e-9)
    assert tree.labels(3).max() == 0  # no cut is that good: one segment
    tree = CutTree(W)
    assert tree.labels(1).max() == 0


def test_cut_tree_is_cached_and_consistent():
    W, truth = planted((60, 40, 30), seed=5)
    tree = CutTree(W)
    three = tree.labels(3)
    two = tree.labels(2)
    # the 3-segment labelling refines the 2-segment one
    for lab in np.unique(three):
        assert np.unique(two[three == lab]).size == 1
    assert len(tree.ncut_values) == 2
    assert adjusted_rand_score(truth, three) == 1.0


def generalized_fiedler(W):
    """Reference: second generalized eigenpair of (D − W) y = λ D y by dense eigh."""
    D = np.diag(W.sum(1))
    vals, vecs = scipy.linalg.eigh(D - W, D)
    return vals[1], vecs[:, 1]


def fallen_apart(n=700, seed=0):
    """A thesis-like affinity (s = 1): unit self loops, tiny couplings, a few blocks
    nearly isolated, and a group of 40 blocks bound to each other but weakly to the rest
    whose eigenvalue lies *below* those of the isolated blocks (the case where a single
    iterated vector can settle on the wrong eigenpair)."""
    rng = np.random.default_rng(seed)
    W = 1e-3 * rng.random((n, n)) ** 8
    group = np.arange(100, 140)
    W[np.ix_(group, group)] = 0.5 + 0.1 * rng.random((40, 40))
    W[group[:, None], np.setdiff1d(np.arange(n), group)[None, :]] *= 0.01
    for i, scale in zip((5, 300, 600), (0.5, 0.3, 0.2), strict=True):  # isolated blocks
        W[i, :] *= scale
    W = np.minimum(W, W.T)
    np.fill_diagonal(W, 1.0)
    return W, group


def test_block_lobpcg_finds_the_smallest_eigenpair_on_a_clustered_spectrum():
    from napari_polarseg.engine.graph import ncut

    W, group = fallen_apart()
    assert W.shape[0] > ncut.DENSE_EIGH_MAX  # the iterative path
    lam, ref = generalized_fiedler(W)
    y = fiedler_vector(W)
    D = np.diag(W.sum(1))
    assert y @ (D - W) @ y / (y @ D @ y) == pytest.approx(lam, rel=1e-5)
    cos = abs(y @ D @ ref) / np.sqrt((y @ D @ y) * (ref @ D @ ref))
    assert cos > 1 - 1e-6


def straightforward_tree(W, k):
    """Greedy recursive Ncut with eigh per segment (the rule of CutTree)."""
    segments = [np.arange(W.shape[0])]
    while len(segments) < k:
        best = (np.inf, None, None)
        for pos, idx in enumerate(segments):
            if idx.size < 2:
                continue
            sub = W[np.ix_(idx, idx)]
            _, y = generalized_fiedler(sub)
            mask, value = best_split(sub, y)
            if mask is not None and value < best[0]:
                best = (value, pos, mask)
        _, pos, mask = best
        idx = segments[pos]
        segments[pos] = idx[mask]
        segments.append(idx[~mask])
    labels = np.empty(W.shape[0], dtype=int)
    for lab, idx in enumerate(segments):
        labels[idx] = lab
    return labels


@pytest.mark.parametrize("seed", [0, 1])
def test_cut_tree_on_a_fallen_apart_graph_agrees_with_eigh(seed):
    """Peeling cuts (children of ~all the parent's nodes: products through the whole
    matrix, starts from the parent's vectors) give eigh's labels."""
    W, _ = fallen_apart(seed=seed)
    tree = CutTree(W)
    for k in (2, 3, 4, 5):
        assert adjusted_rand_score(straightforward_tree(W, k), tree.labels(k)) == 1.0


def test_warm_started_tree_equals_cold_tree():
    """Starting from an earlier tree's vectors (same segments or supersets) changes the
    work, not the result."""
    W, truth = planted((300, 250, 150, 100), p_in=0.6, p_out=0.1, noise=0.3, seed=6)
    old = CutTree(W**3)
    old.labels(4)
    cold = CutTree(W).labels(4)
    warm = CutTree(W, warm=old.fiedler_vectors()).labels(4)
    np.testing.assert_array_equal(warm, cold)
    assert adjusted_rand_score(truth, cold) == 1.0


@pytest.mark.parametrize("order", ["C", "F"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_symmetric_product_takes_either_memory_order(order, dtype):
    from napari_polarseg.engine.graph.dense_graph import symmetric_product

    rng = np.random.default_rng(0)
    A = rng.random((50, 50))
    A = np.asarray(A + A.T, dtype=dtype, order=order)
    X = rng.random((50, 3))
    got = symmetric_product(A)(np.asfortranarray(X, dtype=dtype))
    np.testing.assert_allclose(got, A @ X, rtol=1e-5 if dtype == np.float32 else 1e-12)


@pytest.mark.parametrize("kept", [2400, 1000])  # through the whole matrix / own copy
def test_dense_segment_products_degrees_and_split_sums(kept):
    from napari_polarseg.engine.graph.dense_graph import DenseGraph
    from napari_polarseg.engine.graph.ncut import lower_prefix_sums

    rng = np.random.default_rng(1)
    n = 2500  # float32 products from FLOAT32_MIN_NODES
    W = rng.random((n, n))
    W = (W + W.T) / 2
    idx = np.sort(rng.choice(n, kept, replace=False))
    sub = W[np.ix_(idx, idx)]
    seg = DenseGraph(W).segment(idx)
    np.testing.assert_allclose(seg.d, sub.sum(1), rtol=1e-12)
    np.testing.assert_array_equal(seg.diag, np.diagonal(sub))
    X = rng.random((kept, 2))
    np.testing.assert_allclose(seg.product(X), sub @ X, rtol=1e-5)
    order = rng.permutation(kept)
    rank = np.empty(kept, dtype=int)
    rank[order] = np.arange(kept)
    want = np.where(rank[None, :] < rank[:, None], sub, 0.0).sum(1)[order]
    np.testing.assert_allclose(lower_prefix_sums(W, order, idx), want, rtol=1e-12)


@pytest.mark.parametrize("kept", [2400, 1000])  # the whole matrix minus outsiders / a copy
def test_float32_affinity_is_used_as_is_with_float64_degrees(kept):
    """A float32 W of FLOAT32_MIN_NODES nodes or more (the pipeline's affinity) is the
    product matrix itself; degrees and prefix sums are accumulated in float64."""
    from napari_polarseg.engine.graph.dense_graph import FLOAT32_MIN_NODES, DenseGraph
    from napari_polarseg.engine.graph.ncut import lower_prefix_sums

    rng = np.random.default_rng(2)
    n = 2500
    assert n >= FLOAT32_MIN_NODES
    W64 = rng.random((n, n))
    W64 = (W64 + W64.T) / 2
    W = W64.astype(np.float32)
    exact = W.astype(np.float64)  # the float32 values, summed exactly in float64
    graph = DenseGraph(W)
    assert graph.W is W and graph.Wop is W  # no copy of the n² matrix
    np.testing.assert_allclose(graph.d, exact.sum(1), rtol=1e-12)
    idx = np.sort(rng.choice(n, kept, replace=False))
    sub = exact[np.ix_(idx, idx)]
    seg = graph.segment(idx)
    np.testing.assert_allclose(seg.d, sub.sum(1), rtol=1e-9)
    assert seg.d.dtype == np.float64
    order = rng.permutation(kept)
    rank = np.empty(kept, dtype=int)
    rank[order] = np.arange(kept)
    want = np.where(rank[None, :] < rank[:, None], sub, 0.0).sum(1)[order]
    got = lower_prefix_sums(W, order, idx)
    assert got.dtype == np.float64
    np.testing.assert_allclose(got, want, rtol=1e-9)


def test_float32_tree_gives_the_float64_labels():
    """The issue's condition for float32: the same labels. A 2,400-node graph with five
    planted groups (and the thesis-like fallen-apart graph, tiled) cut from its float32
    and float64 affinities."""
    W, truth = planted((700, 600, 500, 400, 200), p_in=0.6, p_out=0.1, noise=0.3, seed=3)
    for k in (2, 3, 5):
        labels64 = CutTree(W).labels(k)
        labels32 = CutTree(W.astype(np.float32)).labels(k)
        np.testing.assert_array_equal(labels32, labels64)
    assert adjusted_rand_score(truth, CutTree(W.astype(np.float32)).labels(5)) == 1.0
    # 2,100 nodes: three different thesis-like graphs, weakly joined
    big = scipy.linalg.block_diag(*(fallen_apart(n=700, seed=s)[0] for s in (0, 1, 2))) + 1e-9
    for k in (2, 4):
        np.testing.assert_array_equal(
            CutTree(big.astype(np.float32)).labels(k), CutTree(big).labels(k)
        )


def test_prefetch_solves_what_the_next_split_needs():
    from napari_polarseg.engine.graph import ncut

    W, _ = fallen_apart(seed=0)
    tree = CutTree(W)
    tree.labels(3)
    solved = list(tree.prefetch())
    assert solved and set(solved) <= {0, 1, 2}  # the segments not solved yet
    assert list(tree.prefetch()) == []  # nothing left to solve
    calls = []
    original = ncut.segment_vectors

    def counting(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    ncut.segment_vectors = counting
    try:
        four = tree.labels(4)
    finally:
        ncut.segment_vectors = original
    assert calls == []  # the 4th cut only compared the prefetched candidates
    np.testing.assert_array_equal(four, CutTree(W).labels(4))


# -- bounded work, isolated blocks, Cancel (issue 13) ----------------------------------------


def chain_of_groups(n_groups=200, size=5, eps=1e-2, seed=0):
    """A graph that has fallen apart into groups: strong ties inside each group of
    ``size`` nodes, the groups joined in a chain by one weak link each (~eps).

    The smallest eigenvalues of its Laplacian lie close together (those of a long chain,
    1e-6–1e-4) and the Jacobi preconditioner cannot separate them: at 200 groups the
    uncapped eigensolvers made 19,477 products (14 s) for the first cut alone, at 600
    groups 117,382 (6 minutes).
    """
    rng = np.random.default_rng(seed)
    W = scipy.linalg.block_diag(*(0.5 + 0.5 * rng.random((size, size)) for _ in range(n_groups)))
    ends = np.arange(size - 1, (n_groups - 1) * size, size)
    W[ends, ends + 1] = eps * (0.5 + rng.random(ends.size))
    W = np.maximum(W, W.T)
    np.fill_diagonal(W, 1.0)
    return W


def test_cut_on_a_fallen_apart_graph_stops_at_its_product_cap():
    from napari_polarseg.engine.graph import ncut

    size, cap = 5, 300
    W = chain_of_groups(size=size)
    assert W.shape[0] > ncut.DENSE_EIGH_MAX  # the iterative path
    tree = CutTree(W, max_products=cap)
    labels = tree.labels(2)
    limits = tree.cut_limits(2)
    assert limits["eigensolver_capped"] == 1 and limits["isolated_skipped"] == 0
    assert limits["max_products"] == cap
    assert tree.products == limits["products"] <= cap  # one solve, within its cap
    # the cut still goes along the chain: whole groups on either side, at a weak link
    groups = labels.reshape(-1, size)
    assert (groups == groups[:, :1]).all() and 0 < labels.sum() < labels.size
    assert tree.ncut_values[0] < 1e-4
    # twice the products: still not converged (the uncapped solve needs ~20,000)
    twice = CutTree(W, max_products=2 * cap)
    twice.labels(2)
    assert twice.cut_limits()["eigensolver_capped"] == 1
    assert twice.products <= 2 * cap


def test_cut_limits_count_each_solve_and_the_default_cap_leaves_normal_cuts_alone():
    W, truth = planted((300, 250, 150, 100), p_in=0.6, p_out=0.1, noise=0.3, seed=6)
    tree = CutTree(W)
    assert adjusted_rand_score(truth, tree.labels(4)) == 1.0
    limits = tree.cut_limits(4)
    assert limits["eigensolver_capped"] == 0 and limits["isolated_skipped"] == 0
    assert 0 < limits["products"] == tree.products
    assert tree.cut_limits(1)["products"] == 0  # nothing was solved for one segment
    assert tree.cut_limits(2)["products"] <= limits["products"]
    with pytest.raises(ValueError, match="max_products"):
        CutTree(W, max_products=5)


def isolated_graph(n=700, isolated=(42, 500), seed=0):
    """``fallen_apart`` with some nodes cut loose (less than 1e-9 of their degree leaves
    them): below what an iterative solver resolves."""
    W, _ = fallen_apart(n=n, seed=seed)
    for i, scale in zip(isolated, (1e-10, 1e-12), strict=False):
        W[i, :] *= scale
        W[:, i] *= scale
        W[i, i] = 1.0
    return W


def test_isolated_blocks_are_peeled_off_without_an_eigensolve():
    from napari_polarseg.engine.graph import ncut

    W = isolated_graph()
    tree = CutTree(W)
    three = tree.labels(3)
    limits = tree.cut_limits(3)
    assert limits["isolated_skipped"] == 2 and limits["products"] == 0
    # the most isolated node first (its singleton Ncut is the lowest), then the other
    assert np.bincount(tree.labels(2)).min() == 1 and tree.labels(2)[500] != tree.labels(2)[0]
    assert three[42] != three[500] and np.bincount(three).min() == 1
    assert tree.ncut_values[0] <= tree.ncut_values[1] < ncut.ISOLATED_NCUT
    # eigh on the whole problem finds the same cuts
    assert adjusted_rand_score(straightforward_tree(W, 3), three) == 1.0
    # with a minimum segment size above 1 no single block can be split off: solved
    bigger = CutTree(W, min_size=2)
    bigger.labels(2)
    assert bigger.cut_limits()["isolated_skipped"] == 0 and bigger.products > 0


def test_sparse_graph_that_fell_apart_is_solved_by_the_block_solver():
    """A kNN graph of 12-dimensional features at the thesis scale (s = 1): the most
    isolated node keeps all but 1e-5 of its degree. Lanczos alone made 161,000 products
    (4 minutes) at 8,000 nodes; the preconditioned block solver needs a few dozen."""
    from napari_polarseg.engine.graph import affinity as feat
    from napari_polarseg.engine.graph import eigensolver, ncut

    x = np.random.default_rng(0).standard_normal((3000, 12))
    W = feat.knn_affinity(x, 1.0)
    d = np.asarray(W.sum(axis=1)).ravel()
    share = 1.0 - W.diagonal() / d
    assert ncut.ISOLATED_NCUT < share.min() < eigensolver.FALLEN_APART
    tree = CutTree(W)
    labels = tree.labels(2)
    limits = tree.cut_limits(2)
    assert limits["eigensolver_capped"] == 0 and limits["products"] < 200
    # the cut is as good as peeling off the most isolated node (the Ncut of the split
    # search is summed over all nodes: 1e-5 relative round-off at these values)
    i = int(np.argmin(share))
    single = share[i] + share[i] * d[i] / (d.sum() - d[i])
    assert tree.ncut_values[0] <= single * (1 + 1e-4)
    assert np.bincount(labels).min() >= 1


def test_cancel_stops_a_running_cut_within_a_few_products():
    """Cancel set from another thread while the eigensolver runs on a graph whose
    uncapped first cut takes minutes (117,000 products)."""
    import threading
    import time

    from napari_polarseg.engine import Cancelled

    tree = CutTree(chain_of_groups(n_groups=600), max_products=10_000)  # ~30 s uncancelled
    stop = threading.Event()
    at_stop: dict[str, float] = {}

    def press_cancel() -> None:
        deadline = time.perf_counter() + 60
        while tree.products < 40 and time.perf_counter() < deadline:  # the solve runs
            time.sleep(0.005)
        at_stop["products"] = tree.products
        at_stop["time"] = time.perf_counter()
        stop.set()

    presser = threading.Thread(target=press_cancel)
    presser.start()
    with pytest.raises(Cancelled, match="normalized cut"):
        tree.labels(2, cancel=stop.is_set)
    elapsed = time.perf_counter() - at_stop["time"]
    presser.join()
    after = tree.cut_limits()["products"] - at_stop["products"]
    assert 0 <= after <= 8  # at most the iteration under way when Cancel came (4 + 4)
    assert elapsed < 1.0
    # the tree stays usable: nothing half-made was kept
    assert tree.ncut_values == [] and tree.labels(1).max() == 0


def test_pipeline_hands_its_cancel_to_the_cut_and_stays_consistent():
    from napari_polarseg.engine import Cancelled, Pipeline, SegmentParams

    with np.load("napari_polarseg/sample_data/camouflage.npz") as f:
        stack, angles = f["stack"], np.deg2rad(f["angles"])
    params = SegmentParams(window=5, degree=4, n_segments=3)  # 624 blocks: iterative
    pipe = Pipeline(stack, angles, params)
    pipe.get("cut")
    calls = []

    def cancel() -> bool:
        calls.append(1)
        return True

    with pytest.raises(Cancelled, match="normalized cut"):
        for _ in pipe.run_iter(reconstruction=False, cancel=cancel):
            pass
    assert calls and not pipe.is_fresh("labels") and pipe.is_fresh("cut")
    result = pipe.run(reconstruction=False)
    fresh = Pipeline(stack, angles, params).run(reconstruction=False)
    np.testing.assert_array_equal(result.labels, fresh.labels)
    assert result.cut_limits == fresh.cut_limits
    assert result.summary()["cut_limits"]["eigensolver_capped"] == 0
