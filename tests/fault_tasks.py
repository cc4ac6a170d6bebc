"""Task functions for the fault tests (top level, so spawned worker processes can import them)."""
from __future__ import annotations

import os
import time
from pathlib import Path


def sleep_then_pid(seconds: float) -> int:
    """Sleep ``seconds``, return the worker's pid."""
    time.sleep(seconds)
    return os.getpid()


def die_on(task: str) -> str:
    """``"die"`` kills its worker process (as the OOM killer would); anything else returns itself."""
    if task == "die":
        os._exit(9)
    time.sleep(0.1)
    return task


def die_first_time(marker: str | None) -> str:
    """Kill the worker the first time (leaving ``marker``); succeed when run again. None: just succeed."""
    if marker is None:
        time.sleep(0.1)
        return "ok"
    p = Path(marker)
    if not p.exists():
        p.write_text("died once")
        os._exit(9)
    return "ok"


#: How long a slow task sleeps (s): far longer than any wait of the tests, so a child that stops at all
#: was not waiting for one, however loaded the machine is.
SLOW_TASK_S = 3600.0


def main_map_slow(n_slow: int = 6) -> None:
    """Script body: one quick task then slow ones (``SLOW_TASK_S``) over 2 local workers; prints each result."""
    from cdnf_ti.experiments.parallel import exit_on_second_interrupt, map_tasks

    exit_on_second_interrupt(True)  # as the command line does
    try:
        for i, r in map_tasks(sleep_then_pid, [0.05] + [SLOW_TASK_S] * n_slow, workers=2, arch=None):
            print("done", i, r, flush=True)
    except KeyboardInterrupt:
        from cdnf_ti.experiments.parallel import stop_all_pools

        stop_all_pools()  # as the command line does
        print("interrupted", flush=True)
        os._exit(130)  # as the command line does


def hold_the_interpreter() -> None:
    """Never return, in native code that holds the interpreter and ignores signals, as a long kernel
    compile does: lock a plain pthread mutex twice from one thread (``ctypes.PyDLL`` keeps the GIL)."""
    import ctypes

    libc = ctypes.PyDLL(None)
    mutex = ctypes.create_string_buffer(64)  # zeroed: PTHREAD_MUTEX_INITIALIZER, a normal mutex
    libc.pthread_mutex_lock(mutex)
    libc.pthread_mutex_lock(mutex)


def main_run_with_native_stall() -> None:
    """Script body: ``python -m cdnf_ti.run`` with the arguments given, where the models' pass over an
    input named ``stall`` first holds the interpreter for good (:func:`hold_the_interpreter`); prints
    ``stalling`` just before."""
    import sys

    from cdnf_ti import run

    real = run.run_models

    def stalling(models, frames, **kw):
        if "stall" in str(kw.get("progress")):
            print("stalling", flush=True)
            hold_the_interpreter()
        return real(models, frames, **kw)

    run.run_models = stalling
    sys.exit(run.main())
