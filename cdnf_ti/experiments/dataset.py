"""The dataset run engine: every labelled clip x model x condition (clean / rain), resumable.

Output folder layout (every file written atomically)::

    OUT/traces/<condition>/<clip>.<model>.csv    per-frame trace (Trace.to_csv)
    OUT/traces/<condition>/<clip>.<model>.json   what the run of that trace recorded (done marker)
    OUT/results.csv                              one row per clip x model x condition
    OUT/threshold_sweep.csv                      accuracy / hits / false alarms vs alert level
    OUT/summary.md, OUT/summary.json             Table II style summary
    OUT/figures/*.png                            traces (Fig. 5 style), threshold sweep, accuracy

A (clip, model, condition) whose ``.json`` exists is finished and skipped on a
rerun; scoring is always recomputed from the saved traces, so a rerun with a
different window padding re-scores without running any model.
"""
from __future__ import annotations

import math
import os
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

from ..atomic import atomic_write_json, output_lock, prepare_output, remove_stale_temps
from ..errors import InputError, UserError
from ..frames import iter_grey, open_source
from ..limits import check_frame_size
from ..models import create_model
from ..models.base import NotConvergedWarning, run_models
from ..stimuli.rain import RainParams, RainyFrames
from . import parallel  # parallel.map_tasks looked up at call time (tests replace it)
from .labels import ClipLabel, drop_missing, read_labels, unlabelled_videos, validate_dataset
from .layout import (
    CONDITIONS as CONDITIONS,  # re-exported: dataset.py was their home
    RAIN_CHOICES as RAIN_CHOICES,
    RESULT_COLUMNS as RESULT_COLUMNS,
    fingerprint as fingerprint,
    load_meta as load_meta,
    rain_seed as rain_seed,
    report_stale,
    trace_path as trace_path,
)
from .parallel import TaskFailed, init_worker
from .reports import write_reports
from .scoring import Padding, score_clip


@dataclass(frozen=True)
class ClipTask:
    """One clip under one condition, for the models not yet finished.

    Attributes
    ----------
    clip : str
    path : str
        The clip's file.
    condition : {"clean", "rain"}
    models : tuple of str
    out : str
        The run's output folder.
    seed : int
        Run seed (rain).
    backend, arch : str
        Model backend and Taichi arch.
    rain_params : dict or None
        Keyword arguments of ``RainParams``.
    params : dict or None
        ``{model: parameter object or None}`` (``--param``); absent models keep their defaults.
    fps, color_order :
        How the clip is read (:func:`~cdnf_ti.frames.open_source`; ``--fps``, ``--color-order``).
    """

    clip: str
    path: str
    condition: str
    models: tuple[str, ...]
    out: str
    seed: int = 0
    backend: str = "taichi"
    arch: str = "cpu"
    rain_params: dict | None = None
    params: dict | None = None
    fps: float | None = None
    color_order: str = "bgr"

    def fingerprint(self, model: str) -> dict:
        """The :func:`~cdnf_ti.experiments.layout.fingerprint` of this task's ``model``."""
        return fingerprint(self.path, self.condition, model, self.seed, self.backend, self.rain_params, self.arch,
                           run_options(model, self.params, self.fps, self.color_order))


def run_options(model: str, params: dict | None, fps: float | None, color_order: str) -> dict:
    """What a trace depends on beside the input and code, where not the defaults: the model's
    parameters (``--param``), the frame rate (``--fps``) and the colour order (``--color-order``)."""
    opts: dict[str, Any] = {}
    p = (params or {}).get(model)
    if p is not None and hasattr(p, "to_dict"):
        default = type(p)().to_dict()
        changed = {k: v for k, v in p.to_dict().items() if default.get(k) != v}
        if changed:
            opts["params"] = changed
    if fps is not None:
        opts["fps"] = float(fps)
    if color_order != "bgr":
        opts["color_order"] = color_order
    return opts


def _frames(task: ClipTask, src):
    """The frame stream of a task (grey; rainy for the rain condition) and the rain object."""
    grey = iter_grey(src)
    if task.condition == "clean":
        return grey, None
    params = RainParams(**task.rain_params) if task.rain_params else None
    rain = RainyFrames(grey, params, seed=rain_seed(task.seed, task.clip),
                       backend="numpy" if task.backend == "numpy" else "taichi")
    return rain, rain


