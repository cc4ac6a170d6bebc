"""Exceptions that carry a one-line, user-facing message.

The command line (:func:`cdnf_ti.run.main`) prints a :class:`UserError` as one
line, ``error: <message>``, with no traceback, and exits with code 2. Any other
exception is a bug and keeps its traceback.

:class:`UserError` derives from ``ValueError`` so that code catching
``ValueError`` for bad arguments keeps working.
"""
from __future__ import annotations


class UserError(ValueError):
    """A problem the user can fix (bad option, bad file, missing device): one line, exit 2."""


class InputError(UserError):
    """Bad user input (a file, a frame, a labels row).

    The message is one line and names the offending file or item, e.g.
    ``"clip.mp4: cannot decode frame 17 (corrupt or truncated video)"``.
    The command line prints it without a traceback and exits with code 2.
    """

    def __init__(self, source: object, problem: str):
        self.source = str(source)
        self.problem = problem
        super().__init__(f"{self.source}: {problem}")


class OutputError(InputError):
    """An output file or folder cannot be written (read-only, full disk, not a folder).

    The message names the path, e.g. ``"out/results.csv: No space left on device"``.
    """


def output_error(path: object, e: OSError) -> OutputError:
    """An :class:`OutputError` for an ``OSError`` raised while writing ``path``."""
    text = e.strerror or (str(e).splitlines() or [type(e).__name__])[0]
    return OutputError(path, text)
