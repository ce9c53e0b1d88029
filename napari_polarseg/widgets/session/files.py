"""Files the widgets write without Qt: the parameters JSON."""

from __future__ import annotations

from pathlib import Path

from ...engine import SegmentParams
from ...io import atomic_output


def write_params_json(path: Path, params: SegmentParams) -> None:
    """Write ``params`` to ``path`` as JSON (``SegmentParams.to_json`` and a newline),
    atomically: the format of ``polarseg segment --params``. Raises ``OSError``."""
    text = params.to_json() + "\n"
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
