"""A consensus of segmentations drawn on superpixels of several sizes.

One segmentation of superpixels depends on where the superpixels happen to fall: a
small object, a soft shadow or a shading gradient lands in one cluster or another by
how its superpixels straddle it, and a different superpixel size draws them
differently. :func:`consensus_clustering` takes region models of the same pixels at
several sizes (:class:`~.segmenter.RegionModel`, the first the finest), labels each
with k segments (``merged_clustering``: k + 1 clusters merged to k, each pixel its
superpixel's label, no border refinement) and describes each superpixel a of the
finest model by the share of its pixels that each run puts in each segment:

    x_a = (c_a1 / N_a, …, c_ak / N_a)  for each run, concatenated (k × runs values),

c_aj the pixels of a in the run's segment j, N_a the pixels of a (the runs' own
segment numbers need not match: the shares are compared, not the labels). The
superpixels are then clustered into k by k-means on x weighted by area
(:func:`.kmeans.weighted_kmeans`, :data:`~.segmenter.KMEANS_RESTARTS` seedings) and
every pixel takes its superpixel's label, the borders refined as the finest model's
parameters ask (:func:`~.segmenter.pixel_labels`). This is evidence accumulation
(Fred & Jain 2005) with the co-association read per superpixel instead of per pair.
Written here because neither scikit-learn nor scikit-image has a cluster ensemble; the
shares are one ``np.bincount`` per run and the clustering is the package's k-means.

The figures (development and held-out scenes) are in ``docs/quality.md``, *A consensus
over superpixel sizes*.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ..degenerate import degenerate_result
from .kmeans import weighted_kmeans
from .merge import Merge, closest_centroids, merged_clustering
from .params import UnsupervisedResult
from .segmenter import KMEANS_RESTARTS, RegionModel, pixel_labels, without_refinement


def segment_shares(
    fine: RegionModel, model: RegionModel, node_labels: np.ndarray, k: int
) -> np.ndarray:
    """(n, k): for each of the n superpixels of ``fine``, the share of its clustered
    pixels that ``model``'s superpixels labelled ``node_labels`` (0 … k − 1) put in each
    segment. Both models must cover the same clustered pixels (same image and mask)."""
    if model.regions.shape != fine.regions.shape:
        raise ValueError(f"models of {model.regions.shape} and {fine.regions.shape} pixels")
    rows = fine.regions.ravel()
    inside = rows < fine.n  # the clustered pixels (with a mask, the outside region is n)
    seg = np.asarray(node_labels)[model.regions.ravel()[inside]]
    counts = np.bincount(rows[inside] * k + seg, minlength=fine.n * k).reshape(fine.n, k)
    return counts / np.maximum(counts.sum(axis=1, keepdims=True), 1)


def consensus_clustering(
    models: Sequence[RegionModel],
    k: int,
    merge: Merge = closest_centroids,
    seed: int = 0,
) -> UnsupervisedResult:
    """The labels of k segments on which the ``models`` (the same pixels' superpixels at
    several sizes, the finest first) agree (module docstring): each model clustered
    into k by :func:`~.merge.merged_clustering` with ``merge``, each superpixel of the
    first described by the shares of its pixels in each run's segments, these shares
    clustered into k by area-weighted k-means (``seed``). With one model, k = 1 or
    fewer superpixels than k + 1 in any model: the first model's own merged clustering."""
    t0 = time.perf_counter()
    fine = models[0]
    if len(models) < 2 or k < 2 or min(m.n for m in models) <= k:
        return merged_clustering(fine, k, merge=merge)
    runs = [merged_clustering(without_refinement(m), k, merge=merge) for m in models]
    x = np.concatenate(
        [segment_shares(fine, m, run.node_labels, k) for m, run in zip(models, runs, strict=True)],
        axis=1,
    )
    fit = weighted_kmeans(x, k, fine.weight, n_init=KMEANS_RESTARTS, seed=seed)
    labels, node_labels = pixel_labels(fine, fit.labels)
    return replace(
        runs[0],
        labels=labels,
        node_labels=node_labels,
        seconds=time.perf_counter() - t0,
        degenerate=bool(degenerate_result(labels, requested=k).degenerate),
        params=fine.params,
    )
