"""Running independent tasks: in this process, over local processes, or on a Dask cluster.

Every task function is a plain top-level function of one picklable argument
that returns a picklable result, so the same tasks run unchanged wherever they
go and give the same results. Worker processes are started with the ``spawn``
method (never ``fork`` after Taichi is initialised) and initialise Taichi
themselves (:func:`init_worker`).
"""
from __future__ import annotations

import multiprocessing as mp
import os
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any, Callable, Iterator, Sequence


class TaskFailed(Exception):
    """A task raised instead of returning (its worker died or a bug); carries a one-line message."""


def default_workers(n_tasks: int) -> int:
    """Local worker processes used by default: one per CPU core, at most one per task."""
    return max(1, min(os.cpu_count() or 1, n_tasks))


def taichi_threads_per_worker(workers: int) -> int:
    """Taichi CPU threads per worker so that workers x threads ~ CPU cores."""
    return max(1, (os.cpu_count() or 1) // max(1, workers))


def init_worker(arch: str = "cpu", threads: int | None = None) -> None:
    """Initialise Taichi in a worker process (no-op if already done).

    Parameters
    ----------
    arch : str
        Taichi architecture.
    threads : int, optional
        Taichi CPU thread-pool size for this process (``TI_CPU_MAX_NUM_THREADS``);
        None leaves Taichi's default (all cores).
    """
    from ..taichi_runtime import current_arch, ensure_taichi

    if current_arch() is None and threads:
        os.environ["TI_CPU_MAX_NUM_THREADS"] = str(int(threads))
    ensure_taichi(arch)


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0] if text else ''}".rstrip(": ")


def map_tasks(fn: Callable[[Any], Any], tasks: Sequence[Any], *, workers: int | None = None,
              scheduler: str | Any | None = None, arch: str = "cpu",
              progress: bool | str = False, connect_timeout: float = 20.0) -> Iterator[tuple[int, Any]]:
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
    arch : str
        Taichi architecture the workers initialise.
    progress : bool or str
        Show a tqdm bar over tasks (a string is its label).
    connect_timeout : float
        Seconds to wait for the Dask scheduler.

    Yields
    ------
    (int, object)
        The task's index in ``tasks`` and ``fn``'s result, or a
        :class:`TaskFailed` instance if the task raised.
    """
    from tqdm import tqdm

    n = len(tasks)
    bar = tqdm(total=n, desc=progress if isinstance(progress, str) else "clips", unit="task",
               disable=None if progress else True)
    try:
        if n == 0:
            return
        if scheduler is not None:
            yield from _dask(fn, tasks, scheduler, arch, bar, connect_timeout)
            return
        w = default_workers(n) if workers is None else max(0, int(workers))
        if w <= 1:
            init_worker(arch)
            for i, t in enumerate(tasks):
                try:
                    res = fn(t)
                except Exception as e:  # noqa: BLE001 - one failed task must not stop the run
                    res = TaskFailed(_one_line(e))
                bar.update(1)
                yield i, res
            return
        yield from _local(fn, tasks, min(w, n), arch, bar)
    finally:
        bar.close()


def _local(fn, tasks, workers, arch, bar) -> Iterator[tuple[int, Any]]:
    ctx = mp.get_context("spawn")
    threads = taichi_threads_per_worker(workers)
    ex = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=init_worker,
                             initargs=(arch, threads))
    try:
        pending = {ex.submit(fn, t): i for i, t in enumerate(tasks)}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in sorted(done, key=lambda f: pending[f]):
                i = pending.pop(fut)
                try:
                    res = fut.result()
                except Exception as e:  # noqa: BLE001 - a crashed worker becomes an error row
                    res = TaskFailed(_one_line(e))
                bar.update(1)
                yield i, res
    except BaseException:
        ex.shutdown(wait=False, cancel_futures=True)
        raise
    else:
        ex.shutdown(wait=True)


def _dask_task(fn, task, arch):
    init_worker(arch)
    return fn(task)


def _dask(fn, tasks, scheduler, arch, bar, connect_timeout=20.0) -> Iterator[tuple[int, Any]]:
    try:
        from distributed import Client, as_completed
    except ImportError as e:  # pragma: no cover - dask[distributed] is a dependency
        raise ValueError("--scheduler needs dask.distributed (pip install 'dask[distributed]')") from e
    own = not isinstance(scheduler, Client)
    try:
        client = Client(scheduler, timeout=f"{connect_timeout}s") if own else scheduler
    except OSError as e:
        raise ValueError(f"cannot connect to the Dask scheduler at {scheduler}: {_one_line(e)}") from None
    futures: dict = {}
    try:
        futures = {client.submit(_dask_task, fn, t, arch, pure=False): i for i, t in enumerate(tasks)}
        for fut in as_completed(list(futures)):
            i = futures[fut]
            try:
                res = fut.result()
            except Exception as e:  # noqa: BLE001
                res = TaskFailed(_one_line(e))
            bar.update(1)
            yield i, res
    except BaseException:
        if own:
            for f in futures:
                f.cancel()
        raise
    finally:
        if own:
            client.close()
