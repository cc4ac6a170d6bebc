"""Running independent tasks: in this process, over local processes, or on a Dask cluster.

Every task function is a plain top-level function of one picklable argument
that returns a picklable result, so the same tasks run unchanged wherever they
go and give the same results. Worker processes are started with the ``spawn``
method (never ``fork`` after Taichi is initialised) and initialise Taichi
themselves (:func:`init_worker`).
"""
from __future__ import annotations

import contextlib
import ctypes
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Iterator, Sequence

from tqdm import tqdm

from ..atomic import remove_stale_temps
from ..errors import UserError
from ..taichi_runtime import current_arch, ensure_taichi, limit_cpu_threads


class TaskFailed(Exception):
    """A task raised instead of returning (its worker died or a bug); carries a one-line message."""


def default_workers(n_tasks: int) -> int:
    """Local worker processes used by default: one per CPU core, at most one per task."""
    return max(1, min(os.cpu_count() or 1, n_tasks))


def taichi_threads_per_worker(workers: int) -> int:
    """Taichi CPU threads per worker so that workers x threads ~ CPU cores."""
    return max(1, (os.cpu_count() or 1) // max(1, workers))


def init_worker(arch: str | None = "cpu", threads: int | None = None) -> None:
    """Initialise Taichi in a worker process (no-op if already done).

    Parameters
    ----------
    arch : str or None
        Taichi architecture; None: the tasks do not use Taichi (nothing to initialise).
    threads : int, optional
        CPU thread-pool size for this process (:func:`~cdnf_ti.taichi_runtime.limit_cpu_threads`,
        for either compiler); None leaves the compiler's default (all cores).
    """
    if current_arch() is None and threads:
        limit_cpu_threads(threads)
    if arch is not None:
        ensure_taichi(arch)


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0] if text else ''}".rstrip(": ")


def map_tasks(fn: Callable[[Any], Any], tasks: Sequence[Any], *, workers: int | None = None,
              scheduler: str | Any | None = None, arch: str | None = "cpu",
              progress: bool | str = False, connect_timeout: float = 20.0,
              describe: Callable[[Any, Any], str] | None = None,
              retries: int = 1) -> Iterator[tuple[int, Any]]:
    """Run ``fn(task)`` for every task and yield ``(index, result)`` as each finishes.

    Parameters
    ----------
    fn : callable
        Top-level (picklable) function of one task.
    tasks : sequence
        Picklable task descriptions.
    workers : int, optional
        Local processes; None = :func:`default_workers`; 0 or 1 = run in this
        process, one task after another. Ignored with ``scheduler``.
    scheduler : str or distributed.Client, optional
        Address of a Dask distributed scheduler (``tcp://host:8786``) or a
        connected ``Client``: tasks are submitted to that cluster.
    arch : str or None
        Taichi architecture the workers initialise (None: the tasks do not use Taichi).
    progress : bool or str
        Report progress on stderr (a string names the tasks). In a terminal: a
        tqdm bar naming the latest task; elsewhere (logs, pipes): one line per
        finished task and a final summary line. Failed tasks are reported in
        both cases.
    connect_timeout : float
        Seconds to wait for the Dask scheduler.
    describe : callable, optional
        ``describe(task, result)`` -> one line naming the task and its outcome
        (e.g. ``"clip3 [cdnf, rain]: 2.1 s"``); ``result`` is None for a task
        about to start. Default: the task's index.
    retries : int
        Local processes only: how many times a task whose worker process died
        (killed, out of memory, crashed) is run again, alone, in a fresh worker
        before it is recorded as failed.

    Yields
    ------
    (int, object)
        The task's index in ``tasks`` and ``fn``'s result, or a
        :class:`TaskFailed` instance if the task raised or its worker died.

    Notes
    -----
    Ctrl-C (SIGINT) stops the run: tasks not started are cancelled, running
    local workers are stopped, finished results have already been yielded and
    ``KeyboardInterrupt`` is raised within a second or two; a second Ctrl-C
    during that clean-up ends the process at once (exit code 130). Local
    workers ignore SIGINT themselves and die with their parent process.
    """
    n = len(tasks)
    rep = _Reporter(n, progress, describe, tasks)
    try:
        if n == 0:
            return
        source_is_parallel = True
        if scheduler is not None:
            source = _dask(fn, tasks, scheduler, arch, rep, connect_timeout)
        else:
            w = default_workers(n) if workers is None else max(0, int(workers))
            if w <= 1:
                source_is_parallel = False
                source = _serial(fn, tasks, arch, rep)
            else:
                source = _local(fn, tasks, min(w, n), arch, rep, retries)
        with _interruptible() if source_is_parallel else contextlib.nullcontext():
            for i, res in source:
                rep.finished(i, res)
                yield i, res
        rep.summary()
    finally:
        rep.close()


