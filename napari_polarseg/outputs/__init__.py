"""What the package writes: result folders and their figures (no napari, no Qt).

- :mod:`~napari_polarseg.outputs.contract`: the file names and TIFF metadata of a
  ``segment`` result folder, :class:`OutputError`, :func:`labels_image`,
  :func:`used_pixels`;
- :mod:`~napari_polarseg.outputs.result_folder`: :func:`write_result_folder` (what
  ``polarseg segment --out`` and the plugin's *Export results…* write),
  :func:`write_outputs`, ``segments.csv`` (:func:`segment_rows`,
  :func:`write_segments_csv`), ``params.json`` (:func:`run_info`) and the items of
  ``summary.json`` (:func:`evaluation_summary`, :func:`classifier_summary`);
- :mod:`~napari_polarseg.outputs.overview`: ``overview.png`` (:func:`overview_figure`,
  :func:`render_overview`, :func:`segment_colours_for`);
- :mod:`~napari_polarseg.outputs.figures`: the analyst's plots (:func:`render_plots`,
  :func:`save_plots`, :data:`PLOT_FILES`) and the sweep heatmap
  (:func:`sweep_heatmap_figure`).

The names listed in ``__all__`` are importable from here.
"""

from .contract import (
    COMPOSITE_FILE,
    EVALUATION_SUMMARY_KEYS,
    FLOAT_OUTPUTS,
    MASK_META,
    PLOT_FILES,
    PROBABILITY_META,
    STOKES_FILE,
    UNCERTAINTY_META,
    OutputError,
    labels_image,
    result_files,
    used_pixels,
)
from .figures import png_bytes, render_plots, save_plots, sweep_heatmap_figure
from .overview import overview_figure, render_overview, segment_colours_for
from .result_folder import (
    classifier_summary,
    evaluation_summary,
    run_info,
    segment_rows,
    write_outputs,
    write_result_folder,
    write_segments_csv,
)

__all__ = [
    "COMPOSITE_FILE",
    "EVALUATION_SUMMARY_KEYS",
    "FLOAT_OUTPUTS",
    "MASK_META",
    "PLOT_FILES",
    "PROBABILITY_META",
    "STOKES_FILE",
    "UNCERTAINTY_META",
    "OutputError",
    "classifier_summary",
    "evaluation_summary",
    "labels_image",
    "overview_figure",
    "png_bytes",
    "render_overview",
    "render_plots",
    "run_info",
    "save_plots",
    "segment_colours_for",
    "segment_rows",
    "sweep_heatmap_figure",
    "used_pixels",
    "result_files",
    "write_outputs",
    "write_result_folder",
    "write_segments_csv",
]
