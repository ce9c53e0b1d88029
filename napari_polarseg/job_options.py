"""What ``polarseg segment`` (and each scene of a batch) is asked for: how to read the
input (:class:`~napari_polarseg.io.read_options.ReadOptions`, defined in ``io``), which
optional files to write (:class:`OutputOptions`), and the command-line options that ask
for both (:func:`segment_args`, a batch's record).
"""

from __future__ import annotations

from dataclasses import dataclass

from .io.read_options import ReadOptions

__all__ = ["OutputOptions", "ReadOptions", "segment_args"]


@dataclass(frozen=True)
class OutputOptions:
    """Which optional files a result folder gets.

    Attributes
    ----------
    overview, plots : bool
        ``overview.png`` (matplotlib figure); the analyst's plots as PNGs in ``plots/``.
    save_classifier : str or None
        With scribbles: also write the trained classifier to this file.
    thesis_maps : bool
        Also compute the thesis maps for a method that does not need them (harmonic
        coefficients and PCA features: the feature columns of ``segments.csv`` and the
        plots; the reconstruction-error map ``reconstruction_error.tif``). The thesis
        method always computes them; ``plots`` asks for them too.
    image_format : str
        The images as ``tiff`` (a tiled BigTIFF when large) or ``zarr`` (OME-Zarr
        directories, ``labels.zarr``, …): ``polarseg segment --format``.
    """

    overview: bool = False
    plots: bool = False
    save_classifier: str | None = None
    thesis_maps: bool = False
    image_format: str = "tiff"


def segment_args(read: ReadOptions, outputs: OutputOptions) -> list[str]:
    """The ``polarseg segment`` options that ask for ``read`` and ``outputs`` (the record
    a batch keeps in each scene's completion marker; defaults are left out): the reading
    options (:meth:`ReadOptions.to_args`), then --overview, --plots, --save-classifier."""
    flags = [
        ("--overview", outputs.overview),
        ("--plots", outputs.plots),
        ("--thesis-maps", outputs.thesis_maps),
    ]
    out = read.to_args() + [flag for flag, on in flags if on]
    if outputs.save_classifier:
        out += ["--save-classifier", outputs.save_classifier]
    return out