class _Reporter:
    """Progress and failures, the same in a terminal (tqdm bar) and in a log (one line per task)."""

    def __init__(self, n: int, progress: bool | str, describe, tasks) -> None:
        self.n, self.done, self.failed = n, 0, 0
        self.tasks, self.describe = tasks, describe
        self.enabled = bool(progress)
        self.label = progress if isinstance(progress, str) else "tasks"
        self.t0 = time.perf_counter()
        self.started: dict[int, float] = {}
        self.tty = self.enabled and _isatty(sys.stderr)
        self.bar = None
        if self.tty and n:
            self.bar = tqdm(total=n, desc=self.label, unit="task", file=sys.stderr)

    def _text(self, i: int, res: Any) -> str:
        if self.describe is not None:
            try:
                return self.describe(self.tasks[i], res)
            except Exception:  # noqa: BLE001 - a report must not break the run
                pass
        text = _task_name(self.tasks[i]) or f"task {i + 1}"
        if res is not None and i in self.started:
            text += f": {time.perf_counter() - self.started[i]:.1f} s"
        return text

    def starting(self, i: int) -> None:
        self.started[i] = time.perf_counter()
        if self.bar is not None:
            self.bar.set_postfix_str(self._text(i, None), refresh=True)

    def finished(self, i: int, res: Any) -> None:
        self.done += 1
        # a task that returned error records (a clip that could not be read) failed too, so this count
        # agrees with the error rows the command reports afterwards
        failed = isinstance(res, TaskFailed) or (isinstance(res, list) and any(
            isinstance(r, dict) and r.get("error") for r in res))
        self.failed += failed
        if not self.enabled:
            return
        line = f"[{self.done}/{self.n}] {self._text(i, res)}"
        if isinstance(res, TaskFailed) and self.describe is None:
            line += f": error: {res}"
        if self.bar is not None:
            if failed:
                self.bar.write(line, file=sys.stderr)
            self.bar.set_postfix_str(self._text(i, res)[:60], refresh=False)
            self.bar.update(1)
        else:
            print(line, file=sys.stderr, flush=True)

    def summary(self) -> None:
        if self.enabled and self.n:
            line = (f"{self.label}: {self.done} of {self.n} tasks finished, {self.failed} failed, "
                    f"{time.perf_counter() - self.t0:.1f} s")
            if self.bar is not None:
                self.bar.close()
                self.bar = None
            print(line, file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


#: Task attributes named in progress lines, in this order.
_NAME_FIELDS = ("clip", "stimulus", "model", "models", "condition", "coherence")


def _task_name(task: Any) -> str:
    """``"dark_looming [cdnf, clean]"`` from a task's clip/stimulus/model/condition attributes ('' if none)."""
    vals = []
    for f in _NAME_FIELDS:
        v = getattr(task, f, None)
        if v is None:
            continue
        if isinstance(v, (tuple, list)):
            v = ", ".join(map(str, v))
        vals.append(f"c={v:g}" if f == "coherence" and isinstance(v, float) else str(v))
    if not vals:
        return ""
    return vals[0] + (f" [{', '.join(vals[1:])}]" if len(vals) > 1 else "")


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def _serial(fn, tasks, arch, rep) -> Iterator[tuple[int, Any]]:
    init_worker(arch)
    for i, t in enumerate(tasks):
        rep.starting(i)
        try:
            res = fn(t)
        except Exception as e:  # noqa: BLE001 - one failed task must not stop the run
            res = TaskFailed(_one_line(e))
        yield i, res


def _init_local_worker(arch: str, threads: int, parent_pid: int) -> None:
    """Initializer of a local worker process: ignore Ctrl-C (the parent handles it), die with the
    parent, initialise Taichi."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent_pid)
    init_worker(arch, threads)


def die_with_parent(parent_pid: int, poll_s: float = 1.0) -> None:
    """Make this process end when process ``parent_pid`` ends, however it ends (even ``kill -9``).

    On Linux the kernel sends SIGKILL (``prctl(PR_SET_PDEATHSIG)``); everywhere a
    daemon thread also polls the parent pid every ``poll_s`` seconds.
    """
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):  # pragma: no cover - no libc prctl
            pass
    if os.getppid() != parent_pid:  # the parent died before we got here
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(poll_s)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="cdnf_ti-parent-watchdog", daemon=True).start()


#: Seconds a Ctrl-C or SIGTERM may wait for Python to take it before :func:`watch_interrupts` ends the process.
INTERRUPT_GRACE_S = 1.5

#: The watchdog process's code (:func:`watch_interrupts`); it runs with ``python -S`` and imports only built-ins.
_WATCHDOG = r"""
import os, select, signal, sys, time
# a terminal's Ctrl-C, and a SIGTERM sent to the process group (`timeout`, a job scheduler), reach this
# process too: it outlives them, to end the program if that is held, and ends when the program does
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, signal.SIG_IGN)
sig_fd, ack_fd, parent, grace = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
while True:
    got = os.read(sig_fd, 64)
    if not got:
        os._exit(0)  # the program has ended
    if not set(got) & {signal.SIGINT, signal.SIGTERM}:
        continue
    deadline = time.monotonic() + grace
    while time.monotonic() < deadline:
        ready = select.select([ack_fd, sig_fd], [], [], max(0.0, deadline - time.monotonic()))[0]
        if ack_fd in ready:
            os.read(ack_fd, 64)
            break
        if sig_fd in ready and not os.read(sig_fd, 64):
            os._exit(0)
    else:
        os.write(2, b"interrupted while native code (a kernel compile) holds the interpreter: exiting now; "
                    b"finished results are saved, run the same command again to resume\n")
        os.kill(parent, signal.SIGKILL)
        os._exit(0)
