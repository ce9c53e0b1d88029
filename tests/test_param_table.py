"""The parameter tables (engine.params.PARAM_SPECS, the shared fields, and each method's
own, ``all_param_specs``) describe every field coherently."""

from __future__ import annotations

from dataclasses import fields

import pytest

from napari_polarseg.engine.errors import PolarsegError
from napari_polarseg.engine.methods.thesis import ThesisParams
from napari_polarseg.engine.params import (
    PARAM_SPECS,
    PRESET_HELP,
    PRESETS,
    SegmentParams,
    all_param_specs,
)


def _every_spec():
    """(method or None for a shared field, name, spec) of every parameter."""
    rows = [(None, name, spec) for name, spec in PARAM_SPECS.items()]
    for method, specs in all_param_specs().items():
        rows += [(method, name, spec) for name, spec in specs.items()]
    return rows


def test_every_field_has_one_spec_with_a_unique_flag_and_label():
    shared = [f.name for f in fields(SegmentParams) if f.name != "method_params"]
    assert list(PARAM_SPECS) == shared
    assert list(all_param_specs()["thesis"]) == [f.name for f in fields(ThesisParams)]
    rows = _every_spec()
    flags = [s.flag for _, _, s in rows]
    assert len(set(flags)) == len(flags)
    assert all(f.startswith("--") for f in flags)
    labels = [s.label for _, _, s in rows if s.label is not None]
    assert len(set(labels)) == len(labels)
    assert all(s.help and not s.help.endswith(".") for _, _, s in rows)
    # every control says what it does to the result (the tooltip's first line)
    assert all(s.effect for _, _, s in rows if s.label is not None)


@pytest.mark.parametrize(
    "method,name", [(m, n) for m, n, s in _every_spec() if s.choices is not None]
)
def test_choices_are_what_validate_accepts(method, name):
    spec = PARAM_SPECS[name] if method is None else all_param_specs()[method][name]
    base = SegmentParams(method=method or "thesis")
    for choice in spec.choices:
        assert getattr(base.replace(**{name: choice}), name) == choice
    with pytest.raises(PolarsegError, match=name):
        base.replace(**{name: "no-such-choice"})
    assert [value for _, value in spec.menu()] == list(spec.choices)


@pytest.mark.parametrize("preset", list(PRESETS))
def test_preset_values_fit_the_controls(preset):
    params = PRESETS[preset]
    for method, name, spec in _every_spec():
        value = getattr(params if method is None else params.params_of(method), name)
        if spec.minimum is not None:
            assert spec.minimum <= value <= spec.maximum, (preset, name, value)


def test_every_preset_is_described_and_the_docstrings_list_every_field():
    assert set(PRESET_HELP) == set(PRESETS)
    for method, name, spec in _every_spec():
        doc = (SegmentParams if method is None else ThesisParams).__doc__
        assert f"    {name} : " in doc and spec.flag in doc
