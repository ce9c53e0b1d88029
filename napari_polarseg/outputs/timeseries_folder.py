"""The folder ``polarseg timeseries`` writes: per-day labels, per-pair change, score and
distance maps, ``params.json`` and ``summary.json``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import io as pio
from .contract import OutputError, labels_image

if TYPE_CHECKING:
    from ..engine.analysis.timeseries_result import TimeSeriesResult


def timeseries_files(score_threshold: float) -> dict[str, str]:
    """What each kind of file of the folder holds (the ``files`` entry of ``params.json``).

    Parameters
    ----------
    score_threshold
        The change score above which a block changed significantly.
    """
    return {
        "labels": "labels_DD.tif: segment of every pixel on day DD (0 = first segment, "
        "the same numbering every day)",
        "change": "change_DD.tif: 1 where the block changed segment from day DD to DD+1",
        "score": "score_DD.tif: change score of the pixel's change block between day DD "
        "and DD+1 (normal deviate of the p-value that its polarisation image did not "
        f"change; significant above {score_threshold:.2f})",
        "distance": "distance_DD.tif: Mahalanobis distance of the block's features "
        "between day DD and DD+1 (shared basis)",
    }


def write_timeseries_folder(
    folder: str | Path,
    result: TimeSeriesResult,
    info: dict[str, Any],
    summary: dict[str, Any],
) -> list[str]:
    """Write a time series into ``folder`` (created if needed), each file atomically.

    Parameters
    ----------
    folder
        The output folder.
    result
        The time series: ``labels_DD.tif`` for every day DD (01, 02, ...);
        ``change_DD.tif``, ``score_DD.tif`` and ``distance_DD.tif`` for days DD, DD+1.
    info
        The content of ``params.json``.
    summary
        The content of ``summary.json``.

    Returns
    -------
    list[str]
        The names of the files written, in order.

    Raises
    ------
    OutputError
        If a file could not be written (its name in the message).
    """
    out = Path(folder)
    written: list[str] = []
    name = str(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        for t, labels in enumerate(result.labels):
            name = str(out / f"labels_{t + 1:02d}.tif")
            meta = {"quantity": "segment labels", "first_label": 0, "day": t + 1}
            if summary.get("labels_from") == "classifier":  # numbered as the strokes
                meta = {"quantity": "segment labels", "values": "scribble values", "day": t + 1}
            pio.write_tiff(name, labels_image(labels), meta)
            written.append(Path(name).name)
        pairs = zip(result.changes, result.change_score, result.feature_distance, strict=True)
        for t, (change, score, dist) in enumerate(pairs):
            name = str(out / f"change_{t + 1:02d}.tif")
            meta = {"quantity": "segment changed", "from_day": t + 1, "to_day": t + 2}
            pio.write_tiff(name, change.astype(np.uint8), meta)
            written.append(Path(name).name)
            name = str(out / f"score_{t + 1:02d}.tif")
            meta = {"quantity": "change score (normal deviate)", "from_day": t + 1}
            pio.write_tiff(name, score.astype(np.float32), {**meta, "to_day": t + 2})
            written.append(Path(name).name)
            name = str(out / f"distance_{t + 1:02d}.tif")
            meta = {"quantity": "feature distance (Mahalanobis)", "from_day": t + 1}
            pio.write_tiff(name, dist.astype(np.float32), {**meta, "to_day": t + 2})
            written.append(Path(name).name)
        name = str(out / "params.json")
        pio.write_json(name, info)
        name = str(out / "summary.json")
        pio.write_json(name, summary)
        written += ["params.json", "summary.json"]
    except OSError as exc:
        raise OutputError(f"cannot write {name}: {exc.strerror or exc}") from exc
    return written
