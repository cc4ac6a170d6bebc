"""The stimulus engine: models on generated stimuli (Table I, the coherence sweep, the selectivity grid).

Two task types, both cache entries of :mod:`.tasks` and run through
:func:`.tasks.run_cached` (resumed, in this process, on local processes or on
Dask, in batches of one model at one frame size so that a worker compiles a
model's kernels once per shape):

* :class:`StimulusTask`: a model on a basic stimulus at one size, coherent or
  incoherent (``experiment table1``, ``demo``, ``experiment coherence``);
  trace ``<out>/traces/<stimulus>[_c<coh>].<model>.csv``, record ``.json`` beside it;
* :class:`GridTask`: a model on one point of the selectivity grid
  (``experiment selectivity``); record ``<out>/tasks/<key>.json``, trace
  ``<out>/traces/<key>.csv``.

:func:`table1_results` is the one Table I runner, at the paper's 600 x 600 px
by default (:data:`TABLE1_SIZE`). The engine returns records; the experiments
(:mod:`.builtin`, :mod:`.selectivity`) write tables and figures afterwards.
This module imports no reporter.
"""
from __future__ import annotations

import hashlib
import json
import warnings
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Sequence

from ..models import create_model, get_model_class
from ..models.base import NotConvergedWarning
from ..paths import inside
from ..stimuli.basic import BASIC_STIMULI, basic_stimulus
from ..stimuli.grating import GratingStimulus
from ..stimuli.incoherent import IncoherentStimulus, incoherent_stimulus
from .parallel import init_worker
from .tasks import (
    Batch,
    Entry,
    batches,
    describe_batch,
    one_per_entry,
    run_batch,
    run_cached,
    save_finished,
    task_fingerprint,
)

#: Frame side (px) of Table I everywhere (``demo``, ``experiment table1``): the paper's 600 x 600 stimuli.
TABLE1_SIZE = 600


@dataclass(frozen=True)
class StimulusTask:
    """One model on one generated stimulus.

    Attributes
    ----------
    model : str
    stimulus : str
        Basic stimulus name.
    size : int
        Frame side (px).
    coherence : float or None
        None: the coherent basic stimulus; else the incoherent stimulus.
    seed : int
    out : str
        Folder for the trace CSV (``traces/<stimulus>[_c<coh>].<model>.csv``) and its
        record (``.json`` beside it); empty: nothing is saved (the demo).
    backend, arch : str
    scatter : {"flicker", "static"}
        Incoherent construction (:class:`cdnf_ti.stimuli.incoherent.IncoherentStimulus`).
    params : object or None
        The model's parameter object (``--param``); None: its defaults.
    """

    model: str
    stimulus: str
    size: int
    coherence: float | None
    seed: int
    out: str
    backend: str = "taichi"
    arch: str = "cpu"
    scatter: str = "flicker"
    params: Any = None

    @property
    def trace_file(self) -> Path:
        tag = self.stimulus if self.coherence is None else f"{self.stimulus}_c{round(self.coherence * 100):03d}"
        if self.coherence is not None and self.scatter != "flicker":
            tag += f"_{self.scatter}"
        return inside(Path(self.out) / "traces", f"{tag}.{self.model}.csv")

    def entry(self) -> Entry:
        """The task's cache entry: every field but the output folder, plus the code (:mod:`.tasks`)."""
        inputs = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("out", "backend", "arch")}
        inputs["params"] = dict(changed_params(self.params))
        return Entry.make(self.trace_file.stem + ("" if self.coherence is None else f" [c={self.coherence:g}]"),
                          self.trace_file.with_suffix(".json") if self.out else None,
                          task_fingerprint(self.backend, self.arch, inputs),
                          [self.trace_file] if self.out else [])

    def run(self) -> dict:
        """Run the model on the stimulus; save the trace and the record (unless ``out`` is empty)."""
        return run_stimulus_task(self)


def make_stimulus(name: str, size: int, coherence: float | None = None, seed: int = 0, scatter: str = "flicker"):
    """A basic (coherence None) or incoherent stimulus, scaled to ``size`` x ``size`` px."""
    kw = dict(height=size, width=size)  # start half-size: default_start_half_size(size)
    if coherence is None:
        return basic_stimulus(name, **kw)
    return incoherent_stimulus(name, coherence, seed=seed, scatter=scatter, **kw)


def frames_of(stim):
    """The frame iterator of a stimulus object."""
    return stim.frames() if hasattr(stim, "frames") else iter(stim)


