"""The clip engine: models on labelled clips, clean or with synthetic rain, for ``dataset`` and ``experiment sweep``.

One unit of work (:class:`ClipTask`) decodes a clip once (and rains on it once)
for several models; a clip that is an event recording (:func:`~cdnf_ti.events.readers.is_event_file`)
is binned instead (``--event-threshold``, ``--sensor-size``), once per bin width (the task's ``bin_ms``:
one for every model of a dataset run, :func:`batch_bin_ms`), and every model takes its bins through
its ON/OFF input stage (:meth:`~cdnf_ti.models.base.Model.step_on_off`).
Each (clip, model, condition) is one cache entry of
:mod:`.tasks`, saved as ``<out>/traces/<condition>/<clip>.<model>.csv`` and its
record ``.json`` beside it (:mod:`.layout`). A parameter sweep runs the same
units with one model setting each (:class:`SweepTask`), under
``OUT/settings/<setting>/``.

The engine returns records; the experiments (:mod:`.dataset`, :mod:`.paramsweep`)
score them and hand them to the reporters afterwards. This module imports no reporter.
"""
from __future__ import annotations

import dataclasses
import math
import os
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import cv2

from ..errors import InputError, UserError
from ..events.binning import DEFAULT_BIN_MS, DEFAULT_EVENT_THRESHOLD, DEFAULT_MAX_GAP_S, DEFAULT_MAX_SPAN_S
from ..events.readers import is_event_file, open_events
from ..events.source import EventSource, open_event_source
from ..frames import ColourFrame, iter_frames, open_source
from ..limits import check_frame_size
from ..models import create_model, get_model_class
from ..models.base import NotConvergedWarning, bin_ms_for, run_models, takes_colour
from ..paths import inside
from ..stimuli.rain import RainParams, RainyFrames
from .labels import ClipLabel
from .layout import fingerprint, rain_seed, trace_entry
from .parallel import TaskFailed, init_worker
from .scoring import Padding
from .tasks import CachedRun, Entry, run_cached, save_finished


@dataclass(frozen=True)
class ClipTask:
    """One clip under one condition, for several models (decoded once for all of them).

    Attributes
    ----------
    clip : str
    path : str
        The clip's file.
    condition : {"clean", "rain"}
    models : tuple of str
    out : str
        The folder its traces go under (``out/traces/<condition>/``).
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
    setting : tuple of (name, value)
        Model parameters other than the defaults (a parameter sweep's setting).
    downscale : float
        Frames are resized by this factor (1 = native size).
    key : str
        The setting's name in a parameter sweep (:func:`cdnf_ti.experiments.paramsweep.setting_key`);
        empty for a dataset run. A sweep's fingerprints hold the setting and the downscale factor.
    sensor_size, bin_ms, event_threshold :
        How an event recording is binned and scaled (``--sensor-size``, ``--bin-ms``,
        ``--event-threshold``); unused for a video. An event clip's fingerprints hold all three.
    max_gap_s, max_span_s :
        Corrupt-timestamp limits of an event recording (``--max-gap-s``, ``--max-span-s``); not in
        the fingerprint (a recording within them bins the same whatever they are).
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
    setting: tuple = ()
    downscale: float = 1.0
    key: str = ""
    sensor_size: tuple[int, int] | None = None
    bin_ms: float = DEFAULT_BIN_MS
    event_threshold: float = DEFAULT_EVENT_THRESHOLD
    max_gap_s: float = DEFAULT_MAX_GAP_S
    max_span_s: float = DEFAULT_MAX_SPAN_S

    @property
    def events(self) -> bool:
        """Whether the clip is an event recording (binned) rather than frames."""
        return is_event_file(self.path)

    def fingerprint(self, model: str) -> dict:
        """The fingerprint of ``model``'s result (:func:`.layout.fingerprint`; a sweep adds
        ``params`` and ``downscale``; an event recording adds ``bin_ms``, ``event_threshold`` and
        ``sensor_size``, and leaves out ``--fps`` and ``--color-order``, which do not apply to it; a model that
        takes the colour frames, :meth:`colour_frames`, adds ``frames: "bgr"``)."""
        events = self.events
        options = (run_options(model, self.params, None, "bgr") if events
                   else run_options(model, self.params, self.fps, self.color_order))
        if self.colour_frames(model):
            options["frames"] = "bgr"
        fp = fingerprint(self.path, self.condition, model, self.seed, self.backend, self.rain_params, self.arch,
                         options)
        if events:
            fp.update(bin_ms=float(self.bin_ms), event_threshold=float(self.event_threshold),
                      sensor_size=None if self.sensor_size is None else list(self.sensor_size))
        if self.key:
            fp.update(params={k: v for k, v in self.setting}, downscale=self.downscale)
        return fp

    def model_params(self, model: str) -> Any:
        """The parameters ``model`` runs with: a sweep's setting, else ``--param``'s (None: the defaults)."""
        if self.setting:
            return get_model_class(model).params_type(**dict(self.setting))
        return (self.params or {}).get(model)

    def colour_frames(self, model: str) -> bool:
        """Whether ``model`` takes the clip's decoded colour frames (:meth:`~cdnf_ti.models.base.Model.frame_colour`
        ``"bgr"``): a video under the clean condition (rainy frames are grey; event bins have no colour)."""
        if self.events or self.condition != "clean":
            return False
        return get_model_class(model).frame_colour(self.model_params(model)) == "bgr"

    def entry(self, model: str) -> Entry:
        """The cache entry of ``model``'s trace on this clip."""
        e = trace_entry(self.out, self.condition, self.clip, model, self.fingerprint(model))
        return dataclasses.replace(e, name=f"{self.clip}.{model} [{self.key}, {self.condition}]") if self.key else e


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


