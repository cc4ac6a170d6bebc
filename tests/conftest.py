"""Shared fixtures: one Taichi runtime per test session, small stimuli, shared data."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# Under pytest-xdist (`-n auto`: one worker process per core) each worker gets cores / workers
# pool threads, so the workers' kernels do not oversubscribe the cores (the project's own
# parallel runners do the same). Set before any runtime starts; an explicit setting wins.
if os.environ.get("PYTEST_XDIST_WORKER_COUNT"):
    from cdnf_ti.experiments.parallel import taichi_threads_per_worker
    from cdnf_ti.taichi_runtime import THREADS_ENV, limit_cpu_threads

    if not any(os.environ.get(name) for name in THREADS_ENV):
        limit_cpu_threads(taichi_threads_per_worker(int(os.environ["PYTEST_XDIST_WORKER_COUNT"])))

# the shared material next to the repository, or where $CDNF_TI_SHARED points
SHARED_REAL = Path(os.environ.get("CDNF_TI_SHARED", REPO.parent / "shared")) / "data" / "real"


@pytest.fixture(scope="session", autouse=True)
def taichi_runtime():
    """Initialise the kernel compiler ($CDNF_TI_COMPILER, else the fastest) on the CPU once per session."""
    from cdnf_ti.taichi_runtime import ensure_taichi

    return ensure_taichi("cpu")


@pytest.fixture(scope="session")
def shared_real() -> Path | None:
    """The development dashcam clips folder ($CDNF_TI_SHARED/data/real), or None when absent."""
    return SHARED_REAL if (SHARED_REAL / "labels.csv").exists() else None


def small_stimulus(name: str, size: int = 96, **kw):
    """A basic stimulus scaled down for fast tests (same geometry as 600x600)."""
    from cdnf_ti.stimuli.basic import basic_stimulus

    return basic_stimulus(name, height=size, width=size, **kw)