"""

#: Write end of the pipe on which Python-level signal handlers tell the watchdog they ran (None: no watchdog).
_ACK_FD: int | None = None
#: The watchdog process (kept referenced: it runs as long as the program).
_WATCHDOG_PROCESS: Any = None


def acknowledge_signal() -> None:
    """Tell the watchdog of :func:`watch_interrupts` that Python took the signal (every handler calls it first)."""
    if _ACK_FD is not None:
        with contextlib.suppress(OSError):
            os.write(_ACK_FD, b"\x01")


def watch_interrupts(grace_s: float = INTERRUPT_GRACE_S) -> bool:
    """For command-line programs: a Ctrl-C or SIGTERM ends the process within ``grace_s`` s even while
    native code holds the interpreter.

    Python runs a signal handler only between two bytecodes, so during a kernel compile (native code,
    interpreter held, up to minutes on a loaded machine) Ctrl-C did nothing. CPython's C-level handler
    still writes the signal's number to the wake-up file (:func:`signal.set_wakeup_fd`) at once; here
    that is a pipe read by a small watchdog process. Each Python-level handler first calls
    :func:`acknowledge_signal`; a SIGINT or SIGTERM not acknowledged within ``grace_s`` seconds means the
    interpreter is held, and the watchdog says so on stderr and kills the program (SIGKILL, exit status
    137). Nothing finished is lost: every result is written atomically, and the temporary file and
    output lock a killed run leaves are removed by the next run. The watchdog ends with the program.

    Returns
    -------
    bool
        Whether the watchdog runs: POSIX, the main thread, no wake-up file set by a host program.
    """
    global _ACK_FD, _WATCHDOG_PROCESS
    if _ACK_FD is not None:
        return True
    if os.name != "posix" or threading.current_thread() is not threading.main_thread():
        return False

    sig_r, sig_w = os.pipe()
    ack_r, ack_w = os.pipe()
    os.set_blocking(sig_w, False)
    host = signal.set_wakeup_fd(sig_w, warn_on_full_buffer=False)
    try:
        if host != -1:
            raise OSError("a host program has its own wake-up file")
        _WATCHDOG_PROCESS = subprocess.Popen(
            [sys.executable, "-S", "-c", _WATCHDOG, str(sig_r), str(ack_r), str(os.getpid()), str(grace_s)],
            pass_fds=(sig_r, ack_r), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
    except OSError:
        signal.set_wakeup_fd(host)  # the host's own again (or none)
        for fd in (sig_r, sig_w, ack_r, ack_w):
            os.close(fd)
        return False
    os.close(sig_r)
    os.close(ack_r)
    _ACK_FD = ack_w
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _interrupt)
    return True


#: While a worker process is being started (:func:`_interrupts_deferred`): the signals that came meanwhile.
_DEFERRED: list[int] | None = None


@contextlib.contextmanager
def _interrupts_deferred() -> Iterator[None]:
    """Hold a first Ctrl-C or SIGTERM until the block ends, then raise it (KeyboardInterrupt).

    ``ProcessPoolExecutor.submit`` may start a worker: ``spawn`` launches the child, then writes it its
    start-up data through a pipe, and only then lists it among the pool's processes. An interrupt that
    landed in between left a child the pool did not know of, and that child, reading an unfinished
    pipe, printed multiprocessing's "Ran out of input" traceback. Held until ``submit`` returns, the
    interrupt finds every started worker listed, and :func:`_stop_pool` stops it. A second signal
    still ends the process at once.
    """
    global _DEFERRED
    if _DEFERRED is not None or threading.current_thread() is not threading.main_thread():
        yield
        return
    _DEFERRED = []
    try:
        yield
    finally:
        pending, _DEFERRED = _DEFERRED, None
        if pending:
            raise KeyboardInterrupt


def _raise_interrupt(signum: int) -> None:
    """A Python signal handler's last step: KeyboardInterrupt now, or at the end of :func:`_interrupts_deferred`."""
    if _DEFERRED is not None:
        _DEFERRED.append(signum)
        return
    raise KeyboardInterrupt


