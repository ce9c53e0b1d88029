"""Coarse-to-fine prediction of a pixel classifier: every s-th pixel, then the borders.

Predicting every pixel of a camera frame costs seconds, most of it where the answer is
plain: inside a material, where every pixel gets the same class. So the classifier
first predicts the pixels of a grid of stride s (one pixel per s × s cell, the cell's
centre pixel ⌊s/2⌋ rows and columns in), and the class probabilities p_k of every other
pixel are interpolated from it (linear, :func:`upsampled`).
A cell whose 3 × 3 neighbourhood of grid samples does not agree on the most probable
class lies on a border between materials (or holds a speck of another one): each of
its pixels is predicted on its own features, exactly as a full prediction would. So
the labels differ from predicting every pixel only inside cells whose nine surrounding
samples all agree — a region of another class smaller than about a cell that no grid
sample hits.

s = 1 predicts every pixel. The grid's features are kept pixel-major (one C-contiguous
(n, F) float32 block, :meth:`~..features.pixel_features.FeatureStack.grid_rows`), so a
new stroke reads them without copying the planes again.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from ..chunks import N_THREADS, chunk_bounds
from ..errors import Cancelled
from ..features.pixel_features import FeatureStack

#: Pixels read at once at stride 1, or predicted in one call by a model other than a
#: forest (bounds the (n, F) copy).
CHUNK_PIXELS = 131_072
#: Rows a forest predicts at once on one thread (:func:`predict_read`): 8192 rows of 88
#: features (2.9 MB) stay in the caches while all the trees walk them, and their
#: gathered features too. With the trees summed by :class:`TreeSum`, two threads of
#: 8192-row chunks predicted 262 k rows of the bench's 50-tree forest in 46 ms, of
#: 16384-row chunks in 51 ms, one thread in 79 ms (scikit-learn's ``predict_proba`` of
#: 16384-row chunks: 95 and 109 ms).
FOREST_CHUNK = 8_192


@dataclass(frozen=True)
class RefinedProbabilities:
    """Output of :func:`refined_probabilities`.

    Attributes
    ----------
    probabilities : ndarray (K, H, W) float32
        p_k of every pixel (summing to 1 over k).
    n_predicted : int
        Pixels whose own features were predicted (grid samples plus border cells).
    """

    probabilities: np.ndarray
    n_predicted: int


def predict_rows(model: Any, rows: np.ndarray, cancel: Any = None) -> np.ndarray:
    """``model.predict_proba`` of (n, F) rows in chunks → (n, K) float32; ``cancel()``
    returning True between chunks raises :class:`Cancelled` (:func:`predict_read`)."""
    return predict_read(model, rows.shape[0], lambda a, b: rows[a:b], cancel)


class TreeSum:
    """A fitted scikit-learn forest classifier's ``predict_proba`` on the calling thread,
    the same values to the bit with less of its time under the GIL.

    scikit-learn's forest checks its input and runs ``joblib.Parallel`` on every call,
    and each tree checks it again (about 1.7 ms a call, and 30 µs a tree, of Python
    holding the GIL: two threads of 16384-row chunks ran 1.1 × as fast as one). Here
    each tree's leaves come from its compiled ``tree_.apply`` (no GIL) and its leaves'
    class shares are gathered and added in the trees' order in float64, then divided by
    the number of trees: scikit-learn's own sum (``_accumulate_prediction`` with
    ``n_jobs`` = 1). Rows whose float32 sum is not finite (a NaN or an infinity among
    them, or an overflow) are given to the forest itself, which handles or refuses them
    as it does."""

    def __init__(self, model: Any) -> None:
        self.model = model
        k = len(model.classes_)
        #: (tree, (nodes, K) class shares of its nodes) of every tree, in order.
        self.trees = [
            (e.tree_, np.ascontiguousarray(e.tree_.value[:, 0, :k])) for e in model.estimators_
        ]
        self.n_features = int(model.n_features_in_)

    @classmethod
    def of(cls, model: Any) -> TreeSum | None:
        """A :class:`TreeSum` of ``model`` when it is a fitted single-output forest
        classifier of scikit-learn's trees (every estimator has a ``tree_`` with one
        output of the forest's classes) and scikit-learn keeps its leaves' class shares
        (1.4 on; before, counts its trees' ``predict_proba`` normalised), else None."""
        trees = getattr(model, "estimators_", None)
        if not trees or getattr(model, "n_outputs_", None) != 1 or not hasattr(model, "classes_"):
            return None
        import sklearn

        version = re.match(r"(\d+)\.(\d+)", sklearn.__version__)
        if version is None or (int(version[1]), int(version[2])) < (1, 4):
            return None
        k = len(model.classes_)
        for e in trees:
            value = getattr(getattr(e, "tree_", None), "value", None)
            if value is None or value.ndim != 3 or value.shape[1:] != (1, k) or e.n_classes_ != k:
                return None
        return cls(model)

    def predict_proba(self, rows: np.ndarray) -> np.ndarray:
        """(n, K) float64 class probabilities of (n, F) ``rows``: the forest's
        ``predict_proba``."""
        x = np.asarray(rows, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != self.n_features or not np.isfinite(x.sum()):
            return self.model.predict_proba(x)  # its checks and messages
        out = np.zeros((x.shape[0], self.trees[0][1].shape[1]))
        for tree, shares in self.trees:
            out += shares.take(tree.apply(x), axis=0)
        out /= len(self.trees)
        return out


def one_thread(model: Any) -> Any:
    """A forest ``model`` (``estimators_`` and ``n_jobs``) that predicts on the calling
    thread alone: its :class:`TreeSum` where it has one, else a shallow copy with
    ``n_jobs`` = 1 (the trees are shared); None for another model."""
    if not (hasattr(model, "estimators_") and hasattr(model, "n_jobs")):
        return None
    summed = TreeSum.of(model)
    if summed is not None:
        return summed
    single = copy.copy(model)
    single.n_jobs = 1
    return single


def predict_read(
    model: Any, n: int, read: Callable[[int, int], np.ndarray], cancel: Any = None
) -> np.ndarray:
    """``model.predict_proba`` of n rows → (n, K) float32, ``read(start, stop)`` giving
    the (stop − start, F) rows start:stop; ``cancel()`` returning True between chunks
    raises :class:`Cancelled`.

    A forest predicts chunks of :data:`FOREST_CHUNK` rows on :data:`~..chunks.N_THREADS`
    threads, each chunk read and predicted by all the trees on one thread (so its rows
    stay in the caches; no joblib pool per call, and every row's probabilities summed
    over the trees in their order); another model chunks of :data:`CHUNK_PIXELS` rows
    in the calling thread (with its own threads)."""
    out = np.empty((n, len(model.classes_)), dtype=np.float32)
    single = one_thread(model)
    if single is None or N_THREADS == 1 or n <= FOREST_CHUNK // 4:
        for start, stop in chunk_bounds(n, CHUNK_PIXELS if single is None else FOREST_CHUNK):
            if cancel is not None and cancel():
                raise Cancelled("prediction cancelled")
            out[start:stop] = (model if single is None else single).predict_proba(read(start, stop))
        return out

    def work(start: int, stop: int) -> None:
        out[start:stop] = single.predict_proba(read(start, stop))

    # chunks of at most FOREST_CHUNK rows, as many as fill every thread the same times
    rounds = -(-n // (N_THREADS * FOREST_CHUNK))
    step = -(-n // (N_THREADS * rounds))
    with ThreadPoolExecutor(N_THREADS) as pool:
        futures = [pool.submit(work, a, b) for a, b in chunk_bounds(n, step)]
        try:
            for future in futures:
                if cancel is not None and cancel():
                    raise Cancelled("prediction cancelled")
                future.result()
        except BaseException:
            for future in futures:  # leaving the pool waits for the running chunks only
                future.cancel()
            raise
    return out


def border_cells(labels: np.ndarray) -> np.ndarray:
    """Grid cells (h', w') whose 3 × 3 neighbourhood of labels is not all one class."""
    high = ndimage.maximum_filter(labels, size=3, mode="nearest")
    low = ndimage.minimum_filter(labels, size=3, mode="nearest")
    return high != low


def axis_weights(n_fine: int, f: int, n_coarse: int) -> tuple[np.ndarray, ...]:
    """Linear interpolation along one axis from a grid of step f to ``n_fine`` pixels:
    (lower sample, upper sample, weight of the upper) per fine pixel. Sample k stands
    for fine pixels k·f … k·f + f − 1, at u = (i + ½)/f − ½ samples for fine pixel i (the
    grid of :func:`~..features.pixel_features.upsample`); beyond the first and last
    sample the value is held."""
    u = (np.arange(n_fine) + 0.5) / f - 0.5
    low = np.floor(u).astype(np.intp)
    weight = (u - low).astype(np.float32)
    high = np.clip(low + 1, 0, n_coarse - 1)
    return np.clip(low, 0, n_coarse - 1), high, weight


def upsampled(coarse: np.ndarray, stride: int, shape: tuple[int, int]) -> np.ndarray:
    """(K, H, W) C-contiguous float32: every plane of ``coarse`` (K, h', w') linearly interpolated
    from the grid of ``stride`` to ``shape`` (rows, then columns; all planes at once)."""
    r0, r1, wr = axis_weights(shape[0], stride, coarse.shape[1])
    c0, c1, wc = axis_weights(shape[1], stride, coarse.shape[2])
    c = coarse.astype(np.float32, copy=False)
    rows = c[:, r0] * (1 - wr)[:, None] + c[:, r1] * wr[:, None]
    out = np.empty((c.shape[0], *shape), dtype=np.float32)  # C-contiguous
    np.take(rows, c0, axis=2, out=out)
    out *= 1 - wc
    out += np.take(rows, c1, axis=2) * wc
    return out


def grid_index(shape: tuple[int, int], stride: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the grid samples of ``stride`` in an image of ``shape``
    (:meth:`~..features.pixel_features.FeatureStack.grid_rows`'s pixels)."""
    s = int(stride)
    h, w = shape
    rows = np.minimum(np.arange(0, h, s) + s // 2, h - 1)
    cols = np.minimum(np.arange(0, w, s) + s // 2, w - 1)
    return rows, cols


def grid_probabilities(
    model: Any, features: FeatureStack, stride: int, cancel: Any = None
) -> np.ndarray:
    """p_k (K, ⌈H/s⌉, ⌈W/s⌉) float32 of the grid samples of ``stride``."""
    h, w = features.shape
    s = int(stride)
    k = len(model.classes_)
    return predict_rows(model, features.grid_rows(s), cancel).T.reshape(k, -(-h // s), -(-w // s))


def refined_probabilities(
    model: Any,
    features: FeatureStack,
    stride: int,
    cancel: Any = None,
    coarse: np.ndarray | None = None,
) -> RefinedProbabilities:
    """p_k of every pixel by the grid of ``stride`` and the border cells (module
    docstring); ``stride`` 1 predicts every pixel.

    Parameters
    ----------
    model : fitted scikit-learn classifier (``predict_proba``)
    features : FeatureStack
        The features the model was trained on, by name and order.
    stride : int
        Grid step s, pixels (>= 1).
    cancel : callable, optional
        Returning True between chunks raises :class:`Cancelled`.
    coarse : array (K, ⌈H/s⌉, ⌈W/s⌉), optional
        :func:`grid_probabilities` of this model, when already predicted.
    """
    h, w = features.shape
    k = len(model.classes_)
    s = max(1, int(stride))
    if s == 1:
        proba = np.empty((k, h, w), dtype=np.float32)
        step = max(1, CHUNK_PIXELS // max(w, 1))
        for start in range(0, h, step):
            stop = min(h, start + step)
            p = predict_rows(model, features.rows(start, stop), cancel)
            proba[:, start:stop] = p.T.reshape(k, stop - start, w)
        return RefinedProbabilities(proba, h * w)
    if coarse is None:
        coarse = grid_probabilities(model, features, s, cancel)
    # every pixel of every border cell, flat row-major indices inside the image
    flat = border_pixels(border_cells(np.argmax(coarse, axis=0)), s, (h, w))
    border = predict_read(model, flat.size, lambda a, b: features.take(flat[a:b]), cancel)
    proba = upsampled(coarse, s, (h, w))  # C-contiguous: written through the view below
    proba.reshape(k, -1)[:, flat] = border.T
    return RefinedProbabilities(proba, int(coarse[0].size + flat.size))


def border_pixels(cells: np.ndarray, stride: int, shape: tuple[int, int]) -> np.ndarray:
    """Flat row-major indices (sorted) inside ``shape`` of every pixel of the grid cells
    where ``cells`` (h', w') is True, cells of ``stride`` pixels."""
    s = int(stride)
    h, w = shape
    # the cells' pixels as a mask: its True pixels come out in row-major order (no sort)
    pixels = np.repeat(np.repeat(cells, s, axis=0)[:h], s, axis=1)[:, :w]
    return np.flatnonzero(pixels)


def window_probabilities(
    model: Any,
    features: FeatureStack,
    window: tuple[slice, slice],
    stride: int,
    cancel: Any = None,
) -> RefinedProbabilities:
    """:func:`refined_probabilities` of the pixels of ``window`` (rows, columns of
    ``features``) only: p_k (K, h, w) of the window.

    The grid samples are the whole image's when the window starts on a multiple of
    ``stride`` (counted from the image's origin), so away from the window's edges (two
    cells: the interpolation and the 3 × 3 border test read one cell each way) the
    probabilities equal those of the whole image (to float rounding).

    The grid samples' rows are read in the forest's threads, chunk by chunk, as the
    border cells' are (:func:`predict_read`; each row is read on its own, so the same
    values): a large image's tiles may run one at a time, and the whole window's read
    in the calling thread kept the other core idle (10 of a tile's 107 ms)."""
    h, w = features.shape
    r0, r1 = window[0].start, min(window[0].stop, h)
    c0, c1 = window[1].start, min(window[1].stop, w)
    size = (r1 - r0, c1 - c0)
    k = len(model.classes_)
    s = max(1, int(stride))
    rows = np.minimum(r0 + np.arange(0, size[0], s) + s // 2, r1 - 1)
    cols = np.minimum(c0 + np.arange(0, size[1], s) + s // 2, c1 - 1)
    samples = (rows[:, None] * w + cols[None, :]).ravel()
    grid = predict_read(model, samples.size, lambda a, b: features.take(samples[a:b]), cancel)
    coarse = grid.T.reshape(k, rows.size, cols.size)
    if s == 1:
        return RefinedProbabilities(np.ascontiguousarray(coarse), coarse[0].size)
    flat = border_pixels(border_cells(np.argmax(coarse, axis=0)), s, size)
    pr, pc = np.divmod(flat, size[1])
    image_index = (pr + r0) * w + (pc + c0)
    read = lambda a, b: features.take(image_index[a:b])  # noqa: E731
    proba = upsampled(coarse, s, size)
    proba.reshape(k, -1)[:, flat] = predict_read(model, flat.size, read, cancel).T
    return RefinedProbabilities(proba, int(coarse[0].size + flat.size))
