"""The superpixels' edge map and superpixels of a large image, made band by band into
full-size arrays placed by the run's memory limit (:mod:`..disk_arrays`, issue 39).

:func:`~.superpixels.superpixel_edges` of a whole image holds its two gradient
magnitudes, log Î, the Stokes components and the Gaussian filters' temporaries at once:
about 40 bytes a pixel, 1 GB for a 24 MP frame. Every value of the edge map reads the
maps only :data:`EDGE_REACH` pixels each way (σ = :data:`~.superpixels.EDGE_SIGMA`,
truncated at 4σ), so :func:`banded_superpixel_edges` computes the gradients of a
band of rows at a time (:func:`band_rows`) on the band grown by that reach (the image's own
borders stay where they are, so SciPy's reflection there is the whole image's) and
keeps the band's rows: the same values to the bit. The two medians that scale the
gradients are exact too (:func:`exact_median`: ``np.median`` selected by radix over the
values' bits, band by band, with no copy of the image).

:func:`banded_superpixels` is :func:`~.superpixels.polarisation_superpixels` on the
coarser watershed grid (``grid`` > 1): the grid's block means are taken band by band,
the compact watershed runs once over the whole coarse grid (its regions are global: a
region grows from its seed over the whole edge map), and every pixel takes its block's
region band by band: the same superpixels to the bit.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from skimage.segmentation import watershed
from skimage.util import regular_seeds

from .. import disk_arrays, tiles
from ..chunks import chunk_bounds, run_chunks
from .superpixels import COMPACTNESS, EDGE_SIGMA, edge_gradients, seed_count

#: Pixels of a band (bounds its temporaries: the gradients of a band hold about 40
#: bytes a pixel, 80 MB).
BAND_PIXELS = 1 << 21
#: Pixels the Gaussian derivatives of the edge map read each way: SciPy's radius
#: int(4σ + 0.5) of σ = :data:`~.superpixels.EDGE_SIGMA`.
EDGE_REACH = int(4.0 * EDGE_SIGMA + 0.5)
#: Bits of the value a pass of :func:`kth_smallest` counts.
DIGIT_BITS = 16
#: Candidates :func:`kth_smallest` gathers and partitions at once instead of counting
#: another digit of them (4 or 8 bytes each).
GATHER = 1 << 22


def band_rows(width: int) -> int:
    """Rows of a band of :data:`BAND_PIXELS` pixels of an image ``width`` pixels wide,
    at least 4 :data:`EDGE_REACH` (the rows read beyond a band's two sides are then at
    most half as many as its own)."""
    return max(4 * EDGE_REACH, BAND_PIXELS // max(int(width), 1))


def row_bands(shape: tuple[int, ...], rows: int | None = None) -> Iterator[slice]:
    """Slices of ``rows`` rows (default :func:`band_rows` of the width ``shape[1]``; the
    last one shorter) covering the ``shape[0]`` rows of an image of ``shape``."""
    step = band_rows(shape[1] if len(shape) > 1 else 1) if rows is None else rows
    return tiles.row_bands(shape[0], step)


def ordered_keys(values: np.ndarray) -> np.ndarray:
    """Unsigned integer keys (uint64 of float64 ``values``, uint32 of float32 ones) in
    the values' order: their IEEE bits, the sign bit set on non-negative values and
    every bit flipped on negative ones."""
    dtype = np.dtype(values.dtype)
    unsigned = np.dtype(f"u{dtype.itemsize}")
    sign = unsigned.type(1 << (8 * dtype.itemsize - 1))
    bits = np.ascontiguousarray(values).view(unsigned)
    return np.where(bits & sign, ~bits, bits | sign)


def key_value(key: int, dtype: np.typing.DTypeLike) -> float:
    """The value of ``dtype`` (float32 or float64) whose :func:`ordered_keys` key is
    ``key``."""
    dtype = np.dtype(dtype)
    unsigned = np.dtype(f"u{dtype.itemsize}")
    sign = 1 << (8 * dtype.itemsize - 1)
    bits = int(key) & ~sign if int(key) & sign else ~int(key) & (2 * sign - 1)
    return np.array([bits], dtype=unsigned).view(dtype)[0]


def _digit_counts(values: np.ndarray, prefix: int, shift: int) -> np.ndarray:
    """Counts (2^:data:`DIGIT_BITS`,) of the digit at bit ``shift`` of the keys of
    ``values`` (H, W) whose bits above that digit are ``prefix`` (all keys when the
    digit is the top one), band by band."""
    top = shift + DIGIT_BITS
    counts = np.zeros(1 << DIGIT_BITS, dtype=np.int64)
    for band in row_bands(values.shape):
        keys = ordered_keys(values[band]).ravel()
        if top < 8 * keys.itemsize:
            keys = keys[(keys >> keys.dtype.type(top)) == prefix]
        digits = (keys >> keys.dtype.type(shift)) & keys.dtype.type((1 << DIGIT_BITS) - 1)
        counts += np.bincount(digits.astype(np.intp), minlength=1 << DIGIT_BITS)
    return counts


def _gathered(values: np.ndarray, prefix: int, shift: int) -> np.ndarray:
    """The keys of ``values`` whose bits from ``shift`` up are ``prefix``."""
    parts = []
    for band in row_bands(values.shape):
        keys = ordered_keys(values[band]).ravel()
        parts.append(keys[(keys >> keys.dtype.type(shift)) == prefix])
    return np.concatenate(parts)


def kth_smallest(values: np.ndarray, k: int) -> float:
    """The ``k``-th smallest (0-based) of float32 or float64 ``values`` (H, W), of their
    dtype (:func:`smallest_at`)."""
    return smallest_at(values, (k,))[0]


def smallest_at(values: np.ndarray, ranks: tuple[int, ...]) -> list[float]:
    """The ``ranks``-th smallest (0-based) of float32 or float64 ``values`` (H, W), of
    their dtype: one digit of :data:`DIGIT_BITS` bits of their :func:`ordered_keys`
    counted a pass (band by band), until at most :data:`GATHER` candidates are left,
    which are gathered and partitioned (or every bit is known). The ranks share the
    passes while they fall on the same digit (the median's two middle ranks nearly
    always do); where they part, each is looked for on its own. No NaN among the
    values.

    Written by hand: ``np.median`` and ``np.partition`` work on a copy of the whole
    array (0.8 GB for a 100 MP float64 edge map), and a Dask median gathers it into one
    chunk; an approximate (histogram) median would move the edge map's values and so the
    superpixels."""
    bits = 8 * values.dtype.itemsize
    prefix, below, shift = 0, 0, bits
    left = int(values.size)
    while left > GATHER and shift > 0:
        shift -= DIGIT_BITS
        counts = _digit_counts(values, prefix, shift)
        ends = np.cumsum(counts)
        digits = {int(np.searchsorted(ends, k - below, side="right")) for k in ranks}
        if len(digits) > 1:
            return [smallest_at(values, (k,))[0] for k in ranks]
        digit = digits.pop()
        below += int(ends[digit - 1]) if digit else 0
        prefix, left = (prefix << DIGIT_BITS) | digit, int(counts[digit])
    if shift == 0:  # every bit known: all the candidates are that value
        return [key_value(prefix, values.dtype)] * len(ranks)
    keys = _gathered(values, prefix, shift) if shift < bits else ordered_keys(values).ravel()
    at = [k - below for k in ranks]
    keys = np.partition(keys, at)
    return [key_value(keys[j], values.dtype) for j in at]


def exact_median(values: np.ndarray) -> float:
    """``np.median`` of float32 or float64 ``values`` (H, W), of their dtype, read band by
    band (:func:`smallest_at`; NaN when one is NaN): the middle value, or the mean of
    the two middle ones."""
    if any(np.isnan(values[band]).any() for band in row_bands(values.shape)):
        return values.dtype.type(np.nan)
    n = int(values.size)
    middle = (n // 2,) if n % 2 else (n // 2 - 1, n // 2)
    return np.mean(np.array(smallest_at(values, middle), dtype=values.dtype))


def banded_gradients(
    intensity: np.ndarray, dop: np.ndarray, phase: np.ndarray, polarisation: bool = True
) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`~.superpixels.edge_gradients` (H, W) float64 each, placed by
    :func:`~..disk_arrays.empty`, computed a band of rows at a time (:func:`row_bands`) on the band
    grown by :data:`EDGE_REACH` rows: the same values to the bit. The bands are
    independent: they run on the CPU cores (:func:`~..chunks.run_chunks`; SciPy's
    filters release the GIL), each writing its own rows."""
    h, w = intensity.shape
    grad = disk_arrays.empty((h, w))
    pol = disk_arrays.empty((h, w)) if polarisation else None
    bands = list(row_bands((h, w)))

    def work(first: int, stop: int) -> None:
        for band in bands[first:stop]:
            top, end = max(band.start - EDGE_REACH, 0), min(band.stop + EDGE_REACH, h)
            rows = slice(band.start - top, band.stop - top)
            g, p = edge_gradients(intensity[top:end], dop[top:end], phase[top:end], polarisation)
            grad[band] = g[rows]
            if pol is not None and p is not None:
                pol[band] = p[rows]
            disk_arrays.release(grad, pol)

    run_chunks(chunk_bounds(len(bands), 1), work, h * w)
    return grad, pol


