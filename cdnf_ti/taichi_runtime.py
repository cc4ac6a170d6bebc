"""One Taichi runtime per process: initialisation and architecture selection.

:func:`check_arch` tells whether a GPU arch works on this machine *before* any
work starts: it initialises Taichi in a short-lived child process, because
asking Taichi 1.7 for ``gpu`` on a machine without one can crash the process
(segmentation fault) instead of raising. :func:`ensure_taichi` never resets a
Taichi runtime that a host program initialised itself: it adopts it.
"""
from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import threading

from .errors import UserError

ARCHS = ("cpu", "cuda", "vulkan", "gpu")

_lock = threading.Lock()

#: Architectures whose availability was already probed in this process: arch -> backend name or None.
_probed: dict[str, str | None] = {}

_CPU_NAMES = ("x64", "arm64")
#: Environment variable prefix recording a successful probe, so worker processes need not probe again.
_ENV_OK = "CDNF_TI_ARCH_OK_"


class BackendUnavailableError(UserError):
    """The requested Taichi architecture is not available on this machine."""


_arch: str | None = None

_PROBE = """
import os, sys
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")
import taichi as ti
ti.init(arch=getattr(ti, sys.argv[1]), log_level=ti.ERROR)
print("ARCH=" + ti.lang.impl._ti_core.arch_name(ti.lang.impl.current_cfg().arch), flush=True)
"""


def _unavailable(arch: str, why: str = "no driver/device found") -> BackendUnavailableError:
    return BackendUnavailableError(f"Taichi backend {arch!r} is not available on this machine ({why}); "
                                   "use --arch cpu")


def check_arch(arch: str, timeout: float = 120.0) -> str:
    """Check, without touching this process's Taichi runtime, that ``arch`` works here.

    ``cpu`` is always available. For a GPU arch a child process initialises
    Taichi on it (a few seconds, once per process).

    Returns
    -------
    str
        The Taichi backend the arch resolves to (``"cpu"``, ``"cuda"``, ``"vulkan"``, ...).

    Raises
    ------
    UserError
        Unknown arch.
    BackendUnavailableError
        No such device or driver here (the probe crashed, failed or fell back to the CPU).
    """
    if arch not in ARCHS:
        raise UserError(f"unknown arch {arch!r}; choose one of {', '.join(ARCHS)}")
    if arch == "cpu":
        return "cpu"
    if _arch is not None and (_arch == arch or (arch == "gpu" and _arch != "cpu")):
        return _arch  # already running on it in this process
    known = os.environ.get(_ENV_OK + arch)  # probed by a parent process (workers inherit the answer)
    if arch not in _probed and known:
        _probed[arch] = known
    if arch not in _probed:
        try:
            proc = subprocess.run([sys.executable, "-c", _PROBE, arch], capture_output=True, text=True,
                                  timeout=timeout, env={**os.environ, "TI_LOG_LEVEL": "error"})
            got = [ln[5:] for ln in proc.stdout.splitlines() if ln.startswith("ARCH=")]
            _probed[arch] = got[0] if proc.returncode == 0 and got and got[0] not in _CPU_NAMES else None
        except (OSError, subprocess.TimeoutExpired):
            _probed[arch] = None
    if _probed[arch] is None:
        raise _unavailable(arch)
    os.environ[_ENV_OK + arch] = _probed[arch]  # type: ignore[assignment]
    return _probed[arch]  # type: ignore[return-value]


def _host_runtime_arch() -> str | None:
    """The arch of a Taichi runtime some other code already initialised in this process, or None."""
    if "taichi" not in sys.modules:
        return None
    try:
        import taichi as ti

        if ti.lang.impl.get_runtime().prog is None:
            return None
        name = ti.lang.impl._ti_core.arch_name(ti.lang.impl.current_cfg().arch)
    except Exception:  # noqa: BLE001 - internal API moved: behave as if not initialised
        return None
    return "cpu" if name in _CPU_NAMES else name


def ensure_taichi(arch: str = "cpu") -> str:
    """Initialise Taichi once per process on ``arch`` and return the arch in use.

    If the host program already initialised Taichi, that runtime is adopted as
    it is (never reset), provided it runs on the requested arch.

    Parameters
    ----------
    arch : {"cpu", "cuda", "vulkan", "gpu"}
        Requested backend. ``cpu`` is the default and always available.

    Raises
    ------
    UserError
        Unknown ``arch``, or a different arch than the one this process
        already runs (Taichi allows one runtime per process).
    BackendUnavailableError
        The requested GPU backend is not available on this machine.
    """
    global _arch
    if arch not in ARCHS:
        raise UserError(f"unknown arch {arch!r}; choose one of {', '.join(ARCHS)}")
    with _lock:
        if _arch is None:
            _arch = _host_runtime_arch()
        if _arch is not None:
            if arch != _arch and not (arch == "gpu" and _arch not in ("cpu",)):
                raise UserError(
                    f"Taichi is already running on {_arch!r} in this process; "
                    f"cannot switch to {arch!r} (start a new process)"
                )
            return _arch
        if arch != "cpu":
            check_arch(arch)  # a missing GPU can crash ti.init; find out in a child process first
        import taichi as ti

        with contextlib.redirect_stdout(io.StringIO()):  # Taichi prints "[Taichi] Starting on arch=..."
            ti.init(
                arch=getattr(ti, arch),
                default_fp=ti.f32,
                default_ip=ti.i32,
                offline_cache=True,
                log_level=ti.WARN,
            )
        got_name = ti.lang.impl._ti_core.arch_name(ti.lang.impl.current_cfg().arch)
        if arch != "cpu" and got_name in _CPU_NAMES:  # fell back to the CPU after all
            _arch = "cpu"
            raise _unavailable(arch)
        _arch = "cpu" if got_name in _CPU_NAMES else got_name
        return _arch


def current_arch() -> str | None:
    """The arch Taichi was initialised with in this process, or ``None``."""
    return _arch
