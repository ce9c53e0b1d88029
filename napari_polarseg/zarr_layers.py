"""The OME-Zarr images ``polarseg segment --format zarr`` writes, as lazy multiscale
napari layers (what :mod:`napari_polarseg._reader` returns for them).

A result folder written with ``--format zarr`` holds ``labels.zarr``, ``intensity.zarr``,
``dop.zarr``, … (:func:`napari_polarseg.io.ome_zarr.write_ome_zarr`): each an NGFF 0.4
pyramid, full resolution first, with the writer's own metadata under ``"polarseg"``.
Each opens as one layer whose data is the list of its levels as Dask arrays, so napari
reads only the tiles of the level it draws: ``labels.zarr`` (``image-label`` metadata)
as a Labels layer, a map as an image, and planes with a channel axis (``stokes.zarr``:
S0, S1, S2) as one image layer a plane, named after its component. Other OME-Zarr
images (without the ``"polarseg"`` attribute) are left to other readers
(napari-ome-zarr). No napari import here: layer data tuples only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: The attribute the writer puts its own metadata under (its presence marks a result).
RESULT_ATTR = "polarseg"

LayerData = tuple[Any, dict[str, Any], str]


def _group_attrs(path: Path) -> dict[str, Any] | None:
    """The attributes of the Zarr group at ``path``, or None (not a group; never raises)."""
    try:
        import zarr

        node = zarr.open(path, mode="r")
    except Exception:
        return None
    return dict(node.attrs) if isinstance(node, zarr.Group) else None


def _multiscale(attrs: dict[str, Any]) -> dict[str, Any] | None:
    """The first ``multiscales`` entry (NGFF 0.4, or 0.5 under ``"ome"``), or None."""
    scales = attrs.get("multiscales", attrs.get("ome", {}).get("multiscales"))
    return scales[0] if isinstance(scales, list) and scales else None


def is_result_image(path: Path) -> bool:
    """Whether ``path`` is an OME-Zarr image written by polarseg (a cheap look at its
    attributes; never raises)."""
    attrs = _group_attrs(path) if path.is_dir() else None
    return attrs is not None and RESULT_ATTR in attrs and _multiscale(attrs) is not None


def result_levels(path: Path) -> tuple[list[Any], dict[str, Any]]:
    """The levels of the result image at ``path`` (Dask arrays, full resolution first)
    and the group's attributes."""
    import dask.array as da
    import zarr

    group = zarr.open_group(path, mode="r")
    attrs = dict(group.attrs)
    scale = _multiscale(attrs)
    if scale is None:
        raise ValueError(f"{path}: not an OME-Zarr image (no 'multiscales' metadata)")
    levels = [da.from_zarr(group[d["path"]]) for d in scale["datasets"]]
    return levels, attrs


def result_layer_data(path: Path) -> list[LayerData]:
    """The layer data of a result image: one Labels layer (``image-label``), one image
    layer a plane (a ``c`` axis), or one image layer; multiscale when the pyramid has
    more than one level."""
    levels, attrs = result_levels(path)
    scale = _multiscale(attrs) or {}
    info = attrs.get(RESULT_ATTR, {})
    data: Any = levels if len(levels) > 1 else levels[0]
    name = path.name.removesuffix(".zarr")
    kwargs: dict[str, Any] = {
        "name": name,
        "metadata": {RESULT_ATTR: info, "source": str(path)},
        "multiscale": len(levels) > 1,
    }
    if "image-label" in attrs:
        return [(data, kwargs, "labels")]
    axes = [a.get("name") if isinstance(a, dict) else str(a) for a in scale.get("axes", [])]
    if levels[0].ndim == 3 and axes[:1] == ["c"]:
        planes = levels[0].shape[0]
        names = info.get("components") if isinstance(info, dict) else None
        if not (isinstance(names, list) and len(names) == planes):
            names = [f"{name} {i}" for i in range(planes)]
        kwargs |= {"channel_axis": 0, "name": [str(n) for n in names], "colormap": "gray"}
    return [(data, kwargs, "image")]
