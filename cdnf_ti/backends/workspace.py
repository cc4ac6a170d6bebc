"""The lane backends' arrays: each backend's own state, and the scratch of the persistent workers."""
from __future__ import annotations

import threading
from typing import Any

import numpy as np

from ..taichi_runtime import kernels, lanes


class Scratch:
    """The per-launch scratch of the persistent-worker kernels, one set per process.

    The phase counters ``sync`` (int32, :func:`~cdnf_ti.kernels.schedule.sync_size`), the
    per-update residuals ``rbuf`` (float32, (MAX_STEPS, 2)) and a launch's float64 sum and flag
    ``msum``: the scheduler's fields (:func:`cdnf_ti.kernels.schedule.build`), one set per
    process, so a second model compiles nothing new. ``lock`` serialises the launches that use them
    (:meth:`Model.step <cdnf_ti.models.base.Model.step>` holds it around each frame).
    """

    _one: Scratch | None = None
    _make = threading.Lock()

    def __init__(self):
        sched = kernels("schedule")
        self.sync, self.rbuf, self.msum = sched.sync, sched.rbuf, sched.msum
        self.lock = threading.RLock()

    @classmethod
    def get(cls) -> Scratch:
        """The process's scratch, made on first use."""
        with cls._make:
            if cls._one is None:
                cls._one = cls()
            return cls._one


class LaneState:
    """A lane backend's own arrays for frames of ``shape`` (subclasses allocate them), with the
    process's :class:`Scratch` (``sync``, ``rbuf``, ``msum``, ``lock``)."""

    def __init__(self, shape: tuple[int, int]):
        self.shape = tuple(shape)
        scratch = Scratch.get()
        self.sync, self.rbuf, self.msum, self.lock = scratch.sync, scratch.rbuf, scratch.msum, scratch.lock

    def frame(self, x: np.ndarray) -> Any:
        """The (H, W) frame columns of a lane field's ``to_numpy()`` array (H, NB, LANES)."""
        LANES = lanes()
        H, W = self.shape
        return np.ascontiguousarray(x.reshape(H, -1)[:, LANES:LANES + W])