def _resized(frames, factor: float):
    """Frames (arrays, or :class:`~cdnf_ti.frames.ColourFrame`: both forms) resized by ``factor`` (area average)."""
    for f in frames:
        h, w = f.shape[:2]
        size = (max(2, round(w * factor)), max(2, round(h * factor)))
        if isinstance(f, ColourFrame):
            yield ColourFrame(*(cv2.resize(a, size, interpolation=cv2.INTER_AREA) for a in (f.grey, f.bgr)))
        else:
            yield cv2.resize(f, size, interpolation=cv2.INTER_AREA)


def _resized_bins(bins, factor: float):
    """Event bins ``(p_on, p_off)`` resized as frames are (area average of each channel: the model's net
    contrast ``p_on - p_off`` is then the area average of the full-size one, as for frames)."""
    for p_on, p_off in bins:
        h, w = p_on.shape
        size = (max(2, round(w * factor)), max(2, round(h * factor)))
        yield (cv2.resize(p_on, size, interpolation=cv2.INTER_AREA),
               cv2.resize(p_off, size, interpolation=cv2.INTER_AREA))


def _open(task: ClipTask):
    """The task's input: an :class:`~cdnf_ti.events.source.EventSource` for an event recording,
    else a frame source."""
    if task.events:
        if task.condition != "clean":
            raise InputError(task.path, "is an event recording; --rain applies to frames only")
        return open_event_source(task.path, task.sensor_size, task.bin_ms, quiet=True, max_gap_s=task.max_gap_s,
                                 max_span_s=task.max_span_s)
    return open_source(task.path, fps=task.fps, color_order=task.color_order)


