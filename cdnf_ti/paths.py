"""Paths built from names that come from data: they stay inside their folder.

A clip name in a labels file, an input's stem or a model name ends up in file names
under the dataset folder (read) and under ``--out`` (written). Such a name comes from
files the user may not have written, so every path made from one goes through
:func:`inside`, which refuses a name that would leave its folder (``..``, an absolute
path, a path separator); :func:`name_problem` says what is wrong with a name, so the
labels reader can reject the row before any work.

The check is on the path as written (no file system access): a symbolic link that the
folder's owner put inside the folder is followed as any other file.
"""
from __future__ import annotations

import os
from pathlib import Path, PurePosixPath, PureWindowsPath

from .errors import UserError


class PathEscapeError(UserError):
    """A name would make a path outside its folder (one line: the folder and the name)."""

    def __init__(self, folder: object, name: object, problem: str):
        self.folder = str(folder)
        self.name = str(name)
        super().__init__(f"{name!s}: {problem}; a name must stay inside {folder!s}")


#: Longest file name most file systems take (bytes, UTF-8; ``NAME_MAX`` on Linux and macOS).
NAME_MAX = 255


def name_problem(name: str, max_bytes: int = NAME_MAX) -> str | None:
    """What makes ``name`` unfit as a plain file name inside a folder, or ``None`` when it is fit.

    A plain name is not empty, not ``.`` or ``..``, has no ``/`` or ``\\`` and no NUL
    character, is not absolute or drive-relative on any system (``/etc/passwd``,
    ``C:x``), and is at most ``max_bytes`` bytes long in UTF-8.

    Parameters
    ----------
    name : str
        The name as written (a clip name from a labels file, a file stem).
    max_bytes : int
        Longest name accepted (bytes); less than :data:`NAME_MAX` leaves room for what a
        caller appends to the name.

    Returns
    -------
    str or None
        A short phrase (``"is an absolute path"``, ``"contains '..'"``, ...) or ``None``.
    """
    if not name:
        return "is empty"
    if "\0" in name:
        return "contains a NUL character"
    if PurePosixPath(name).is_absolute() or PureWindowsPath(name).is_absolute() or PureWindowsPath(name).drive:
        return "is an absolute path"
    parts = name.replace("\\", "/").split("/")
    if ".." in parts:
        return "contains '..'"
    if name == ".":
        return "is '.'"
    if len(parts) > 1:
        return "contains a path separator"
    if len(name.encode("utf-8", "surrogatepass")) > max_bytes:
        return f"is longer than {max_bytes} bytes"
    return None


def inside(folder: str | os.PathLike, name: str | os.PathLike) -> Path:
    """``folder / name``, checked to lie inside ``folder``.

    ``name`` may have several plain parts (``"traces/clean/c01.cdnf.csv"``); every part
    must be a plain name (:func:`name_problem`).

    Parameters
    ----------
    folder : path-like
        The folder the path must stay in.
    name : str or path-like
        A name relative to ``folder``.

    Returns
    -------
    Path
        ``Path(folder) / name``.

    Raises
    ------
    PathEscapeError
        ``name`` is absolute, contains ``..``, is empty or holds a NUL character: the
        path would leave ``folder`` (or is not a path).
    """
    text = os.fspath(name)
    for part in text.replace("\\", "/").split("/"):
        problem = name_problem(part)
        if problem is not None:
            problem = name_problem(text) or problem
            raise PathEscapeError(folder, text, problem)
    return Path(folder) / text
