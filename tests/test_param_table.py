"""The one parameter table (engine.params.PARAM_SPECS) describes every field coherently."""

from __future__ import annotations

from dataclasses import fields

import pytest

from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.params import PARAM_SPECS, PRESET_HELP, PRESETS, SegmentParams


def test_every_field_has_one_spec_with_a_unique_flag_and_label():
    names = [f.name for f in fields(SegmentParams)]
    assert list(PARAM_SPECS) == names
    flags = [s.flag for s in PARAM_SPECS.values()]
    assert len(set(flags)) == len(flags)
    assert all(f.startswith("--") for f in flags)
    labels = [s.label for s in PARAM_SPECS.values() if s.label is not None]
    assert len(set(labels)) == len(labels)
    assert all(s.help and not s.help.endswith(".") for s in PARAM_SPECS.values())


@pytest.mark.parametrize("name", list(PARAM_SPECS))
def test_choices_are_what_validate_accepts(name):
    spec = PARAM_SPECS[name]
    if spec.choices is None:
        return
    for choice in spec.choices:
        SegmentParams().replace(**{name: choice})
    with pytest.raises(PolarsegError, match=name):
        SegmentParams().replace(**{name: "no-such-choice"})
    assert [value for _, value in spec.menu()] == list(spec.choices)


@pytest.mark.parametrize("preset", list(PRESETS))
def test_preset_values_fit_the_controls(preset):
    params = PRESETS[preset]
    for name, spec in PARAM_SPECS.items():
        value = getattr(params, name)
        if spec.minimum is not None:
            assert spec.minimum <= value <= spec.maximum, (preset, name, value)


def test_every_preset_is_described_and_the_docstring_lists_every_field():
    assert set(PRESET_HELP) == set(PRESETS)
    doc = SegmentParams.__doc__
    for name, spec in PARAM_SPECS.items():
        assert f"    {name} : " in doc and spec.flag in doc
