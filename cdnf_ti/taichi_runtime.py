"""The kernel compiler and its runtime: one per process, chosen once.

cdnf_ti's kernels are written in the Taichi DSL and compile under either

* ``taichi`` 1.7 (upstream; LLVM 15; wheels up to Python 3.12), the default where it is
  installed: with the lane kernels compiled with explicit vector types (:func:`vector_kernel`)
  it runs C-DNF about as fast as quadrants at 426x240 and faster at 600x600 on the project's
  Zen 5 machines, and starts 3 s sooner (``docs/PERFORMANCE.md``), or
* ``quadrants`` (``import quadrants as qd``; the maintained fork, LLVM 22, wheels for
  Python 3.10-3.13+), the default where taichi has no wheel (Python 3.13).

Both expose the same DSL (``ti.kernel``, ``ti.func``, ``ti.field``...). Kernel modules define
their kernels in a factory, ``build(ti, lanes)``, that :func:`kernels` calls with the DSL module
of the process's compiler (:func:`dsl`) once the compiler and arch are chosen, so one statement
of each kernel serves both and importing a kernel module loads no compiler. A process runs
one compiler on one architecture (like Taichi itself, which allows one runtime per process):
:func:`ensure_taichi` initialises it on first use; asking for another
compiler or arch later is an error. The compiler is chosen, in this order, by the
``compiler=`` argument of the first model (or ``--compiler`` on the command line), the
``CDNF_TI_COMPILER`` environment variable, or the fastest one installed.

:func:`check_arch` tells whether a GPU arch works on this machine *before* any work starts:
it initialises the compiler in a short-lived child process, because asking Taichi 1.7 for
``gpu`` on a machine without one can crash the process (segmentation fault) instead of
raising. :func:`ensure_taichi` never resets a runtime that a host program initialised
itself: it adopts it.
"""
from __future__ import annotations

import atexit
import contextlib
import importlib
import importlib.util
import io
import os
import subprocess
import sys
import threading
import time
from types import ModuleType

from .errors import UserError

ARCHS = ("cpu", "cuda", "vulkan", "gpu")
#: Supported kernel compilers, fastest first (the default is the first one installed).
COMPILERS = ("taichi", "quadrants")
#: Environment variable naming the default compiler of a process.
COMPILER_ENV = "CDNF_TI_COMPILER"
#: Environment variable naming the compile-cache folder (optional; default: :func:`cache_folder`).
CACHE_ENV = "CDNF_TI_CACHE_DIR"
#: Size of the compile cache before the compiler evicts its least recently used kernels (bytes).
#: Both compilers default to 100 MiB, which the kernels of the five models at a few frame sizes
#: outgrow: each later run then evicted and recompiled kernels it needed (minutes per run).
CACHE_MAX_BYTES = 1 << 30  # 1 GiB (the setting is a 32-bit int)
#: Environment variable overriding the fast path's lanes per vector (optional; ``kernels.common.lane_count``).
LANES_ENV = "CDNF_TI_LANES"
#: The lane counts ``$CDNF_TI_LANES`` may choose (to tune the lane layout on another CPU).
LANE_CHOICES = (8, 16, 32)
#: Environment variables sizing a process's CPU thread pool: taichi reads the first, quadrants the second.
THREADS_ENV = ("TI_CPU_MAX_NUM_THREADS", "QD_CPU_MAX_NUM_THREADS")

_lock = threading.Lock()

os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")
os.environ.setdefault("ENABLE_QUADRANTS_HEADER_PRINT", "False")

_CPU_NAMES = ("x64", "arm64")
#: Environment variable prefix recording a successful probe, so worker processes need not probe again.
_ENV_OK = "CDNF_TI_ARCH_OK_"
#: Architectures whose availability was already probed in this process: (compiler, arch) -> backend or None.
_probed: dict[tuple[str, str], str | None] = {}


class BackendUnavailableError(UserError):
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


