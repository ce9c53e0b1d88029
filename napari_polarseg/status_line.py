"""A progress line on the terminal for long command-line work (no napari, no Qt).

``polarseg segment`` and ``polarseg sweep`` (and ``demo``, which segments) say on stderr
which stage is running, one line rewritten in place (carriage return, then the ANSI
"erase to end of line" sequence) and erased when the job ends, so a terminal shows the
progress while it runs and only the command's own output afterwards. It is shown only
when both stdout and stderr are terminals: never into a file, a pipe or a test's captured
output, and never with ``--quiet``. ``--verbose`` keeps its permanent stage lines instead.
"""

from __future__ import annotations

import shutil
import sys
import time
from typing import TextIO

#: Carriage return and ANSI EL (erase from the cursor to the end of the line).
ERASE = "\r\x1b[K"


def on_terminal(*streams: TextIO) -> bool:
    """Whether every stream is a terminal (False for anything without ``isatty``)."""
    for stream in streams:
        try:
            if not stream.isatty():
                return False
        except (AttributeError, ValueError, OSError):  # closed or not a file
            return False
    return True


class StatusLine:
    """One line of progress on stderr, rewritten in place and erased at the end.

    Parameters
    ----------
    enabled : bool
        False makes every call a no-op (not a terminal, ``--quiet``, ``--verbose``).
    prog : str
        Prefix of the line (the program's name).

    The stream is looked up as ``sys.stderr`` at each write, so a redirected stderr is
    honoured. Times are seconds since the line was created.
    """

    def __init__(self, enabled: bool, prog: str = "polarseg") -> None:
        self.enabled = bool(enabled)
        self.prog = prog
        self.start = time.perf_counter()
        self.shown = False

    @classmethod
    def for_terminal(cls, quiet: bool = False, prog: str = "polarseg") -> StatusLine:
        """A line enabled when stdout and stderr are terminals and not ``quiet``."""
        return cls(not quiet and on_terminal(sys.stdout, sys.stderr), prog)

    def elapsed(self) -> float:
        """Seconds since the line was created."""
        return time.perf_counter() - self.start

    def show(self, text: str) -> None:
        """Replace the line by ``"<prog>: <text> (<elapsed> s)"``, cut to the width."""
        if not self.enabled:
            return
        line = f"{self.prog}: {text} ({self.elapsed():.1f} s)"
        width = shutil.get_terminal_size((80, 24)).columns
        if len(line) > width - 1:  # a wrapped line could not be rewritten in place
            line = line[: max(width - 2, 1)] + "…"
        sys.stdout.flush()  # keep the order of the two streams on the terminal
        sys.stderr.write(ERASE + line)
        sys.stderr.flush()
        self.shown = True

    def stage(self, name: str, index: int, total: int, what: str = "") -> None:
        """Show ``what [index/total] name``: the stage being worked on, 1-based."""
        prefix = f"{what} " if what else ""
        self.show(f"{prefix}[{index}/{total}] {name}")

    def clear(self) -> None:
        """Erase the line (before anything else is printed, and when the job ends)."""
        if self.enabled and self.shown:
            sys.stderr.write(ERASE)
            sys.stderr.flush()
            self.shown = False
