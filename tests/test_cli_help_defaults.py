"""Issue 25: ``--help`` shows, for every parameter flag, what a run without it uses."""

from __future__ import annotations

import pytest

from napari_polarseg import cli
from napari_polarseg.engine.params import PARAM_SPECS, PRESETS, all_param_specs


def _subparser(name):
    return cli.build_parser()._subparsers._group_actions[0].choices[name]


def _table() -> dict[str, tuple[str | None, object]]:
    """flag -> (method or None for a shared parameter, spec) of every parameter flag."""
    table = {spec.flag: (None, spec) for spec in PARAM_SPECS.values()}
    for method, specs in all_param_specs().items():
        table.update({spec.flag: (method, spec) for spec in specs.values()})
    return table


def _flag_helps(name):
    """flag -> help text of the parameter flags of subcommand ``name``."""
    actions = _subparser(name)._actions
    flags = _table()
    return {s: (a.dest, a.help) for a in actions for s in a.option_strings[:1] if s in flags}


@pytest.mark.parametrize("command", ["segment", "demo", "batch", "sweep", "timeseries"])
def test_every_parameter_flag_shows_the_value_a_run_without_it_uses(command):
    preset = _subparser(command).get_default("preset")
    params = PRESETS[preset]
    helps = _flag_helps(command)
    # the time series cuts the block graph of the days itself: no --method
    block = command == "timeseries"
    table = {f: v for f, v in _table().items() if not (block and f == "--method")}
    if command == "timeseries":
        del helps["--method"]  # its own option: how the days are compared
    assert set(helps) == set(table)
    for flag, (method, _) in table.items():
        name, text = helps[flag]
        value = getattr(params if method is None else params.params_of(method), name)
        value = "none" if value is None else str(value)
        assert text.endswith(f"[default: preset {preset}'s {value}]"), flag


def test_segment_help_shows_preset_auto_not_the_thesis():
    text = " ".join(_subparser("segment").format_help().split())
    assert "[default: preset auto's 12]" in text  # --window (thesis: 10)
    assert "[default: preset auto's 8]" in text  # --degree (thesis: 12)
    assert "[default: preset auto's surface_superpixels]" in text  # --method (thesis: thesis)
    assert "[10]" not in text and "[recursive]" not in text
    assert PRESETS["auto"].window == 12 and PRESETS["auto"].method == "surface_superpixels"
