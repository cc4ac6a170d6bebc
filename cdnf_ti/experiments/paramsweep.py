"""Parameter sweeps: a grid of any model's parameters over a labelled dataset.

``python -m cdnf_ti.run experiment sweep DIR --model cdnf --param h=0.1:0.3:5 --param alpha_on=0.3,0.5,0.7``

* The grid is the product of every ``--param NAME=SPEC``; ``SPEC`` is
  ``START:STOP:N`` (N evenly spaced values, both ends included), a comma list
  ``V1,V2,...`` or one value. ``NAME`` is a field of the model's parameter
  dataclass (``CDNFParams``, ``LGMD2Params``, ...). The whole grid is checked
  (names, ranges, every combination built and validated) before any work.
* One task per clip x setting (x condition), run by the clip engine of
  ``dataset`` (:mod:`.clip_tasks`, through :func:`.tasks.run_cached`) in this
  process, on local processes or on a Dask cluster, each saving its trace
  atomically under ``OUT/settings/<setting>/traces/<condition>/``; a rerun reuses
  every finished task whose fingerprint (input, model, setting, downscale, rain
  seed, and the code, compiler and arch) matches, and says what it recomputes.
* Per setting and condition: accuracy at the setting's own alert rule, the
  clip-level ROC AUC over the alert level, leave-one-out (or k-fold)
  cross-validated accuracy with the alert level chosen on the other folds, and
  the best in-sample accuracy (marked as such).
* Over the whole grid: nested cross-validated accuracy, with the setting and
  the alert level both chosen on the other folds (:mod:`.nested`), with a
  bootstrap interval and how often each setting was chosen; the same for
  before-contact hits only.

Output: ``OUT/param_sweep.csv``, ``OUT/param_sweep.json``, ``OUT/param_sweep.md``,
``OUT/figures/param_sweep_*.png`` and ``OUT/report.html``.
"""
from __future__ import annotations

import dataclasses
import itertools
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..atomic import atomic_write_json
from ..errors import InputError, UserError
from ..models import get_model_class
from ..models.base import Trace
from ..param_options import convert_value, field_kind
from .clip_tasks import (
    ParamSweepRun as ParamSweepRun,  # re-exported: paramsweep.py was their home
    SweepTask as SweepTask,
    batch_bin_ms,
    check_event_bins,
    describe_sweep_task as describe_task,
    frames_only_conditions,
    note_inferred_sensor_size,
    run_sweep,
    run_sweep_task as run_sweep_task,
    setting_folder as setting_folder,
    task_fingerprint as task_fingerprint,
)
from .clipscores import choose_level, correctness_matrix, cross_validated_accuracy, roc
from .labels import load_labels
from .layout import RAIN_CHOICES, trace_path
from .nested import sweep_nested_cv
from .parallel import cleaned_up
from .scoring import Padding, score_clip
from .sweep import (
    alert_levels as alert_levels,
    setting_default_level as setting_default_level,
    sweep_first_alerts,
    sweep_spec,
)
from .sweep_reports import write_param_sweep_reports

__all__ = ["MAX_SETTINGS", "ParamAxis", "ParamSweepRun", "SweepTask", "alert_levels", "before_contact", "build_grid",
           "describe_task", "evaluate", "parse_param", "run_param_sweep", "run_sweep_task", "setting_default_level",
           "setting_folder", "setting_key", "task_fingerprint"]

MAX_SETTINGS = 10_000


@dataclass(frozen=True)
class ParamAxis:
    """One swept parameter: its name and values (typed like the dataclass field)."""

    name: str
    values: tuple


