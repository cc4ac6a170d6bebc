"""One Taichi runtime per process: initialisation and architecture selection."""
from __future__ import annotations

import contextlib
import io
import threading

ARCHS = ("cpu", "cuda", "vulkan", "gpu")

_lock = threading.Lock()


class BackendUnavailableError(RuntimeError):
    """The requested Taichi architecture is not available on this machine."""

_arch: str | None = None


def ensure_taichi(arch: str = "cpu") -> str:
    """Initialise Taichi once per process on ``arch`` and return the arch in use.

    Parameters
    ----------
    arch : {"cpu", "cuda", "vulkan", "gpu"}
        Requested backend. ``cpu`` is the default and always available.

    Raises
    ------
    ValueError
        Unknown ``arch``, or a different arch than the one this process
        already initialised (Taichi allows one runtime per process).
    BackendUnavailableError
        The requested GPU backend is not available on this machine.
    """
    global _arch
    if arch not in ARCHS:
        raise ValueError(f"unknown arch {arch!r}; choose one of {', '.join(ARCHS)}")
    with _lock:
        if _arch is not None:
            if arch != _arch and not (arch == "gpu" and _arch in ("cuda", "vulkan")):
                raise ValueError(
                    f"Taichi is already running on {_arch!r} in this process; "
                    f"cannot switch to {arch!r} (start a new process)"
                )
            return _arch
        import taichi as ti

        with contextlib.redirect_stdout(io.StringIO()):  # Taichi prints "[Taichi] Starting on arch=..."
            ti.init(
                arch=getattr(ti, arch),
                default_fp=ti.f32,
                default_ip=ti.i32,
                offline_cache=True,
                log_level=ti.WARN,
            )
        got = ti.lang.impl.current_cfg().arch
        got_name = ti.lang.impl._ti_core.arch_name(got)
        if arch != "cpu" and got_name in ("x64", "arm64"):
            ti.reset()
            with contextlib.redirect_stdout(io.StringIO()):
                ti.init(arch=ti.cpu, default_fp=ti.f32, offline_cache=True, log_level=ti.WARN)
            _arch = "cpu"
            raise BackendUnavailableError(
                f"Taichi backend {arch!r} is not available on this machine "
                "(no driver/device found); use --arch cpu"
            )
        _arch = "cpu" if got_name in ("x64", "arm64") else got_name
        return _arch


def current_arch() -> str | None:
    """The arch Taichi was initialised with in this process, or ``None``."""
    return _arch
