"""Raw polarisation-camera frames in the Segment dock: a 2-D grey image layer (as napari's
own reader opens ``fruits_IMX250MZR.png``) offered as a *raw mosaic*, decoded into an
angle-stack layer before a run.

napari's *Choose reader* dialog preselects *napari builtins* for a PNG or TIFF (it sorts
the readers by name; npe2 has no reader priority), which opens the camera's raw frame as
one 2-D image. The Segment dock lists such a layer (grey, 2-D, even height and width) as
``"<name> (raw mosaic)"`` with a *mosaic layout* menu (:data:`MOSAIC_LAYOUTS`: the
layouts the engine knows, :data:`~napari_polarseg.engine.physics.mosaic.IMX250MZR_LAYOUT`
and the colour sensors' under their Bayer filter). Run decodes it in the worker by
super-pixel (:func:`~napari_polarseg.engine.physics.mosaic.demosaic`,
:func:`~napari_polarseg.engine.physics.colour_mosaic.demosaic_colour`) into a new
angle-stack layer ``"<name> stack"`` that overlays the frame, exactly as the plugin's
reader would have opened it, chooses that layer and runs on it. A second Run on the raw
frame with the same layout chooses the decoded layer again instead of decoding anew.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from magicgui.widgets import ComboBox
from napari.layers import Image
from napari.utils.notifications import show_warning

from .._reader import stack_layer_data
from ..engine.physics.colour_mosaic import (
    IMX250MYR_BAYER,
    IMX250MYR_LAYOUT,
    demosaic_colour,
    luminance,
)
from ..engine.physics.mosaic import IMX250MZR_LAYOUT, demosaic
from ..io import StackData, sensor_from_name
from ..io.mosaic_checks import periodicity_warning
from ._layers import layer_tag, source_key
from .session import Result

#: Text after a raw mosaic layer's name in the stack chooser.
RAW_MOSAIC_SUFFIX = " (raw mosaic)"

#: Metadata key of a decoded stack layer: the raw layer's key and the layout's label.
DECODED_KEY = "raw_mosaic"


@dataclass(frozen=True)
class MosaicLayout:
    """One raw-frame layout the dock decodes.

    Attributes
    ----------
    label : str
        The menu entry.
    layout_deg : tuple of 4 floats
        Polariser angles of the 2 × 2 super-pixel, degrees, row-major.
    bayer : str or None
        The Bayer order of a colour-polarisation sensor (None: mono).
    """

    label: str
    layout_deg: tuple[float, ...]
    bayer: str | None = None

    @property
    def period(self) -> int:
        """Pixels of the pattern's period along each side (2 mono, 4 colour)."""
        return 2 if self.bayer is None else 4


#: The layouts of the Sony polarisation sensors the engine knows, mono first.
MOSAIC_LAYOUTS: tuple[MosaicLayout, ...] = (
    MosaicLayout(
        "mono: 90/45 over 135/0 (Sony IMX250MZR, IMX253MZR, IMX264MZR)",
        tuple(IMX250MZR_LAYOUT),
    ),
    MosaicLayout(
        f"colour: 90/45 over 135/0 under {IMX250MYR_BAYER} (Sony IMX250MYR, IMX253MYR)",
        tuple(IMX250MYR_LAYOUT),
        IMX250MYR_BAYER,
    ),
)


def layout_named(label: str) -> MosaicLayout:
    """The :class:`MosaicLayout` of a menu entry."""
    return next(layout for layout in MOSAIC_LAYOUTS if layout.label == label)


def is_raw_mosaic(layer: Any) -> bool:
    """True for an image layer that can be a raw mosaic frame: 2-D, grey, real numbers,
    an even height and width, not one of the plugin's outputs."""
    if not isinstance(layer, Image) or layer.rgb or layer.multiscale or layer.ndim != 2:
        return False
    shape = tuple(layer.data.shape)
    even = all(n >= 2 and n % 2 == 0 for n in shape)
    return even and np.dtype(layer.data.dtype).kind in "biuf" and layer_tag(layer) is None


def default_layout(name: str, shape: tuple[int, ...]) -> MosaicLayout:
    """The layout a raw layer starts on: a colour sensor named in its name (and a size
    its 4 × 4 period divides), else the mono layout."""
    sensor = sensor_from_name(name)
    colour = MOSAIC_LAYOUTS[1]
    fits = all(n % colour.period == 0 for n in shape)
    return colour if sensor is not None and sensor.bayer is not None and fits else MOSAIC_LAYOUTS[0]


def decode_raw(raw: Any, layout: MosaicLayout, source: str) -> StackData:
    """The angle stack of a raw frame decoded by super-pixel with ``layout`` (any thread):
    mono, the four sub-lattices; colour, the luminance of the R, G, B stacks, which it
    keeps as ``colour_stack``. Raises PolarsegError for a size the layout does not fit."""
    frame = np.asarray(raw)  # a lazy (Dask) layer is read here, in the worker
    colour_stack = None
    if layout.bayer is None:
        stack, angles = demosaic(frame, layout.layout_deg, "superpixel")
    else:
        colour_stack, angles = demosaic_colour(frame, layout.layout_deg, layout.bayer)
        stack = luminance(colour_stack)
    info: dict[str, Any] = {
        "format": "mosaic",
        "demosaic": "superpixel",
        "mosaic_layout_deg": [float(a) for a in layout.layout_deg],
        "raw_shape": list(frame.shape),
    }
    if layout.bayer is not None:
        info["bayer"] = layout.bayer
    warning = periodicity_warning(Path(source), frame)
    if warning is not None:
        info["mosaic_warning"] = warning
    return StackData(stack, angles, source, info, colour_stack=colour_stack)


