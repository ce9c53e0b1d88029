"""A pixel feature stack kept as compact as its features allow, read row by row.

:func:`~.pixel_features.pixel_features` makes three kinds of feature planes:

- at σ < 4 px, one value per pixel (a :class:`GridBlock` of factor 1);
- at σ ≥ 4 px, maps filtered on a grid f = 2 or 4 times coarser and linearly
  interpolated back (a :class:`GridBlock` of factor f, kept on its coarse grid);
- region means, one value per superpixel (a :class:`RegionBlock`).

Expanding every plane to the full image costs F × H × W × 4 bytes (≈ 440 MB for the 88
default features of a 1224 × 1024 frame) and, on a fresh machine, as much time again as
computing them. A classifier only reads some pixels' rows: the strokes, a prediction
grid, the cells on a border. So a :class:`FeatureStack` keeps each block as it was made
and builds the (n, F) rows it is asked for (:meth:`FeatureStack.take`,
:meth:`~FeatureStack.rows`), interpolating the coarse blocks at just those pixels
(the same linear interpolation as :func:`upsample`, to float rounding).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .superpixels import region_means


def interpolation_at(
    x: np.ndarray, f: int, m: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Linear interpolation at fine coordinates ``x`` from an axis f times coarser of
    ``m`` cells (pixel-area grid): (lo, hi, w_lo, w_hi), value = w_lo x[lo] + w_hi x[hi].

    Coarse cell k covers fine pixels k·f … k·f + f − 1, so fine pixel k·f + a sits at
    u = (a + ½)/f − ½ cells from cell k's centre; beyond the first and last cell the
    edge cell is repeated. Equals ``scipy.ndimage.zoom(…, order=1, grid_mode=True,
    mode="nearest")`` (tested), written out because zoom evaluates a general spline per
    output pixel (4× slower) and cannot give single pixels.
    """
    k, a = np.divmod(np.asarray(x, dtype=np.int64), f)
    u = ((a + 0.5) / f - 0.5).astype(np.float32)
    before = u < 0
    lo = np.clip(np.where(before, k - 1, k), 0, m - 1)
    hi = np.clip(np.where(before, k, k + 1), 0, m - 1)
    w_lo = np.where(before, -u, 1 - u).astype(np.float32)
    return lo, hi, w_lo, (1 - w_lo).astype(np.float32)