def run_clip_task(task: ClipTask) -> list[dict]:
    """Run the task's models on its clip in one pass; save each trace and its record.

    The clip is decoded (and, for the rain condition, rained on) once for all
    the task's models (:func:`~cdnf_ti.models.base.run_models`). Models are
    isolated: one model that fails gives an error record for that model only.

    Returns
    -------
    list of dict
        One record per model: ``clip, model, condition, frames, fps,
        first_alert, max_output, output_name, threshold, snr_db,
        unconverged_frames, seconds, error`` (``error`` empty on success). A
        clip that cannot be opened or decoded gives records with ``error`` set
        for every model; nothing is saved for them, so a rerun tries again.
    """
    if task.backend == "taichi":
        init_worker(task.arch)
    base = {"clip": task.clip, "condition": task.condition}

    def failed(names, e: BaseException) -> list[dict]:
        msg = str(e) if isinstance(e, InputError) else f"{task.path}: {type(e).__name__}: {e}"
        return [dict(base, model=m, error=msg.splitlines()[0] if msg else type(e).__name__) for m in names]

    try:
        src = open_source(task.path, fps=task.fps, color_order=task.color_order)
        try:
            check_frame_size(*src.shape, n_models=len(task.models), what=str(task.path))
        except UserError as e:  # frames smaller than the widest kernel: that clip's error rows
            raise InputError(task.path, str(e).split(": ", 1)[-1]) from None
    except InputError as e:
        return failed(task.models, e)
    records: dict[str, dict] = {}
    names, instances = [], []
    for name in task.models:
        try:
            instances.append(create_model(name, (task.params or {}).get(name), backend=task.backend, arch=task.arch,
                                          fps=src.fps))
            names.append(name)
        except Exception as e:  # noqa: BLE001 - one model's failure is that model's error row
            records.update((r["model"], r) for r in failed([name], e))
    if instances:
        errors: list = []
        rain = None
        try:
            frames, rain = _frames(task, src)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", NotConvergedWarning)  # recorded as unconverged_frames
                traces = run_models(instances, frames, progress=False, errors=errors)
        except (InputError, OSError, RuntimeError, ValueError) as e:  # the clip (or its rain) is bad
            traces, errors = [None] * len(names), [e] * len(names)
        snr = None
        if rain is not None and errors.count(None):
            s = getattr(rain, "snr_db", None)
            snr = None if s is None or not math.isfinite(float(s)) else float(s)
        for name, trace, err in zip(names, traces, errors):
            if err is not None or trace is None:
                records.update((r["model"], r) for r in failed([name], err or RuntimeError("no trace")))
                continue
            meta = dict(
                base, model=name, frames=trace.n_frames, fps=float(src.fps), first_alert=trace.first_alert,
                max_output=float(trace.output.max()) if trace.n_frames else None,
                output_name=trace.output_name, threshold=trace.threshold, snr_db=snr,
                unconverged_frames=int((~trace.converged).sum()), seconds=round(float(trace.seconds), 3),
                source=str(task.path), seed=task.seed if rain is not None else None,
                rain_seed=rain_seed(task.seed, task.clip) if rain is not None else None, error="",
                fingerprint=task.fingerprint(name),
            )
            trace.to_csv(trace_path(task.out, task.condition, task.clip, name))
            atomic_write_json(trace_path(task.out, task.condition, task.clip, name, "json"), meta)
            records[name] = meta
    return [records[m] for m in task.models]


def describe_task(task: ClipTask, records: Any) -> str:
    """One progress line for a finished task: ``clip [models, condition]: seconds`` or its error."""
    head = f"{task.clip} [{', '.join(task.models)}, {task.condition}]"
    if records is None:
        return head
    if isinstance(records, TaskFailed):
        return f"{head}: error: {records}"
    errs = [r for r in records if r.get("error")]
    secs = sum(float(r.get("seconds") or 0) for r in records if not r.get("error"))
    line = f"{head}: {secs:.1f} s"
    if errs:
        line += "; " + "; ".join(f"error [{r['model']}]: {r['error']}" for r in errs)
    return line


