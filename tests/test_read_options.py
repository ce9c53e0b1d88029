"""One reading-options type (io.ReadOptions): read_stack, the command line's reading flags
and a batch's record are all made from it; one suffix -> stack format table."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest

import napari_polarseg
from napari_polarseg import _reader, job_options, jobs, messages
from napari_polarseg import io as pio
from napari_polarseg.cli import build_parser
from napari_polarseg.cli.options import INPUT_OPTIONS, read_option_kwargs
from napari_polarseg.cli.running import read_options
from napari_polarseg.engine.errors import PolarsegError

SAMPLES = Path(napari_polarseg.__file__).parent / "sample_data"

#: Every reading option away from its default (scribbles and classifier exclude each other).
FULL = pio.ReadOptions(
    angles_deg=(0.0, 45.0, 90.0, 22.5),
    mosaic_deg=(90.0, 45.0, 135.0, 0.0),
    demosaic="interpolated",
    bayer="RGGB",
    channel=1,
    max_memory_gib=2.5,
    dark_frame="dark.png",
    offset=3.0,
    saturation=1000.0,
    dark_level=None,
    mask="mask.png",
    scribbles="strokes.png",
    ground_truth="truth.png",
    register=True,
)


def _actions(command: str) -> dict[str, argparse.Action]:
    """dest -> argparse action of a subcommand."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {a.dest: a for a in sub.choices[command]._actions}


def test_every_field_is_described_once_with_a_distinct_flag() -> None:
    specs = pio.read_specs()
    assert list(specs) == [f.name for f in dataclasses.fields(pio.ReadOptions)]
    flags = [spec.flag for spec in specs.values()]
    assert len(set(flags)) == len(flags)
    assert all(
        spec.help and spec.dest == spec.flag[2:].replace("-", "_") for spec in specs.values()
    )


@pytest.mark.parametrize("command", ["segment", "sweep", "batch", "timeseries"])
def test_the_reading_flags_are_made_from_the_table(command: str) -> None:
    actions = _actions(command)
    specs = pio.read_specs()
    names = list(specs) if command == "segment" else list(INPUT_OPTIONS)
    for name in names:
        flag, kwargs = read_option_kwargs(name, "stack" if command == "segment" else "x")
        action = actions[specs[name].dest]
        assert action.option_strings == [flag]
        assert action.default == kwargs.get("default", False if "action" in kwargs else None)
        assert action.type is kwargs.get("type") and action.choices == kwargs.get("choices")
        assert action.metavar == kwargs.get("metavar")
    if command == "segment":  # every reading option, each help the table's word for word
        for name in specs:
            assert actions[specs[name].dest].help == specs[name].help_for("stack")


def test_options_to_flags_to_options_round_trip() -> None:
    outputs = job_options.OutputOptions(overview=True, plots=True, save_classifier="c.clf")
    words = job_options.segment_args(FULL, outputs)
    args = build_parser().parse_args(["segment", "in.png", "-o", "out", *words])
    assert read_options(args) == FULL
    assert args.overview and args.plots and args.save_classifier == "c.clf"
    classifier = dataclasses.replace(FULL, scribbles=None, classifier="m.polarseg-clf")
    args = build_parser().parse_args(["segment", "in.png", "-o", "o", *classifier.to_args()])
    assert read_options(args) == classifier


def test_a_batch_record_keeps_its_order() -> None:
    """A batch resumes only a scene whose marker holds the same options in the same order."""
    read = dataclasses.replace(FULL, scribbles=None, classifier="m.polarseg-clf")
    flags = job_options.segment_args(read, job_options.OutputOptions(True, True, "s"))
    assert [w for w in flags if w.startswith("--")] == [
        "--angles",
        "--mosaic",
        "--demosaic",
        "--bayer",
        "--channel",
        "--max-memory",
        "--classifier",
        "--dark-frame",
        "--offset",
        "--saturation",
        "--dark-level",
        "--mask",
        "--ground-truth",
        "--register",
        "--overview",
        "--plots",
        "--save-classifier",
    ]
    assert flags[flags.index("--angles") + 1] == "0,45,90,22.5"
    assert flags[flags.index("--dark-level") + 1] == "none"
    assert pio.ReadOptions().to_args() == []


def test_a_command_without_an_option_gets_its_default() -> None:
    args = build_parser().parse_args(["batch", "a.npz", "-o", "out", "--angles", "0,60,120"])
    read = read_options(args)
    assert read == pio.ReadOptions(angles_deg=(0.0, 60.0, 120.0))
    assert jobs.ReadOptions is pio.ReadOptions is job_options.ReadOptions


def test_read_stack_takes_the_options_or_the_keywords() -> None:
    path = SAMPLES / "leaves.npz"
    by_keywords = pio.read_stack(path, saturation=None, offset=1.0, max_bytes=2**30)
    read = pio.ReadOptions(saturation=None, offset=1.0, max_memory_gib=1.0, mask="ignored")
    by_options = pio.read_stack(path, options=read)
    np.testing.assert_array_equal(by_keywords.stack, by_options.stack)
    assert by_keywords.metadata == by_options.metadata
    with pytest.raises(TypeError, match="offset"):
        pio.read_stack(path, offset=1.0, options=read)
    with pytest.raises(PolarsegError, match="demosaic method"):
        pio.read_stack(path, options=pio.ReadOptions(demosaic="nearest"))


def test_one_suffix_table_for_read_stack_and_the_napari_reader(tmp_path: Path) -> None:
    assert pio.STACK_SUFFIXES == tuple(pio.STACK_FORMATS)
    manifest = (Path(napari_polarseg.__file__).parent / "napari.yaml").read_text()
    (patterns,) = re.findall(r"filename_patterns: (\[.*\])", manifest)[:1]
    suffixes = {p.removeprefix("*") for p in json.loads(patterns)}
    assert ".npz" in suffixes and ".png" in suffixes
    assert suffixes <= set(pio.STACK_FORMATS) | set(pio.FRAME_SUFFIXES)
    stack = np.ones((3, 4, 4))
    np.save(tmp_path / "s.npy", stack)
    np.savez(tmp_path / "no_angles.npz", stack=stack)
    np.savez(tmp_path / "angles.npz", stack=stack, angles=np.array([0.0, 60, 120]))
    for name, claimed in (("s.npy", False), ("no_angles.npz", False), ("angles.npz", True)):
        fmt = pio.STACK_FORMATS[Path(name).suffix]
        assert fmt.carries_angles(tmp_path / name) is claimed
        assert (_reader.get_reader(str(tmp_path / name)) is not None) is claimed


def _runtime_imports(module: object) -> set[str]:
    """Modules ``module`` imports outside ``if TYPE_CHECKING:``."""
    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))  # type: ignore[attr-defined]
    skip = {
        id(n)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING"
        for n in ast.walk(node)
    }
    return {
        node.module or ""
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and id(node) not in skip
    }


def test_the_command_line_wording_is_out_of_the_job() -> None:
    assert (
        jobs.Message is messages.Message and jobs.degenerate_warning is messages.degenerate_warning
    )
    jobs_source = Path(jobs.__file__).read_text(encoding="utf-8")
    assert 'f"{PROG}:' not in jobs_source  # no message line is worded in jobs.py
    for module in (jobs, messages):
        assert not any("cli" in name.split(".") for name in _runtime_imports(module)), module
    assert "jobs" not in _runtime_imports(messages)
