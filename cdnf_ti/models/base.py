"""The interface every looming model implements: parameters, step, run, reset, fields."""
from __future__ import annotations

import csv
import io
import time
import warnings
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar, Iterable

import numpy as np

from ..atomic import atomic_write_text


class NotConvergedWarning(RuntimeWarning):
    """A per-frame fixed point did not reach its tolerance within ``max_iter``."""


@dataclass
class StepResult:
    """Output of one model step (one frame).

    Attributes
    ----------
    t : int
        Frame index (0-based) within the current run.
    output : float
        The model's continuous output (C-DNF: ``I_v``; LGMD family: ``K``).
    spike : bool
        Collision alert on this frame.
    converged : bool
        Every iterative solve of this frame reached its tolerance (always True
        for models without per-frame iteration).
    diagnostics : dict of str to float
        Model-specific per-frame values (iterations, residuals, ...).
    """

    t: int
    output: float
    spike: bool
    converged: bool = True
    diagnostics: dict[str, float] = field(default_factory=dict)


@dataclass
class Trace:
    """Per-frame results of a model over a frame stream (arrays over frames).

    Attributes
    ----------
    model : str
        Registry name of the model.
    output_name : str
        Name of the continuous output (``"I_v"`` for C-DNF).
    threshold : float or None
        The alert threshold on ``output`` when the model has one (for plots).
    output, spike, converged : ndarray, shape (T,)
    diagnostics : dict of str to ndarray, shape (T,)
    seconds : float
        Wall time spent in the model's steps (s), excluding frame decoding and
        the first frame (which allocates the model's state and compiles kernels).
    """

    model: str
    output_name: str
    threshold: float | None
    output: np.ndarray
    spike: np.ndarray
    converged: np.ndarray
    diagnostics: dict[str, np.ndarray]
    seconds: float = 0.0

    @property
    def n_frames(self) -> int:
        return int(self.output.shape[0])

    @property
    def first_alert(self) -> int | None:
        """Index of the first frame with a spike, or ``None``."""
        idx = np.flatnonzero(self.spike)
        return int(idx[0]) if idx.size else None

    @property
    def fps(self) -> float:
        """Model throughput in frames per second (frames after the first / ``seconds``)."""
        return (self.n_frames - 1) / self.seconds if self.seconds > 0 and self.n_frames > 1 else float("nan")

    @classmethod
    def from_steps(cls, model: "Model", steps: list[StepResult], seconds: float) -> "Trace":
        keys: list[str] = []
        for s in steps:
            for k in s.diagnostics:
                if k not in keys:
                    keys.append(k)
        diag = {k: np.array([s.diagnostics.get(k, np.nan) for s in steps], dtype=np.float64) for k in keys}
        return cls(
            model=model.name,
            output_name=model.output_name,
            threshold=model.threshold,
            output=np.array([s.output for s in steps], dtype=np.float64),
            spike=np.array([s.spike for s in steps], dtype=bool),
            converged=np.array([s.converged for s in steps], dtype=bool),
            diagnostics=diag,
            seconds=seconds,
        )

    def to_csv_text(self) -> str:
        """CSV text: ``frame, <output_name>, spike, converged, <diagnostics...>``."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        keys = list(self.diagnostics)
        w.writerow(["frame", self.output_name, "spike", "converged", *keys])
        for t in range(self.n_frames):
            row: list[Any] = [t, f"{self.output[t]:.9f}", int(self.spike[t]), int(self.converged[t])]
            for k in keys:
                val = self.diagnostics[k][t]
                row.append(int(val) if float(val).is_integer() and abs(val) < 2**31 else f"{val:.6g}")
            w.writerow(row)
        return buf.getvalue()

    def to_csv(self, path) -> None:
        """Write :meth:`to_csv_text` atomically to ``path``."""
        atomic_write_text(path, self.to_csv_text())

    @classmethod
    def from_csv(cls, path, model: str = "", threshold: float | None = None) -> "Trace":
        """Read a trace written by :meth:`to_csv`."""
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
        header, body = rows[0], rows[1:]
        cols = {name: np.array([float(r[i]) for r in body]) for i, name in enumerate(header)}
        output_name = header[1]
        diag = {k: v for k, v in cols.items() if k not in ("frame", output_name, "spike", "converged")}
        return cls(model, output_name, threshold, cols[output_name], cols["spike"].astype(bool),
                   cols["converged"].astype(bool), diag)


class Model(ABC):
    """Base class of every looming-perception model in cdnf_ti.

    Subclasses set ``name`` (registry key), ``output_name`` and ``params_type``
    and implement :meth:`step`, :meth:`reset` and :meth:`fields`.

    Parameters
    ----------
    params : dataclass instance, optional
        The model's parameters (defaults when omitted).
    backend : {"taichi", "numpy"}
        ``taichi`` runs the kernels; ``numpy`` the float64 reference.
    arch : str
        Taichi architecture (``cpu`` default; ``cuda``/``vulkan`` where available).
    fps : float
        Frame rate of the input (models with time constants need it).
    compiler : {"quadrants", "taichi"} or None
        Kernel compiler of the process (see :mod:`cdnf_ti.taichi_runtime`); ``None``: the
        one running, else the fastest installed.
    """

    name: ClassVar[str] = ""
    output_name: ClassVar[str] = "output"
    params_type: ClassVar[type] = object
    description: ClassVar[str] = ""
    BACKENDS: ClassVar[tuple[str, ...]] = ("taichi", "numpy")

    def __init__(self, params: Any = None, *, backend: str = "taichi", arch: str = "cpu", fps: float = 30.0,
                 compiler: str | None = None):
        if backend not in self.BACKENDS:
            raise ValueError(f"{self.name}: unknown backend {backend!r}; choose one of {self.BACKENDS}")
        if not (fps > 0):
            raise ValueError(f"{self.name}: fps must be > 0, got {fps}")
        self.params = params if params is not None else self.params_type()
        if not isinstance(self.params, self.params_type):
            raise TypeError(f"{self.name}: params must be {self.params_type.__name__}")
        self.backend_name = backend
        self.arch = arch
        if backend == "taichi" and compiler is not None:
            from ..taichi_runtime import select_compiler

            select_compiler(compiler)
        self.compiler = compiler
        self.fps = float(fps)
        self._unconverged = 0

    @property
    def threshold(self) -> float | None:
        """Alert threshold on the continuous output, if the model has one."""
        return None

    @abstractmethod
    def step(self, frame: np.ndarray) -> StepResult:
        """Process one frame (2-D grey float in [0, 1] or uint8, or BGR uint8)."""

    @abstractmethod
    def reset(self) -> None:
        """Forget all state; the next frame is treated as the first."""

    @abstractmethod
    def fields(self) -> dict[str, np.ndarray]:
        """Copies of the model's inner layers/fields, each (H, W), for pictures."""

    def run(self, frames: Iterable[np.ndarray], progress: bool | str = False, total: int | None = None) -> Trace:
        """Reset, then step through ``frames`` and return the :class:`Trace`.

        Parameters
        ----------
        frames : iterable of ndarray
            Frame stream (consumed lazily; never held in memory at once).
        progress : bool or str
            Show a tqdm progress bar (a string is used as its label).
        total : int, optional
            Number of frames, for the progress bar.
        """
        return run_models([self], frames, progress=progress, total=total)[0]


