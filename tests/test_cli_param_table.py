"""The segmentation flags of every command are made from the parameter table."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from napari_polarseg import cli
from napari_polarseg.cli.arguments import UsageError
from napari_polarseg.cli.options import method_options
from napari_polarseg.engine.params import PARAM_SPECS, ParamSpec, all_param_specs

# today's option list of `polarseg segment` (recorded before the flags came from the table)
SEGMENT_FLAGS = (
    "--window --degree --refractive-index --model --specular-branch --coefficients --ridge "
    "--features --variance --scale --scale-mode --spatial-radius --spatial-sigma --segments "
    "--ncut-threshold --min-segment-blocks --clustering --fit --affinity-graph --preset "
    "--params --overview --verbose --quiet --angles --mosaic --bayer --demosaic --dark-frame "
    "--offset --saturation --dark-level --mask --max-memory --channel --register --scribbles "
    "--classifier --save-classifier --ground-truth --plots --out"
).split()


def _segment_parser(parser):
    return parser._subparsers._group_actions[0].choices["segment"]


def test_a_new_field_of_the_table_gets_its_flag() -> None:
    knob = ParamSpec(help="a new knob", flag="--new-knob", metavar="X")
    specs = {**PARAM_SPECS, "new_knob": knob}
    parser = cli.build_parser(specs)
    help_text = _segment_parser(parser).format_help()
    assert "--new-knob X" in help_text and "a new knob [default: preset auto's none]" in help_text
    args = parser.parse_args(["segment", "in.tif", "--out", "o", "--new-knob", "7"])
    assert args.new_knob == "7"
    assert "--new-knob" not in _segment_parser(cli.build_parser()).format_help()


def test_todays_segment_flags_all_exist() -> None:
    options = {s for a in _segment_parser(cli.build_parser())._actions for s in a.option_strings}
    assert set(SEGMENT_FLAGS) <= options


def test_flags_take_the_field_types_and_help_from_the_table() -> None:
    options = cli.param_options()
    assert options["n_segments"][1]["type"]("4") == 4
    assert options["refractive_index"][1]["type"] is float
    assert options["model"][1]["choices"] == PARAM_SPECS["model"].choices
    assert json.dumps(list(options)) == json.dumps(list(PARAM_SPECS))
    # a method's own flags come from its own table (the thesis method's ThesisParams)
    thesis, specs = method_options()["thesis"], all_param_specs()["thesis"]
    assert thesis["window"][1]["type"] is int and thesis["scale"][1]["type"] is float
    assert thesis["ncut_threshold"][1]["type"]("none") == "none"
    assert thesis["window"][1]["help"] == specs["window"].help
    assert list(thesis) == list(specs)
    assert Path(cli.__file__).is_file()


def test_segments_takes_auto_for_found_by_itself() -> None:
    """``--segments auto`` is 0 (the method finds the number), any case; other words are
    refused with the words the flag takes."""
    parse = cli.param_options()["n_segments"][1]["type"]
    assert parse("auto") == 0 and parse(" AUTO ") == 0 and parse("4") == 4
    parser = cli.build_parser()
    args = parser.parse_args(["segment", "stack.tif", "-o", "out", "--segments", "auto"])
    assert args.n_segments == 0
    with pytest.raises(UsageError, match="expected a number or 'auto', got 'many'"):
        parser.parse_args(["segment", "stack.tif", "-o", "out", "--segments", "many"])
