"""The texts the widgets show, made without Qt: the status line of a running job, error
messages, the polariser angles field (parsed by :func:`napari_polarseg.io.parse_angles`),
the warnings of a result."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...engine import PolarsegError
from ...engine.methods import get_method, method_names
from ...engine.physics.pixel_mask import mask_reasons
from ...engine.registered import computes_block_maps
from ...engine.unsupervised.choose_k import choice_text
from ...io.common import format_numbers
from .runs import StageFailed


def stage_text(stage: str, index: float, total: int) -> str:
    """The status line of a running job: ``"running: pca (4/8)"`` after a stage,
    ``"running: harmonics 40 % (2/8)"`` within one (a fractional ``index``)."""
    if not stage:
        return "running…"
    done = int(index)
    share = index - done
    within = f" {share:.0%}".replace("%", " %") if share > 0 else ""
    return f"running: {stage}{within} ({done}/{total})"


def error_message(exc: BaseException) -> str:
    """The one line shown to the user: the engine's message, or type and message."""
    if isinstance(exc, (PolarsegError, StageFailed)):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"


def format_angles(angles_deg: Any) -> str:
    """``[0.0, 45.0]`` -> ``"0, 45"``."""
    return format_numbers(np.asarray(angles_deg, dtype=float).ravel())


#: What to try after a degenerate result, in the plugin's words, by kind of method.
DEGENERATE_TRIES = {
    "blocks": "the recommended preset, fewer or more segments, a larger window, or scribbles",
    "classifier": "more strokes on every material",
    "other": "fewer or more segments, another object size, or scribbles",
}


def degenerate_text(summary: dict[str, Any]) -> str:
    """The status line's warning of a degenerate result, from ``result.summary()``
    (``"degenerate"``: one segment holds >= 95 % of the pixels, or, for a method that
    cuts blocks, every other is below the minimum size), with what to try for the method
    that made the labels (:data:`DEGENERATE_TRIES`: a larger window only where the method
    reads one); "" when the result is not degenerate."""
    if not summary.get("degenerate"):
        return ""
    method = str(summary.get("method") or "")
    if method in method_names() and get_method(method).inputs:  # scribbles, a classifier
        kind = "classifier"
    else:
        kind = "blocks" if computes_block_maps(method) else "other"
    return f"degenerate: {summary.get('degenerate_reason')} (try {DEGENERATE_TRIES[kind]})"


def close_up_text(summary: dict[str, Any]) -> str:
    """The status line's note that the frame was taken for a close-up of one smooth
    surface (``summary["superpixels"]["close_up"]``, preset auto); "" otherwise."""
    record = summary.get("superpixels") or {}
    if not record.get("close_up"):
        return ""
    return (
        f"one smooth surface ({record['surface_share']:.0%} of the polarisation): "
        "segments where it departs from the surface's trend"
    )


def mask_text(counts: dict[str, Any]) -> str:
    """``"masked: 120 saturated, 3 black"`` from ``result.mask_counts`` ("" if none)."""
    parts = mask_reasons(counts)
    return f"masked: {', '.join(parts)}" if parts else ""


def k_choice_text(summary: dict[str, Any]) -> str:
    """The status line's note of the number of segments found by itself and how sure
    (``summary["superpixels"]``, ``n_segments = 0``); "" when k was given."""
    return choice_text(summary.get("superpixels") or {})


def object_size_text(summary: dict[str, Any]) -> str:
    """The status line's note of the object size the superpixels followed
    (``summary["superpixels"]``): ``"objects 34 px (given)"``, ``"objects ~34 px
    (estimated, not applied)"``; "" for a method that does not read it."""
    record = summary.get("superpixels") or {}
    if "object_size" not in record:
        return ""
    if not record.get("object_size_found"):
        return f"objects {record['object_size']:.0f} px (given)"
    applied = "" if record.get("object_size_applied") else ", not applied"
    return f"objects ~{record['object_size']:.0f} px (estimated{applied})"