def upsample(
    small: np.ndarray, f: int, shape: tuple[int, int], rows: tuple[int, int] | None = None
) -> np.ndarray:
    """Maps (…, h, w) of the f-times coarser grid interpolated to ``shape`` (H, W), rows
    first, then columns (the weights of :func:`interpolation_at`, applied by
    slices: one per phase of the f fine pixels of a cell, no gathers); ``rows`` =
    (start, stop) gives only those fine rows (from the coarse rows they need)."""
    if f == 1:
        return small if rows is None else small[..., rows[0] : rows[1], :]
    start, stop = (0, shape[0]) if rows is None else rows
    # the coarse rows of the band and one more on each side (what its edge rows read)
    k0, k1 = max(start // f - 1, 0), min(-(-stop // f) + 1, small.shape[-2])
    tall = _upsample_axis(small[..., k0:k1, :], f, -2)
    tall = tall[..., start - k0 * f : stop - k0 * f, :]
    wide = _upsample_axis(tall, f, -1)
    return wide if wide.shape[-1] == shape[1] else np.ascontiguousarray(wide[..., : shape[1]])


def _upsample_axis(x: np.ndarray, f: int, axis: int) -> np.ndarray:
    """Linear interpolation by the factor f along ``axis`` (:func:`interpolation_at`;
    the first and last cell repeated beyond the edges); C-contiguous, so the maps read
    next (region means, rows) are not strided."""
    axis %= x.ndim
    n = x.shape[axis]

    def cells(start: int, stop: int) -> tuple[slice, ...]:
        return (slice(None),) * axis + (slice(start, stop),)

    padded = np.concatenate([x[cells(0, 1)], x, x[cells(n - 1, n)]], axis=axis)
    out = np.empty(x.shape[: axis + 1] + (f,) + x.shape[axis + 1 :], dtype=np.float32)
    for a in range(f):
        u = (a + 0.5) / f - 0.5
        phase = (slice(None),) * (axis + 1) + (a,)
        if u < 0:  # between cell k − 1 and k
            lo, hi, w_lo = padded[cells(0, n)], padded[cells(1, n + 1)], np.float32(-u)
        else:  # between cell k and k + 1
            lo, hi, w_lo = padded[cells(1, n + 1)], padded[cells(2, n + 2)], np.float32(1 - u)
        out[phase] = lo * w_lo + hi * (np.float32(1) - w_lo)
    return out.reshape(x.shape[:axis] + (n * f,) + x.shape[axis + 1 :])


@dataclass(frozen=True)
class GridBlock:
    """Feature planes (k, h, w) float32 on a grid ``factor`` times coarser than the
    image of ``shape`` (H, W); factor 1: the image's own grid."""

    values: np.ndarray
    factor: int
    shape: tuple[int, int]

    @property
    def n_features(self) -> int:
        return self.values.shape[0]

    def take(self, index: np.ndarray) -> np.ndarray:
        """(n, k) rows of the pixels at flat (row-major) ``index``."""
        flat = self.values.reshape(self.n_features, -1)
        if self.factor == 1:
            return flat[:, index].T
        h, w = self.values.shape[1:]
        r, c = np.divmod(np.asarray(index, dtype=np.int64), self.shape[1])
        rl, rh, ra, rb = interpolation_at(r, self.factor, h)
        cl, ch, ca, cb = interpolation_at(c, self.factor, w)
        top = flat[:, rl * w + cl] * ca + flat[:, rl * w + ch] * cb
        bottom = flat[:, rh * w + cl] * ca + flat[:, rh * w + ch] * cb
        return (top * ra + bottom * rb).T

    def rows(self, start: int, stop: int) -> np.ndarray:
        """(n, k) rows of image rows ``start:stop``, row-major."""
        band = upsample(self.values, self.factor, self.shape, (start, stop))
        return band.reshape(self.n_features, -1).T

    def plane(self, j: int) -> np.ndarray:
        """Feature ``j`` (H, W) at every pixel."""
        return upsample(self.values[j], self.factor, self.shape)


@dataclass(frozen=True)
class RegionBlock:
    """One value per superpixel: ``values`` (k, n) float32 of the regions 0 … n − 1 of
    ``regions`` (H, W)."""

    values: np.ndarray
    regions: np.ndarray

    @property
    def n_features(self) -> int:
        return self.values.shape[0]

    @property
    def shape(self) -> tuple[int, int]:
        return self.regions.shape

    def take(self, index: np.ndarray) -> np.ndarray:
        """(n, k) rows of the pixels at flat (row-major) ``index``."""
        return self.values[:, self.regions.ravel()[index]].T

    def rows(self, start: int, stop: int) -> np.ndarray:
        """(n, k) rows of image rows ``start:stop``, row-major."""
        return self.values[:, self.regions[start:stop].ravel()].T

    def plane(self, j: int) -> np.ndarray:
        """Feature ``j`` (H, W) at every pixel."""
        return self.values[j][self.regions]


Block = GridBlock | RegionBlock


@dataclass(frozen=True)
class FeatureStack:
    """Named float32 pixel features of one image, kept as blocks (module docstring).

    Attributes
    ----------
    blocks : tuple of GridBlock or RegionBlock
        The features in order: block b holds ``names[o_b : o_b + k_b]``.
    names : tuple of str
        ``names[f]`` describes feature f (column f of every row read).
    params : PixelFeatureParams
    """

    blocks: tuple[Block, ...]
    names: tuple[str, ...]
    params: Any = None
    _grids: dict[int, np.ndarray] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        if sum(b.n_features for b in self.blocks) != len(self.names):
            raise ValueError("the blocks hold another number of features than names")

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W)."""
        return tuple(self.blocks[0].shape)

    @property
    def n_features(self) -> int:
        return len(self.names)

    @property
    def nbytes(self) -> int:
        """Bytes the blocks hold."""
        return sum(b.values.nbytes for b in self.blocks)

    def _rows(self, n: int, read: Any) -> np.ndarray:
        out = np.empty((n, self.n_features), dtype=np.float32)
        k = 0
        for block in self.blocks:
            out[:, k : k + block.n_features] = read(block)
            k += block.n_features
        return out

    def take(self, index: np.ndarray) -> np.ndarray:
        """(n, F) C-contiguous float32 rows of the pixels at flat (row-major) ``index``."""
        index = np.asarray(index, dtype=np.int64).ravel()
        return self._rows(index.size, lambda b: b.take(index))

    def pixels(self, where: np.ndarray) -> np.ndarray:
        """(n, F) C-contiguous float32 rows of the pixels where ``where`` (H, W) is True."""
        return self.take(np.flatnonzero(np.asarray(where).ravel()))

    def rows(self, start: int, stop: int) -> np.ndarray:
        """(n, F) C-contiguous float32 rows of image rows ``start:stop``, row-major."""
        n = (min(stop, self.shape[0]) - start) * self.shape[1]
        return self._rows(n, lambda b: b.rows(start, stop))

    def grid_rows(self, stride: int) -> np.ndarray:
        """(n, F) rows of the pixels of a grid of step ``stride``: pixel (i·s + ⌊s/2⌋,
        j·s + ⌊s/2⌋) of every s × s cell (the last row and column of the image for a
        cut-off cell), row-major over the ⌈H/s⌉ × ⌈W/s⌉ cells. Kept: the same array on
        every call for a stride (read by every prediction)."""
        s = int(stride)
        if s not in self._grids:
            h, w = self.shape
            r = np.minimum(np.arange(0, h, s) + s // 2, h - 1)
            c = np.minimum(np.arange(0, w, s) + s // 2, w - 1)
            self._grids[s] = self.take((r[:, None] * w + c[None, :]).ravel())
        return self._grids[s]

    def plane(self, key: int | str) -> np.ndarray:
        """One feature (H, W) at every pixel, by index or name."""
        j = self.names.index(key) if isinstance(key, str) else int(key)
        for block in self.blocks:
            if j < block.n_features:
                return block.plane(j)
            j -= block.n_features
        raise IndexError(key)

    def planes(self) -> np.ndarray:
        """Every feature at every pixel, (F, H, W) float32 (F × H × W × 4 bytes)."""
        out = np.empty((self.n_features, *self.shape), dtype=np.float32)
        for j in range(self.n_features):
            out[j] = self.plane(j)
        return out

    def region_means(self, regions: np.ndarray) -> np.ndarray:
        """Mean of every feature over each region of ``regions`` (H, W; 0 … n − 1):
        (F, n) float32, one plane made at a time."""
        return region_means((self.plane(j) for j in range(self.n_features)), regions)

    @classmethod
    def joined(cls, stacks: Sequence[FeatureStack]) -> FeatureStack:
        """The features of ``stacks`` (of one image) side by side."""
        blocks = tuple(b for s in stacks for b in s.blocks)
        return cls(blocks, tuple(n for s in stacks for n in s.names), stacks[0].params)