def cache_folder(compiler: str) -> str:
    """The folder where ``compiler`` keeps cdnf_ti's compiled kernels.

    ``$CDNF_TI_CACHE_DIR`` when set, else ``cdnf_ti/<compiler>`` under ``$XDG_CACHE_HOME``
    (``~/.cache``). cdnf_ti does not share the compiler's own folder (``~/.cache/taichi``,
    ``~/.cache/quadrants``): every runtime trims the kernels it found in its folder to its *own*
    size limit, so any other Taichi program, with the default 100 MiB, would evict the kernels
    that cdnf_ti keeps up to :data:`CACHE_MAX_BYTES` (a cold start costs ~45 s); taichi 1.7 does
    so even in a process that runs with the cache off.

    Parameters
    ----------
    compiler : {"taichi", "quadrants"}

    Returns
    -------
    str
        Absolute path of the folder (created by the compiler on first use).
    """
    env = os.environ.get(CACHE_ENV, "").strip()
    if env:
        return os.path.abspath(os.path.expanduser(env))
    base = os.environ.get("XDG_CACHE_HOME", "").strip() or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(os.path.abspath(base), "cdnf_ti", compiler)


def lanes_override() -> int | None:
    """``$CDNF_TI_LANES`` as lanes per vector of the fast path; ``None`` when unset.

    Raises
    ------
    UserError
        The variable is set to anything but one of :data:`LANE_CHOICES`.
    """
    raw = os.environ.get(LANES_ENV, "").strip()
    if not raw:
        return None
    if raw not in {str(n) for n in LANE_CHOICES}:
        raise UserError(f"${LANES_ENV}={raw!r}: lanes per vector must be one of "
                        f"{', '.join(map(str, LANE_CHOICES))} (unset: the compiler's default)")
    return int(raw)


def _check_compiler(compiler: str) -> None:
    if compiler not in COMPILERS:
        raise UserError(f"unknown compiler {compiler!r}; choose one of {', '.join(COMPILERS)}")
    if importlib.util.find_spec(compiler) is None:
        raise BackendUnavailableError(
            f"kernel compiler {compiler!r} is not installed in this Python; "
            f"installed: {', '.join(installed_compilers()) or 'none'}"
        )


def select_compiler(compiler: str | None) -> None:
    """Name the compiler this process will use (before its runtime starts).

    ``None`` leaves the choice to :func:`default_compiler`. Raises :class:`UserError` if the
    runtime already started with another compiler.
    """
    if compiler is None:
        return
    compiler = compiler.strip().lower()
    _check_compiler(compiler)
    with _lock:
        if _compiler is not None and compiler != _compiler:
            raise UserError(f"this process already runs its kernels with {_compiler!r}; "
                            f"cannot switch to {compiler!r} (start a new process)")
        os.environ[COMPILER_ENV] = compiler


_PROBE = """
import os, sys
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")
os.environ.setdefault("ENABLE_QUADRANTS_HEADER_PRINT", "False")
import importlib
ti = importlib.import_module(sys.argv[1])
# no compile cache (this runtime still trims the compiler's default folder, never cdnf_ti's: cache_folder)
ti.init(arch=getattr(ti, sys.argv[2]), log_level=ti.ERROR, offline_cache=False)
impl = ti.lang.impl
core = getattr(impl, "_ti_core", None) or getattr(impl, "_qd_core")
print("ARCH=" + core.arch_name(impl.current_cfg().arch), flush=True)
"""


def _unavailable(arch: str, why: str = "no driver/device found") -> BackendUnavailableError:
    return BackendUnavailableError(f"Taichi backend {arch!r} is not available on this machine ({why}); "
                                   "use --arch cpu")