def run_stimulus_task(task: StimulusTask) -> dict:
    """Run one model on one stimulus; save the trace and its record; return the record.

    The record holds ``alert`` (0/1), ``first_alert``, ``max_output``, ``frames``, ``fps``
    (the stimulus' frame rate), ``proc_fps`` (the model's throughput, frames/s),
    ``threshold``, ``converged`` and ``seconds``.
    """
    if task.backend == "taichi":
        init_worker(task.arch)
    stim = make_stimulus(task.stimulus, task.size, task.coherence, task.seed, task.scatter)
    fps = float(getattr(stim, "fps", 30.0))
    model = create_model(task.model, task.params, backend=task.backend, arch=task.arch, fps=fps)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotConvergedWarning)  # recorded per frame in "converged"
        tr = model.run(frames_of(stim), progress=False)
    rec = {"model": task.model, "stimulus": task.stimulus, "coherence": task.coherence,
           "alert": int(tr.first_alert is not None), "first_alert": tr.first_alert,
           "max_output": float(tr.output.max()), "frames": tr.n_frames, "fps": fps, "proc_fps": tr.fps,
           "threshold": tr.threshold, "converged": bool(tr.converged.all()), "seconds": round(tr.seconds, 3),
           "error": ""}
    entry = task.entry()
    if entry.kept:
        tr.to_csv(task.trace_file)
    return save_finished(entry, rec)


def run_stimulus_tasks(tasks: Sequence[StimulusTask], workers: int | None = None, scheduler: Any = None,
                       arch: str = "cpu", progress: bool = True, label: str = "stimuli") -> list[dict]:
    """Every task through :func:`.tasks.run_cached`: finished ones reused, the others in batches of
    one model at one frame size (one task per unit when everything runs in this process anyway)."""
    def failed(i: int, msg: str) -> dict:
        t = tasks[i]
        return {"model": t.model, "stimulus": t.stimulus, "coherence": t.coherence, "alert": None, "error": msg}

    key = lambda t: (t.model, t.size)  # noqa: E731
    one_batch = scheduler is None and len(batches(range(len(tasks)), tasks, key)) <= 1
    if one_batch:  # all of it is one batch anyway: run in this process, a task per unit (finer progress)
        workers = 0

    def plan(todo: list[int]) -> list:
        if one_batch:
            return one_per_entry(todo, lambda i: Batch((tasks[i],), tasks[i].trace_file.stem))
        return batches(todo, tasks, key, lambda t: f"{t.model} {t.size}x{t.size} px {label}")

    run = run_cached([t.entry() for t in tasks], plan, run_batch, failed=failed, workers=workers,
                     scheduler=scheduler, arch=arch, progress=label if progress else False, describe=describe_batch)
    return [{**{k: v for k, v in r.items() if k != "fingerprint"}, "model": t.model, "stimulus": t.stimulus,
             "coherence": t.coherence, "alert": r.get("alert")} for t, r in zip(tasks, run.records)]


def table1_results(models: Sequence[str], size: int = TABLE1_SIZE, out: str | Path | None = None, seed: int = 0,
                   workers: int | None = None, scheduler: Any = None, backend: str = "taichi", arch: str = "cpu",
                   progress: bool = True, params: dict | None = None) -> dict[str, dict[str, dict]]:
    """Paper Table I: each model on the six basic stimuli (the one runner of the demo and ``experiment table1``).

    Parameters
    ----------
    models : sequence of str
    size : int
        Frame side in px (default :data:`TABLE1_SIZE`, the paper's 600).
    out : path-like, optional
        Folder for the traces and their records (reused by a rerun with the same code and
        settings); None: nothing is saved.
    seed, workers, scheduler, backend, arch, progress
        As :func:`cdnf_ti.experiments.builtin.table1`.
    params : dict, optional
        ``{model: parameter object or None}`` (``--param``).

    Returns
    -------
    dict
        ``result[model][stimulus] = {"alert", "first_alert", "max_output", "frames", "fps",
        "proc_fps", ...}`` (``alert`` None and ``error`` set where the run failed).
    """
    tasks = [StimulusTask(m, s, size, None, seed, "" if out is None else str(out), backend, arch,
                          params=(params or {}).get(m)) for m in models for s in BASIC_STIMULI]
    res: dict[str, dict[str, dict]] = {m: {} for m in models}
    for r in run_stimulus_tasks(tasks, workers, scheduler, arch, progress, "table1"):
        res[r["model"]][r["stimulus"]] = r
    return res


def changed_params(params: Any) -> tuple:
    """``(name, value)`` pairs of a parameter object that differ from its defaults (``()`` for None)."""
    if params is None or not hasattr(params, "to_dict"):
        return ()
    default = type(params)().to_dict()
    return tuple((k, v) for k, v in params.to_dict().items() if default.get(k) != v)


