"""*Paint here next* and *Use as scribbles* (issue 23, item 4): the engine's functions on
synthetic maps with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from napari_polarseg.engine.classifier.scribbles_from_labels import scribbles_from_labels
from napari_polarseg.engine.classifier.suggestion import (
    SuggestionParams,
    paint_here_next,
)
from napari_polarseg.engine.errors import PolarsegError

SHAPE = (120, 160)


def _uncertainty_map(seed=0):
    """Sure background (u ≈ 0.1, noisy) with three unsure places: a large C-shaped region
    (u = 0.7, the most uncertain in sum), a small one that is more unsure (u = 0.95, 6 × 6
    pixels) and isolated unsure pixels (noise)."""
    rng = np.random.default_rng(seed)
    u = 0.1 + 0.05 * rng.random(SHAPE)
    rows, cols = np.mgrid[: SHAPE[0], : SHAPE[1]]
    ring = (np.hypot(rows - 60, cols - 100) < 30) & (np.hypot(rows - 60, cols - 100) > 14)
    big = ring & ~((cols > 100) & (np.abs(rows - 60) < 8))  # a C: its centre is outside
    u[big] = 0.7
    small = np.zeros(SHAPE, bool)
    small[10:16, 10:16] = True
    u[small] = 0.95
    speckle = rng.random(SHAPE) < 0.002
    u[speckle] = 1.0
    return np.clip(u, 0, 1), big, small


def test_the_suggestion_lies_inside_the_most_uncertain_region():
    u, big, small = _uncertainty_map()
    s = paint_here_next(u)
    assert s is not None
    r, c = s.centre
    assert big[r, c]  # the deepest point is inside the C, not at its empty centre
    assert not big[60, 100] and not s.region[60, 100]
    # the region is (nearly) the C: within it, and most of it (the smoothing rounds edges)
    assert np.mean(big[s.region]) > 0.95
    assert s.region.sum() > 0.5 * big.sum()
    assert not (s.region & small).any()
    assert s.mean_uncertainty == pytest.approx(u[s.region].mean())
    r0, c0, r1, c1 = s.bbox
    rows, cols = np.nonzero(s.region)
    assert (r0, c0, r1, c1) == (rows.min(), cols.min(), rows.max() + 1, cols.max() + 1)


def test_painted_and_unused_pixels_are_never_suggested():
    u, big, small = _uncertainty_map()
    # painted over the C: the small region is what is left to suggest
    s = paint_here_next(u, painted=big.astype(np.int32))
    assert s is not None and small[s.centre] and not (s.region & big).any()
    # the small region unused as well: nothing uncertain enough is left
    assert paint_here_next(u, painted=big.astype(np.int32), valid=~small) is None
    # a classifier that is sure everywhere has nothing to suggest
    assert paint_here_next(np.full(SHAPE, 0.05)) is None
    with pytest.raises(PolarsegError):
        paint_here_next(np.zeros((2, 3, 4)))
    with pytest.raises(PolarsegError):
        SuggestionParams(top_share=0)


def test_use_as_scribbles_keeps_segment_interiors_and_leaves_borders():
    labels = np.zeros((40, 60), np.int64)
    labels[:, 30:] = 1
    labels[5:9, 5:25] = 2  # a 4-pixel-thin segment: no interior at margin 3
    s = scribbles_from_labels(labels, margin=3)
    assert s.dtype == np.int32
    assert set(np.unique(s)) == {0, 1, 2}  # values 1, 2 (label + 1); the thin one gone
    # columns 26..33 (within 3 pixels of the border pixels 29 and 30) are unlabelled
    assert np.all(s[20, 26:34] == 0)
    assert np.all(s[20:, 34:] == 2) and np.all(s[20:, :26][s[20:, :26] > 0] == 1)
    assert np.all(s[20:, 10:26] == 1)
    assert not np.any(s[4:10, 5:25] == 3)
    # the image's own edge is not a border
    assert s[0, 40] == 2 and s[39, 0] == 1
    # unused pixels are unlabelled and count as a border
    valid = np.ones_like(labels, bool)
    valid[30:, :] = False
    s2 = scribbles_from_labels(labels, margin=3, valid=valid)
    assert np.all(s2[27:, :] == 0) and s2[20, 40] == 2
    # the viewer's values kept: first_value = the smallest shown label
    np.testing.assert_array_equal(scribbles_from_labels(labels + 1, 3, first_value=1), s)
    np.testing.assert_array_equal(scribbles_from_labels(labels, 0), labels + 1)
    with pytest.raises(PolarsegError):
        scribbles_from_labels(labels.astype(float))