def check_arch(arch: str, timeout: float = 120.0) -> str:
    """Check, without touching this process's runtime, that ``arch`` works here.

    ``cpu`` is always available. For a GPU arch a child process initialises the
    process's compiler on it (a few seconds, once per process).

    Returns
    -------
    str
        The backend the arch resolves to (``"cpu"``, ``"cuda"``, ``"vulkan"``, ...).

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
    compiler = _compiler or default_compiler()
    key = (compiler, arch)
    env_key = f"{_ENV_OK}{compiler}_{arch}"
    known = os.environ.get(env_key)  # probed by a parent process (workers inherit the answer)
    if key not in _probed and known:
        _probed[key] = known
    if key not in _probed:
        try:
            proc = subprocess.run([sys.executable, "-c", _PROBE, compiler, arch], capture_output=True, text=True,
                                  timeout=timeout, env={**os.environ, "TI_LOG_LEVEL": "error"})
            got = [ln[5:] for ln in proc.stdout.splitlines() if ln.startswith("ARCH=")]
            _probed[key] = got[0] if proc.returncode == 0 and got and got[0] not in _CPU_NAMES else None
        except (OSError, subprocess.TimeoutExpired):
            _probed[key] = None
    if _probed[key] is None:
        raise _unavailable(arch)
    os.environ[env_key] = _probed[key]  # type: ignore[assignment]
    return _probed[key]  # type: ignore[return-value]


def _arch_name(ti: ModuleType) -> str:
    impl = ti.lang.impl
    core = getattr(impl, "_ti_core", None) or impl._qd_core
    return core.arch_name(impl.current_cfg().arch)


def _host_runtime(name: str) -> tuple[str, ModuleType] | None:
    """The (arch, module) of a runtime of compiler ``name`` that other code already started here, or None."""
    if name not in sys.modules:
        return None
    try:
        ti = sys.modules[name]
        if ti.lang.impl.get_runtime().prog is None:
            return None
        got = _arch_name(ti)
    except Exception:  # noqa: BLE001 - internal API moved: behave as if not initialised
        return None
    return ("cpu" if got in _CPU_NAMES else got), ti


def _one_line_source_positions(module: ModuleType) -> None:
    """Have taichi 1.7's kernel parser note each source position as one line.

    For every statement and expression of every kernel it parses, taichi 1.7 formats the
    source line with a caret hint, wrapped by ``textwrap``, for messages that are almost
    never shown. It parses every kernel even with a warm compile cache (the cache is
    consulted after parsing), so this was 1.5 s of C-DNF's 4.8 s warm start-up on the
    Zen 3 host. The position (``File "...", line N, in kernel:``) stays in compile errors
    and debug messages; only the echoed source line goes. The compile cache's keys do not
    depend on it. quadrants formats positions only when needed and is left as it is.
    """
    if module.__name__ != "taichi":
        return
    try:
        context = importlib.import_module("taichi.lang.ast.ast_transformer_utils").ASTTransformerContext
        context.get_pos_info  # noqa: B018 - the method replaced below must exist
    except (ImportError, AttributeError):  # another taichi version: leave it as it is
        return

    def get_pos_info(self, node) -> str:
        return f'File "{self.file}", line {node.lineno + self.lineno_offset}, in {self.func.func.__name__}:\n'

    context.get_pos_info = get_pos_info


def ensure_taichi(arch: str = "cpu", compiler: str | None = None) -> str:
    """Initialise the kernel compiler once per process on ``arch``; return the arch in use.

    A runtime that the host program already started (``ti.init`` before cdnf_ti was
    used) is adopted as it is, never reset.

    Parameters
    ----------
    arch : {"cpu", "cuda", "vulkan", "gpu"}
        Requested backend. ``cpu`` is the default and always available.
    compiler : {"quadrants", "taichi"} or None
        Kernel compiler; ``None``: the one already running, else :func:`default_compiler`.

    Raises
    ------
    UserError
        Unknown ``arch``/``compiler``, or a different one than this process already runs
        (one runtime per process).
    BackendUnavailableError
        The compiler is not installed, or the GPU backend is not available here.
    """
    global _arch, _compiler, _module, init_seconds
    if arch not in ARCHS:
        raise UserError(f"unknown arch {arch!r}; choose one of {', '.join(ARCHS)}")
    if compiler is not None:
        select_compiler(compiler)
    name = default_compiler()
    with _lock:
        if _arch is None:
            host = _host_runtime(name)
            if host is not None:
                (_arch, _module), _compiler = host, name
        if _arch is not None:
            if arch != _arch and not (arch == "gpu" and _arch not in ("cpu",)):
                raise UserError(
                    f"{_compiler} is already running on {_arch!r} in this process; "
                    f"cannot switch to {arch!r} (start a new process)"
                )
            return _arch
    if arch != "cpu":
        check_arch(arch)  # a missing GPU can crash init; find out in a child process first
    with _lock:
        t0 = time.perf_counter()
        ti = importlib.import_module(name)
        _one_line_source_positions(ti)
        kw = dict(default_fp=ti.f32, default_ip=ti.i32, offline_cache=True, log_level=ti.ERROR,
                  offline_cache_file_path=cache_folder(name), offline_cache_max_size_of_files=CACHE_MAX_BYTES)
        # both print "[Taichi|Quadrants] Starting on arch=..."
        with contextlib.redirect_stdout(io.StringIO()):
            ti.init(arch=getattr(ti, arch), **kw)
        got_name = _arch_name(ti)
        if arch != "cpu" and got_name in _CPU_NAMES:
            # no such device: the compiler fell back to the CPU; say so instead of running slowly
            _arch, _compiler, _module = "cpu", name, ti
            raise _unavailable(arch)
        _arch = "cpu" if got_name in _CPU_NAMES else got_name
        _compiler, _module = name, ti
        init_seconds = time.perf_counter() - t0
        return _arch


def limit_cpu_threads(threads: int) -> None:
    """Give this process's CPU runtime ``threads`` pool threads, under either compiler.

    Sets :data:`THREADS_ENV`, so it must run before the runtime starts (worker processes
    call it first); child processes inherit it.
    """
    for name in THREADS_ENV:
        os.environ[name] = str(max(1, int(threads)))


def dsl() -> ModuleType:
    """The DSL module (``taichi`` or ``quadrants``) of this process's runtime.

    Starts the runtime with the defaults (``cpu``, :func:`default_compiler`) if needed.
    :func:`kernels` hands it to the kernel modules' ``build(ti, lanes)``.
    """
    if _module is None:
        ensure_taichi(_arch or "cpu")
    return _module  # type: ignore[return-value]


_build_lock = threading.RLock()
_built: dict[str, object] = {}
#: Kernel instances compiled (or loaded from the compile cache) in this process: each first launch of
#: a new compile signature (:func:`compiled_as`) and each kernel module built (:func:`kernels`).
_compiles = 0
_count_lock = threading.Lock()


def compile_count() -> int:
    """How many kernels this process has compiled so far (a step during which it grows compiled).

    Counts each first launch of a kernel instance (:func:`compiled_as`: the compiler builds its code
    then, or loads it from the compile cache) and each kernel module built (:func:`kernels`).
    """
    return _compiles


def _count_compile(what: str = "") -> None:
    """Count one compile; announce it (:class:`compiling`) when it is the first of its scope.

    ``what``: the kernel module compiling (``"stimuli"``), named when no scope is active.
    """
    global _compiles
    with _count_lock:
        _compiles += 1
    scope = getattr(_notice_state, "scope", None)
    if scope is not None:
        scope.compiled()
    elif what and _announce(what):  # e.g. "stimuli": the generators of stim: inputs and rain (no duration line)
        _remember(what)


# -- compile notices -------------------------------------------------------------------------------
# A cold compile takes seconds per kernel (tens of seconds under load): every command says so in
# one line before it compiles for a new model or frame size, and how long it took after. A label
# is announced once per code version and compile-cache folder (a marker file in that folder lists
# the labels compiled there), so a run whose kernels come from the cache stays quiet.

#: Environment variable: ``0`` silences the compile notices (``--no-progress``; worker processes inherit it).
NOTICES_ENV = "CDNF_TI_COMPILE_NOTICES"
#: The marker file, in the compile-cache folder, of the labels compiled there (one key a line).
NOTICES_FILE = "cdnf_ti_compiled.txt"
_notice_state = threading.local()
_notice_lock = threading.Lock()
_seen: set[str] | None = None  # keys of the marker file, read once per process
_announced: set[str] = set()  # labels announced by this process


def set_compile_notices(on: bool) -> None:
    """Print the compile notices (default) or not (``--no-progress``), here and in child processes."""
    os.environ[NOTICES_ENV] = "1" if on else "0"


def compile_notices() -> bool:
    """Whether compile notices are printed (:data:`NOTICES_ENV` is not ``0``)."""
    return os.environ.get(NOTICES_ENV, "1").strip() != "0"


def _notice_key(label: str) -> str:
    """``label`` tied to what makes the compiled code: the compiler, its version, the lanes and cdnf_ti's source."""
    from .provenance import compiler_identity, engine_settings, source_digest

    ident = compiler_identity()
    return (f"{ident['compiler']} {ident['compiler_version']} lanes={engine_settings()['lanes']} "
            f"{source_digest()[:16]} {label}")


