"""The dataset experiment: every labelled clip x model x condition (clean / rain), resumable.

Output folder layout (every file written atomically)::

    OUT/traces/<condition>/<clip>.<model>.csv    per-frame trace (Trace.to_csv)
    OUT/traces/<condition>/<clip>.<model>.json   what the run of that trace recorded (done marker)
    OUT/results.csv                              one row per clip x model x condition
    OUT/threshold_sweep.csv                      accuracy / hits / false alarms vs alert level
    OUT/summary.md, OUT/summary.json             Table II style summary
    OUT/figures/*.png                            traces (Fig. 5 style), threshold sweep, accuracy

A (clip, model, condition) whose ``.json`` exists, with the fingerprint the rerun
would write, is finished and reused (:mod:`.tasks`); the clip engine
(:mod:`.clip_tasks`) runs the rest, and the reports are written after it
returns. Scoring is always recomputed from the saved traces, so a rerun with a
different window padding re-scores without running any model.
"""
from __future__ import annotations

import os
import sys
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable, Sequence

from ..atomic import output_lock, prepare_output
from ..errors import InputError, UserError
from . import parallel
from .benchmark_formats import read_benchmark
from .clip_tasks import (
    ClipTask as ClipTask,  # re-exported: dataset.py was their home
    DatasetRun as DatasetRun,
    batch_bin_ms,
    check_event_bins,
    describe_clip_task as describe_task,
    frames_only_conditions,
    note_inferred_sensor_size,
    run_clip_task as run_clip_task,
    run_clips,
)
from .labels import ClipLabel, labels_in_frames, load_labels, unlabelled_videos
from .layout import (
    CONDITIONS as CONDITIONS,
    RAIN_CHOICES as RAIN_CHOICES,
    RESULT_COLUMNS as RESULT_COLUMNS,
    fingerprint as fingerprint,
    load_meta as load_meta,
    rain_seed as rain_seed,
    trace_path as trace_path,
)
from .reports import write_reports
from .scoring import Padding, score_clip

__all__ = ["CONDITIONS", "RAIN_CHOICES", "RESULT_COLUMNS", "ClipTask", "DatasetRun", "build_row", "config_dict",
           "describe_task", "fingerprint", "load_meta", "rain_seed", "run_clip_task", "run_dataset", "trace_path"]


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
    if meta.get("frames") == 0:  # nothing was seen: not a correct non-collision
        row["error"] = f"{meta.get('source') or label.clip}: holds no frames"
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
                fps: float | None = None, color_order: str = "bgr", skip_missing: bool = False,
                events: dict | None = None, fmt: str = "labels", split: str | None = None) -> DatasetRun:
    """Run ``models`` on every labelled clip of ``folder`` and write the reports.

    Parameters
    ----------
    folder : path-like
        Folder of videos and/or event recordings (:func:`~cdnf_ti.events.readers.is_event_file`).
        A recording is a clip whose frames are its bins: its labels count bins, bin ``k``
        starting ``k * bin_ms / 1000`` s into the recording. Every model reads a recording at one
        width (:func:`~.clip_tasks.check_event_bins`): ``--bin-ms``, else the models' own.
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
    events : dict, optional
        How event recordings are binned: ``sensor_size``, ``bin_ms`` (None or absent: the models'
        own width), ``event_threshold`` (:func:`cdnf_ti.cli_common.event_options_of`; default: the
        defaults). Rain applies to
        frames only (:func:`~.clip_tasks.frames_only_conditions`).
    fmt : {"labels", "nexar", "ccd", "dad", "dota"}
        The folder's layout: cdnf_ti's labels CSV, or a public benchmark's as distributed
        (:mod:`.benchmark_formats`; ``labels_path`` then names its annotation file, if not at its place).
    split : str, optional
        The benchmark's split (DAD ``training``/``testing``, DoTA ``train``/``val``; default: all clips).

    Raises
    ------
    InputError
        Bad labels file (before any work starts), or a recording's labels in bins of another width.
    UserError
        Bad option, or models of different bin widths on event recordings without ``--bin-ms``.
    OutputError
        ``out`` cannot be created or written (before any work starts).
    """
    if rain not in RAIN_CHOICES:
        raise UserError(f"--rain must be one of {', '.join(RAIN_CHOICES)}, got {rain!r}")
    folder = Path(folder)
    annotations = None
    models = list(dict.fromkeys(models))
    if not models:
        raise UserError("no model named")
    events = dict(events or {})
    width = batch_bin_ms(models, params, events.get("bin_ms"))  # the labels' bins (None: the default width)
    if fmt == "labels":
        labels_path = Path(labels_path) if labels_path is not None else folder / "labels.csv"
        labels, files = load_labels(labels_path, folder, fps, width, skip_missing)
    else:
        annotations, labels, files, fps = benchmark_labels(fmt, folder, labels_path, split, skip_missing, fps)
        labels_path = Path(labels_path) if labels_path is not None else folder
        labels = labels_in_frames(labels, files, fps, width, labels_path)
    events["bin_ms"] = check_event_bins(labels, files, models, params, events.get("bin_ms"), labels_path)
    conditions = frames_only_conditions(files, RAIN_CHOICES[rain], folder)
    note_inferred_sensor_size(files, events.get("sensor_size"))
    out = prepare_output(out)  # before any work: a folder that cannot be written fails now
    files = {clip: Path(f).resolve() for clip, f in files.items()}  # workers may run elsewhere
    with output_lock(out), parallel.cleaned_up(out):
        return _run_locked(folder, labels_path, labels, files, out, models, conditions, padding, seed,
                           workers, scheduler, backend, arch, progress, figures, rain_params, on_record,
                           dict(params=params, fps=fps, color_order=color_order, **events),
                           fmt, annotations)