def _frames(task: ClipTask, src, colour: bool = False):
    """The frame stream of a task (grey, or :class:`~cdnf_ti.frames.ColourFrame` with ``colour``, where a
    model takes colour frames; rainy, and grey, for the rain condition; resized) and the rain object;
    for an event recording, its bins ``(p_on, p_off)`` (resized)."""
    if isinstance(src, EventSource):
        bins = src.contrast(task.event_threshold)
        return (_resized_bins(bins, task.downscale) if task.downscale != 1.0 else bins), None
    frames = iter_frames(src, colour and task.condition == "clean")
    rain = None
    if task.condition != "clean":
        params = RainParams(**task.rain_params) if task.rain_params else None
        rain = RainyFrames(frames, params, seed=rain_seed(task.seed, task.clip),
                           backend="numpy" if task.backend == "numpy" else "taichi")
        frames = iter(rain)
    if task.downscale != 1.0:
        frames = _resized(frames, task.downscale)
    return frames, rain


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
        unconverged_frames, seconds, error`` (``error`` empty on success; a
        sweep's records add ``key`` and ``setting``). A clip that cannot be
        opened or decoded gives records with ``error`` set for every model;
        nothing is saved for them, so a rerun tries again.
    """
    if task.backend == "taichi":
        init_worker(task.arch)
    base = {"clip": task.clip, "condition": task.condition}
    if task.key:
        base["key"] = task.key

    def failed(names, e: BaseException) -> list[dict]:
        msg = str(e) if isinstance(e, InputError) else f"{task.path}: {type(e).__name__}: {e}"
        return [dict(base, model=m, error=msg.splitlines()[0] if msg else type(e).__name__) for m in names]

    try:
        src = _open(task)
        try:
            check_frame_size(*src.shape, n_models=len(task.models), what=str(task.path),
                             binning=isinstance(src, EventSource))
        except UserError as e:  # frames smaller than the widest kernel: that clip's error rows
            raise InputError(task.path, str(e).split(": ", 1)[-1]) from None
    except InputError as e:
        return failed(task.models, e)
    records: dict[str, dict] = {}
    names, instances = [], []
    for name in task.models:
        try:
            instances.append(create_model(name, task.model_params(name), backend=task.backend, arch=task.arch,
                                          fps=src.fps))
            names.append(name)
        except Exception as e:  # noqa: BLE001 - one model's failure is that model's error row
            records.update((r["model"], r) for r in failed([name], e))
    if instances:
        errors: list = []
        rain = None
        t0 = time.perf_counter()
        try:
            frames, rain = _frames(task, src, takes_colour(instances))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", NotConvergedWarning)  # recorded as unconverged_frames
                traces = run_models(instances, frames, progress=False, errors=errors)
        except (InputError, OSError, RuntimeError, ValueError) as e:  # the clip (or its rain) is bad
            traces, errors = [None] * len(names), [e] * len(names)
        wall = time.perf_counter() - t0
        snr = None
        if rain is not None and errors.count(None):
            s = getattr(rain, "snr_db", None)
            snr = None if s is None or not math.isfinite(float(s)) else float(s)
        problems = src.report.problems() if isinstance(src, EventSource) else []
        for name, trace, err in zip(names, traces, errors):
            if err is not None or trace is None:
                records.update((r["model"], r) for r in failed([name], err or RuntimeError("no trace")))
                continue
            meta = dict(
                base, model=name, frames=trace.n_frames, fps=float(src.fps), first_alert=trace.first_alert,
                max_output=float(trace.output.max()) if trace.n_frames else None,
                output_name=trace.output_name, threshold=trace.threshold, snr_db=snr,
                unconverged_frames=int((~trace.converged).sum()),
                seconds=round(float(trace.seconds if not task.key else wall), 3),
                source=str(task.path), seed=task.seed if rain is not None else None,
                rain_seed=rain_seed(task.seed, task.clip) if rain is not None else None, error="",
            )
            if isinstance(src, EventSource):
                meta.update(bin_ms=task.bin_ms, event_threshold=task.event_threshold,
                            sensor_size=list(src.sensor_size), event_warnings=problems)
            if task.key:
                meta["setting"] = {k: v for k, v in task.setting}
            entry = task.entry(name)
            trace.to_csv(entry.outputs[0])
            records[name] = save_finished(entry, meta)
    return [records[m] for m in task.models]


def describe_clip_task(task: ClipTask, records: Any) -> str:
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


def run_clips(clips: Sequence[tuple[str, str]], out: str | os.PathLike, models: Sequence[str],
              conditions: Sequence[str], seed: int = 0, workers: int | None = None, scheduler: Any = None,
              backend: str = "taichi", arch: str = "cpu", progress: bool = True, rain_params: dict | None = None,
              on_record: Callable[[dict], None] | None = None, params: dict | None = None, fps: float | None = None,
              color_order: str = "bgr", sensor_size: tuple[int, int] | None = None, bin_ms: float | None = None,
              event_threshold: float = DEFAULT_EVENT_THRESHOLD, max_gap_s: float = DEFAULT_MAX_GAP_S,
              max_span_s: float = DEFAULT_MAX_SPAN_S) -> tuple[dict[tuple[str, str, str], dict], CachedRun]:
    """Every clip x condition x model, reusing finished traces (the dataset engine).

    Parameters
    ----------
    clips : sequence of (clip, path)
        Clip names and their (absolute) files.
    out : path-like
        Output folder (traces under ``out/traces/``).
    models, conditions : sequence of str
    seed, workers, scheduler, backend, arch, progress, rain_params, params, fps, color_order
        As :func:`cdnf_ti.experiments.dataset.run_dataset`.
    sensor_size, bin_ms, event_threshold, max_gap_s, max_span_s
        How the clips that are event recordings are binned (``--sensor-size``, ``--bin-ms``,
        ``--event-threshold``, ``--max-gap-s``, ``--max-span-s``); ``bin_ms`` None: each model at its
        own width (:func:`~cdnf_ti.models.base.bin_ms_for`), the models of one width sharing a pass.
    on_record : callable, optional
        Called in this process with each record computed now (after a ``warning:`` line on stderr
        for each problem found while binning an event recording).

    Returns
    -------
    (dict, CachedRun)
        ``{(clip, model, condition): record}`` and what was reused and computed.
    """
    keys, tasks = [], []
    for clip, path in clips:
        for cond in conditions:
            for m in models:
                keys.append((clip, m, cond))
                tasks.append(ClipTask(clip, str(path), cond, (m,), str(out), seed, backend, arch, rain_params,
                                      params=params, fps=fps, color_order=color_order, sensor_size=sensor_size,
                                      bin_ms=bin_ms_for(get_model_class(m), (params or {}).get(m), bin_ms),
                                      event_threshold=event_threshold, max_gap_s=max_gap_s,
                                      max_span_s=max_span_s))

    def plan(todo: list[int]) -> list[tuple[ClipTask, list[int]]]:
        groups: dict[tuple[str, str, float], list[int]] = {}
        for i in todo:  # one pass per clip, condition and bin width (a video's width is unused)
            groups.setdefault((tasks[i].clip, tasks[i].condition, tasks[i].bin_ms), []).append(i)
        return [(dataclasses.replace(tasks[ix[0]], models=tuple(tasks[i].models[0] for i in ix)), ix)
                for ix in groups.values()]

    def failed(i: int, msg: str) -> dict:
        t = tasks[i]
        return dict(clip=t.clip, model=t.models[0], condition=t.condition,
                    error=msg if msg == "not run" else f"{t.path}: {msg}")

    run = run_cached([t.entry(t.models[0]) for t in tasks], plan, run_clip_task, failed=failed, workers=workers,
                     scheduler=scheduler, arch=arch, progress="clips" if progress else False,
                     describe=describe_clip_task, on_record=lambda i, r: _arrived(r, on_record))
    return dict(zip(keys, run.records)), run


def _arrived(record: dict, on_record: Callable[[dict], None] | None = None) -> None:
    """A record computed now: print its binning problems (``warning: <file>: ...``), then hand it on."""
    for line in record.get("event_warnings") or ():
        print(f"warning: {record.get('source', record.get('clip'))}: {line}", file=sys.stderr)
    if on_record is not None:
        on_record(record)


def batch_bin_ms(models: Sequence[str], params: dict | None = None, bin_ms: float | None = None) -> float | None:
    """The one width, ms, at which a batch run bins its event recordings for all its models.

    A batch scores every model against one set of labels per clip, so its models read a recording's
    bins at one width: ``bin_ms`` (``--bin-ms``) when given, else the own width
    (:func:`~cdnf_ti.models.base.bin_ms_for`) of the models that take events (of every model when
    none does) when they share one, else None (they differ; :func:`check_event_bins` then bins at
    the default width, with a note).
    """
    readers = [m for m in models if get_model_class(m).takes_events] or list(models)
    widths = {bin_ms_for(get_model_class(m), (params or {}).get(m), bin_ms) for m in readers}
    return widths.pop() if len(widths) == 1 else None


def check_event_bins(labels: Sequence[ClipLabel], files: dict[str, str | os.PathLike], models: Sequence[str],
                     params: dict | None, bin_ms: float | None, labels_path: str | os.PathLike) -> float:
    """The width a batch run bins its event recordings at (:func:`batch_bin_ms`), checked against its labels.

    Parameters
    ----------
    labels : sequence of ClipLabel
        The labels, their windows in frames at that width (:func:`~.labels.labels_in_frames`).
    files : dict
        Clip -> its file.
    models, params, bin_ms :
        The run's models, ``{model: parameter object}`` and ``--bin-ms`` (None: not given).
    labels_path : path-like
        The labels file, for messages.

    Returns
    -------
    float
        The width, ms; the default width when the models' own widths differ (with a ``note:`` when a clip
        is a recording).

    Raises
    ------
    InputError
        A recording's window or contact is given in frames, which count bins of ``--bin-ms``, else of
        the default width, while the models bin it at another width of their own.
    """
    width = batch_bin_ms(models, params, bin_ms)
    recordings = [lab for lab in labels if lab.clip in files and is_event_file(files[lab.clip])]
    if not recordings or bin_ms is not None:
        return DEFAULT_BIN_MS if width is None else width
    if width is None:
        own = ", ".join(f"{m} {bin_ms_for(get_model_class(m), (params or {}).get(m)):.4g} ms" for m in models
                        if get_model_class(m).takes_events)
        print(f"note: the models bin event recordings at different widths ({own}); a batch run scores every model "
              f"against one set of labels per clip, so all bin them at {DEFAULT_BIN_MS:.6g} ms here "
              "(--bin-ms MS chooses the width)", file=sys.stderr)
        return DEFAULT_BIN_MS
    in_bins = [lab.clip for lab in recordings
               if not lab.in_seconds and (lab.window_start is not None or lab.contact_frame is not None)]
    if in_bins and width != DEFAULT_BIN_MS:
        shown = ", ".join(in_bins[:5]) + (", ..." if len(in_bins) > 5 else "")
        raise InputError(labels_path, f"the windows of {len(in_bins)} event recording(s) ({shown}) are in frames, "
                                      f"which count bins of --bin-ms (default {DEFAULT_BIN_MS:.6g} ms), but "
                                      f"{', '.join(models)} bin(s) them at {width:.4g} ms: give --bin-ms MS (the width "
                                      "the labels count; every model then bins at it) or the windows in seconds "
                                      "(window_start_s, window_end_s)")
    return width


def event_clips(files: dict[str, str | os.PathLike]) -> list[str]:
    """The clips (of ``{clip: file}``) that are event recordings, in order."""
    return [clip for clip, f in files.items() if is_event_file(f)]


def note_inferred_sensor_size(files: dict[str, str | os.PathLike], sensor_size: tuple[int, int] | None) -> None:
    """A ``note:`` naming the event recordings whose sensor size is inferred from their events
    (neither ``--sensor-size`` nor the file states one), as ``run`` says per file."""
    if sensor_size is not None:
        return
    inferred = []
    for clip in event_clips(files):
        try:
            if open_events(files[clip]).sensor_size is None:
                inferred.append(clip)
        except InputError:
            continue  # a bad recording: its own error line when the run reaches it
    if inferred:
        shown = ", ".join(inferred[:5]) + (", ..." if len(inferred) > 5 else "")
        print(f"note: {len(inferred)} event recording(s) state no sensor size ({shown}); each uses the smallest "
              "that holds its events (give --sensor-size WxH to set it)", file=sys.stderr)


def frames_only_conditions(files: dict[str, str | os.PathLike], conditions: Sequence[str],
                           folder: str | os.PathLike) -> list[str]:
    """The conditions a batch runs, given that synthetic rain applies to frames only.

    Rain is drawn on frames; an event recording has none. When every clip is an event
    recording, ``--rain both`` runs them clean (a ``note:`` says so).

    Raises
    ------
    UserError
        Rain is asked for the event recordings of a folder that also holds videos, or rain
        only (``--rain on``) for a folder of event recordings.
    """
    if "rain" not in conditions:
        return list(conditions)
    ev = event_clips(files)
    if not ev:
        return list(conditions)
    shown = ", ".join(ev[:5]) + (", ..." if len(ev) > 5 else "")
    if len(ev) == len(files) and "clean" in conditions:
        print(f"note: --rain applies to frames only; the {len(ev)} event recording(s) of {folder} run clean only",
              file=sys.stderr)
        return ["clean"]
    what = ("every labelled clip in {} is an event recording" if len(ev) == len(files)
            else f"{len(ev)} of the {len(files)} labelled clips in {{}} are event recordings").format(folder)
    raise UserError(f"--rain applies to frames only, and {what} ({shown}); "
                    f"run them with --rain off" + ("" if len(ev) == len(files) else
                                                   " (or the videos and the recordings as separate folders)"))


@dataclass(frozen=True)
class SweepTask:
    """One clip x model setting x condition of a parameter sweep.

    Attributes
    ----------
    clip, path : str
    model : str
    setting : tuple of (name, value)
    key : str
        :func:`cdnf_ti.experiments.paramsweep.setting_key` of the setting.
    condition : {"clean", "rain"}
    out : str
        The sweep's output folder (the task writes under ``OUT/settings/<key>``).
    seed : int
    backend, arch : str
    downscale : float
        Frames are resized by this factor (1 = native size).
    fps, color_order :
        How the clip is read (``--fps``, ``--color-order``).
    sensor_size, bin_ms, event_threshold, max_gap_s, max_span_s :
        How an event recording is binned (``--sensor-size``, ``--bin-ms``, ``--event-threshold``,
        ``--max-gap-s``, ``--max-span-s``); ``bin_ms`` None: the model's own width with its default
        parameters (:func:`~cdnf_ti.models.base.bin_ms_for`).
    """

    clip: str
    path: str
    model: str
    setting: tuple
    key: str
    condition: str
    out: str
    seed: int = 0
    backend: str = "taichi"
    arch: str = "cpu"
    downscale: float = 1.0
    fps: float | None = None
    color_order: str = "bgr"
    sensor_size: tuple[int, int] | None = None
    bin_ms: float | None = None
    event_threshold: float = DEFAULT_EVENT_THRESHOLD
    max_gap_s: float = DEFAULT_MAX_GAP_S
    max_span_s: float = DEFAULT_MAX_SPAN_S

    @property
    def clip_task(self) -> ClipTask:
        """The same work as a :class:`ClipTask` of one model under ``OUT/settings/<key>``."""
        return ClipTask(self.clip, self.path, self.condition, (self.model,), str(setting_folder(self.out, self.key)),
                        self.seed, self.backend, self.arch, None, fps=self.fps, color_order=self.color_order,
                        setting=tuple(self.setting), downscale=float(self.downscale), key=self.key,
                        sensor_size=self.sensor_size, bin_ms=bin_ms_for(get_model_class(self.model), None, self.bin_ms),
                        event_threshold=self.event_threshold,
                        max_gap_s=self.max_gap_s, max_span_s=self.max_span_s)


def setting_folder(out: str | os.PathLike, key: str) -> Path:
    """``OUT/settings/<key>``: where the traces of one sweep setting go."""
    return inside(Path(out) / "settings", key)


def task_fingerprint(task: SweepTask) -> dict:
    """The dataset fingerprint of the input plus the setting and the downscale factor."""
    return task.clip_task.fingerprint(task.model)


def run_sweep_task(task: SweepTask) -> dict:
    """Run one model setting on one clip; save its trace and record (atomically).

    Returns
    -------
    dict
        The record (``error`` empty on success).
    """
    return run_clip_task(task.clip_task)[0]


def describe_sweep_task(task: SweepTask, result: Any = None) -> str:
    """Progress line of one task: ``c01 [cdnf h=0.1,alpha_off=0.7, clean]: 12.3 s``."""
    line = f"{task.clip} [{task.model} {task.key}, {task.condition}]"
    if isinstance(result, TaskFailed):
        return f"{line}: error: {result}"
    if isinstance(result, dict):
        if result.get("error"):
            return f"{line}: error: {result['error']}"
        if result.get("seconds") is not None:
            return f"{line}: {result['seconds']:.1f} s"
    return line


def run_sweep(tasks: Sequence[SweepTask], workers: int | None = None, scheduler: Any = None, arch: str = "cpu",
              progress: bool | str = False) -> CachedRun:
    """Every sweep task, reusing finished traces (the parameter-sweep engine); one unit per task."""
    def failed(i: int, msg: str) -> dict:
        t = tasks[i]
        return dict(clip=t.clip, model=t.model, condition=t.condition, key=t.key,
                    error=msg if msg == "not run" else f"{t.path}: {msg}")

    return run_cached([t.clip_task.entry(t.model) for t in tasks], lambda todo: [(tasks[i], [i]) for i in todo],
                      run_sweep_task, failed=failed, workers=workers, scheduler=scheduler, arch=arch,
                      progress=progress, describe=describe_sweep_task, on_record=lambda i, r: _arrived(r))


@dataclass
class DatasetRun:
    """Everything a dataset run produced.

    Attributes
    ----------
    rows : list of dict
        results.csv rows (:data:`~.layout.RESULT_COLUMNS`), in labels x condition x model order.
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


@dataclass
class ParamSweepRun:
    """What a parameter sweep produced."""

    model: str
    axes: list
    settings: list
    conditions: list
    rows: list
    records: dict
    out: Path
    ran: int = 0
    skipped: int = 0
    errors: list = field(default_factory=list)
    nested: dict = field(default_factory=dict)