def _marker() -> str:
    return os.path.join(cache_folder(_compiler or default_compiler()), NOTICES_FILE)


def _announce(label: str) -> bool:
    """Print ``compiling kernels for <label>, first time only; cached in <dir>`` unless notices are off, this
    process announced ``label`` already, or the marker file says the cache holds it. Returns whether it printed."""
    global _seen
    if not compile_notices():
        return False
    with _notice_lock:
        if label in _announced:
            return False
        _announced.add(label)
        key = _notice_key(label)
        if _seen is None:
            try:
                with open(_marker(), encoding="utf-8") as f:
                    _seen = {line.rstrip("\n") for line in f}
            except (OSError, UnicodeDecodeError):
                _seen = set()
        if key in _seen:
            return False
    print(f"compiling kernels for {label}, first time only; cached in {os.path.dirname(_marker())}",
          file=sys.stderr, flush=True)
    return True


def _remember(label: str) -> None:
    """Add ``label`` to the marker file (the kernels it compiled are in the cache from now on)."""
    key = _notice_key(label)
    with _notice_lock:
        if _seen is not None:
            _seen.add(key)
        try:
            os.makedirs(os.path.dirname(_marker()), exist_ok=True)
            with open(_marker(), "a", encoding="utf-8") as f:
                f.write(key + "\n")
        except OSError:  # a read-only cache: the notice shows again next time
            pass