def _run_locked(folder, labels_path, labels, files, out, models, conditions, padding, seed, workers, scheduler,
                backend, arch, progress, figures, rain_params, on_record, read: dict | None = None,
                fmt: str = "labels", annotations: dict | None = None) -> DatasetRun:
    metas, done = run_clips([(lab.clip, files[lab.clip]) for lab in labels], out, models, conditions, seed,
                            workers, scheduler, backend, arch, progress, rain_params, on_record, **(read or {}))
    rows = [build_row(lab, m, c, metas.get((lab.clip, m, c)), padding)
            for lab in labels for c in conditions for m in models]
    result = DatasetRun(rows, labels, models, conditions, padding, out, done.ran, done.reused,
                        unlabelled=unlabelled_videos(folder, labels) if fmt == "labels" else [])
    write_reports(result, dataset=str(folder), labels_path=str(labels_path), seed=seed, figures=figures,
                  progress=progress, fmt=fmt, annotations=annotations)
    return result


def benchmark_labels(fmt: str, folder: Path, annotation: str | os.PathLike | None, split: str | None,
                     skip_missing: bool, fps: float | None) -> tuple[dict, list[ClipLabel], dict, float | None]:
    """A benchmark folder's annotations (:func:`~.benchmark_formats.read_benchmark`) as the dataset engine
    takes them: ``(annotations by clip, labels, files by clip, fps)``.

    The labels are :meth:`~.annotations.Annotation.to_clip_label`; ``fps`` is ``--fps``, else the rate the
    benchmark states when its clips are image folders (DoTA: 10 fps), else None (each video's own).

    Raises
    ------
    InputError
        A bad annotation file; an annotated video that is absent (unless ``skip_missing``: then a
        ``note:`` lists them and they are left out).
    """
    anns = read_benchmark(fmt, folder, annotation, split)
    missing = [a for a in anns if a.path is None]
    if missing and not skip_missing:
        shown = ", ".join(a.clip for a in missing[:5]) + (", ..." if len(missing) > 5 else "")
        raise InputError(missing[0].source, f"{len(missing)} annotated clip(s) have no video in {folder}: {shown} "
                                            "(hint: --skip-missing runs the clips that are there)")
    if missing:
        print(f"note: --skip-missing: {len(missing)} annotated clip(s) have no video in {folder} and are left out",
              file=sys.stderr)
    anns = [a for a in anns if a.path is not None]
    if not anns:
        raise InputError(folder, "no annotated clip has its video here")
    if fps is None and all(a.path.is_dir() for a in anns) and anns[0].fps:
        fps = anns[0].fps
    labels = [a.to_clip_label(row=i + 1) for i, a in enumerate(anns)]
    return {a.clip: a for a in anns}, labels, {a.clip: a.path for a in anns}, fps


def config_dict(**kw: Any) -> dict:
    """JSON-safe copy of run options (for summary.json)."""
    return {k: (asdict(v) if hasattr(v, "__dataclass_fields__") else v) for k, v in kw.items()}