def make_grid_stimulus(point: Any, seed: int = 0):
    """The stimulus of a grid point (:class:`cdnf_ti.experiments.selectivity.GridPoint`): a frame
    generator with ``fps`` and ``n_frames``."""
    kw = point.kwargs
    coherence = kw.pop("coherence", None)
    scatter = kw.pop("scatter", "flicker")
    if point.cls == "grating":
        return GratingStimulus(seed=seed, **kw)
    base = basic_stimulus(point.stimulus, **kw)
    if coherence is None:
        return base
    return IncoherentStimulus(base, coherence, seed, scatter=scatter)


@dataclass(frozen=True)
class GridTask:
    """One model on one grid stimulus; result (record) in ``<out>/tasks/<key>.json``, trace in
    ``<out>/traces/<key>.csv``."""

    model: str
    point: Any
    seed: int
    out: str
    backend: str = "taichi"
    arch: str = "cpu"
    model_params: tuple = ()  # (name, value) pairs that differ from the model's defaults (--param)

    @property
    def spec(self) -> dict:
        spec = {"model": self.model, "stimulus": self.point.stimulus, "params": dict(self.point.spec),
                "seed": self.seed, "backend": self.backend}
        if self.model_params:  # absent with the defaults, so earlier results keep their keys
            spec["model_params"] = dict(self.model_params)
        return spec

    @property
    def key(self) -> str:
        h = hashlib.sha1(json.dumps(self.spec, sort_keys=True, default=str).encode()).hexdigest()[:12]
        return f"{self.point.stimulus}.{self.model}.{h}"

    @property
    def result_file(self) -> Path:
        return inside(Path(self.out) / "tasks", f"{self.key}.json")

    @property
    def trace_file(self) -> Path:
        return inside(Path(self.out) / "traces", f"{self.key}.csv")

    def entry(self) -> Entry:
        """The task's cache entry (:mod:`.tasks`): its specification plus the code that runs it."""
        return Entry.make(self.key, self.result_file, task_fingerprint(self.backend, self.arch, self.spec),
                          [self.trace_file])

    def run(self) -> dict:
        return run_grid_task(self)


def run_grid_task(task: GridTask) -> dict:
    """Run one model on one grid stimulus; write its trace and result file; return the result."""
    if task.backend == "taichi":
        init_worker(task.arch)
    stim = make_grid_stimulus(task.point, task.seed)
    fps = float(stim.fps)
    params = get_model_class(task.model).params_type(**dict(task.model_params)) if task.model_params else None
    model = create_model(task.model, params, backend=task.backend, arch=task.arch, fps=fps)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotConvergedWarning)  # recorded per frame in "converged"
        tr = model.run(stim.frames(), progress=False)
    tr.to_csv(task.trace_file)
    spikes = [int(i) for i, s in enumerate(tr.spike) if s]
    rec = {"spec": task.spec, "alert": int(tr.first_alert is not None), "first_alert": tr.first_alert,
           "alert_frames": len(spikes), "frames": tr.n_frames, "fps": fps,
           "max_output": float(tr.output.max()), "argmax_output": int(tr.output.argmax()),
           "threshold": tr.threshold, "seconds": round(tr.seconds, 3)}
    return save_finished(task.entry(), rec)


#: Grid tasks of one model at one frame size, run one after another in one worker (:class:`.tasks.Batch`).
GridBatch = Batch


def run_grid_batch(batch: Batch) -> list[dict]:
    """Run every task of a batch (a failed task gives an error record, the rest go on)."""
    return run_batch(batch)


def _model_and_shape(t: GridTask) -> tuple:
    kw = t.point.kwargs
    return t.model, kw.get("height"), kw.get("width")


def make_batches(tasks: Sequence[GridTask], chunk: int = 16) -> list[Batch]:
    """Group tasks by (model, frame shape), in chunks of at most ``chunk`` tasks."""
    return [b for b, _ in batches(range(len(tasks)), tasks, _model_and_shape, chunk=chunk)]


def run_grid_tasks(tasks: Sequence[GridTask], workers: int | None = None, scheduler: Any = None,
                   arch: str = "cpu", progress: bool = True):
    """Every grid task through :func:`.tasks.run_cached` (finished ones reused, the others in
    batches of one model at one frame size); returns the :class:`.tasks.CachedRun`."""
    def failed(i: int, msg: str) -> dict:
        return {"spec": tasks[i].spec, "alert": None, "error": msg}

    def plan(todo: list[int]) -> list:
        return batches(todo, tasks, _model_and_shape, lambda t: f"{t.model} {t.point.kwargs.get('height')} px")

    return run_cached([t.entry() for t in tasks], plan, run_batch, failed=failed, workers=workers,
                      scheduler=scheduler, arch=arch, progress="selectivity (batches)" if progress else False,
                      describe=describe_batch)
