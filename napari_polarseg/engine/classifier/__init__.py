"""The pixel classifier: trained on the user's scribbles, it labels every pixel.

Its features (:mod:`..features.pixel_features`) and the model
(:mod:`.pixel_classifier`, settings in :mod:`.classifier_settings`), the coarse-to-fine
prediction (:mod:`.refined_prediction`) and the region walk (:mod:`.region_walk`), the
classifier on a pipeline's image (:mod:`.pixel_segmentation`) and the interactive loop
(:mod:`.scribble_session`); the block classifier of the thesis method
(:mod:`.scribbles`), strokes made from labels (:mod:`.scribbles_from_labels`) and where
to paint next (:mod:`.suggestion`). The method that runs it in a
:class:`~napari_polarseg.engine.Scene` is
:mod:`napari_polarseg.engine.methods.pixel_classification`; its file format is
:mod:`napari_polarseg.classifier_file`, above the engine.
"""
