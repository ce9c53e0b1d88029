"""A grid of tiles with halos: bounded memory for per-pixel work on a large image.

Per-pixel work whose value at a pixel reads only pixels within a distance r of it (a
Gaussian of σ truncated at t σ reads r = ⌈t σ⌉ pixels each way) gives the same value
on a tile as on the whole image at every pixel at least r from the tile's cut edges.
So the image is cut into *cores* that cover it exactly once; every core is computed on
its *outer* box, the core grown by the halo h ≥ r on every side (clipped at the image's
edges, where the whole-image computation sees the same edge), and only the core's part
of the result is kept. Stitched cores then equal the whole-image result, without
seams.

Cores start on multiples of ``align`` pixels and are a multiple of it long (but the
last of a row or column), and so is the halo: work on a coarser grid (block means of
f × f pixels, a prediction grid of step s) then sees the same blocks on a tile as on the
whole image when ``align`` is a multiple of f and s.

The core side follows from a memory budget (:meth:`TileGrid.for_budget`): the outer box
of (c + 2h)² pixels times the bytes the work needs per pixel stays within it.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from .errors import PolarsegError

#: Smallest core side (pixels) :meth:`TileGrid.for_budget` chooses.
MIN_CORE = 128

Box = tuple[slice, slice]


def row_bands(height: int, rows: int) -> Iterator[slice]:
    """The row ranges of the bands of ``rows`` rows (at least 1; the last one shorter) of
    an image ``height`` rows high, top to bottom."""
    step, height = max(int(rows), 1), int(height)
    for top in range(0, height, step):
        yield slice(top, min(top + step, height))


@dataclass(frozen=True)
class Tile:
    """One tile of a :class:`TileGrid`.

    Attributes
    ----------
    core : (slice, slice)
        The pixels this tile answers for, in image coordinates (cores do not overlap
        and cover the image).
    outer : (slice, slice)
        The core grown by the halo (clipped to the image): what the tile reads.
    """

    core: Box
    outer: Box

    @property
    def inner(self) -> Box:
        """The core in the outer box's coordinates."""
        r0, c0 = self.outer[0].start, self.outer[1].start
        return (
            slice(self.core[0].start - r0, self.core[0].stop - r0),
            slice(self.core[1].start - c0, self.core[1].stop - c0),
        )

    @property
    def outer_shape(self) -> tuple[int, int]:
        return (self.outer[0].stop - self.outer[0].start, self.outer[1].stop - self.outer[1].start)

    def grown(self, margin: int, shape: tuple[int, int]) -> Box:
        """The core grown by ``margin`` pixels (clipped to ``shape``), image coordinates."""
        return _grow(self.core, margin, shape)


def _grow(box: Box, margin: int, shape: tuple[int, int]) -> Box:
    return (
        slice(max(box[0].start - margin, 0), min(box[0].stop + margin, shape[0])),
        slice(max(box[1].start - margin, 0), min(box[1].stop + margin, shape[1])),
    )


def round_up(value: float, step: int) -> int:
    """The smallest multiple of ``step`` ≥ ``value``."""
    return int(math.ceil(value / step) * step)


@dataclass(frozen=True)
class TileGrid:
    """Cores of ``core`` × ``core`` pixels (the last row and column shorter) with a halo
    of ``halo`` pixels, on an image of ``shape`` (H, W).

    Attributes
    ----------
    shape : (int, int)
        Image (H, W), pixels.
    core : int
        Side of a core, pixels (a multiple of ``align``).
    halo : int
        Pixels read beyond a core on every side (a multiple of ``align``).
    align : int
        Cores and halos are multiples of it (module docstring).
    at_once : int
        Most tiles worked on at once: as many outer boxes as the memory limit holds
        (0: as many as the tile map runs; :func:`~.tile_map.tile_map_for`). It never
        changes the tiles themselves.
    """

    shape: tuple[int, int]
    core: int
    halo: int
    align: int = 1
    at_once: int = 0

    def __post_init__(self) -> None:
        if self.core < 1 or self.halo < 0 or self.align < 1:
            raise PolarsegError(f"bad tile grid: core {self.core}, halo {self.halo}")
        if self.core % self.align or self.halo % self.align:
            raise PolarsegError(
                f"tile core {self.core} and halo {self.halo} must be multiples of {self.align}"
            )

    @classmethod
    def for_budget(
        cls,
        shape: tuple[int, int],
        budget: float,
        bytes_per_pixel: float,
        reach: int,
        align: int = 1,
    ) -> TileGrid:
        """The grid whose outer boxes fit ``budget`` bytes at ``bytes_per_pixel``.

        Core side c = ⌊√(budget / bytes_per_pixel) − 2h⌋ rounded down to ``align``
        (at least :data:`MIN_CORE` and at most the image's longer side), with the halo
        h = ``reach`` rounded up to ``align``.
        """
        halo = round_up(max(int(reach), 0), align)
        side = math.sqrt(max(budget, 0.0) / max(bytes_per_pixel, 1e-9)) - 2 * halo
        core = max(round_up(MIN_CORE, align), int(side // align) * align)
        core = min(core, round_up(max(shape), align))
        return cls((int(shape[0]), int(shape[1])), core, halo, align)

    @property
    def counts(self) -> tuple[int, int]:
        """Tiles along the rows and the columns."""
        return -(-self.shape[0] // self.core), -(-self.shape[1] // self.core)

    def __len__(self) -> int:
        rows, cols = self.counts
        return rows * cols

    def __iter__(self) -> Iterator[Tile]:
        h, w = self.shape
        for r in range(0, h, self.core):
            for c in range(0, w, self.core):
                core = (slice(r, min(r + self.core, h)), slice(c, min(c + self.core, w)))
                yield Tile(core, _grow(core, self.halo, self.shape))

    @property
    def largest_outer(self) -> int:
        """Pixels of the largest outer box."""
        return max(t.outer_shape[0] * t.outer_shape[1] for t in self)

    def borders(self) -> np.ndarray:
        """(H, W) bool: the pixels on either side of a cut between two cores."""
        out = np.zeros(self.shape, dtype=bool)
        for r in range(self.core, self.shape[0], self.core):
            out[r - 1 : r + 1] = True
        for c in range(self.core, self.shape[1], self.core):
            out[:, c - 1 : c + 1] = True
        return out
