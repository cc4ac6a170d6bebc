"""The kernel compiler and its runtime: one per process, chosen once.

cdnf_ti's kernels are written in the Taichi DSL and compile under either

* ``taichi`` 1.7 (upstream; LLVM 15; wheels up to Python 3.12), the default where it is
  installed: with the lane-vectorised layout of :mod:`cdnf_ti.kernels.cdnf` it measured
  about 3x less CPU time per frame than quadrants on the project's Zen 5 machines
  (``docs/PERFORMANCE.md``), or
* ``quadrants`` (``import quadrants as qd``; the maintained fork, LLVM 22, wheels for
  Python 3.10-3.13+), the default where taichi has no wheel (Python 3.13).

Both expose the same DSL (``ti.kernel``, ``ti.func``, ``ti.field``...). Kernel modules get the
DSL module of the process's compiler from :func:`dsl`, so one statement of each kernel serves
both. A process runs one compiler on one architecture (like Taichi itself, which allows one
runtime per process): :func:`ensure_taichi` initialises it on first use; asking for another
compiler or arch later is an error. The compiler is chosen, in this order, by the
``compiler=`` argument of the first model (or ``--compiler`` on the command line), the
``CDNF_TI_COMPILER`` environment variable, or the fastest one installed.
"""
from __future__ import annotations

import contextlib
import importlib
import importlib.util
import io
import os
import threading
import time
from types import ModuleType

ARCHS = ("cpu", "cuda", "vulkan", "gpu")
#: Supported kernel compilers, fastest first (the default is the first one installed).
COMPILERS = ("taichi", "quadrants")
#: Environment variable naming the default compiler of a process.
COMPILER_ENV = "CDNF_TI_COMPILER"
#: Environment variable naming the compile-cache folder (optional).
CACHE_ENV = "CDNF_TI_CACHE_DIR"

_lock = threading.Lock()

os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")
os.environ.setdefault("ENABLE_QUADRANTS_HEADER_PRINT", "False")


class BackendUnavailableError(RuntimeError):
    """The requested compiler or Taichi architecture is not available on this machine."""


_arch: str | None = None
_compiler: str | None = None
_module: ModuleType | None = None
#: Seconds spent in the compiler's ``init`` (import + runtime start), for start-up reports.
init_seconds: float = 0.0


def installed_compilers() -> tuple[str, ...]:
    """The supported compilers importable in this environment, fastest first."""
    return tuple(c for c in COMPILERS if importlib.util.find_spec(c) is not None)


def default_compiler() -> str:
    """The compiler a process uses when none is named.

    ``$CDNF_TI_COMPILER`` when set, else the fastest installed one.

    Raises
    ------
    BackendUnavailableError
        Neither compiler is installed, or the environment variable names one that is not.
    """
    env = os.environ.get(COMPILER_ENV, "").strip().lower()
    if env:
        _check_compiler(env)
        return env
    have = installed_compilers()
    if not have:
        raise BackendUnavailableError("no kernel compiler installed: pip install quadrants (or taichi)")
    return have[0]


def _check_compiler(compiler: str) -> None:
    if compiler not in COMPILERS:
        raise ValueError(f"unknown compiler {compiler!r}; choose one of {', '.join(COMPILERS)}")
    if importlib.util.find_spec(compiler) is None:
        raise BackendUnavailableError(
            f"kernel compiler {compiler!r} is not installed in this Python; "
            f"installed: {', '.join(installed_compilers()) or 'none'}"
        )


def select_compiler(compiler: str | None) -> None:
    """Name the compiler this process will use (before its runtime starts).

    ``None`` leaves the choice to :func:`default_compiler`. Raises ``ValueError`` if the
    runtime already started with another compiler.
    """
    if compiler is None:
        return
    compiler = compiler.strip().lower()
    _check_compiler(compiler)
    with _lock:
        if _compiler is not None and compiler != _compiler:
            raise ValueError(f"this process already runs its kernels with {_compiler!r}; "
                             f"cannot switch to {compiler!r} (start a new process)")
        os.environ[COMPILER_ENV] = compiler


