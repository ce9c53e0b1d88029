"""Scribble-guided segmentation: a classifier of block features trained on user strokes.

The unsupervised pipeline (thesis section 4.5) ends with a normalized cut of the block
affinity. When the analyst can point at a few examples of each material (strokes drawn
in a napari Labels layer, 0 = unlabelled), the same per-block PCA features (thesis
section 4.3.3) can instead train a supervised classifier that labels every block. This
is not in the thesis; it replaces only the last stage (affinity and cut).
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import PolarsegError
from ..features import harmonics
from ..features.harmonics import pixel_block_index
from ..params import SegmentParams
from ..pipeline import Pipeline
from ..result import ScribbleSegmentation
from ..timing import timed
from .pixel_classifier import check_scribbles

#: A block is a training example of class c when at least this share of its scribbled
#: pixels are c.
MAJORITY = 0.5


def training_blocks(
    scribbles: np.ndarray, grid: tuple[int, int], window: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blocks that the scribbles label, and their class.

    Every pixel belongs to its w × w block; pixels of the remainder strips (when the
    size is not a multiple of w) to the nearest whole block, as for the labels
    (:func:`~napari_polarseg.engine.features.harmonics.pixel_block_index`). A block is an example
    of class c when c holds at least :data:`MAJORITY` of its scribbled pixels (the
    smaller label wins an exact tie); blocks without scribbles are not used.

    Parameters
    ----------
    scribbles : array (H, W) of int
        0 = unlabelled, 1, 2, … = material classes.
    grid : (R, C)
        Block grid, ``(H // w, W // w)``.
    window : int
        Block side w, pixels.

    Returns
    -------
    blocks : ndarray (n,) of int
        Flat (row-major) indices of the training blocks.
    targets : ndarray (n,) of int
        Index into ``classes`` of each training block.
    classes : ndarray (K,) of int
        The scribble values that have at least one training block, ascending.
    """
    s = check_scribbles(scribbles)
    r, c = (int(v) for v in grid)
    if (s.shape[0] // window, s.shape[1] // window) != (r, c):
        raise PolarsegError(
            f"the scribbles are {s.shape[0]} x {s.shape[1]} pixels, which does not match a "
            f"{r} x {c} grid of {window} x {window} blocks"
        )
    values, inv = np.unique(s.ravel(), return_inverse=True)
    inv = inv.ravel()
    rows, cols = pixel_block_index(s.shape, window)
    block = (rows[:, None] * c + cols[None, :]).ravel()
    marked = values[inv] > 0
    names = values[values > 0]
    if names.size == 0:
        raise PolarsegError("the scribbles label no pixel (0 = unlabelled everywhere)")
    k = names.size
    cls = inv[marked] - (values.size - k)  # positions of the positive values
    counts = np.bincount(block[marked] * k + cls, minlength=r * c * k).reshape(r * c, k)
    total = counts.sum(axis=1)
    best = np.argmax(counts, axis=1)
    ok = (total > 0) & (counts[np.arange(r * c), best] >= MAJORITY * total)
    blocks = np.flatnonzero(ok)
    used = np.unique(best[blocks])
    dropped = np.setdiff1d(np.arange(k), used)
    if dropped.size:
        warnings.warn(
            f"scribble label(s) {', '.join(str(int(v)) for v in names[dropped])} hold the "
            "majority of no block and are left out",
            stacklevel=2,
        )
    remap = np.full(k, -1)
    remap[used] = np.arange(used.size)
    return blocks, remap[best[blocks]], names[used]


def _checked_blocks(
    features: np.ndarray, n_blocks: int, valid: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """(features as (n_blocks, F) float64, usable blocks) of :func:`classify_blocks`."""
    x = np.asarray(features, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] != n_blocks:
        raise PolarsegError(f"features are {x.shape} but the block grid has {n_blocks} blocks")
    if not np.all(np.isfinite(x)):
        raise PolarsegError("block features contain NaN or infinite values")
    use = np.ones(n_blocks, bool) if valid is None else np.asarray(valid, bool).ravel()
    if use.size != n_blocks:
        raise PolarsegError(f"valid has {use.size} entries but the grid has {n_blocks} blocks")
    if not use.any():
        raise PolarsegError("the mask leaves no block to classify")
    return x, use


def classify_blocks(
    features: np.ndarray,
    grid: tuple[int, int],
    scribbles: np.ndarray,
    window: int,
    valid: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Label every block with a classifier trained on the scribbled blocks.

    The classifier is scikit-learn's multinomial ``LogisticRegression`` on standardised
    features (``StandardScaler``; C = 1, class weights balanced). Why this one: a few
    strokes give tens of training blocks in a handful of dimensions, where a linear model
    overfits least, trains in milliseconds and gives smooth, calibrated-looking
    probabilities (a random forest gives piecewise-constant ones and memorises the few
    examples; it scored no better on the synthetic scenes). Standardising puts the PCA
    components, whose variances differ by orders of magnitude, on one scale; balanced
    weights keep a material that got a short stroke from being swamped.

    Parameters
    ----------
    features : array (n_blocks, F)
        Block features (the PCA features of thesis section 4.3.3), row-major over
        ``grid``.
    grid : (R, C)
        Block grid; R * C == n_blocks.
    scribbles : array (H, W) of int
        User strokes: 0 = unlabelled, 1, 2, … = classes; H // w == R and W // w == C.
    window : int
        Block side w, pixels.
    valid : array (n_blocks,) of bool, optional
        Blocks that may be used (default: all). Masked-out blocks are no training
        examples, even when strokes cover them, and take the class and probabilities of
        the nearest valid block — as the normalized cut gives them the nearest segmented
        block's label.

    Returns
    -------
    block_labels : ndarray (R, C) of int
        Most probable class of every block, as an index into ``classes`` (0 = first).
    probabilities : ndarray (n_blocks, K)
        Class probabilities of every block (rows sum to 1).
    classes : ndarray (K,) of int
        The scribble value of each class index, ascending.

    Raises
    ------
    PolarsegError
        If the sizes disagree, or fewer than 2 classes have a training block.
    """
    from sklearn.linear_model import LogisticRegression
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    r, c = (int(v) for v in grid)
    x, use = _checked_blocks(features, r * c, valid)
    blocks, targets, classes = training_blocks(scribbles, (r, c), window)
    keep = use[blocks]
    blocks, targets = blocks[keep], targets[keep]
    present = np.unique(targets)
    classes, targets = classes[present], np.searchsorted(present, targets)
    if classes.size < 2:
        found = "none" if classes.size == 0 else f"only label {int(classes[0])}"
        raise PolarsegError(
            f"scribbles must mark at least 2 materials (non-zero labels), found {found}"
        )
    model = make_pipeline(
        StandardScaler(), LogisticRegression(C=1.0, class_weight="balanced", max_iter=1000)
    )
    model.fit(x[blocks], targets)
    proba = np.asarray(model.predict_proba(x), dtype=np.float64)
    proba /= proba.sum(axis=1, keepdims=True)
    if not use.all():
        from scipy import ndimage

        _, (ri, ci) = ndimage.distance_transform_edt(~use.reshape(r, c), return_indices=True)
        proba = proba[(ri * c + ci).ravel()]
    labels = np.argmax(proba, axis=1).reshape(r, c)
    return labels, proba, classes


def scribble_segmentation(
    pipe: Pipeline,
    scribbles: np.ndarray,
    reconstruction: bool = True,
    params: SegmentParams | None = None,
) -> ScribbleSegmentation:
    """The whole result of a scribble-guided run (:func:`scribble_result`).

    Returns the :class:`SegmentationResult` (labels = class index 0..K−1, no Ncut
    values; affinity and cut are neither computed nor invalidated), the class
    probabilities (K, H, W), the scribble value of every class and the number of
    training blocks.
    """
    p = pipe.snapshot(params)
    scribble_seconds: dict[str, float] = {}
    with timed(scribble_seconds, "scribbles"):
        block, labels, maps, classes, n_train = _classify(pipe, scribbles, p)
    names = ["polarisation", "normals", "harmonics", "pca"]
    names += ["reconstruction"] if reconstruction else []
    timings = {s: pipe.stage_seconds(s) for s in names}
    timings.update(scribble_seconds)
    done = pipe.recomputed_stages(p)
    recomputed = [s for s in names if s in done] + ["scribbles"]
    result = pipe.assemble_result(block, labels, [], reconstruction, timings, recomputed, params=p)
    return ScribbleSegmentation(result, maps, classes, n_train)


def scribble_result(
    pipe: Pipeline, scribbles: np.ndarray, params: SegmentParams | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Labels from a classifier trained on user strokes instead of the normalized cut.

    The block features of the ``pca`` stage (thesis section 4.3.3) of the blocks the
    strokes cover train :func:`~napari_polarseg.engine.classifier.scribbles.classify_blocks`,
    which labels every block; affinity and cut are not needed.

    Parameters
    ----------
    scribbles : array (H, W) of int
        Strokes over the stack's frames: 0 = unlabelled, 1, 2, … = materials (at
        least two).

    Returns
    -------
    labels : ndarray (H, W) of int
        Class of every pixel (remainder strips take their nearest block's), as an
        index 0..K-1 into the scribble values in ascending order.
    probabilities : ndarray (K, H, W) float
        Probability of each class per pixel (its block's); sums to 1 over K.
    """
    _, labels, maps, _, _ = _classify(pipe, scribbles, pipe.snapshot(params))
    return labels, maps


def _classify(
    pipe: Pipeline, scribbles: np.ndarray, params: SegmentParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """(block labels, pixel labels, probability maps, classes, training blocks)."""
    scribbles = np.asarray(scribbles)
    shape = pipe.stack.shape[1:]
    if scribbles.shape != shape:
        raise PolarsegError(
            f"the scribbles are {' x '.join(map(str, scribbles.shape))} pixels but the "
            f"frames are {shape[0]} x {shape[1]}"
        )
    window = params.window
    grid = pipe.get("harmonics", params).shape[:2]
    valid = pipe.block_valid(params)
    block, proba, classes = classify_blocks(
        pipe.get("pca", params).features, grid, scribbles, window, valid=valid
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # classify_blocks has warned already
        blocks, _, _ = training_blocks(scribbles, grid, window)
    rows, cols = harmonics.pixel_block_index(shape, window)
    labels = harmonics.upsample_block_labels(block, shape, window)
    maps = proba.T.reshape(-1, *grid)[:, rows[:, None], cols[None, :]]
    return block, labels, maps, classes, int(valid[blocks].sum())
