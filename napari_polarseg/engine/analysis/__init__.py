"""Analyses around a segmentation: scoring, sweeps, time series, plots and views.

Evaluation against a truth (:mod:`.evaluation`), the parameter sweep (:mod:`.sweep`,
:mod:`.sweep_result`), time series (:mod:`.timeseries` with :mod:`.change_test`,
:mod:`.tracking`, :mod:`.timeseries_segments`, :mod:`.timeseries_result`), plot data
(:mod:`.plots`) and display views (:mod:`.views`). The pixel classifier has its own
package, :mod:`napari_polarseg.engine.classifier`.
"""