def ensure_taichi(arch: str = "cpu", compiler: str | None = None) -> str:
    """Initialise the kernel compiler once per process on ``arch``; return the arch in use.

    Parameters
    ----------
    arch : {"cpu", "cuda", "vulkan", "gpu"}
        Requested backend. ``cpu`` is the default and always available.
    compiler : {"quadrants", "taichi"} or None
        Kernel compiler; ``None``: the one already running, else :func:`default_compiler`.

    Raises
    ------
    ValueError
        Unknown ``arch``/``compiler``, or a different one than this process already runs
        (one runtime per process).
    BackendUnavailableError
        The compiler is not installed, or the GPU backend is not available here.
    """
    global _arch, _compiler, _module, init_seconds
    if arch not in ARCHS:
        raise ValueError(f"unknown arch {arch!r}; choose one of {', '.join(ARCHS)}")
    if compiler is not None:
        select_compiler(compiler)
    with _lock:
        if _arch is not None:
            if arch != _arch and not (arch == "gpu" and _arch in ("cuda", "vulkan")):
                raise ValueError(
                    f"{_compiler} is already running on {_arch!r} in this process; "
                    f"cannot switch to {arch!r} (start a new process)"
                )
            return _arch
        name = default_compiler()
        t0 = time.perf_counter()
        ti = importlib.import_module(name)
        kw = dict(default_fp=ti.f32, default_ip=ti.i32, offline_cache=True, log_level=ti.ERROR)
        if os.environ.get(CACHE_ENV):  # compile cache folder (default: the compiler's, in ~/.cache)
            kw["offline_cache_file_path"] = os.environ[CACHE_ENV]
        # both print "[Taichi|Quadrants] Starting on arch=..."
        with contextlib.redirect_stdout(io.StringIO()):
            try:
                ti.init(arch=getattr(ti, arch), **kw)
            except Exception as e:  # a broken GPU driver: report it as unavailable, keep the CPU
                with contextlib.suppress(Exception):
                    ti.reset()
                ti.init(arch=ti.cpu, **kw)
                _arch, _compiler, _module = "cpu", name, ti
                raise BackendUnavailableError(
                    f"{name} backend {arch!r} failed to start on this machine ({e}); use --arch cpu") from None
        got_name = _arch_name(ti)
        if arch != "cpu" and got_name in ("x64", "arm64"):
            # no such device: the compiler fell back to the CPU; say so instead of running slowly
            _arch, _compiler, _module = "cpu", name, ti
            raise BackendUnavailableError(
                f"{name} backend {arch!r} is not available on this machine "
                "(no driver/device found); use --arch cpu"
            )
        _arch = "cpu" if got_name in ("x64", "arm64") else got_name
        _compiler, _module = name, ti
        init_seconds = time.perf_counter() - t0
        return _arch


def _arch_name(ti: ModuleType) -> str:
    impl = ti.lang.impl
    core = getattr(impl, "_ti_core", None) or getattr(impl, "_qd_core")
    return core.arch_name(impl.current_cfg().arch)


def dsl() -> ModuleType:
    """The DSL module (``taichi`` or ``quadrants``) of this process's runtime.

    Starts the runtime with the defaults (``cpu``, :func:`default_compiler`) if needed.
    Kernel modules do ``ti = dsl()`` instead of ``import taichi as ti``.
    """
    if _module is None:
        ensure_taichi(_arch or "cpu")
    return _module  # type: ignore[return-value]


def current_arch() -> str | None:
    """The arch the runtime was initialised with in this process, or ``None``."""
    return _arch


def current_compiler() -> str | None:
    """The compiler running this process's kernels, or ``None`` before the runtime starts."""
    return _compiler