@dataclass
class DatasetRun:
    """Everything a dataset run produced.

    Attributes
    ----------
    rows : list of dict
        results.csv rows (:data:`RESULT_COLUMNS`), in labels x condition x model order.
    labels : list of ClipLabel
    models : list of str
    conditions : list of str
    padding : Padding
    out : Path
    ran, skipped : int
        (clip, model, condition) runs done now / found finished on disk.
    sweep : list of dict
        Threshold-sweep rows.
    summary : dict
        The summary.json content.
    """

    rows: list[dict]
    labels: list[ClipLabel]
    models: list[str]
    conditions: list[str]
    padding: Padding
    out: Path
    ran: int = 0
    skipped: int = 0
    sweep: list[dict] = field(default_factory=list)
    summary: dict = field(default_factory=dict)
    #: Videos in the dataset folder that have no row in the labels file (not run).
    unlabelled: list[str] = field(default_factory=list)

    @property
    def n_errors(self) -> int:
        return sum(1 for r in self.rows if r.get("error"))

    @property
    def failed(self) -> bool:
        return self.n_errors > 0


def build_row(label: ClipLabel, model: str, condition: str, meta: dict | None, padding: Padding) -> dict:
    """One results.csv row from a label and a finished (or failed) record."""
    row: dict[str, Any] = {k: "" for k in RESULT_COLUMNS}
    row.update(clip=label.clip, model=model, condition=condition, label=label.label,
               window_start=label.window_start, window_end=label.window_end, contact_frame=label.contact_frame)
    if meta is None:
        row["error"] = "not run"
        return row
    if meta.get("error"):
        row["error"] = meta["error"]
        return row
    fps = float(meta.get("fps") or 30.0)
    fa = meta.get("first_alert")
    sc = score_clip(fa, label, fps, padding)
    row.update(
        window_lo=sc.window_lo, window_hi=sc.window_hi, frames=meta.get("frames"), video_fps=fps,
        first_alert=fa, first_alert_s=None if fa is None else round(fa / fps, 4),
        outcome=sc.outcome, fn_reason=sc.fn_reason,
        lead_time_ms=None if sc.lead_time_ms is None else round(sc.lead_time_ms, 3),
        output_name=meta.get("output_name"), max_output=meta.get("max_output"), threshold=meta.get("threshold"),
        snr_db=meta.get("snr_db"), unconverged_frames=meta.get("unconverged_frames"),
        seconds=meta.get("seconds"), error="",
    )
    return row


