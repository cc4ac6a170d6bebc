"""Exceptions that carry a one-line, user-facing message."""
from __future__ import annotations


class InputError(Exception):
    """Bad user input (a file, a frame, a labels row).

    The message is one line and names the offending file or item, e.g.
    ``"clip.mp4: cannot decode frame 17 (corrupt or truncated video)"``.
    The command line prints it without a traceback and exits with code 2.
    """

    def __init__(self, source: object, problem: str):
        self.source = str(source)
        self.problem = problem
        super().__init__(f"{self.source}: {problem}")
