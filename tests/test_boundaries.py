"""Border refinement (engine/unsupervised/boundaries.py) against known answers."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from napari_polarseg.engine.unsupervised.boundaries import (
    REFINE_PASSES,
    refine_boundaries,
    refine_maps,
    refined_labels,
)


def _two_materials(shape=(60, 80), edge=40, noise=0.01, seed=0):
    """Î and ρ of two materials split by a vertical edge at column ``edge``."""
    rng = np.random.default_rng(seed)
    left = np.arange(shape[1])[None, :] < edge
    intensity = np.where(left, 0.2, 0.8) * (1 + noise * rng.standard_normal(shape))
    dop = np.where(left, 0.05, 0.4) + noise * rng.standard_normal(shape)
    return intensity, dop, np.broadcast_to(~left, shape).astype(np.int32)


def test_a_border_three_pixels_off_moves_onto_the_edge():
    intensity, dop, truth = _two_materials()
    labels = np.zeros_like(truth)
    labels[:, 37:] = 1  # the segment border 3 px left of the material edge at column 40
    out = refined_labels(labels, intensity, dop, 2)
    assert np.array_equal(out, truth)


def test_a_border_further_off_than_the_passes_moves_by_the_passes_only():
    intensity, dop, _ = _two_materials(edge=40)
    labels = np.zeros((60, 80), dtype=np.int32)
    labels[:, 30:] = 1  # 10 px off: each pass moves the border one pixel
    out = refined_labels(labels, intensity, dop, 2)
    assert np.all(out[:, : 30 - 1] == 0)  # nothing far from the border changed
    first_one = np.argmax(out == 1, axis=1)
    assert np.all(first_one == 30 + REFINE_PASSES)


def _reference(labels, intensity, dop, k):
    """Full-image passes of refine_boundaries with the spread of the first labels: the
    definition refined_labels must reproduce."""
    maps = refine_maps(intensity, dop)
    flat = labels.ravel()
    count = np.maximum(np.bincount(flat, minlength=k), 1)
    spread = []
    for m in maps:
        mean = np.bincount(flat, m.ravel(), k) / count
        spread.append(np.sqrt(np.mean((m.ravel() - mean[flat]) ** 2)) + 1e-12)
    for _ in range(REFINE_PASSES):
        moved = refine_boundaries(labels, intensity, dop, k, np.array(spread))
        if np.array_equal(moved, labels):
            break
        labels = moved
    return labels


def test_refined_labels_equal_full_image_passes_on_random_blobs():
    rng = np.random.default_rng(3)
    shape, k = (90, 110), 4
    truth = ndimage.zoom(rng.integers(0, k, (9, 11)), 10, order=0)
    intensity = np.exp(truth * 0.5 + 0.3 * rng.standard_normal(shape))
    dop = 0.1 * truth + 0.05 * rng.standard_normal(shape)
    # a guess with ragged borders: the truth shifted and speckled
    labels = np.roll(truth, (2, -3), axis=(0, 1)).astype(np.int32)
    speckle = rng.random(shape) < 0.05
    labels[speckle] = rng.integers(0, k, speckle.sum())
    out = refined_labels(labels, intensity, dop, k)
    assert np.array_equal(out, _reference(labels, intensity, dop, k))
    assert (out == truth).mean() > (labels == truth).mean()  # and it helps
