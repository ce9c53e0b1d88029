"""Scribble-guided segmentation of a pipeline's image by the pixel classifier.

:class:`PixelSegmenter` sits beside a :class:`~.pipeline.Pipeline`: it takes the
pipeline's polarisation image (Î, ρ, φ; thesis eq. 3.14), keeps the pixel feature stack
(:mod:`.pixel_features`) while the feature parameters stay the same, trains the pixel
classifier (:mod:`.pixel_classifier`) on scribbles or applies a trained one, and
assembles a :class:`~.pipeline.SegmentationResult` whose labels are the classifier's —
the thesis stages (harmonics, PCA, reconstruction) still give the maps and the error map
of the segmentation contract; affinity and cut are not computed.

For a colour-polarisation camera (:mod:`~napari_polarseg.engine.physics.colour_mosaic`) the pipeline
runs on the
luminance stack and the segmenter is also given the (colour, angle, H, W) stack: the
features are then those of the luminance image (plain names, as for a mono camera)
followed by those of every colour's own polarisation image (names prefixed ``"R:"``,
``"G:"``, ``"B:"``; :func:`~napari_polarseg.engine.features.pixel_features.multichannel_features`),
so the classifier
can tell materials apart by the colour of their polarised reflection as well.
"""

from __future__ import annotations

import contextlib
import math
import threading
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .. import disk_arrays
from ..chunks import in_background
from ..features.banded_edges import add_banded, banded_superpixel_edges, banded_superpixels
from ..features.harmonics import top_left_block_labels
from ..features.object_size import (
    ObjectSize,
    scene_object_size,
    smallest_estimate,
    usable_pixels,
)
from ..features.pixel_features import (
    EPS_INTENSITY,
    FeatureStack,
    PixelFeatureParams,
    multichannel_features,
    pixel_features,
)
from ..features.superpixels import polarisation_superpixels, superpixel_edges, watershed_grid
from ..params import SegmentParams
from ..physics.colour_mosaic import COLOURS, colour_polarisation_images
from ..physics.pixel_mask import fill_from_nearest
from ..pipeline import Pipeline
from ..result import SegmentationResult
from ..timing import timed
from .pixel_classifier import (
    PREDICTION_STRIDE,
    ClassifierParams,
    PixelClassifier,
    PixelPrediction,
    check_feature_names,
    guide_stats,
    predict_pixels,
    train_pixel_classifier,
)
from .region_walk import RegionGraph, region_graph, walk_region_area, walked_prediction
from .tiled_features import (
    TiledFeatures,
    log_centres_of,
    tile_align,
    tile_halo,
    tiled_features,
)
from .tiled_prediction import prediction_margin, scribble_tiles, tiled_pixels, tiled_walk

#: Largest edge-aware smoothing radius (pixels) a tile's halo is grown for; a larger
#: ``smoothing`` on a tiled image reads past the halo (its probabilities near the
#: tiles' cuts then differ slightly from the whole image's).
TILED_SMOOTHING = 8.0


@dataclass(frozen=True)
class PixelSegmentation:
    """What :meth:`PixelSegmenter.segment` returns.

    Attributes
    ----------
    result : SegmentationResult
        Labels = class index 0..K−1 at pixel resolution (block labels: the label at each
        block's top-left pixel); no Ncut values; ``materials`` the classifier's (the
        scribble value and name of each class).
    prediction : PixelPrediction
        Probabilities (K, H, W), uncertainty (H, W), classes.
    classifier : PixelClassifier
        The classifier that was trained or applied.
    seconds : dict
        ``features``, ``train`` (0 when applied), ``predict``.
    """

    result: SegmentationResult
    prediction: PixelPrediction
    classifier: PixelClassifier
    seconds: dict[str, float] = field(default_factory=dict)


