"""Exceptions raised by the engine.

Every problem with the user's input or parameters is raised as :class:`PolarsegError`
(a :class:`ValueError`), with a one-line message that names the bad argument. The command
line prints that line without a traceback; the napari plugin shows it as a notification.
"""

from __future__ import annotations


class PolarsegError(ValueError):
    """Invalid input or parameters for a napari-polarseg computation."""


class Cancelled(Exception):
    """A run was cancelled, between stages or inside a normalized cut (not an error of the
    input)."""


class ClassifierInputError(PolarsegError):
    """The scribbles cannot train the pixel classifier (e.g. fewer than two materials
    among the valid pixels), or a given classifier does not fit the image: the user's
    strokes or file to change, which a front end shows beside them (not as a failure)."""