def _interrupt(signum, frame) -> None:
    """Ctrl-C under :func:`watch_interrupts`: Python's own behaviour (KeyboardInterrupt), acknowledged."""
    acknowledge_signal()
    _raise_interrupt(signum)


def _terminate(signum, frame) -> None:
    """SIGTERM under :func:`handle_sigterm_as_interrupt`: the same as a first Ctrl-C (KeyboardInterrupt: the
    run stops its workers, removes its temporary files and lock, and says so); a second SIGTERM or Ctrl-C
    during that clean-up ends the process at once."""
    acknowledge_signal()
    signal.signal(signal.SIGTERM, _exit_now)
    if _EXIT_ON_SECOND_INTERRUPT:
        signal.signal(signal.SIGINT, _exit_now)
    _raise_interrupt(signum)


def handle_sigterm_as_interrupt() -> bool:
    """For command-line programs: SIGTERM (``kill``, a job scheduler's stop) is handled like a first Ctrl-C
    instead of ending the process on the spot, which left temporary files, the output lock and the worker
    pool's semaphores behind. Returns whether it is installed (the main thread, SIGTERM not handled by a host)."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGTERM) not in (signal.SIG_DFL, _terminate):
        return False
    signal.signal(signal.SIGTERM, _terminate)
    return True


@contextlib.contextmanager
def cleaned_up(out: str | os.PathLike) -> Iterator[None]:
    """A batch run writing under ``out``: first remove the temporary files of writers that died (a run
    killed mid-write), and on Ctrl-C or SIGTERM stop the workers at once and remove the temporary files
    they leave (every finished result is kept: it was written atomically)."""
    remove_stale_temps(out)
    try:
        yield
    except KeyboardInterrupt:
        stop_all_pools()
        remove_stale_temps(out)
        raise


def _exit_now(signum, frame) -> None:
    """Second Ctrl-C during clean-up: end the process at once."""
    acknowledge_signal()
    try:
        sys.stderr.write("interrupted again: exiting now\n")
        sys.stderr.flush()
    finally:
        os._exit(130)


def _first_interrupt(signum, frame) -> None:
    """First Ctrl-C: arm :func:`_exit_now` for a second one, then stop the run (KeyboardInterrupt)."""
    acknowledge_signal()
    signal.signal(signal.SIGINT, _exit_now)
    _raise_interrupt(signum)


#: Set by the command line (:func:`cdnf_ti.run.main`): after a first Ctrl-C the process is on its way
#: out, so a second one ends it at once even after the parallel section. A library host (a notebook)
#: keeps its own Ctrl-C handling once :func:`map_tasks` returns.
_EXIT_ON_SECOND_INTERRUPT = False


def exit_on_second_interrupt(on: bool = True) -> None:
    """For command-line programs: after a Ctrl-C that stopped :func:`map_tasks`, a second one exits at once."""
    global _EXIT_ON_SECOND_INTERRUPT
    _EXIT_ON_SECOND_INTERRUPT = bool(on)


@contextlib.contextmanager
def _interruptible() -> Iterator[None]:
    """While running parallel tasks: Ctrl-C raises KeyboardInterrupt once; a second Ctrl-C during the
    clean-up that follows ends the process at once (exit code 130). Only in the main thread, and only
    when Python's default Ctrl-C handling is in place (a host program's own handler is left alone)."""
    main = threading.current_thread() is threading.main_thread()
    old = signal.getsignal(signal.SIGINT) if main else None
    if old is not signal.default_int_handler and old is not _interrupt:
        yield
        return
    signal.signal(signal.SIGINT, _first_interrupt)
    try:
        yield
    finally:
        interrupted = signal.getsignal(signal.SIGINT) is _exit_now
        if not (interrupted and _EXIT_ON_SECOND_INTERRUPT) and \
                threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, old)


#: Local pools in use, so that :func:`stop_all_pools` can stop them when Ctrl-C lands outside map_tasks.
_LIVE_POOLS: set = set()


def stop_all_pools() -> None:
    """Stop every local worker pool of this process now (cancel queued tasks, kill the workers).

    The command line calls this on Ctrl-C, so that a pool whose consumer was
    interrupted is not waited for at interpreter exit.
    """
    for ex in list(_LIVE_POOLS):
        _stop_pool(ex)


def _stop_pool(ex: ProcessPoolExecutor | None) -> None:
    """Cancel queued tasks and stop the workers now (no waiting for running tasks)."""
    if ex is None:
        return
    _LIVE_POOLS.discard(ex)
    procs = list((getattr(ex, "_processes", None) or {}).values())
    ex.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        with contextlib.suppress(Exception):
            p.kill()
    for p in procs:
        with contextlib.suppress(Exception):
            p.join(timeout=2)


def _local(fn, tasks, workers, arch, rep, retries=1) -> Iterator[tuple[int, Any]]:
    """Local worker processes; at most ``workers`` tasks in flight, so that little is left to
    cancel on Ctrl-C and the task that killed a worker can be told apart and retried."""
    ctx = mp.get_context("spawn")
    threads = taichi_threads_per_worker(workers)
    todo: deque[int] = deque(range(len(tasks)))
    retry: deque[int] = deque()  # suspects of a worker death: re-run one at a time
    deaths = [0] * len(tasks)
    ex: ProcessPoolExecutor | None = None
    inflight: dict = {}
    try:
        while todo or retry or inflight:
            if ex is None:
                ex = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_local_worker,
                                         initargs=(arch, threads, os.getpid()))
                _LIVE_POOLS.add(ex)
            if retry:
                if not inflight:
                    i = retry.popleft()
                    rep.starting(i)
                    with _interrupts_deferred():  # submit may start a worker
                        inflight[ex.submit(fn, tasks[i])] = i
            else:
                while todo and len(inflight) < workers:
                    i = todo.popleft()
                    rep.starting(i)
                    with _interrupts_deferred():
                        inflight[ex.submit(fn, tasks[i])] = i
            done, _ = wait(inflight, return_when=FIRST_COMPLETED)
            if any(isinstance(f.exception(), BrokenProcessPool) for f in done):
                # a worker died: every task in flight fails with it; collect them all
                done, _ = wait(inflight, timeout=30)
                done = set(done) | set(inflight)
                _stop_pool(ex)
                ex = None
            # A death counts against a task only when it ran alone: tasks in flight beside the one
            # that killed the worker are suspects, re-run one at a time without a mark.
            alone = len(inflight) == 1
            for fut in sorted(done, key=lambda f: inflight[f]):
                i = inflight.pop(fut)
                exc = fut.exception() if fut.done() else BrokenProcessPool("worker did not answer")
                if exc is None:
                    yield i, fut.result()
                elif isinstance(exc, BrokenProcessPool):
                    deaths[i] += alone
                    if deaths[i] <= retries:
                        retry.append(i)
                    else:
                        yield i, TaskFailed(f"its worker process died (killed, out of memory or crashed) "
                                            f"{deaths[i]} times")
                else:
                    yield i, TaskFailed(_one_line(exc))
    except BaseException:
        _stop_pool(ex)
        raise
    else:
        if ex is not None:
            _LIVE_POOLS.discard(ex)
            ex.shutdown(wait=True)


def _dask_task(fn, task, arch):
    init_worker(arch)
    return fn(task)


def _dask(fn, tasks, scheduler, arch, rep, connect_timeout=20.0) -> Iterator[tuple[int, Any]]:
    try:
        # lazy: heavy dependency, needed only with --scheduler
        from distributed import Client, as_completed
    except ImportError as e:  # pragma: no cover - dask[distributed] is a dependency
        raise UserError("--scheduler needs dask.distributed (pip install 'dask[distributed]')") from e
    own = not isinstance(scheduler, Client)
    try:
        client = Client(scheduler, timeout=f"{connect_timeout}s") if own else scheduler
    except (OSError, ValueError, TypeError) as e:  # unreachable, or not an address (distributed: ValueError)
        raise UserError(f"cannot connect to the Dask scheduler at {scheduler}: {_one_line(e)}") from None
    futures: dict = {}
    try:
        futures = {client.submit(_dask_task, fn, t, arch, pure=False): i for i, t in enumerate(tasks)}
        for fut in as_completed(list(futures)):
            i = futures[fut]
            try:
                res = fut.result()
            except Exception as e:  # noqa: BLE001
                res = TaskFailed(_one_line(e))
            yield i, res
    except BaseException:
        for f in futures:
            f.cancel()
        raise
    finally:
        if own:
            client.close()
