"""The segments' qualitative palette: bright colours that are far apart from each other.

Label k (k = 1, 2, …) of a segments or scribbles layer gets ``SEGMENT_COLOURS[(k - 1) %
10]``; the plots and ``overview.png`` colour a segment with the colour of the value the
viewer shows it as (:func:`label_rgba`), so a point, a panel and its region match. The
colours are the first ten of Sasha Trubetskoy's "20 simple distinct colours" (red, green,
yellow, blue, orange, purple, cyan, magenta, lime, pink): every channel maximum is at least
0.7 and two of them are at least 0.3 apart in RGB (0–1 per channel; yellow and lime are
the closest pair, 0.31). napari's default labels colormap gave label 1 a dark brown.
"""

from __future__ import annotations

import numpy as np

#: The palette, in label order (label 1 first).
SEGMENT_COLOURS: tuple[str, ...] = (
    "#e6194b",
    "#3cb44b",
    "#ffe119",
    "#4363d8",
    "#f58231",
    "#911eb4",
    "#42d4f4",
    "#f032e6",
    "#bfef45",
    "#fabed4",
)


def segment_rgba(count: int | None = None) -> np.ndarray:
    """RGBA (0–1) of the palette: ``count`` rows for labels 1, 2, … (cycled), or one
    per colour."""
    rgb = np.array([[int(h[i : i + 2], 16) / 255.0 for i in (1, 3, 5)] for h in SEGMENT_COLOURS])
    rgba = np.concatenate([rgb, np.ones((rgb.shape[0], 1))], axis=1)
    if count is None:
        return rgba
    return rgba[np.arange(count) % rgba.shape[0]]


def label_rgba(values: np.ndarray | list[int]) -> np.ndarray:
    """RGBA (0–1) of label values as a segments or scribbles layer draws them: value v ≥ 1
    gets ``SEGMENT_COLOURS[(v - 1) % 10]`` (the viewer's cyclic colormap, label 0 being
    transparent). The plots and ``overview.png`` colour a label with the colour of the
    value the viewer shows it as
    (:func:`napari_polarseg.engine.materials.display_values`)."""
    rgba = segment_rgba()
    return rgba[(np.asarray(values, dtype=np.int64) - 1) % rgba.shape[0]]