@dataclass
class PixelSegmenter:
    """Pixel features and the pixel classifier on a pipeline's polarisation image.

    Parameters
    ----------
    pipeline : Pipeline
        Its ``polarisation`` stage gives Î, ρ, φ and the invalid pixels (which do not
        train the classifier).
    colour_stack : array (C, N, H, W), optional
        Per-colour stacks of a colour-polarisation camera whose luminance is the
        pipeline's stack (same angles, size and alignment); their polarisation images
        (fitted like the pipeline's, with its sample weights) add features.
    colours : tuple of str
        Names of the colours of ``colour_stack`` (feature-name prefixes).
    stride : int
        Grid step of the coarse-to-fine prediction (:func:`predict_pixels`; 1 = every
        pixel on its own features).
    max_bytes : int, optional
        Memory limit of the method's work, bytes (default: the pipeline's
        ``work_limit()``, its limit less the stack and its flags; the limit is its
        ``max_bytes``, else :func:`~napari_polarseg.engine.limits.memory_limit`). An
        image whose whole-image features would exceed it is segmented tile by tile
        (:mod:`.tiled_prediction`): the features are then a
        :class:`~.tiled_features.TiledFeatures`.
    """

    pipeline: Pipeline
    colour_stack: np.ndarray | None = None
    colours: tuple[str, ...] = COLOURS
    stride: int = PREDICTION_STRIDE
    max_bytes: int | None = None
    _features: tuple[Any, FeatureStack] | None = field(default=None, init=False, repr=False)
    _colour_images: tuple[int, list] | None = field(default=None, init=False, repr=False)
    _graph: tuple[int, RegionGraph] | None = field(default=None, init=False, repr=False)
    #: The edge maps and superpixels of the polarisation image of ``"image"`` (its id).
    _kept: dict[Any, Any] = field(default_factory=dict, init=False, repr=False)
    _lock: threading.RLock = field(default_factory=threading.RLock, init=False, repr=False)
    #: The object size of the polarisation image and given size of the key (:meth:`object_size`).
    _size: tuple[Any, ObjectSize] | None = field(default=None, init=False, repr=False)
    _size_lock: threading.Lock = field(default_factory=threading.Lock, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.colour_stack is not None:
            shape = np.shape(self.colour_stack)
            if len(shape) != 4 or shape[1:] != self.pipeline.stack.shape:
                raise ValueError(
                    f"a colour stack {shape} does not match the pipeline's stack "
                    f"{self.pipeline.stack.shape}"
                )
            if len(self.colours) != shape[0]:
                raise ValueError(f"{shape[0]} colours but names {self.colours}")

    def colour_images(self, segment_params: SegmentParams | None = None) -> list:
        """Polarisation images of every colour (empty without a colour stack), fitted
        like the pipeline's for ``segment_params`` (default: the pipeline's last run's;
        its robust setting and sample weights) and kept."""
        if self.colour_stack is None:
            return []
        segment_params = segment_params or self.pipeline.params
        pol = self.pipeline.get("polarisation", segment_params)
        if self._colour_images is None or self._colour_images[0] != id(pol):
            mask = self.pipeline.mask
            weights = mask.sample_weights if bool(np.any(mask.flags)) else None
            images = colour_polarisation_images(
                self.colour_stack,
                self.pipeline.angles,
                robust=segment_params.fit == "robust",
                weights=weights,
            )
            self._colour_images = (id(pol), images)
        return self._colour_images[1]

    def features(
        self,
        params: PixelFeatureParams | None = None,
        colour: bool = True,
        segment_params: SegmentParams | None = None,
        progress: Any = None,
    ) -> FeatureStack:
        """The feature stack for ``params`` at the scene's object size (:meth:`sized`;
        kept while the image and params stay):
        the luminance image's features and, with ``colour`` and a colour stack, every
        colour's. ``segment_params``: the pipeline parameters of the polarisation image
        (default: the pipeline's last run's). The ``regions`` group's superpixels
        (:meth:`superpixels`) are drawn on a second thread meanwhile (the watershed
        releases the GIL)."""
        params = self.sized(params, segment_params)
        pol = self.pipeline.get("polarisation", segment_params)
        colour = colour and self.colour_stack is not None
        key = (id(pol), params, colour)
        if self._features is None or self._features[0] != key:
            maps = self.maps(segment_params)
            tiled = self.tiled(params, colour, segment_params)
            if tiled is not None:
                self._features = (key, tiled)
                return tiled
            regions = None
            if "regions" in params.groups:
                area = params.regions_of(maps[0].shape)
                regions = in_background(lambda: self.superpixels(area, segment_params, colour))
            if colour:
                images = [maps]
                colours = self.colour_images(segment_params)
                images += [(c.intensity, c.dop, c.phase) for c in colours]
                channels = ["", *self.colours]
                feats = multichannel_features(images, params, channels, regions=regions)
            else:
                feats = pixel_features(*maps, params, progress=progress, regions=regions)
            self._features = (key, feats)
        return self._features[1]

    def tiled(
        self,
        params: PixelFeatureParams,
        colour: bool = True,
        segment_params: SegmentParams | None = None,
    ) -> TiledFeatures | None:
        """The image's features as tiles (:class:`~.tiled_features.TiledFeatures`) when
        its whole-image estimate exceeds the memory limit (:attr:`max_bytes`;
        :func:`~.tiled_prediction.scribble_tiles`), else None. The halo: the features'
        reach and the prediction's margin (:func:`~.tiled_features.tile_halo`)."""
        maps = self.maps(segment_params)
        shape = maps[0].shape
        colour = colour and self.colour_stack is not None
        channels = ["", *self.colours] if colour else [""]
        align = tile_align(params, self.stride)
        margin = prediction_margin(self.stride, TILED_SMOOTHING)
        halo = tile_halo(params, margin)
        limit = self.work_limit()
        grid = scribble_tiles(shape, params, halo, align, len(channels), limit=limit)
        if grid is None:
            return None
        images = [maps]
        images += [(c.intensity, c.dop, c.phase) for c in self.colour_images(segment_params)]
        images = images[: len(channels)]
        centres = log_centres_of(images)
        regions, block = None, 1
        if "regions" in params.groups:
            area = params.regions_of(shape)
            regions, block = self.superpixels(area, segment_params, colour), watershed_grid(area)
        return tiled_features(images, channels, params, grid, regions, centres, block)

    def work_limit(self) -> int:
        """The memory limit of the method's work, bytes: :attr:`max_bytes`, else the
        pipeline's ``work_limit()``."""
        return self.max_bytes if self.max_bytes is not None else self.pipeline.work_limit()

    def full_size_arrays(self) -> contextlib.AbstractContextManager[None]:
        """The context in which the method's full-size arrays (edge map, superpixels,
        the prediction's planes) are made: in memory, or in temporary files when the
        image's full-size arrays do not fit :meth:`work_limit`
        (:func:`~..disk_arrays.full_size_limit`)."""
        return disk_arrays.full_size_limit(self.work_limit())

    def edges(self, segment_params: SegmentParams | None = None, colour: bool = True) -> np.ndarray:
        """The superpixels' edge map: :func:`superpixel_edges` of the maps of
        :meth:`maps` plus, with ``colour`` and a colour stack, every colour's
        polarisation image's (a border seen in one colour only is an edge too); kept
        while the polarisation image stays. When the image's full-size arrays go to
        temporary files (:func:`~..disk_arrays.pixels_on_disk`), made band by band
        into one (:func:`~..features.banded_edges.banded_superpixel_edges`: the same
        values)."""
        colour = colour and self.colour_stack is not None
        with self._lock, self.full_size_arrays():
            kept = self._kept_for(segment_params)
            if ("edges", colour) not in kept:
                maps = self.maps(segment_params)
                colours = self.colour_images(segment_params) if colour else []
                banded = disk_arrays.pixels_on_disk(maps[0].size)
                make = banded_superpixel_edges if banded else superpixel_edges
                edges = make(*maps)
                for c in colours:
                    add_banded(edges, make(c.intensity, c.dop, c.phase))
                kept["edges", colour] = edges
            return kept["edges", colour]

    def superpixels(
        self, area: int, segment_params: SegmentParams | None = None, colour: bool = True
    ) -> np.ndarray:
        """Superpixels (H, W) of ``area`` pixels on :meth:`edges` (``colour``: with the
        colours' edges) (:func:`polarisation_superpixels`, on the coarser grid of
        :func:`watershed_grid` for large regions), kept while the polarisation image
        stays: the pixel features' regions and the region walk's graph share
        them when their areas agree (a camera frame). Thread-safe: a second caller
        waits for the first one's watershed. When the image's full-size arrays go to
        temporary files, in one (on the coarser grid every pixel given its block's
        region band by band, :func:`~..features.banded_edges.banded_superpixels`: the
        same superpixels)."""
        colour = colour and self.colour_stack is not None
        with self._lock, self.full_size_arrays():
            kept = self._kept_for(segment_params)
            if ("regions", area, colour) not in kept:
                i, d, p = self.maps(segment_params)
                edges = self.edges(segment_params, colour)
                grid = watershed_grid(area)
                disk = disk_arrays.pixels_on_disk(edges.size)
                if disk and grid > 1:
                    regions = banded_superpixels(edges, area, grid)
                else:
                    regions = polarisation_superpixels(i, d, p, area, edges=edges, grid=grid)
                    regions = disk_arrays.copy_of(regions) if disk else regions
                kept["regions", area, colour] = regions
            return kept["regions", area, colour]

    def _kept_for(self, segment_params: SegmentParams | None) -> dict[Any, Any]:
        """What :meth:`edges` and :meth:`superpixels` keep, emptied when the
        polarisation image changes."""
        pol = self.pipeline.get("polarisation", segment_params)
        if self._kept.get("image") != id(pol):
            self._kept = {"image": id(pol)}
        return self._kept

    def object_size(self, segment_params: SegmentParams | None = None) -> ObjectSize:
        """The scene's object size D (px): ``segment_params.object_size`` when set, else
        estimated from the polarisation image's valid pixels in the user's region
        (:func:`~..features.object_size.scene_object_size`), kept while the image stays.
        Thread-safe: a second caller waits for the first one's estimate."""
        key, pol = self._size_key(segment_params)
        with self._size_lock:
            if self._size is None or self._size[0] != key:
                region = self.pipeline.mask.region
                i, d, p = pol.intensity, pol.dop, pol.phase
                size = scene_object_size(i, d, p, pol.invalid, key[1], region)
                self._size = (key, size)
            return self._size[1]

    def _size_key(self, segment_params: SegmentParams | None) -> tuple[tuple[int, float], Any]:
        """What :meth:`object_size` is kept for (the polarisation image's id and the
        given size) and that image."""
        segment_params = segment_params or self.pipeline.params
        pol = self.pipeline.get("polarisation", segment_params)
        return (id(pol), float(segment_params.object_size)), pol

    def sized(
        self, params: PixelFeatureParams | None, segment_params: SegmentParams | None = None
    ) -> PixelFeatureParams:
        """``params`` (default ``PixelFeatureParams()``) at this scene's object size
        (:meth:`~..features.pixel_feature_params.PixelFeatureParams.at_object_size`;
        fixed parameters, e.g. a trained classifier's, are returned as they are). When no
        size the estimate can give on this image would drop a scale (a large image:
        its estimate works on a block-averaged grid), every scale is kept without
        waiting for it."""
        params = params or PixelFeatureParams()
        if not params.follows_object_size:
            return params
        segment_params = segment_params or self.pipeline.params
        if segment_params.object_size <= 0:
            floor = self.smallest_object_size(segment_params)
            if params.at_object_size(floor).scales == params.scales:
                return params.at_object_size(math.inf)
        return params.at_object_size(self.object_size(segment_params).size_px)

    def smallest_object_size(self, segment_params: SegmentParams | None = None) -> float:
        """The smallest object size (px) the estimate can give on this image's valid
        pixels in the user's region (:func:`~..features.object_size.smallest_estimate`)."""
        pol = self.pipeline.get("polarisation", segment_params)
        return smallest_estimate(usable_pixels(pol.invalid, self.pipeline.mask.region))

    def known_object_size(self, segment_params: SegmentParams | None = None) -> ObjectSize | None:
        """The object size :meth:`object_size` has kept for this image and given size,
        None when it was not needed (nothing is computed)."""
        key, _ = self._size_key(segment_params)
        with self._size_lock:
            kept = self._size
        return kept[1] if kept is not None and kept[0] == key else None

    def maps(self, segment_params: SegmentParams | None = None) -> tuple[np.ndarray, ...]:
        """Î, ρ, φ the features are computed on: the pipeline's polarisation image, and
        outside the user's region (``pipeline.mask.region``) the nearest pixel inside it
        (:func:`~napari_polarseg.engine.physics.pixel_mask.fill_from_nearest`), so the
        filters carry nothing from outside the region into it."""
        pol = self.pipeline.get("polarisation", segment_params)
        region = self.pipeline.mask.region
        maps = (pol.intensity, pol.dop, pol.phase)
        if region is None:
            return maps
        return fill_from_nearest(np.asarray(region, dtype=bool), *maps)

    @property
    def cached_features(self) -> FeatureStack | None:
        """The feature stack kept from the last :meth:`features` call (None before).

        The same object until the polarisation image or the feature parameters change:
        retraining on new scribbles does not recompute it.
        """
        return None if self._features is None else self._features[1]

    def graph(self, segment_params: SegmentParams | None = None) -> RegionGraph:
        """The superpixel graph of the region walk (:mod:`.region_walk`): superpixels
        of its area (:func:`~.region_walk.walk_region_area`) on :meth:`edges`, kept
        while the polarisation image stays."""
        pol = self.pipeline.get("polarisation", segment_params)
        if self._graph is None or self._graph[0] != id(pol):
            area = walk_region_area(self.pipeline.stack.shape[1:])
            regions = self.superpixels(area, segment_params)
            self._graph = (id(pol), region_graph(regions, self.edges(segment_params)))
        return self._graph[1]

    def predict(
        self,
        classifier: PixelClassifier,
        features: FeatureStack,
        scribbles: np.ndarray | None = None,
        cancel: Any = None,
        segment_params: SegmentParams | None = None,
        stride: int | None = None,
        coarse: np.ndarray | None = None,
    ) -> PixelPrediction:
        """Every pixel's class: with ``classifier.params.region_walk`` > 0 the walk over
        the superpixel graph from ``scribbles``
        (:func:`~.region_walk.walked_prediction`), else the classifier alone coarse to
        fine, edge-aware smoothed (:func:`~.pixel_classifier.predict_pixels`).
        ``stride``: the grid step (default :attr:`stride`); ``coarse``: its
        probabilities when already predicted."""
        s = self.stride if stride is None else int(stride)
        with self.full_size_arrays():  # the planes in temporary files when they do not fit
            if isinstance(features, TiledFeatures):
                check_feature_names(classifier, features.names)
                if classifier.params.region_walk > 0:
                    graph = self.graph(segment_params)
                    return tiled_walk(classifier, features, graph, s, scribbles, cancel)
                guide = None
                if classifier.params.smoothing > 0:
                    g = self.guide(segment_params)
                    guide = (g, guide_stats(g))
                return tiled_pixels(classifier, features, s, guide, cancel)
            if classifier.params.region_walk > 0:
                graph = self.graph(segment_params)
                return walked_prediction(classifier, features, graph, s, scribbles, cancel, coarse)
            guide = self.guide(segment_params) if classifier.params.smoothing > 0 else None
            return predict_pixels(classifier, features, guide, cancel, s, coarse)

    def guide(self, segment_params: SegmentParams | None = None) -> np.ndarray:
        """Guide image of the edge-aware smoothing: log Î."""
        intensity = self.maps(segment_params)[0]
        return np.log(np.maximum(intensity, EPS_INTENSITY)).astype(np.float32)

    def train(
        self,
        scribbles: np.ndarray,
        feature_params: PixelFeatureParams | None = None,
        params: ClassifierParams | None = None,
        segment_params: SegmentParams | None = None,
    ) -> PixelClassifier:
        """Fit the classifier on the scribbled valid pixels."""
        feats = self.features(feature_params, segment_params=segment_params)
        valid = ~self.pipeline.get("polarisation", segment_params).invalid
        return train_pixel_classifier(feats, scribbles, params, valid=valid)

    def segment(
        self,
        scribbles: np.ndarray | None = None,
        classifier: PixelClassifier | None = None,
        *,
        feature_params: PixelFeatureParams | None = None,
        params: ClassifierParams | None = None,
        reconstruction: bool = True,
        cancel: Any = None,
        segment_params: SegmentParams | None = None,
    ) -> PixelSegmentation:
        """Train on ``scribbles`` (or apply ``classifier``) and label every pixel.

        Exactly one of ``scribbles`` and ``classifier`` is given. A given classifier
        brings its own feature parameters (``feature_params`` is then ignored).
        ``segment_params``: the pipeline parameters of the run (default: the pipeline's
        last run's).
        """
        segment_params = segment_params or self.pipeline.params
        prediction, classifier, seconds = self.classify(
            scribbles,
            classifier,
            feature_params=feature_params,
            params=params,
            cancel=cancel,
            segment_params=segment_params,
        )
        result = self.result(prediction.labels, reconstruction, seconds, segment_params)
        result = replace(result, materials=classifier.materials())
        return PixelSegmentation(result, prediction, classifier, seconds)

    def classify(
        self,
        scribbles: np.ndarray | None = None,
        classifier: PixelClassifier | None = None,
        *,
        feature_params: PixelFeatureParams | None = None,
        params: ClassifierParams | None = None,
        cancel: Any = None,
        segment_params: SegmentParams | None = None,
    ) -> tuple[PixelPrediction, PixelClassifier, dict[str, float]]:
        """Train on ``scribbles`` (or apply ``classifier``) and predict every pixel:
        (prediction, classifier, seconds of ``features``, ``train``, ``predict``); what
        :meth:`segment` does before it assembles the result."""
        segment_params = segment_params or self.pipeline.params
        if (scribbles is None) == (classifier is None):
            raise ValueError("give scribbles or a classifier, not both or neither")
        seconds: dict[str, float] = {}
        with timed(seconds, "features"):
            fparams = classifier.feature_params if classifier is not None else feature_params
            colour = classifier is None or any(
                name.split(":", 1)[0] in self.colours for name in classifier.feature_names
            )
            feats = self.features(fparams, colour, segment_params)
        seconds["train"] = 0.0  # an applied classifier is not retrained
        if classifier is None:
            with timed(seconds, "train"):
                classifier = self.train(scribbles, feats.params, params, segment_params)
        with timed(seconds, "predict"):
            prediction = self.predict(classifier, feats, scribbles, cancel, segment_params)
        return prediction, classifier, seconds

    def result(
        self,
        labels: np.ndarray,
        reconstruction: bool,
        seconds: dict[str, float],
        segment_params: SegmentParams | None = None,
    ) -> SegmentationResult:
        """A :class:`SegmentationResult` of the pipeline's maps for ``segment_params``
        (default: the pipeline's last run's) and these pixel labels; with
        ``reconstruction`` the thesis's harmonics, PCA features and error map too
        (without, they are None, as for the other methods that do not read them)."""
        pipe = self.pipeline
        segment_params = segment_params or pipe.params
        block = top_left_block_labels(labels, segment_params.window)
        names = ["polarisation", "normals"]
        names += ["harmonics", "pca", "reconstruction"] if reconstruction else []
        for name in names:
            pipe.get(name, segment_params)
        timings = {s: pipe.stage_seconds(s) for s in names}
        timings["pixel_classifier"] = float(sum(seconds.values()))
        return pipe.assemble_result(
            block,
            labels.astype(np.int64),
            [],
            reconstruction,
            timings=timings,
            recomputed=names + ["pixel_classifier"],
            params=segment_params,
            maps=reconstruction,
        )
