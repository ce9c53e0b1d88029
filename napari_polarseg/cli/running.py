"""What the ``polarseg`` subcommands do alike once the command line is parsed.

The parameters of a command line, its reading and output options, the memory limit, the
progress reports (permanent lines or the terminal status line), the messages a job
returns, and segmenting already-read data into ``--out``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from .. import io as pio
from .. import jobs
from ..engine.errors import PolarsegError
from ..engine.method_params import owner_of
from ..engine.methods import get_method, method_names
from ..engine.params import PARAM_SPECS, PRESETS, SegmentParams, method_param_specs
from ..engine.registered import computes_block_maps
from ..status_line import StatusLine
from .arguments import PROG
from .options import method_options


def params_from_args(
    args: argparse.Namespace, base: dict[str, Any] | None = None, maps: bool | None = None
) -> SegmentParams:
    """SegmentParams from ``base``, then ``--params``, then explicit flags (validated).

    A method's own flag given while another method runs is set all the same (the thesis
    maps read the thesis method's) and named in a one-line warning on stderr
    (:func:`unread_flags`; ``maps``: the run computes the thesis maps, default: as
    ``--thesis-maps`` and ``--plots`` say).
    """
    params = PRESETS[getattr(args, "preset", "auto")]
    source = "parameters"
    try:
        params = params.updated(base or {})
        if args.params:
            source = args.params
            params = params.updated(pio.read_params_dict(args.params))
    except PolarsegError as exc:
        raise PolarsegError(f"{source}: {exc}") from None
    except TypeError as exc:
        raise PolarsegError(f"{source}: a parameter has the wrong type ({exc})") from None
    names = [*PARAM_SPECS, *(n for options in method_options().values() for n in options)]
    changes = {name: getattr(args, name, None) for name in names}
    changes = {k: (None if v == "none" else v) for k, v in changes.items() if v is not None}
    params = params.replace(**changes)
    if maps is None:
        maps = bool(getattr(args, "thesis_maps", False) or getattr(args, "plots", False))
    for line in unread_flags(params, [n for n in changes if n not in PARAM_SPECS], args, maps):
        print(f"{PROG}: warning: {line}", file=sys.stderr)
    return params


def running_method(params: SegmentParams, args: argparse.Namespace) -> str:
    """The method a run of ``args`` uses: the one that takes the given inputs (--scribbles,
    --classifier), else ``params.method``."""
    given = {k for k in ("scribbles", "classifier") if getattr(args, k, None)}
    for name in method_names():
        if given & set(get_method(name).inputs):
            return name
    return params.method


def unread_flags(
    params: SegmentParams, names: Sequence[str], args: argparse.Namespace, maps: bool
) -> list[str]:
    """One line for each method flag of ``names`` that the running method does not read
    (a flag of a method that computes the thesis maps is read when ``maps``)."""
    method = running_method(params, args)
    lines = []
    for name in names:
        owner = owner_of(name, method)
        if owner == method or owner is None or (maps and computes_block_maps(owner)):
            continue
        flag = method_param_specs(owner)[name].flag
        lines.append(
            f"method {method} does not read {flag} (a parameter of method {owner}); "
            "its labels are the same without it"
        )
    return lines


def progress_report(verbose: bool, status: StatusLine | None = None) -> jobs.Progress | None:
    """Progress callback of a run (:class:`napari_polarseg.engine.Scene`, called as a
    stage starts with the stages done, and within it): with ``verbose`` a permanent line
    per stage as it starts, else the status line naming the stage now running, else
    None."""
    if verbose:
        started: list[str] = []

        def report(stage: str, index: float, total: int) -> None:
            if index < total and stage not in started:
                started.append(stage)
                print(f"{PROG}: [{int(index) + 1}/{total}] {stage}", file=sys.stderr, flush=True)

        return report
    if status is None or not status.enabled:
        return None

    def show(stage: str, index: float, total: int) -> None:
        if index < total:
            status.stage(stage, int(index) + 1, total, "segmenting:")

    return show


def status_line(args: argparse.Namespace) -> StatusLine:
    """The terminal status line of this command (disabled if not wanted or possible)."""
    status = getattr(args, "status_line", None)
    return status if isinstance(status, StatusLine) else StatusLine(False, PROG)


def read_options(args: argparse.Namespace) -> pio.ReadOptions:
    """The reading options of a command line (an option the command has not: its
    default; :func:`napari_polarseg.io.options_from_values`)."""
    return pio.options_from_values(vars(args))


def max_bytes(args: argparse.Namespace) -> int:
    """The memory limit in bytes: ``--max-memory`` GiB, else ``$POLARSEG_MAX_BYTES`` or
    the default (:func:`napari_polarseg.engine.limits.memory_limit`)."""
    return read_options(args).max_bytes()


def read_input(source: str | Sequence[str], args: argparse.Namespace) -> pio.StackData:
    """Read ``source`` with the reading options of the command line."""
    return pio.read_stack(source, options=read_options(args))


def output_options(args: argparse.Namespace) -> jobs.OutputOptions:
    """The output options of a command line (--overview, --plots, --save-classifier,
    --thesis-maps, --format)."""
    return jobs.OutputOptions(
        overview=bool(args.overview),
        plots=bool(getattr(args, "plots", False)),
        save_classifier=getattr(args, "save_classifier", None),
        thesis_maps=bool(getattr(args, "thesis_maps", False)),
        image_format=getattr(args, "image_format", None) or "tiff",
    )


def print_messages(messages: Sequence[jobs.Message]) -> None:
    """Print a job's messages, each on its stream, in order."""
    for message in messages:
        if message.stream == "stderr":
            sys.stdout.flush()  # keep the order of the two streams on a terminal
            print(message.text, file=sys.stderr, flush=True)
        else:
            print(message.text)


def segment_data(
    args: argparse.Namespace,
    command: str,
    data: pio.StackData,
    read_seconds: float,
    params: SegmentParams,
    extra: dict[str, Any] | None = None,
    note_repeated: bool = True,
) -> jobs.FolderResult:
    """Segment already-read data into ``args.out`` and print what the job says.

    Parameters
    ----------
    args
        The parsed command line (its reading and output options, ``out``, ``verbose``).
    command
        The command named in ``params.json``.
    data
        The stack read.
    read_seconds
        Seconds spent reading it.
    params
        The segmentation parameters.
    extra
        More entries of ``params.json``.
    note_repeated
        Whether to say that frames at a repeated angle were averaged.

    Returns
    -------
    jobs.FolderResult
        What the job wrote and said.
    """
    status = status_line(args)
    done = jobs.data_to_folder(
        data,
        args.out,
        params,
        read_options(args),
        output_options(args),
        read_seconds=read_seconds,
        command=command,
        extra=extra,
        note_repeated=note_repeated,
        status=status,
        progress=progress_report(args.verbose, status),
    )
    print_messages(done.messages)
    return done