def run_dataset(folder: str | os.PathLike, labels_path: str | os.PathLike | None, out: str | os.PathLike,
                models: Sequence[str] = ("cdnf",), rain: str = "none", padding: Padding = Padding(),
                seed: int = 0, workers: int | None = None, scheduler: Any = None, backend: str = "taichi",
                arch: str = "cpu", progress: bool = True, figures: bool = True,
                rain_params: dict | None = None,
                on_record: Callable[[dict], None] | None = None, params: dict | None = None,
                fps: float | None = None, color_order: str = "bgr", skip_missing: bool = False) -> DatasetRun:
    """Run ``models`` on every labelled clip of ``folder`` and write the reports.

    Parameters
    ----------
    folder : path-like
        Folder of videos.
    labels_path : path-like or None
        Labels CSV (None: ``folder/labels.csv``).
    out : path-like
        Output folder (created; finished work found there is reused).
    models : sequence of str
        Registry names.
    rain : {"none", "only", "both"}
        Clean clips, clips with synthetic rain, or both.
    padding : Padding
        Window padding in frames.
    seed : int
        Rain seed (each clip's rain depends only on this and the clip name).
    workers : int, optional
        Local worker processes (None = one per core; 0/1 = in this process).
    scheduler : str or distributed.Client, optional
        Dask scheduler address: run the clip tasks on that cluster instead.
    backend, arch : str
        Model backend and Taichi arch.
    progress : bool
        tqdm bar over clip tasks.
    figures : bool
        Draw the figures.
    rain_params : dict, optional
        Keyword arguments of ``cdnf_ti.stimuli.rain.RainParams``.
    on_record : callable, optional
        Called in this process with each record as it arrives (for tests / logging).
    params : dict, optional
        ``{model: parameter object or None}`` (``--param``).
    fps, color_order : optional
        How clips are read (``--fps``, ``--color-order``).
    skip_missing : bool
        Run the clips whose video exists and leave out label rows that name a missing video
        (:func:`~cdnf_ti.experiments.labels.drop_missing`); by default a missing video is an error.

    Raises
    ------
    InputError
        Bad labels file (before any work starts).
    UserError
        Bad option.
    OutputError
        ``out`` cannot be created or written (before any work starts).
    """
    if rain not in RAIN_CHOICES:
        raise UserError(f"--rain must be one of {', '.join(RAIN_CHOICES)}, got {rain!r}")
    folder = Path(folder)
    labels_path = Path(labels_path) if labels_path is not None else folder / "labels.csv"
    labels = read_labels(labels_path)
    if skip_missing:
        labels, _ = drop_missing(labels, folder)
    files = validate_dataset(labels, folder, labels_path)
    conditions = list(RAIN_CHOICES[rain])
    models = list(dict.fromkeys(models))
    if not models:
        raise UserError("no model named")
    out = prepare_output(out)  # before any work: a folder that cannot be written fails now
    files = {clip: Path(f).resolve() for clip, f in files.items()}  # workers may run elsewhere
    with output_lock(out):
        remove_stale_temps(out)  # left by a run killed mid-write
        try:
            return _run_locked(folder, labels_path, labels, files, out, models, conditions, padding, seed,
                               workers, scheduler, backend, arch, progress, figures, rain_params, on_record,
                               dict(params=params, fps=fps, color_order=color_order))
        except KeyboardInterrupt:
            parallel.stop_all_pools()
            remove_stale_temps(out)  # the workers stopped mid-write leave no half-written files
            raise


def _run_locked(folder, labels_path, labels, files, out, models, conditions, padding, seed, workers, scheduler,
                backend, arch, progress, figures, rain_params, on_record, read: dict | None = None) -> DatasetRun:
    metas: dict[tuple[str, str, str], dict] = {}
    tasks: list[ClipTask] = []
    skipped = 0
    stale: list[str] = []
    for lab in labels:
        for cond in conditions:
            todo = []
            for m in models:
                task = ClipTask(lab.clip, str(files[lab.clip]), cond, (m,), str(out), seed, backend, arch,
                                rain_params, **(read or {}))
                meta = load_meta(out, cond, lab.clip, m, task.fingerprint(m), stale)
                if meta is not None:
                    metas[(lab.clip, m, cond)] = meta
                    skipped += 1
                else:
                    todo.append(m)
            if todo:
                tasks.append(ClipTask(lab.clip, str(files[lab.clip]), cond, tuple(todo), str(out), seed,
                                      backend, arch, rain_params, **(read or {})))
    report_stale(stale)
    ran = 0
    for i, res in parallel.map_tasks(run_clip_task, tasks, workers=workers, scheduler=scheduler, arch=arch,
                            progress="clips" if progress else False, describe=describe_task):
        t = tasks[i]
        recs = ([dict(clip=t.clip, model=m, condition=t.condition, error=f"{t.path}: {res}") for m in t.models]
                if isinstance(res, TaskFailed) else res)
        for r in recs:
            metas[(r["clip"], r["model"], r["condition"])] = r
            ran += 0 if r.get("error") else 1
            if on_record is not None:
                on_record(r)
    rows = [build_row(lab, m, c, metas.get((lab.clip, m, c)), padding)
            for lab in labels for c in conditions for m in models]
    result = DatasetRun(rows, labels, models, conditions, padding, out, ran, skipped,
                        unlabelled=unlabelled_videos(folder, labels))
    write_reports(result, dataset=str(folder), labels_path=str(labels_path), seed=seed, figures=figures,
                  progress=progress)
    return result


def config_dict(**kw: Any) -> dict:
    """JSON-safe copy of run options (for summary.json)."""
    return {k: (asdict(v) if hasattr(v, "__dataclass_fields__") else v) for k, v in kw.items()}
