"""Issue 25: ``--help`` shows, for every parameter flag, what a run without it uses."""

from __future__ import annotations

import pytest

from napari_polarseg import cli
from napari_polarseg.engine.params import PARAM_SPECS, PRESETS


def _subparser(name):
    return cli.build_parser()._subparsers._group_actions[0].choices[name]


def _flag_helps(name):
    """flag -> help text of the parameter flags of subcommand ``name``."""
    actions = _subparser(name)._actions
    flags = {spec.flag for spec in PARAM_SPECS.values()}
    return {s: a.help for a in actions for s in a.option_strings[:1] if s in flags}


@pytest.mark.parametrize("command", ["segment", "demo", "batch", "sweep", "timeseries"])
def test_every_parameter_flag_shows_the_value_a_run_without_it_uses(command):
    preset = _subparser(command).get_default("preset")
    used = PRESETS[preset].to_dict()
    helps = _flag_helps(command)
    # the block-graph commands (sweep, timeseries) run the thesis method: no --method
    block = command in ("sweep", "timeseries")
    specs = {k: v for k, v in PARAM_SPECS.items() if not (block and k == "method")}
    if command == "timeseries":
        del helps["--method"]  # its own option: how the days are compared
    assert set(helps) == {spec.flag for spec in specs.values()}
    for name, spec in specs.items():
        value = "none" if used[name] is None else str(used[name])
        assert helps[spec.flag].endswith(f"[default: preset {preset}'s {value}]"), spec.flag


def test_segment_help_shows_preset_auto_not_the_thesis():
    text = " ".join(_subparser("segment").format_help().split())
    assert "[default: preset auto's 12]" in text  # --window (thesis: 10)
    assert "[default: preset auto's 8]" in text  # --degree (thesis: 12)
    assert "[default: preset auto's surface_superpixels]" in text  # --method (thesis: thesis)
    assert "[10]" not in text and "[recursive]" not in text
    assert PRESETS["auto"].window == 12 and PRESETS["auto"].method == "surface_superpixels"