#: Labels announced whose compiles may not be over: label -> [seconds of its compiling steps, quiet steps since].
_pending: dict[str, list[float]] = {}
#: Steps in a row that compile nothing after which a label's compiles count as over (a model compiles on
#: its first steps: C-DNF on frame 0, the LGMD family also on frame 1, oLGMD on frame 2).
QUIET_STEPS = 3


class compiling:
    """Context of one step that may compile kernels for ``label`` (``"cdnf at 432x240"``).

    The first kernel compiled for a label prints ``compiling kernels for <label>, first time only; cached
    in <dir>`` on stderr. Once :data:`QUIET_STEPS` steps of the label in a row compile nothing (or at
    exit), ``compiled kernels for <label> in <s> s`` gives the time of its steps that compiled. Nothing is
    printed when no kernel compiled, the label was compiled into this cache before, or notices are off
    (:func:`set_compile_notices`).
    """

    __slots__ = ("label", "outer", "did_compile", "t0")

    def __init__(self, label: str):
        self.label = label
        self.did_compile = False

    def __enter__(self) -> "compiling":
        self.outer = getattr(_notice_state, "scope", None)
        _notice_state.scope = self
        self.t0 = time.perf_counter()
        return self

    def compiled(self) -> None:
        """A kernel compiled in this scope (the first one of its label may announce it)."""
        if self.did_compile:
            return
        if self.label in _pending or (self.label not in _announced and _announce(self.label)):
            _pending.setdefault(self.label, [0.0, 0])
            self.did_compile = True

    def __exit__(self, *exc) -> bool:
        _notice_state.scope = self.outer
        state = _pending.get(self.label)
        if state is not None:
            if self.did_compile:
                state[0] += time.perf_counter() - self.t0
                state[1] = 0
            else:
                state[1] += 1
                if state[1] >= QUIET_STEPS:
                    _finish(self.label)
        return False


