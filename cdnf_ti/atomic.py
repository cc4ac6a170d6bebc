"""Atomic file writes and output folders.

A result file is either complete or absent, never truncated; a write error
(read-only folder, full disk) is an :class:`~cdnf_ti.errors.OutputError` that
names the path. :func:`prepare_output` checks an output folder before any work,
and :func:`output_lock` keeps two runs from writing into one folder at once.
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import re
import secrets
import sys
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from .errors import OutputError, output_error

#: Name of the lock file a run holds in its output folder.
LOCK_NAME = ".cdnf_ti.lock"


def _new_temp(path: Path) -> str:
    """Create an empty temporary file next to ``path`` and return its name.

    ``os.open`` with mode 0o666 lets the process umask decide the permissions,
    as for any ordinary file (the umask is never changed).
    """
    for _ in range(100):
        tmp = path.parent / f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp{path.suffix}"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return str(tmp)
    raise FileExistsError(f"cannot create a temporary file next to {path}")


_TEMP_NAME = re.compile(r"^\..+\.(\d+)\.[0-9a-f]{8}\.tmp")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def remove_stale_temps(folder: str | os.PathLike) -> int:
    """Delete temporary files of :func:`atomic_write` under ``folder`` whose writer process is gone
    (a worker killed mid-write, a ``kill -9``). Returns how many were removed."""
    removed = 0
    root = Path(folder)
    if not root.is_dir():
        return 0
    for p in root.rglob(".*.tmp*"):
        m = _TEMP_NAME.match(p.name)
        if m and p.is_file() and not _pid_alive(int(m.group(1))):
            with contextlib.suppress(OSError):
                p.unlink()
                removed += 1
    return removed


def atomic_write(path: str | os.PathLike, write: Callable[[str], None]) -> None:
    """Call ``write(tmp_path)`` then rename the temporary file onto ``path``.

    The temporary file lives in the same folder (same file system), so the
    final ``os.replace`` is atomic.

    Raises
    ------
    OutputError
        The folder cannot be made or the file cannot be written (message names ``path``).
    """
    path = Path(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = _new_temp(path)
        write(tmp)
        os.replace(tmp, path)
    except OSError as e:
        _discard(tmp)
        raise output_error(path, e) from None
    except BaseException:
        _discard(tmp)
        raise


def _discard(tmp: str | None) -> None:
    if tmp is not None:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""

    def _w(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())

    atomic_write(path, _w)


def atomic_write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as indented JSON to ``path`` atomically.

    Non-finite floats (NaN, infinity) are written as ``null``: strict JSON has
    no such numbers.
    """
    text = json.dumps(json_safe(obj), indent=2, sort_keys=False, default=_json_default, allow_nan=False)
    atomic_write_text(path, text + "\n")


def json_safe(o: Any) -> Any:
    """``o`` with NumPy scalars/arrays and paths made plain and non-finite floats made ``None``."""
    if isinstance(o, dict):
        return {k: json_safe(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [json_safe(v) for v in o]
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    try:
        plain = _json_default(o)
    except TypeError:
        return o
    return json_safe(plain)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def prepare_output(folder: str | os.PathLike) -> Path:
    """Create ``folder`` if needed and check that files can be written there, before any work.

    Returns
    -------
    Path
        The folder, resolved to an absolute path.

    Raises
    ------
    OutputError
        The folder cannot be created (a file is in the way, no permission) or
        is not writable (read-only, full disk); the message names the folder.
    """
    p = Path(folder).expanduser()
    if p.exists() and not p.is_dir():
        raise OutputError(p, "exists and is not a folder (give a folder for the output)")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise output_error(p, e) from None
    probe = None
    try:
        probe = _new_temp(p / ".write-test")
        with open(probe, "w") as f:
            f.write("cdnf_ti write test\n")
            f.flush()
            os.fsync(f.fileno())
    except OSError as e:
        raise OutputError(p, f"output folder is not writable ({e.strerror or e})") from None
    finally:
        _discard(probe)
    return p.resolve()


@contextlib.contextmanager
def output_lock(folder: str | os.PathLike, wait: bool = True,
                notify: Callable[[str], None] | None = None) -> Iterator[None]:
    """Hold an exclusive lock on ``folder`` (file ``folder/.cdnf_ti.lock``) for a run.

    A second run into the same folder waits until the first one finishes
    (``wait=True``; it then reuses the finished results) or fails at once with
    an :class:`OutputError` (``wait=False``). The lock file is removed when the
    run ends, and the lock is released when the process ends, however it ends
    (a killed run leaves the file, unlocked: the next run takes it). On systems
    without ``fcntl`` (Windows) it does nothing.

    Parameters
    ----------
    notify : callable, optional
        Called with a one-line message when the run has to wait
        (default: print to stderr).
    """
    try:
        # lazy: POSIX only
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    lock = Path(folder) / LOCK_NAME
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as e:
            raise output_error(lock, e) from None
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.pread(fd, 64, 0).decode("ascii", "replace").strip() or "?"
                msg = f"{folder}: another cdnf_ti run (pid {holder}) is writing to this folder"
                if not wait:
                    raise OutputError(folder, f"another cdnf_ti run (pid {holder}) is writing to this folder; "
                                              "wait for it or give another --out") from None
                (notify or (lambda m: print(m, file=sys.stderr, flush=True)))(
                    f"note: {msg}; waiting for it to finish (its finished work will be reused)")
                fcntl.flock(fd, fcntl.LOCK_EX)
        except BaseException:
            os.close(fd)
            raise
        if _same_file(fd, lock):
            break
        os.close(fd)  # the holder removed the file as it finished: lock the one that is there now
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        try:
            os.unlink(lock)  # removed while still held: a run waiting on it locks a fresh file
        except OSError:
            pass
        os.close(fd)  # closing the descriptor releases the lock


def _same_file(fd: int, path: Path) -> bool:
    """Whether the open descriptor ``fd`` is the file now at ``path``."""
    try:
        a, b = os.fstat(fd), os.stat(path)
    except OSError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)
