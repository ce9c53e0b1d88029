"""Polariser angles (degrees) stored in a TIFF file's metadata (no napari, no Qt).

Where a TIFF stack may carry its angles, in the order :func:`tiff_angles` looks:

1. **A JSON ImageDescription** with an ``"angles"`` key, on any page: a plain one
   (``tifffile.imwrite(path, stack, description=json.dumps({"angles": [...]}))``) or
   tifffile's shaped metadata (``metadata={"angles": [...]}``). tifffile writes its own
   shaped description (``{"shape": [...]}``) beside the user's, so every description tag
   of every page is read, not only the first.
2. **ImageJ labels**: the slice (or channel) labels of an ImageJ hyperstack
   (``imagej_metadata["Labels"]``), one per frame.
3. **OME-XML channel names** of the first image (``<Channel Name="45"/>``), one per frame.

A label or channel name gives its angle as **the last number in it**, after a trailing
image-file extension is dropped: ``"0°"`` → 0, ``"pol_045"`` → 45, ``"pol 22.5 deg"`` →
22.5, ``"img_135.tif"`` → 135. Labels count only if every frame has one and each holds a
number; otherwise the next source is tried, and a file with none of them has no angles.
"""

from __future__ import annotations

import contextlib
import json
import re
from collections.abc import Iterator, Sequence
from typing import Any

import tifffile

_NUMBER = re.compile(r"\d+(?:\.\d+)?")
_IMAGE_SUFFIX = re.compile(r"\.(?:tiff?|png|jpe?g)$", re.IGNORECASE)

#: ``angles_from`` values of :func:`tiff_angles`, by source.
FROM_JSON = "tiff"
FROM_IMAGEJ = "imagej labels"
FROM_OME = "ome channel names"


def label_angle(label: Any) -> float | None:
    """Angle in degrees carried by a slice label or channel name: its last number.

    Examples
    --------
    >>> label_angle("0°"), label_angle("pol 22.5 deg"), label_angle("img_135.tif")
    (0.0, 22.5, 135.0)
    >>> label_angle("dark") is None
    True
    """
    text = _IMAGE_SUFFIX.sub("", str(label).strip())
    numbers = _NUMBER.findall(text)
    return float(numbers[-1]) if numbers else None


def json_descriptions(tif: tifffile.TiffFile) -> Iterator[dict[str, Any]]:
    """Every ImageDescription of every page that is a JSON object, in file order."""
    for page in tif.pages:
        tags = getattr(page, "tags", None)
        if tags is None:  # a TiffFrame shares its key frame's tags
            continue
        for tag in tags.getall(270, default=()):
            text = tag.value
            if isinstance(text, bytes):
                text = text.decode("utf-8", "replace")
            if not isinstance(text, str) or not text.lstrip().startswith("{"):
                continue
            with contextlib.suppress(ValueError):
                data = json.loads(text)
                if isinstance(data, dict):
                    yield data


def _label_angles(labels: Sequence[Any] | None, n_frames: int) -> list[float] | None:
    if not labels or len(labels) != n_frames:
        return None
    angles = [label_angle(label) for label in labels]
    return None if any(a is None for a in angles) else angles  # type: ignore[return-value]


def imagej_label_angles(tif: tifffile.TiffFile, n_frames: int) -> list[float] | None:
    """Angles from the ImageJ slice/channel labels, one per frame, or None."""
    labels = None
    with contextlib.suppress(Exception):
        labels = (tif.imagej_metadata or {}).get("Labels")
    if isinstance(labels, str):
        labels = [labels]
    return _label_angles(labels, n_frames)


def ome_channel_angles(tif: tifffile.TiffFile, n_frames: int) -> list[float] | None:
    """Angles from the channel names of the first OME-XML image, one per frame, or None."""
    if not tif.is_ome:
        return None
    try:
        ome = tifffile.xml2dict(tif.ome_metadata or "").get("OME", {})
        images = ome.get("Image", [])
        image = images[0] if isinstance(images, list) else images
        channels = image["Pixels"].get("Channel", [])
    except Exception:
        return None
    if isinstance(channels, dict):
        channels = [channels]
    names = [c.get("Name") if isinstance(c, dict) else None for c in channels]
    if any(name is None for name in names):
        return None
    return _label_angles(names, n_frames)


def tiff_angles(tif: tifffile.TiffFile, n_frames: int) -> tuple[Any, str] | None:
    """The angles a TIFF file's metadata gives its ``n_frames`` frames, and their source.

    Returns
    -------
    (angles, source) or None
        ``angles`` as stored (a JSON value for the JSON description: checked by the
        caller; floats for labels), ``source`` one of :data:`FROM_JSON`,
        :data:`FROM_IMAGEJ`, :data:`FROM_OME`; None when the file has no angles.
    """
    for data in json_descriptions(tif):
        if data.get("angles") is not None:
            return data["angles"], FROM_JSON
    angles = imagej_label_angles(tif, n_frames)
    if angles is not None:
        return angles, FROM_IMAGEJ
    angles = ome_channel_angles(tif, n_frames)
    if angles is not None:
        return angles, FROM_OME
    return None