def _finish(label: str) -> None:
    """Print the duration line of ``label`` and mark its kernels as in the cache."""
    seconds, _ = _pending.pop(label)
    print(f"compiled kernels for {label} in {seconds:.1f} s", file=sys.stderr, flush=True)
    _remember(label)


@atexit.register
def _finish_all() -> None:
    """At exit: the duration lines of labels whose every step compiled."""
    for label in list(_pending):
        try:
            _finish(label)
        except (OSError, ValueError):  # stderr closed
            pass


def lanes() -> int:
    """Lanes per vector element of the fast path under this process's compiler (starts the runtime if needed;
    :func:`cdnf_ti.kernels.common.lane_count`)."""
    from .kernels.common import lane_count

    dsl()
    return lane_count(_compiler)  # type: ignore[arg-type]


def kernels(name):
    """The kernels of ``kernels/<name>.py`` (``"cdnf"``, ``"lgmd"``, ``"sdnf"``, ``"stimuli"``, ``"common"``),
    built for this process's compiler and lane count on first use (the module's ``build(ti, lanes)``);
    ``name`` may also be a ``build(ti, lanes)`` function itself (a model defined outside the package), or
    ``"<module>:<function>"``, a build function of a module that holds several models (``"lgmd:lgmd1"``).

    The kernel modules define their kernels in that factory, so importing them loads no compiler; this
    is the one place that builds them, once per process (a second model compiles nothing new).
    Starts the runtime with the defaults if it has not started (:func:`dsl`).
    """
    with _build_lock:
        got = _built.get(name)
        if got is None:
            ti = dsl()
            module, _, function = ("" if callable(name) else name).partition(":")
            build = name if callable(name) else getattr(importlib.import_module(f"{__package__}.kernels.{module}"),
                                                        function or "build")
            _count_compile(name if isinstance(name, str) else getattr(name, "__module__", ""))
            got = _built[name] = build(ti, lanes())
        return got


def current_arch() -> str | None:
    """The arch the runtime was initialised with in this process, or ``None``."""
    return _arch


def current_compiler() -> str | None:
    """The compiler running this process's kernels, or ``None`` before the runtime starts."""
    return _compiler


def caches_launch_arguments() -> bool:
    """Whether the running compiler caches a launch's argument handling by the identity of its array arguments.

    quadrants does (an entry per new array, alive as long as the array): a caller that passes the same
    array every launch hits the cache; one that passes a new array each frame misses it and keeps an
    entry per frame while the frames live. taichi 1.7.4 caches nothing by identity.
    """
    return _compiler == "quadrants"


def cpu_threads() -> int:
    """Threads of the runtime's CPU thread pool (``cpu_max_num_threads``; at least 1)."""
    ti = dsl()
    try:
        n = int(ti.lang.impl.current_cfg().cpu_max_num_threads)
    except (AttributeError, TypeError, ValueError):  # a compiler without this config field
        n = os.cpu_count() or 1
    return max(1, n)


# -- kernels compiled with explicit vector types ------------------------------------------
# Both compilers normally scalarise ``ti.Vector`` values (``real_matrix_scalarize``, on by
# default) and leave it to LLVM's vectorisers to put them back together: taichi 1.7.4 does so
# 128 bits wide on the Zen 5 host (its LLVM 15 does not know the CPU), quadrants 1.3.3 not at
# all (its pipeline leaves the SLP vectoriser off). Compiled with the option off, a vector stays
# an LLVM vector type, which the code generator, which does see the host's AVX-512, lowers to
# full-width registers: C-DNF's lane solves ran 1.8x (taichi) and 2.9-3.7x (quadrants) faster
# per update (docs/PERFORMANCE.md, "Engine A/B and workarounds"). The option is part of the
# runtime's compile configuration,
# read while a kernel compiles (and part of the compile cache's key). Every kernel of cdnf_ti
# compiles through :func:`vector_kernel` or :func:`scalar_kernel`, which set the option the
# kernel needs under one lock and put back the value they found, so two threads compiling
# kernels of either kind at once never see each other's setting.

_compile_lock = threading.RLock()