def run_models(models: "list[Model]", frames: Iterable[np.ndarray], progress: bool | str = False,
               total: int | None = None) -> list[Trace]:
    """Reset several models and step them all through one pass over ``frames``.

    Each frame is decoded (and e.g. rain is generated) once and handed to every
    model in turn; each model's time is measured separately.

    Parameters
    ----------
    models : list of Model
    frames : iterable of ndarray
        Frame stream (consumed lazily).
    progress : bool or str
        Show a tqdm progress bar (a string is used as its label).
    total : int, optional
        Number of frames, for the progress bar.

    Returns
    -------
    list of Trace
        One per model, in order.
    """
    for m in models:
        m.reset()
    steps: list[list[StepResult]] = [[] for _ in models]
    seconds = [0.0] * len(models)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=total, desc=progress if isinstance(progress, str) else models[0].name,
                   unit="frame", leave=False, disable=None)
    try:
        for frame in frames:
            for k, m in enumerate(models):
                t0 = time.perf_counter()
                steps[k].append(m.step(frame))
                if len(steps[k]) > 1:  # the first step allocates state and compiles kernels
                    seconds[k] += time.perf_counter() - t0
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    traces = []
    for k, m in enumerate(models):
        trace = Trace.from_steps(m, steps[k], seconds[k])
        n_bad = int((~trace.converged).sum())
        if n_bad:
            warnings.warn(
                f"{m.name}: {n_bad} of {trace.n_frames} frames did not reach the tolerance "
                "(see the 'converged' column)",
                NotConvergedWarning,
                stacklevel=3,
            )
        traces.append(trace)
    return traces