def decode_job(raw: Any, layout: MosaicLayout, source: str) -> Generator[Any, None, None]:
    """Worker job of a Run on a raw mosaic frame: :func:`decode_raw`, handed over as a
    :class:`~napari_polarseg.widgets.session.Result` (the run that follows is queued
    quietly behind it)."""
    yield f"decoding the raw mosaic ({layout.label.split(':')[0]})", 0, 1
    yield Result(decode_raw(raw, layout, source))


def decoded_layer_data(data: StackData, raw: Any, layout: MosaicLayout) -> tuple[Any, dict, str]:
    """The layer data tuple of the stack decoded from the raw layer ``raw``: the reader's
    (:func:`~napari_polarseg._reader.stack_layer_data`), its placement composed with the
    raw layer's scale and translate so that it overlays the frame, and a metadata entry
    :data:`DECODED_KEY` naming the raw layer and the layout."""
    stack, kwargs, kind = stack_layer_data(data, name=f"{raw.name} stack")
    period = float(layout.period)
    offset = (period - 1.0) / 2.0
    scale = np.asarray(raw.scale[-2:], dtype=float)
    translate = np.asarray(raw.translate[-2:], dtype=float)
    kwargs["scale"] = (1.0, *(scale * period))
    kwargs["translate"] = (0.0, *(translate + offset * scale))
    kwargs["metadata"][DECODED_KEY] = {"layer": source_key(raw), "layout": layout.label}
    return stack, kwargs, kind


class MosaicInput:
    """The Segment dock's part for raw mosaic frames: the *mosaic layout* menu (shown
    while a raw frame is chosen) and the decoding a Run starts first.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
    stack_layer : ComboBox
        The dock's stack chooser (it lists raw frames too).
    submit : callable(job, args, total, on_result)
        The dock's worker slot.
    run : callable()
        The dock's Run, called once the decoded layer is chosen.
    set_status : callable(str)
        The dock's status line.
    """

    def __init__(
        self,
        viewer: Any,
        stack_layer: ComboBox,
        submit: Callable[..., None],
        run: Callable[[], None],
        set_status: Callable[[str], None],
    ) -> None:
        self._viewer, self._stack_layer = viewer, stack_layer
        self._submit, self._run, self._set_status = submit, run, set_status
        self.layout = ComboBox(
            label="mosaic layout",
            choices=[layout.label for layout in MOSAIC_LAYOUTS],
            visible=False,
            tooltip="The polariser (and colour filter) pattern of the raw camera frame "
            "chosen above: Run decodes it into a 4-angle stack layer (one pixel per 2 x 2 "
            "super-pixel, per 4 x 4 for a colour sensor) and segments that",
        )
        stack_layer.changed.connect(self.on_stack_changed)
        self.on_stack_changed()  # the dock may have chosen a raw frame already

    def raw_chosen(self) -> Any:
        """The chosen stack if it is a raw mosaic frame, else None."""
        layer = self._stack_layer.value
        return layer if layer is not None and is_raw_mosaic(layer) else None

    def on_stack_changed(self, *_: Any) -> None:
        """Show the layout menu for a raw frame (on the layout its name suggests) and
        say what Run does with it."""
        raw = self.raw_chosen()
        self.layout.visible = raw is not None
        if raw is None:
            return
        self.layout.value = default_layout(raw.name, tuple(raw.data.shape)).label
        h, w = raw.data.shape
        self._set_status(
            f"{raw.name!r} is a raw {h} x {w} camera frame: Run decodes it with the mosaic "
            "layout below into an angle-stack layer, then segments it"
        )

    def decoded_layer(self, raw: Any, layout: MosaicLayout) -> Any:
        """The stack layer already decoded from ``raw`` with ``layout``, if any."""
        wanted = {"layer": source_key(raw), "layout": layout.label}
        for layer in self._viewer.layers:
            meta = layer.metadata if isinstance(layer.metadata, dict) else {}
            if meta.get(DECODED_KEY) == wanted:
                return layer
        return None

    def decode_first(self) -> bool:
        """Before a run: with a raw frame chosen, choose its decoded layer (False: the
        run goes on with it) or start decoding it (True: the run comes once the decoded
        layer is added). False without a raw frame."""
        raw = self.raw_chosen()
        if raw is None:
            return False
        layout = layout_named(self.layout.value)
        decoded = self.decoded_layer(raw, layout)
        if decoded is not None:
            self._stack_layer.value = decoded
            return False
        source = str(getattr(raw.source, "path", None) or raw.name)

        def decoded_now(_run_id: int, data: StackData) -> None:
            self.add_decoded(raw, layout, data)

        self._submit(decode_job, (raw.data, layout, source), 1, decoded_now)
        return True

    def add_decoded(self, raw: Any, layout: MosaicLayout, data: StackData) -> None:
        """Add the decoded stack layer; if the raw frame is still the chosen stack,
        choose the decoded layer and run on it."""
        stack, kwargs, _ = decoded_layer_data(data, raw, layout)
        layer = self._viewer.add_image(stack, **kwargs)
        warning = data.metadata.get("mosaic_warning")
        if warning:
            show_warning(f"{raw.name}: {warning}")
        if self._stack_layer.value is not raw:
            return
        self._stack_layer.reset_choices()
        self._stack_layer.value = layer
        self._run()
