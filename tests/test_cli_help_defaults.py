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
        if command == "demo" and flag == "--segments":  # the demo uses the scene's k
            assert text.endswith("[default: the scene's number of materials]"), flag
            continue
        assert text.endswith(f"[default: preset {preset}'s {value}]"), flag


def test_segment_help_shows_preset_auto_not_the_thesis():
    text = " ".join(_subparser("segment").format_help().split())
    assert "[default: preset auto's 12]" in text  # --window (thesis: 10)
    assert "[default: preset auto's 8]" in text  # --degree (thesis: 12)
    assert "[default: preset auto's surface_superpixels]" in text  # --method (thesis: thesis)
    assert "[10]" not in text and "[recursive]" not in text
    assert PRESETS["auto"].window == 12 and PRESETS["auto"].method == "surface_superpixels"


def test_help_texts_describe_the_methods_as_they_are(capsys):
    """The top-level help names the default and the thesis method; the classifier's
    flags say what the model is and what it replaces; the demo lists its scenes, says
    its number of segments is the scene's, and offers no --overview (always drawn)."""
    from napari_polarseg import cli

    def help_of(*argv: str) -> str:
        assert cli.main([*argv, "--help"]) == 0
        return " ".join(capsys.readouterr().out.split())

    top = help_of()
    assert "by default edge-following superpixels" in top and "--method thesis" in top
    segment = help_of("segment")
    assert "random forest" not in segment and "normalized cut;" not in segment
    assert "extremely randomised trees" in segment
    demo = help_of("demo")
    assert "bundled scene: camouflage, fruit, leaves" in demo
    assert "[default: the scene's number of materials]" in demo
    assert "--overview" not in demo
