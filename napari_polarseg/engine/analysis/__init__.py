"""Analyses around the cut: scoring, scribbles, pixel classification, sweeps, time series.

Evaluation against a truth (:mod:`.evaluation`), scribble training of blocks
(:mod:`.scribbles`) and of pixels (:mod:`.pixel_classifier`, :mod:`.pixel_segmentation`),
the parameter sweep (:mod:`.sweep`), time series (:mod:`.timeseries`), plot data
(:mod:`.plots`), display views (:mod:`.views`) and degenerate-input checks
(:mod:`.degenerate`).
"""
