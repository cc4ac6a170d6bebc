"""What a saved result was made by: the code, the kernel compiler and the engine settings.

A batch run (``dataset``, ``experiment sweep``, the selectivity grid) reuses a finished
result on a rerun only when the result's fingerprint equals the one the rerun would write.
:func:`code_identity` is the part of that fingerprint that names the code: a digest of
every source file of the installed package, the kernel compiler and its version, the arch
and the engine settings that can change a result. A kernel fix, a compiler upgrade or
another lane count therefore recomputes every result it could have changed.

This module imports no compiler: it reads the names and versions from the environment and
the installed package metadata.
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any

from ._version import __version__
from .taichi_runtime import LANES_ENV, default_compiler  # the compiler layer's names; it imports no compiler

#: Packages whose source files make up cdnf_ti (``kernels/``, ``stimuli/`` and ``bench/`` are
#: installed under ``cdnf_ti``; listed so that an editable install, where they live beside it, counts them).
_PACKAGES = ("cdnf_ti", "cdnf_ti.models", "cdnf_ti.backends", "cdnf_ti.kernels", "cdnf_ti.stimuli",
             "cdnf_ti.experiments", "cdnf_ti.events")


def _package_folders() -> list[Path]:
    folders = []
    for name in _PACKAGES:
        spec = importlib.util.find_spec(name)
        if spec is not None and spec.submodule_search_locations:
            folders.extend(Path(p) for p in spec.submodule_search_locations)
    return folders


def source_files() -> list[tuple[str, Path]]:
    """The package's Python source files that results can depend on, in a fixed order.

    Returns
    -------
    list of (str, Path)
        ``("<package>/<file>.py", path)`` for every ``*.py`` file directly inside the folders of
        :data:`_PACKAGES` (sub-packages are listed themselves), sorted by that name.
    """
    files = {f"{name}/{f.name}": f for name, folder in zip(_PACKAGES, _package_folders())
             for f in folder.glob("*.py")}
    return sorted(files.items())


@lru_cache(maxsize=1)
def source_digest() -> str:
    """SHA-256 (hex, first 16 digits) of the package's source files, names and contents.

    Computed once per process (the sources do not change under a running program). Any edit
    of any module, a kernel or a comment alike, gives another digest.
    """
    h = hashlib.sha256()
    for name, path in source_files():
        h.update(f"{name}\0".encode())
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()[:16]


def _version_of(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def compiler_identity() -> dict[str, str]:
    """The kernel compiler a process would use now, and its version.

    Reads ``$CDNF_TI_COMPILER`` (set by ``--compiler`` and inherited by workers), else the
    fastest installed compiler, as :func:`cdnf_ti.taichi_runtime.default_compiler` does.
    """
    name = default_compiler()
    return {"compiler": name, "compiler_version": _version_of(name)}


def engine_settings() -> dict[str, Any]:
    """Engine settings that can change a result: the lanes per vector (``$CDNF_TI_LANES``)."""
    return {"lanes": os.environ.get(LANES_ENV, "").strip() or "default"}


def code_identity(backend: str = "taichi", arch: str = "cpu") -> dict[str, Any]:
    """The code part of a result's fingerprint.

    Parameters
    ----------
    backend : {"taichi", "numpy"}
        The NumPy float64 reference depends on the source files only.
    arch : str
        The Taichi arch (``cpu``, ``cuda``, ...).

    Returns
    -------
    dict
        ``source_digest`` and the cdnf_ti version; for the Taichi backend also ``compiler``,
        ``compiler_version``, ``arch`` and :func:`engine_settings`.
    """
    ident: dict[str, Any] = {"version": __version__, "source_digest": source_digest(), "backend": backend}
    if backend == "taichi":
        ident.update(compiler_identity(), arch=arch, **engine_settings())
    return ident


#: Bytes read from each end of an input file for its content digest (:func:`input_identity`).
CONTENT_SPAN = 1 << 20


def content_digest(path: str | os.PathLike) -> str:
    """SHA-256 (hex, first 16 digits) of a file's size, first MiB and last MiB.

    A file changed in place with its size and modification time kept (``cp -p``,
    ``rsync -t``, an unpacked archive) gets another digest whenever the change touches
    either end, which a re-encoded or replaced video always does (its header and index).
    A folder of images gets the digest of its sorted file names and each file's digest.
    Reads at most 2 MiB per file: about 0.3 ms per video (docs/EXPERIMENTS.md).

    Parameters
    ----------
    path : path-like
        A file, or a folder of files.
    """
    p = Path(path)
    h = hashlib.sha256()
    if p.is_dir():
        for f in sorted(q for q in p.iterdir() if q.is_file()):
            h.update(f"{f.name}\0{content_digest(f)}\0".encode())
        return h.hexdigest()[:16]
    with open(p, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        h.update(f"{size}\0".encode())
        h.update(f.read(CONTENT_SPAN))
        if size > CONTENT_SPAN:
            f.seek(max(CONTENT_SPAN, size - CONTENT_SPAN))
            h.update(f.read(CONTENT_SPAN))
    return h.hexdigest()[:16]


@lru_cache(maxsize=4096)
def _content_digest_of(path: str, size: int, mtime_ns: int, ctime_ns: int, inode: int) -> str:
    """:func:`content_digest`, read once per process for one file state (the arguments after the path
    are only the cache key; any write changes ``ctime_ns``, which no program can set back)."""
    return content_digest(path)


def input_identity(path: str | os.PathLike) -> dict[str, Any]:
    """The input part of a result's fingerprint: the file's path, size, modification time and content.

    Returns
    -------
    dict
        ``source`` (the path as given), ``source_size`` (bytes), ``source_mtime_ns`` and
        ``content_digest`` (:func:`content_digest`).
    """
    st = os.stat(path)
    return {"source": str(path), "source_size": st.st_size, "source_mtime_ns": st.st_mtime_ns,
            "content_digest": _content_digest_of(str(path), st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino)}


def differences(saved: dict | None, expected: dict) -> list[str]:
    """The keys on which a saved fingerprint differs from the expected one (sorted).

    A saved fingerprint without a key that the expected one has (a result written by an
    older cdnf_ti) differs on that key.
    """
    saved = saved if isinstance(saved, dict) else {}
    keys = set(saved) | set(expected)
    return sorted(k for k in keys if saved.get(k) != expected.get(k))


def describe_differences(keys: list[str]) -> str:
    """A reader's words for :func:`differences`: ``"source code, compiler version"``."""
    words = {"source_digest": "source code", "compiler": "compiler", "compiler_version": "compiler version",
             "arch": "arch", "lanes": "lanes per vector", "version": "cdnf_ti version", "backend": "backend",
             "source_size": "input file", "source_mtime_ns": "input file", "source": "input path",
             "content_digest": "input file content",
             "seed": "seed", "rain_params": "rain settings", "params": "parameters", "downscale": "downscale",
             "bin_ms": "--bin-ms", "event_threshold": "--event-threshold", "sensor_size": "--sensor-size"}
    return ", ".join(dict.fromkeys(words.get(k, k) for k in keys))