def parse_param(spec: str, params_type: type) -> ParamAxis:
    """Parse ``NAME=START:STOP:N``, ``NAME=V1,V2,...`` or ``NAME=V``.

    Raises
    ------
    ValueError
        One-line message: unknown parameter, malformed range, non-numeric or
        duplicate value.
    """
    name, eq, body = spec.partition("=")
    name = name.strip()
    if not eq or not name:
        raise UserError(f"--param {spec!r}: expected NAME=START:STOP:N or NAME=V1,V2,...")
    kind = field_kind(params_type, name)
    body = body.strip()
    if ":" in body:
        parts = body.split(":")
        if len(parts) != 3:
            raise UserError(f"--param {name}={body}: a range is START:STOP:N (three parts)")
        if kind in ("bool", "str"):
            raise UserError(f"--param {name}={body}: {name} is a {kind}; list its values instead")
        a, b = (convert_value("float", name, p) for p in parts[:2])
        try:
            n = int(parts[2])
        except ValueError:
            raise UserError(f"--param {name}={body}: N must be a whole number of values, got {parts[2]!r}") from None
        if n < 2:
            raise UserError(f"--param {name}={body}: N must be at least 2 (give one value as {name}=V)")
        if n > 1000:
            raise UserError(f"--param {name}={body}: N = {n} values is too many (at most 1000)")
        if a >= b:
            raise UserError(f"--param {name}={body}: START must be below STOP")
        vals = [float(v) for v in np.round(np.linspace(a, b, n), 10)]
        if kind == "int":
            if not all(float(v).is_integer() for v in vals):
                raise UserError(f"--param {name}={body}: {name} is an integer but the range gives "
                                 f"non-integer values {vals}")
            vals = [int(v) for v in vals]
    else:
        vals = [convert_value(kind, name, p) for p in body.split(",")]
    if len(set(vals)) != len(vals):
        raise UserError(f"--param {name}={body}: a value is repeated")
    return ParamAxis(name, tuple(vals))


def setting_key(setting: dict) -> str:
    """File-name-safe key of one setting, e.g. ``h=0.1,alpha_on=0.3``."""
    def fmt(v: Any) -> str:
        return f"{v:.6g}" if isinstance(v, float) else str(v)

    key = ",".join(f"{k}={fmt(v)}" for k, v in setting.items())
    return "".join(ch if ch.isalnum() or ch in "=,._-" else "_" for ch in key) or "default"


def build_grid(model: str, param_specs: Sequence[str]) -> tuple[type, list[ParamAxis], list[dict]]:
    """Parse every ``--param`` and check every combination builds valid parameters.

    Returns
    -------
    (params_type, axes, settings)
        ``settings`` is the grid, one dict per setting (the first axis varies slowest).

    Raises
    ------
    ValueError
        One line naming the bad ``--param`` or the first invalid combination.
    """
    cls = get_model_class(model)
    ptype = cls.params_type
    if not dataclasses.is_dataclass(ptype):
        raise UserError(f"model {cls.name} has no parameter dataclass to sweep")
    axes = [parse_param(s, ptype) for s in param_specs]
    names = [a.name for a in axes]
    dup = [n for n in names if names.count(n) > 1]
    if dup:
        raise UserError(f"--param {dup[0]} is given twice")
    n = 1
    for a in axes:
        n *= len(a.values)
    if n > MAX_SETTINGS:
        raise UserError(f"the grid has {n} settings; at most {MAX_SETTINGS}")
    settings = [dict(zip(names, combo)) for combo in itertools.product(*(a.values for a in axes))] or [{}]
    for s in settings:
        try:
            ptype(**s)
        except (ValueError, TypeError) as e:
            desc = ", ".join(f"{k}={v}" for k, v in s.items())
            raise UserError(f"--param setting {desc} is invalid: {str(e).splitlines()[0]}") from None
    return ptype, axes, settings


