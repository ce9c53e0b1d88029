"""The lines a command line shows about a segment job (:mod:`napari_polarseg.jobs`): its
summary line, the warning of a degenerate result with what to try, what the cut gave up
on, the pixels left out, the files written, the classifier's and the evaluation's lines.

They are built as :class:`Message` data (text and stream), which the job returns in its
:class:`~napari_polarseg.jobs.FolderResult`, the command line prints and a batch keeps as
each scene's log; nothing is printed here. Every line starts with :data:`PROG`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .engine.methods import get_method, method_names
from .engine.params import PARAM_SPECS, PRESETS, SegmentParams, method_param_specs
from .engine.physics.pixel_mask import mask_reasons
from .engine.registered import computes_block_maps
from .engine.unsupervised.choose_k import choice_text

if TYPE_CHECKING:
    from .engine.classifier.pixel_classifier import PixelClassifier
    from .job_run import Run

#: Prefix of every message line (the command's name).
PROG = "polarseg"


@dataclass(frozen=True)
class Message:
    """One line a command line shows about a run, and its stream (stdout or stderr)."""

    text: str
    stream: str = "stdout"


#: What to try for the shared parameters a method may read (``reads``), by field name.
SHARED_ADVICE = {
    "n_segments": "fewer or more segments",
    "object_size": "another object size",
}


def degenerate_advice(method: str, params: SegmentParams, classifier: bool = False) -> str:
    """What to try after a degenerate result of ``method`` (the method that made the
    labels) run with ``params``, naming only flags it reads: a method that cuts blocks
    (the thesis method) the recommended preset (unless in use), ``--segments`` and
    ``--window``; another the shared parameters it reads (``--segments``,
    ``--object-size``) and its own numeric ones; every method scribbles. ``classifier``
    (or a method that takes inputs, such as scribbles): the labels came from a pixel
    classifier."""
    known = method in method_names()
    if classifier or (known and get_method(method).inputs):
        return "paint strokes on every material (--scribbles) or retrain the classifier"
    if computes_block_maps(method):
        tries = ["fewer or more segments (--segments)", "a larger window (--window)"]
        recommended = PRESETS["recommended"].replace(n_segments=params.n_segments)
        if params != recommended:
            tries.insert(0, "--preset recommended")
        return f"try {', '.join(tries)}, or scribbles (--scribbles)"
    reads = get_method(method).reads if known else ()
    tries = [f"{words} ({PARAM_SPECS[n].flag})" for n, words in SHARED_ADVICE.items() if n in reads]
    own = [s.flag for s in method_param_specs(method).values() if s.options() is None]
    if own:
        tries.append(f"other values of its parameters ({', '.join(own)})")
    if not tries:
        return "try scribbles (--scribbles)"
    return f"try {', '.join(tries)}, or scribbles (--scribbles)"


def degenerate_warning(run: Run) -> str | None:
    """The one-line warning of a degenerate result (``SegmentationResult.degenerate``:
    one segment holds >= 95 % of the pixels, or, for a method that cuts blocks, every
    other is below the minimum size), with what to try (:func:`degenerate_advice`); None
    when the result is not degenerate."""
    check = run.result.degenerate()
    if not check.degenerate:
        return None
    # labels from a pixel classifier, not the method of the parameters
    advice = degenerate_advice(run.result.method, run.params, "classifier" in run.seconds)
    return f"{PROG}: warning: degenerate result: {check.reason}; {advice}"


def limit_lines(run: Run) -> list[str]:
    """What the cut gave up on, the close-up of one surface, and the registration
    shifts."""
    lines = []
    limits = run.result.cut_limits
    done = []
    if limits.get("eigensolver_capped"):
        done.append(
            f"stopped {limits['eigensolver_capped']} eigensolve(s) at their cap of "
            f"{limits.get('max_products')} products"
        )
    if limits.get("isolated_skipped"):
        done.append(f"peeled {limits['isolated_skipped']} isolated block(s) off unsolved")
    if done:
        lines.append(f"{PROG}: the cut {' and '.join(done)} (cut_limits in summary.json)")
    record = run.result.superpixels
    found = choice_text(record)
    if found:
        lines.append(f"{PROG}: {found} (k_scores in summary.json)")
    if "object_size" in record:
        lines.append(f"{PROG}: {object_size_text(record)}")
    scales_text = feature_scales_text(run.result.method_record)
    if scales_text:
        lines.append(f"{PROG}: {scales_text}")
    if record.get("close_up"):
        lines.append(
            f"{PROG}: one smooth surface fills the frame (it explains "
            f"{record['surface_share']:.0%} of the polarisation): the segments follow where "
            "the polarisation departs from that surface's trend (superpixels in summary.json)"
        )
    if run.shifts is not None:
        biggest = float(np.max(np.hypot(run.shifts[:, 0], run.shifts[:, 1])))
        lines.append(
            f"{PROG}: registered {len(run.shifts)} frames to frame 0, largest shift "
            f"{biggest:.2f} px (rows, columns per frame in params.json)"
        )
    return lines


def report_messages(
    out: Path,
    run: Run,
    written: list[str],
    note_repeated: bool = True,
    removed: Sequence[str] = (),
) -> list[Message]:
    """The run's lines; ``note_repeated=False`` leaves out the information that frames at
    a repeated angle were averaged (the bundled samples, made that way; it stays in
    params.json and summary.json); ``removed``: an earlier run's files the writing
    removed from ``out``. The reconstruction error is said where the method computed it."""
    result = run.result
    err = result.mean_reconstruction_error
    err_text = "" if err is None else f", mean reconstruction error {err:.4g}"
    h, w = result.labels.shape
    messages = [Message(f"{PROG}: {result.n_segments} segments over {h} x {w} pixels{err_text}")]
    if removed:
        messages.append(
            Message(
                f"{PROG}: removed {len(removed)} file(s) of an earlier run from {out}: "
                + ", ".join(removed),
                "stderr",
            )
        )
    warning = degenerate_warning(run)
    if warning is not None:
        messages.append(Message(warning, "stderr"))
    lines = limit_lines(run)
    counts = result.mask_counts
    if counts.get("masked_pixels"):
        reasons = mask_reasons(counts)
        lines.append(
            f"{PROG}: left out {counts['masked_pixels']} of {h * w} pixels "
            f"({', '.join(reasons)}; see mask.tif)"
        )
    for frames in result.duplicate_angle_frames if note_repeated else ():
        angles = " and ".join(f"{run.data.angles_deg[k]:g}" for k in frames)
        lines.append(
            f"{PROG}: frames {', '.join(map(str, frames))} ({angles} degrees) are one "
            "polariser state: averaged"
        )
    plots = [name for name in written if name.startswith("plots/")]
    listed = [name for name in written if name not in plots]
    if plots:
        listed.insert(-2, f"plots/ ({len(plots)} PNGs)")  # before params.json, summary.json
    lines.append(f"{PROG}: wrote {', '.join(listed)} to {out}")
    return messages + [Message(line) for line in lines]


def classifier_messages(
    clf: PixelClassifier, classifier_file: str | None, save_file: str | None
) -> list[Message]:
    """Say what the classifier ``clf`` did: trained, or read from ``classifier_file`` and
    applied (and that it was written to ``save_file``, if asked)."""
    if classifier_file:
        lines = [f"{PROG}: applied the classifier {classifier_file} (not retrained)"]
    else:
        lines = [
            f"{PROG}: pixel classifier trained on {clf.n_training_pixels} scribbled "
            f"pixels of {clf.classes.size} materials, {len(clf.feature_names)} features"
        ]
    if save_file:
        lines.append(f"{PROG}: wrote the classifier to {save_file}")
    return [Message(line) for line in lines]


def evaluation_message(evaluation: dict[str, Any]) -> Message:
    """The line of the evaluation against a ground truth (the block accuracy only where
    it was computed: labels of a method that cuts blocks)."""
    blocks = ""
    if evaluation.get("block_accuracy_worst") is not None:
        blocks = (
            f", block accuracy {evaluation['block_accuracy_worst']:.3f} (worst) .. "
            f"{evaluation['block_accuracy_optimistic']:.3f} (optimistic)"
        )
    return Message(
        f"{PROG}: against the ground truth: adjusted Rand index "
        f"{evaluation['adjusted_rand_index']:.3f}, mean IoU {evaluation['mean_iou']:.3f}" + blocks
    )


def feature_scales_text(record: dict[str, Any]) -> str:
    """What a classifier trained on scribbles did with the object size (the method's
    record): ``"object size about 9 px (estimated from the scene): feature scales σ = 1,
    2, 4, 8 px"``, or on a large image ``"feature scales σ = 1, 2, 4, 8, 16 px, every
    one: an object size estimated on this image is at least 40 px"``; "" for a record
    without them (another method, an applied classifier, fixed scales)."""
    if "feature_scales" not in record or not record.get("object_size_applied"):
        return ""
    scales = ", ".join(f"{s:g}" for s in record["feature_scales"])
    if "object_size" not in record:
        return (
            f"feature scales σ = {scales} px, every one: an object size estimated on this "
            f"image is at least {record['object_size_at_least']:.0f} px"
        )
    how = "estimated from the scene" if record.get("object_size_found") else "given"
    about = "about " if record.get("object_size_found") else ""
    size = record["object_size"]
    return f"object size {about}{size:.0f} px ({how}): feature scales σ = {scales} px"


def object_size_text(record: dict[str, Any]) -> str:
    """What the superpixel methods did with the object size (their record): given and
    applied, estimated and applied, or estimated and only reported (the default: below a
    tenth of the frame's short side, where it is more likely a texture's grain)."""
    size, area = record["object_size"], record["region_areas"][0]
    if not record.get("object_size_found"):
        return f"object size {size:.0f} px (given): superpixel area {area} px"
    if record.get("object_size_applied"):
        return f"object size {size:.0f} px (estimated from the scene): superpixel area {area} px"
    return (
        f"object size about {size:.0f} px (estimated from the scene, not followed: the "
        f"superpixels keep their share of the frame, area {area} px; --object-size "
        f"{size:.0f} applies it)"
    )
