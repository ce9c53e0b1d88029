"""The unsupervised segmenter: superpixels, their features, clustering and refinement.

Superpixels (:mod:`~napari_polarseg.engine.features.superpixels`), the edge-aware region diffusion
(:mod:`.region_diffusion`), weighted k-means (:mod:`.kmeans`) and the segmenter that
chains them (:mod:`.segmenter`).
"""
