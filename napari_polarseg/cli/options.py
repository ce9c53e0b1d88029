"""Options that several ``polarseg`` subcommands share.

The segmentation flags are made from the parameter tables: the shared one
(:data:`napari_polarseg.engine.params.PARAM_SPECS`) and each registered method's own, in
one ``--help`` group per method (:func:`add_method_options`); the reading flags from the reading
options' specs (:func:`napari_polarseg.io.read_specs`, :func:`add_read_options`); the
plots and INPUT/--out options are added by one function each, so every subcommand spells
them alike.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from typing import Any

from ..engine.method_params import params_class
from ..engine.methods import get_method
from ..engine.param_spec import types_of
from ..engine.params import (
    DEFAULT_PRESET,
    PARAM_SPECS,
    PRESET_HELP,
    PRESETS,
    ParamSpec,
    SegmentParams,
    all_param_specs,
)
from ..engine.registered import METHOD_CHOICES, computes_block_maps
from ..io import ReadOptions, read_specs
from .arguments import (
    angles_arg,
    bayer_arg,
    dark_level_arg,
    gib_arg,
    level_arg,
    number_arg,
    out_folder_arg,
    threshold_arg,
    worded_arg,
)

#: Presets of the commands whose own analysis cuts the block graph (sweep, timeseries).
BLOCK_PRESETS = ("thesis", "recommended")

#: Help of the INPUT of the commands that read one angle stack (segment, sweep).
STACK_INPUT_HELP = "TIFF, .npz/.npy, folder, raw frame, or several frame files (one per angle)"


def param_options(
    specs: dict[str, ParamSpec] | None = None,
    types: dict[str, Any] | None = None,
) -> dict[str, tuple[str, dict[str, Any]]]:
    """Parameter name -> (flag, argparse keywords), made from a parameter table.

    The type comes from ``types`` (default: the shared SegmentParams fields' types; int,
    float; str for a name it lacks); an ``optional`` spec takes the ``none``-accepting
    threshold parser; a spec with choices gets them instead of a type; the help is the
    spec's.
    """
    specs = PARAM_SPECS if specs is None else specs
    types = types_of(SegmentParams) if types is None else types
    options: dict[str, tuple[str, dict[str, Any]]] = {}
    for name, spec in specs.items():
        kwargs: dict[str, Any] = {}
        if spec.options():
            kwargs["choices"] = spec.options()
        elif spec.optional:
            kwargs["type"] = threshold_arg
        else:
            kind = types.get(name, str)
            kind = kind if kind in (int, float, str) else str
            kwargs["type"] = worded_arg(kind, spec.words) if spec.words else kind
        if spec.metavar:
            kwargs["metavar"] = spec.metavar
        kwargs["help"] = spec.help
        options[name] = (spec.flag, kwargs)
    return options


def method_options() -> dict[str, dict[str, tuple[str, dict[str, Any]]]]:
    """Each registered method's own flags (:func:`param_options` of its parameter
    table), by method name, in registration order; a flag two methods declare is listed
    under the first."""
    seen: set[str] = set()
    out: dict[str, dict[str, tuple[str, dict[str, Any]]]] = {}
    for method, specs in all_param_specs().items():
        types = types_of(params_class(method))
        options = param_options(specs, types)
        out[method] = {name: opt for name, opt in options.items() if opt[0] not in seen}
        seen |= {flag for flag, _ in options.values()}
    return out


def _preset_help(presets: Sequence[str]) -> str:
    """What each of ``presets`` is, for --help."""
    return "; ".join(f"{name}: {PRESET_HELP[name]}" for name in presets)


def _flag_value(value: Any) -> str:
    """A parameter value as its flag spells it (None: ``none``)."""
    return "none" if value is None else str(value)


def add_param_options(
    parser: argparse.ArgumentParser,
    preset: str = DEFAULT_PRESET,
    presets: tuple[str, ...] = tuple(PRESETS),
    specs: dict[str, ParamSpec] | None = None,
    method_flag: bool | None = None,
    overview_flag: bool = True,
    default_text: dict[str, str] | None = None,
) -> None:
    """Add --preset, --params, the flags of ``specs`` and of every method's own
    parameters, --overview (unless ``overview_flag`` is False: a command that always
    writes it) and -v/-q to ``parser``; ``default_text`` says, by field name, what a run
    without that flag uses when it is not the preset's value.

    Parameters
    ----------
    parser
        A subcommand's parser.
    preset
        The default of --preset.
    presets
        The choices of --preset.
    specs
        The parameter table (default: :data:`PARAM_SPECS`).
    method_flag
        Offer --method (default: unless ``presets`` are :data:`BLOCK_PRESETS`).
    overview_flag
        Offer --overview.
    default_text
        Field name → the text of its default in the flag's help (e.g. the demo's
        number of segments: the scene's materials).
    """
    defaults = PRESETS[preset].to_dict()
    if method_flag is None:
        method_flag = presets != BLOCK_PRESETS
    if not method_flag:  # a block-graph command that runs the thesis method only
        specs = {
            k: v for k, v in (PARAM_SPECS if specs is None else specs).items() if k != "method"
        }
    group = parser.add_argument_group(
        "segmentation parameters",
        "start from --preset, then --params, then explicit flags; in brackets what a run "
        f"without the flag uses (preset {preset}'s value)",
    )
    group.add_argument(
        "--preset",
        choices=presets,
        default=preset,
        help=f"starting parameters ({_preset_help(presets)}) [{preset}]",
    )
    group.add_argument(
        "--params",
        metavar="FILE.json",
        help="SegmentParams JSON (or a params.json written by polarseg)",
    )
    for name, (flag, kwargs) in param_options(specs).items():
        kwargs = dict(kwargs)
        used = f"preset {preset}'s {_flag_value(defaults.get(name))}"
        used = (default_text or {}).get(name, used)
        kwargs["help"] = f"{kwargs['help']} [default: {used}]".replace("%", "%%")
        group.add_argument(flag, dest=name, default=None, **kwargs)
    add_method_options(parser, preset)
    if overview_flag:
        parser.add_argument(
            "--overview", action="store_true", help="also write overview.png (matplotlib figure)"
        )
    talk = parser.add_mutually_exclusive_group()
    talk.add_argument(
        "-v", "--verbose", action="store_true", help="report stages and warnings on stderr"
    )
    talk.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="no progress on stderr (by default a terminal shows the running stage on one "
        "line, erased at the end; never shown when stdout or stderr is not a terminal)",
    )


def add_method_options(parser: argparse.ArgumentParser, preset: str = DEFAULT_PRESET) -> None:
    """Add one argument group per registered method to ``parser``: its own flags
    (:func:`method_options`), with the value preset ``preset`` gives each, or the shared
    flags it reads when it has none of its own."""
    base = PRESETS[preset]
    options_by_method = method_options()
    for method in dict.fromkeys([*METHOD_CHOICES, *options_by_method]):
        options = options_by_method.get(method, {})
        if options:
            also = " and by the thesis maps of any method" if computes_block_maps(method) else ""
            what = f"read by --method {method}{also}; another method warns it does not read them"
        else:
            reads = [PARAM_SPECS[n].flag for n in get_method(method).reads if n in PARAM_SPECS]
            what = "no parameters of its own; it reads " + (", ".join(reads) or "none")
        group = parser.add_argument_group(
            f"method {method} ({METHOD_CHOICES.get(method, method)})", what
        )
        values = base.params_of(method)
        for name, (flag, kwargs) in options.items():
            kwargs = dict(kwargs)
            used = _flag_value(getattr(values, name))
            help_text = f"{kwargs['help']} [default: preset {preset}'s {used}]"
            kwargs["help"] = help_text.replace("%", "%%")
            group.add_argument(flag, dest=name, default=None, **kwargs)


def add_inputs_and_out(parser: argparse.ArgumentParser, inputs_help: str) -> None:
    """Add the positional INPUT (one or more, help ``inputs_help``) and the required
    -o/--out folder, the first two arguments of every command that writes a folder."""
    parser.add_argument("input", metavar="INPUT", nargs="+", help=inputs_help)
    parser.add_argument(
        "-o", "--out", required=True, metavar="DIR", type=out_folder_arg, help="output folder"
    )


#: The reading options of the commands that read one INPUT per stack, scene or day
#: (``sweep``, ``batch``, ``timeseries``), in the order --help lists them.
INPUT_OPTIONS = (
    "angles_deg",
    "mosaic_deg",
    "demosaic",
    "bayer",
    "channel",
    "register",
    "max_memory_gib",
)

#: How the words of each kind of reading option are parsed (:attr:`ReadSpec.kind`).
_READ_TYPES: dict[str, Callable[[str], Any]] = {
    "angles": angles_arg,
    "number": number_arg,
    "level": level_arg,
    "dark_level": dark_level_arg,
    "gib": gib_arg,
    "bayer": bayer_arg,
    "int": int,
}


def read_option_kwargs(name: str, unit: str = "stack") -> tuple[str, dict[str, Any]]:
    """The flag and argparse keywords of the :class:`~napari_polarseg.io.ReadOptions`
    field ``name``, made from its :class:`~napari_polarseg.io.ReadSpec` (``unit``: what one
    INPUT is to the command, for the help)."""
    spec = read_specs()[name]
    default = getattr(ReadOptions(), name)
    kwargs: dict[str, Any] = {"help": spec.help_for(unit)}
    if spec.kind == "switch":
        kwargs["action"] = "store_true"
        return spec.flag, kwargs
    if spec.kind == "choice":
        kwargs["choices"] = spec.choices
    elif spec.kind in _READ_TYPES:
        kwargs["type"] = _READ_TYPES[spec.kind]
    if default is not None:
        kwargs["default"] = default
    if spec.metavar:
        kwargs["metavar"] = spec.metavar
    return spec.flag, kwargs


def add_read_options(
    parser: Any,
    names: Sequence[str],
    unit: str = "stack",
    helps: dict[str, str] | None = None,
) -> None:
    """Add the reading flags of the :class:`~napari_polarseg.io.ReadOptions` fields
    ``names`` to ``parser`` (a parser or an argument group), in that order.

    Parameters
    ----------
    parser
        Where the flags go.
    names
        ReadOptions fields.
    unit
        What one INPUT is to the command (``stack``, ``scene``, ``day``), for the help.
    helps
        A command's own help of some of the fields (what the option means there).
    """
    for name in names:
        flag, kwargs = read_option_kwargs(name, unit)
        if helps and name in helps:
            kwargs["help"] = helps[name]
        parser.add_argument(flag, **kwargs)


def add_input_options(parser: argparse.ArgumentParser, unit: str) -> None:
    """Reading options shared by ``sweep``, ``batch`` and ``timeseries`` (one INPUT per
    ``unit``): the flags of :data:`INPUT_OPTIONS`; what --register and --max-memory do is
    said per ``unit`` (these commands record no shifts in a params.json of their own,
    and a batch's default limit is its workers')."""
    helps = {
        "register": f"align the frames of each {unit} to its first by sub-pixel phase "
        "correlation first",
        "max_memory_gib": f"memory limit of one {unit}, GiB: a {unit} whose reading or run "
        "would need more is refused",
    }
    add_read_options(parser, INPUT_OPTIONS, unit, helps)


def add_bayer_option(parser: argparse.ArgumentParser) -> None:
    """Add --bayer (the Bayer order of a colour-polarisation mosaic)."""
    add_read_options(parser, ("bayer",))


def add_plots_option(parser: argparse.ArgumentParser) -> None:
    """Add --plots (the analyst's plots as PNGs into OUT/plots/)."""
    parser.add_argument(
        "--plots",
        action="store_true",
        help="also write the analyst's plots as PNGs into OUT/plots/ (I-rho/phi scatter, "
        "explained variance, coefficient and component maps, reconstruction histograms, "
        "error table)",
    )