def run_param_sweep(folder: str | os.PathLike, labels_path: str | os.PathLike | None, out: str | os.PathLike,
                    model: str, param_specs: Sequence[str], rain: str = "none", padding=None, seed: int = 0,
                    folds: int = 0, workers: int | None = None, scheduler: Any = None, backend: str = "taichi",
                    arch: str = "cpu", progress: bool = True, figures: bool = True, downscale: float = 1.0,
                    html: bool = True, fps: float | None = None, color_order: str = "bgr",
                    skip_missing: bool = False, events: dict | None = None) -> ParamSweepRun:
    """Run the grid over every labelled clip and write the sweep reports.

    Parameters
    ----------
    folder, labels_path, out : path-like
        Dataset folder, labels CSV (None: ``folder/labels.csv``), output folder.
    model : str
        Registry name.
    param_specs : sequence of str
        ``NAME=SPEC`` strings (see :func:`parse_param`).
    rain : {"none", "only", "both"}
    padding : Padding, optional
    seed : int
        Rain seed and k-fold shuffle seed.
    folds : int
        0 = leave-one-out cross-validation; k >= 2 = k folds.
    workers, scheduler : see :func:`cdnf_ti.experiments.parallel.map_tasks`
    backend, arch : str
    progress, figures, html : bool
    downscale : float
        Resize factor of every frame (in (0, 1]; 1 = native).
    fps, color_order : optional
        How clips are read (``--fps``, ``--color-order``).
    skip_missing : bool
        Leave out labelled clips whose video is missing (a note lists them); by default an error.
    events : dict, optional
        How the clips that are event recordings are binned: ``sensor_size``, ``bin_ms``,
        ``event_threshold`` (as :func:`cdnf_ti.experiments.dataset.run_dataset`; without ``bin_ms``
        every setting at the model's own width with its default parameters).

    Raises
    ------
    ValueError, InputError
        Bad grid, bad labels, bad option: before any task runs.
    """
    padding = padding or Padding()
    if rain not in RAIN_CHOICES:
        raise UserError(f"--rain must be one of {', '.join(RAIN_CHOICES)}, got {rain!r}")
    if not (0 < downscale <= 1):
        raise UserError(f"--downscale must be in (0, 1], got {downscale}")
    if folds < 0 or folds == 1:
        raise UserError(f"--folds must be 0 (leave-one-out) or at least 2, got {folds}")
    name = get_model_class(model).name
    _ptype, axes, settings = build_grid(name, param_specs)
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(folder, "dataset folder not found")
    labels_path = Path(labels_path) if labels_path is not None else folder / "labels.csv"
    events = dict(events or {})
    labels, files = load_labels(labels_path, folder, fps, batch_bin_ms([name], None, events.get("bin_ms")),
                                skip_missing)
    events["bin_ms"] = check_event_bins(labels, files, [name], None, events.get("bin_ms"), labels_path)
    conditions = frames_only_conditions(files, RAIN_CHOICES[rain], folder)
    note_inferred_sensor_size(files, events.get("sensor_size"))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / "grid.json", {"model": name, "params": {a.name: list(a.values) for a in axes},
                                          "settings": len(settings), "conditions": conditions,
                                          "downscale": downscale, "dataset": str(folder),
                                          "labels": str(labels_path)})
    tasks = [SweepTask(lab.clip, str(Path(files[lab.clip]).resolve()), name, tuple(s.items()), setting_key(s),
                       cond, str(out), seed, backend, arch, float(downscale), fps, color_order, **events)
             for s in settings for cond in conditions for lab in labels]
    with cleaned_up(out):  # stale temporary files removed; Ctrl-C and SIGTERM stop the workers cleanly
        done = run_sweep(tasks, workers=workers, scheduler=scheduler, arch=arch,
                         progress=f"sweep {name}" if progress else False)
    records = {(t.key, t.condition, t.clip): r for t, r in zip(tasks, done.records)}
    errors = [r for r in done.records if r.get("error")]
    ran, skipped = done.ran, done.reused
    alerts: dict = {}
    rows = evaluate(out, name, settings, conditions, labels, padding, folds, seed, alerts=alerts)
    labs = {lab.clip: lab for lab in labels}
    nested = sweep_nested_cv(alerts, labs, {c: before_contact(lab) for c, lab in labs.items()}, padding, folds, seed)
    run = ParamSweepRun(name, axes, settings, conditions, rows, records, out, ran, skipped, errors, nested)
    write_param_sweep_reports(run, labels, padding, folds, seed, figures=figures, html=html)
    return run