def banded_superpixel_edges(
    intensity: np.ndarray,
    dop: np.ndarray,
    phase: np.ndarray,
    polarisation_edge_weight: float = 1.0,
) -> np.ndarray:
    """:func:`~.superpixels.superpixel_edges` (H, W) float64, dimensionless, placed by
    :func:`~..disk_arrays.empty`: the gradients of :func:`banded_gradients`, each
    divided by its :func:`exact_median`, summed band by band (the same values to the
    bit)."""
    w = float(polarisation_edge_weight)
    edges, pol = banded_gradients(intensity, dop, phase, w > 0)
    m_log = max(exact_median(edges), 1e-12)
    m_pol = max(exact_median(pol), 1e-12) if pol is not None else 1.0
    for band in row_bands(edges.shape):
        part = edges[band]
        part /= m_log
        if pol is not None:
            part += w * pol[band] / m_pol
        disk_arrays.release(edges, pol)
    return edges


def add_banded(out: np.ndarray, add: np.ndarray) -> np.ndarray:
    """``out += add`` (H, W each) band by band; returns ``out``."""
    for band in row_bands(out.shape):
        out[band] += add[band]
        disk_arrays.release(out)
    return out


def block_means(edges: np.ndarray, grid: int) -> np.ndarray:
    """(⌈H/grid⌉, ⌈W/grid⌉) float64 means of the ``grid`` × ``grid`` blocks of ``edges``
    (H, W), the image padded with its last row and column, as
    :func:`~.superpixels.polarisation_superpixels` takes them, band by band."""
    h, w = edges.shape
    g = int(grid)
    ww = -(-w // g) * g
    coarse = np.empty((-(-h // g), ww // g))
    for band in row_bands(coarse.shape, max(1, band_rows(w) // g)):
        top, stop = band.start * g, min(band.stop * g, h)
        rows = (band.stop - band.start) * g
        part = np.pad(edges[top:stop], ((0, rows - (stop - top)), (0, ww - w)), mode="edge")
        coarse[band] = part.reshape(rows // g, g, ww // g, g).mean(axis=(1, 3))
    return coarse


def band_counts(labels: np.ndarray, n: int | None = None) -> np.ndarray:
    """(n,) int64 pixels of every label 0 … n − 1 of ``labels`` (H, W; non-negative;
    n default max + 1), counted a band of rows at a time (no full-size index)."""
    n = int(labels.max()) + 1 if n is None else int(n)
    counts = np.zeros(n, dtype=np.int64)
    for band in row_bands(labels.shape):
        counts += np.bincount(labels[band].ravel(), minlength=n)
    return counts


def banded_superpixels(edges: np.ndarray, region_area: int, grid: int) -> np.ndarray:
    """:func:`~.superpixels.polarisation_superpixels` of the edge map ``edges`` (H, W)
    on the watershed grid ``grid`` (> 1): (H, W) int32, 0 … n − 1, placed by
    :func:`~..disk_arrays.empty` (the same superpixels to the bit on one band; in
    bands, :func:`banded_watershed`).

    The watershed is given the block means (:func:`block_means`) and its seeds as int32
    (scikit-image's ``regular_seeds``, which it makes itself from their number, there
    int64: its labels are then int32), in bands (:func:`banded_watershed`); every pixel
    takes its block's region renumbered (:func:`~.superpixels.relabel`'s numbers: the
    regions the coarse grid holds are those the image does) band by band."""
    h, w = edges.shape
    g = int(grid)
    n = seed_count((h, w), region_area)
    shape = (-(-h // g), -(-w // g))
    labels = banded_watershed(
        block_means(edges, g),
        regular_seeds(shape, n, dtype=np.int32),
        COMPACTNESS * g,
    )
    number = (np.cumsum(band_counts(labels) > 0) - 1).astype(np.int32)
    out = disk_arrays.empty((h, w), dtype=np.int32)
    columns = np.arange(w) // g
    for band in row_bands((h, w)):
        out[band] = number[labels[np.arange(band.start, band.stop) // g][:, columns]]
        disk_arrays.release(out)
    return out


#: Rows of the coarse grid a band of :func:`banded_watershed` holds at least.
WATERSHED_BAND_ROWS = 1024
#: Rows a band of :func:`banded_watershed` floods beyond each of its cut sides, at
#: least; and at least this many seed spacings (√(pixels / seeds)).
WATERSHED_OVERLAP = 64
WATERSHED_OVERLAP_SPACINGS = 4


def banded_watershed(values: np.ndarray, seeds: np.ndarray, compactness: float) -> np.ndarray:
    """scikit-image's compact watershed of ``values`` (h, w) from ``seeds`` (h, w) int32
    (≥ 1, 0 elsewhere): (h, w) int32, the seeds' numbers, in ⌊h /
    :data:`WATERSHED_BAND_ROWS`⌋ bands of rows (at least one) flooded on the CPU cores
    (:func:`~..chunks.run_chunks`; the watershed releases the GIL). A band floods its
    rows and :data:`WATERSHED_OVERLAP` more beyond each cut side (or
    :data:`WATERSHED_OVERLAP_SPACINGS` seed spacings, if more), with the seeds there,
    and keeps its own rows: a compact region spans a few seed spacings (16 rows of the
    coarse grid of 1024 px superpixels), so its pixels are claimed by the seeds of the
    band and its overlap. Not the same by construction as one watershed of the whole
    grid, but measured so: on the fruits frame tiled to 24 MP (two bands of 1024 of the
    2048 × 3060 coarse rows) no pixel of the 6.3 M differs, in 2.7 s against 6.0 s. The
    bands follow from the grid's size alone, not from the cores: the same regions on
    any machine."""
    h = values.shape[0]
    n = max(1, h // WATERSHED_BAND_ROWS)
    if n == 1:
        return watershed(values, markers=seeds, compactness=compactness)
    out = np.empty(values.shape, dtype=np.int32)
    bands = list(tiles.row_bands(h, -(-h // n)))
    spacing = np.sqrt(values.size / max(int(seeds.max()), 1))
    overlap = max(WATERSHED_OVERLAP, int(np.ceil(WATERSHED_OVERLAP_SPACINGS * spacing)))

    def work(first: int, stop: int) -> None:
        for band in bands[first:stop]:
            top, end = max(band.start - overlap, 0), min(band.stop + overlap, h)
            labels = watershed(values[top:end], markers=seeds[top:end], compactness=compactness)
            out[band] = labels[band.start - top : band.stop - top]

    run_chunks(chunk_bounds(len(bands), 1), work, values.size)
    return out