def vector_kernel(kernel):
    """Compile the ``@ti.kernel`` ``kernel`` with explicit vector types (``real_matrix_scalarize`` off).

    Returns a function that launches ``kernel`` with the same arguments (:func:`compiled_as`).
    The kernel may hold only constructs that both compilers handle on unscalarised vectors:
    no ``Vector.field`` access (use vector ``ndarray`` arguments), no unary minus or
    ``ti.abs`` on a vector and no ``.any()``/``.all()`` (the helpers of
    :mod:`cdnf_ti.kernels.compat` stand in for them).
    """
    return compiled_as(kernel, scalarize=False)


def scalar_kernel(kernel, fast_math: bool = True):
    """Compile the ``@ti.kernel`` ``kernel`` the usual way (``real_matrix_scalarize`` on), whatever
    another thread's :func:`vector_kernel` is compiling at the same moment (:func:`compiled_as`);
    ``fast_math=False``: without the runtime's fast-math (see :func:`compiled_as`)."""
    return compiled_as(kernel, scalarize=True, fast_math=fast_math)


def compiled_as(kernel, scalarize: bool, fast_math: bool = True):
    """A launcher of ``kernel`` that compiles each new instance with ``real_matrix_scalarize = scalarize``.

    The first launch with a new compile signature (the values of its ``ti.template()``
    arguments, the type, dtype and ndim of the array arguments whose annotation leaves those
    open: what makes the compiler build another instance) runs under the process's compile
    lock with the option set as asked, then puts back the value it found: both compilers build
    an instance's code during its first launch (the AST in ``materialize``, the machine code in
    ``launch_kernel``). Every other launch is a plain call.

    Parameters
    ----------
    kernel : a ``@ti.kernel`` function of the running compiler (:func:`dsl`)
    scalarize : bool
        The option's value while the kernel compiles.
    fast_math : bool
        False: compile it with the compile configuration's ``fast_math`` off (also part of the cache's key).
        Both compilers' fast-math lets LLVM reassociate and factor scalar float code (``a x + (1 - a) y``
        becomes ``a (x - y) + y``) but leaves explicit vector code as written, so scalar code that must give
        the bits of a vector kernel compiles without it.

    Returns
    -------
    callable
        ``launch(*args)``, positional arguments as for ``kernel``; ``launch.kernel`` is the
        kernel, ``launch.scalarize`` the mode.
    """
    import functools
    import inspect

    ti = dsl()
    params = list(inspect.signature(kernel).parameters.values())
    template = type(ti.template())
    ndarray = type(ti.types.ndarray())
    templates = tuple(k for k, p in enumerate(params) if isinstance(p.annotation, template))
    # arrays whose annotation leaves the dtype or ndim open (a frame: uint8 or float); the others
    # cannot make another instance
    open_arrays = tuple(k for k, p in enumerate(params) if isinstance(p.annotation, ndarray)
                        and (p.annotation.dtype is None or p.annotation.ndim is None))
    compiled: set[tuple] = set()
    module_name = str(getattr(kernel, "__module__", "") or "").rsplit(".", 1)[-1]

    def signature(args: tuple) -> tuple:
        return (tuple(args[k] if isinstance(args[k], (int, str)) else id(args[k]) for k in templates),
                tuple((type(args[k]), args[k].dtype, len(args[k].shape)) for k in open_arrays))

    @functools.wraps(kernel)
    def launch(*args):
        sig = signature(args)
        if sig in compiled:
            return kernel(*args)
        _count_compile(module_name)
        with _compile_lock:
            cfg = ti.lang.impl.current_cfg()
            before = cfg.real_matrix_scalarize, cfg.fast_math
            cfg.real_matrix_scalarize = scalarize
            cfg.fast_math = before[1] and fast_math
            try:
                out = kernel(*args)
            finally:
                cfg.real_matrix_scalarize, cfg.fast_math = before
            compiled.add(sig)
        return out

    launch.kernel = kernel  # the kernel itself
    launch.scalarize = scalarize
    launch.fast_math = fast_math
    launch.instances = lambda: len(compiled)  # compiled instances so far
    return launch