def evaluate(out: Path, model: str, settings: Sequence[dict], conditions: Sequence[str], labels, padding,
             folds: int = 0, seed: int = 0, alerts: dict | None = None) -> list[dict]:
    """Score every setting x condition from the saved traces.

    ``alerts``, when given, receives ``alerts[condition][setting key] =
    (first alerts per clip and level, levels, the setting's own level)`` for
    :func:`cdnf_ti.experiments.nested.sweep_nested_cv`.

    Returns
    -------
    list of dict
        One row per setting and condition: the setting's values, ``condition``,
        ``clips``, ``accuracy`` (the setting's own alert rule), ``auc``,
        ``cv_accuracy``, ``cv_scheme``, ``best_in_sample_accuracy``,
        ``best_in_sample_level``, ``alert_parameter``, ``errors``.
    """
    labs = {lab.clip: lab for lab in labels}
    rows = []
    for s in settings:
        key = setting_key(s)
        sf = setting_folder(out, key)
        for cond in conditions:
            traces = {}
            fps_of: dict[str, float] = {}
            n_err = 0
            for lab in labels:
                p = trace_path(sf, cond, lab.clip, model)
                jp = trace_path(sf, cond, lab.clip, model, "json")
                if not (p.is_file() and jp.is_file()):
                    n_err += 1
                    continue
                traces[lab.clip] = Trace.from_csv(p, model=model)
                try:
                    fps_of[lab.clip] = float(json.loads(jp.read_text(encoding="utf-8")).get("fps") or 30.0)
                except (OSError, ValueError):
                    fps_of[lab.clip] = 30.0
            row: dict[str, Any] = dict(s)
            row.update(setting=key, condition=cond, clips=len(traces), errors=n_err)
            if not traces:
                rows.append(row)
                continue
            spec = sweep_spec(model, list(traces.values()))
            levels = alert_levels(spec, list(traces.values()), s)
            spec = dataclasses.replace(spec, values=tuple(levels))
            default = setting_default_level(spec, s)
            fas = {c: sweep_first_alerts(spec, tr) for c, tr in traces.items()}
            if alerts is not None:
                alerts.setdefault(cond, {})[key] = (fas, levels, default)
            own = [score_clip(tr.first_alert, labs[c], 30.0, padding).outcome in ("TP", "TN")
                   for c, tr in traces.items()]
            r = roc(fas, labs, levels, padding)
            cv = cross_validated_accuracy(fas, labs, levels, padding, folds=folds, seed=seed, default=default)
            _, cm = correctness_matrix(fas, labs, padding)
            jb = choose_level(cm, levels, default)
            row.update(alert_parameter=spec.parameter, accuracy=float(np.mean(own)), auc=r.auc,
                       cv_accuracy=cv.accuracy, cv_scheme=cv.scheme,
                       best_in_sample_accuracy=float(cm[:, jb].mean()), best_in_sample_level=levels[jb],
                       max_output=float(max(tr.output.max() for tr in traces.values())),
                       hits=sum(1 for c, tr in traces.items() if labs[c].collision and
                                score_clip(tr.first_alert, labs[c], 30.0, padding).outcome == "TP"),
                       false_alarms=sum(1 for c, tr in traces.items() if not labs[c].collision
                                        and tr.first_alert is not None))
            # the same scores when only alerts strictly before contact count as hits
            pre = {c: before_contact(lab) for c, lab in labs.items()}
            own_pre = [score_clip(tr.first_alert, pre[c], 30.0, padding).outcome in ("TP", "TN")
                       for c, tr in traces.items()]
            row.update(accuracy_pre_contact=float(np.mean(own_pre)), auc_pre_contact=roc(fas, pre, levels, padding).auc,
                       cv_accuracy_pre_contact=cross_validated_accuracy(fas, pre, levels, padding, folds=folds,
                                                                        seed=seed, default=default).accuracy)
            leads = [score_clip(tr.first_alert, labs[c], fps_of.get(c, 30.0), padding)
                     for c, tr in traces.items() if labs[c].collision]
            hit_leads = [sc.lead_time_ms for sc in leads if sc.outcome == "TP" and sc.lead_time_ms is not None]
            row.update(hits_before_contact=sum(1 for v in hit_leads if v > 0),
                       median_hit_lead_ms=float(np.median([v for v in hit_leads if v > 0]))
                       if any(v > 0 for v in hit_leads) else None)
            rows.append(row)
    return rows


def before_contact(label):
    """``label`` with its window cut to end one frame before contact (when the contact frame is known),
    so that an alert at or after contact counts as late."""
    if not label.collision or label.contact_frame is None:
        return label
    end = max(label.window_start, min(label.window_end, label.contact_frame - 1))
    return dataclasses.replace(label, window_end=end)
