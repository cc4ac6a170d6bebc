"""``experiment tune``: a seeded Optuna (TPE) search of one model's parameters inside nested cross-validation.

``python -m cdnf_ti.run experiment tune DIR --model cdnf --param h=0.05:0.3 --param alpha_on=0.3,0.5,0.7
--trials 20``

The outer folds score and the inner folds choose, as in ``experiment sweep``'s nested figure
(:mod:`.nested`), but the settings are proposed by Optuna's TPE sampler instead of a grid. For each
outer fold (default: one held-out clip):

1. a study (TPE, seed ``seed + fold``) runs ``--trials`` settings on the *training* clips only; a trial's
   value is the setting's inner cross-validated accuracy on them (:func:`~.nested.inner_cv_accuracy`: its
   alert level chosen on the other inner folds);
2. the best trial's setting is run on the held-out clips, its alert level chosen on all the training clips
   (:func:`~.clipscores.choose_level`; ties: the level closest to the setting's own);
3. the held-out clips are scored at that setting and level (accuracy; lead time before contact in s).

The out-of-sample accuracy is the share of held-out clips scored correctly over all folds, with a seeded
bootstrap interval; the report lists what each fold chose. Every (setting, clip) trace is a task of the
sweep engine (:func:`~.clip_tasks.run_sweep`: local workers or a Dask scheduler) cached under
``OUT/settings/<setting>/``, so a rerun with the same seed proposes the same settings and reuses them.
A search space is ``NAME=LO:HI`` (uniform; integers for an integer parameter), ``NAME=LO:HI:log``
(log-uniform) or ``NAME=V1,V2,...`` (a choice).
"""
from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..atomic import atomic_write_json, atomic_write_text
from ..errors import InputError, UserError
from ..models import get_model_class
from ..models.base import Trace
from ..param_options import convert_value, field_kind
from .clip_tasks import SweepTask, batch_bin_ms, check_event_bins, run_sweep, setting_folder
from .clipscores import bootstrap_accuracy, choose_level, correctness_matrix, fold_assignment
from .htmlreport import markdown_table
from .labels import drop_missing, labels_in_frames, read_labels, validate_dataset
from .layout import trace_path
from .nested import inner_cv_accuracy
from .paramsweep import setting_key
from .scoring import Padding
from .sweep import alert_levels, setting_default_level, sweep_first_alerts, sweep_spec

#: Most trials per fold.
MAX_TRIALS = 1000


@dataclass(frozen=True)
class SearchAxis:
    """One searched parameter: ``kind`` is ``"float"``, ``"int"`` or ``"choice"``; ``low``/``high`` bound a
    range (``log``: sampled log-uniformly); ``choices`` list the values of a choice."""

    name: str
    kind: str
    low: float = 0.0
    high: float = 0.0
    log: bool = False
    choices: tuple = ()

    def suggest(self, trial) -> Any:
        """This parameter's value for an Optuna trial (floats rounded to 6 significant digits, so a setting's
        name in the cache says its values exactly)."""
        if self.kind == "choice":
            return trial.suggest_categorical(self.name, list(self.choices))
        if self.kind == "int":
            return trial.suggest_int(self.name, int(self.low), int(self.high), log=self.log)
        return float(f"{trial.suggest_float(self.name, self.low, self.high, log=self.log):.6g}")


def parse_search(spec: str, params_type: type) -> SearchAxis:
    """``NAME=LO:HI``, ``NAME=LO:HI:log`` or ``NAME=V1,V2,...`` as a :class:`SearchAxis`.

    Raises
    ------
    UserError
        Unknown parameter, malformed range, or a bad value (one line).
    """
    name, eq, body = spec.partition("=")
    name, body = name.strip(), body.strip()
    if not eq or not name or not body:
        raise UserError(f"--param {spec!r}: expected NAME=LO:HI, NAME=LO:HI:log or NAME=V1,V2,...")
    kind = field_kind(params_type, name)
    if ":" not in body:
        vals = tuple(convert_value(kind, name, v) for v in body.split(","))
        if len(set(vals)) != len(vals):
            raise UserError(f"--param {name}={body}: a value is repeated")
        return SearchAxis(name, "choice", choices=vals)
    parts = body.split(":")
    log = len(parts) == 3 and parts[2].strip().lower() == "log"
    if len(parts) != 2 and not log:
        raise UserError(f"--param {name}={body}: a range is LO:HI or LO:HI:log")
    if kind not in ("int", "float"):
        raise UserError(f"--param {name}={body}: {name} is a {kind}; list its values instead")
    lo, hi = (convert_value("float", name, p) for p in parts[:2])
    if not lo < hi:
        raise UserError(f"--param {name}={body}: LO must be below HI")
    if log and lo <= 0:
        raise UserError(f"--param {name}={body}: a log range needs LO > 0")
    return SearchAxis(name, kind, float(lo), float(hi), log)


def _first_alerts(out: Path, model: str, key: str, setting: dict, clips: Sequence[str], condition: str,
                  spec=None) -> tuple[dict, Any, float | None, dict]:
    """First alerts per clip and level of a finished setting, the level spec (built on ``clips`` unless
    given), the setting's own level and each clip's frame rate."""
    sf = setting_folder(out, key)
    traces, fps = {}, {}
    for c in clips:
        p = trace_path(sf, condition, c, model)
        if not p.is_file():
            raise InputError(p, "trace missing after its task ran (see the error lines above)")
        traces[c] = Trace.from_csv(p, model=model)
        try:
            fps[c] = float(json.loads(trace_path(sf, condition, c, model, "json").read_text()).get("fps") or 30.0)
        except (OSError, ValueError):
            fps[c] = 30.0
    if spec is None:
        spec = sweep_spec(model, list(traces.values()))
        spec = dataclasses.replace(spec, values=tuple(alert_levels(spec, list(traces.values()), setting)))
    return {c: sweep_first_alerts(spec, t) for c, t in traces.items()}, spec, setting_default_level(spec, setting), fps


def run_tune(folder: str | os.PathLike, labels_path: str | os.PathLike | None, out: str | os.PathLike, model: str,
             param_specs: Sequence[str], trials: int = 20, folds: int = 0, seed: int = 0, padding: Padding = Padding(),
             workers: int | None = None, scheduler: Any = None, backend: str = "taichi", arch: str = "cpu",
             progress: bool = True, downscale: float = 1.0, fps: float | None = None, color_order: str = "bgr",
             skip_missing: bool = False, events: dict | None = None) -> dict:
    """Nested cross-validated Optuna search (module docstring); writes ``OUT/tune.json`` and ``OUT/tune.md``.

    Parameters
    ----------
    folder, labels_path, out : path-like
        Dataset folder, its labels CSV (None: ``folder/labels.csv``), output folder.
    model : str
    param_specs : sequence of str
        Search spaces (:func:`parse_search`).
    trials : int
        Optuna trials per outer fold.
    folds : int
        0 = leave-one-out (outer and inner); k >= 2 = k folds of a seeded shuffle.
    seed : int
        TPE seed (fold ``f`` uses ``seed + f``), fold shuffle and bootstrap seed.
    workers, scheduler, backend, arch, progress, downscale, fps, color_order, skip_missing, events
        As ``experiment sweep``.

    Returns
    -------
    dict
        The ``tune.json`` content: ``accuracy`` (out of sample) with ``ci_lo``/``ci_hi``, ``folds`` (per fold:
        ``test_clips``, ``setting``, ``level``, ``inner_accuracy``, ``trials``), ``per_clip`` and ``lead_times_s``.
    """
    try:
        import optuna
    except ImportError:
        raise UserError("experiment tune needs Optuna: pip install 'cdnf_ti[tune]'") from None
    if not 1 <= trials <= MAX_TRIALS:
        raise UserError(f"--trials must be 1..{MAX_TRIALS}, got {trials}")
    if folds < 0 or folds == 1:
        raise UserError(f"--folds must be 0 (leave-one-out) or at least 2, got {folds}")
    if not (0 < downscale <= 1):
        raise UserError(f"--downscale must be in (0, 1], got {downscale}")
    cls = get_model_class(model)
    name = cls.name
    if not dataclasses.is_dataclass(cls.params_type):
        raise UserError(f"model {name} has no parameter dataclass to tune")
    axes = [parse_search(s, cls.params_type) for s in param_specs]
    if not axes:
        raise UserError("experiment tune needs at least one --param NAME=LO:HI or NAME=V1,V2,...")
    folder = Path(folder)
    labels_path = Path(labels_path) if labels_path is not None else folder / "labels.csv"
    labels = read_labels(labels_path)
    if skip_missing:
        labels, _ = drop_missing(labels, folder)
    files = validate_dataset(labels, folder, labels_path)
    events = dict(events or {})
    labels = labels_in_frames(labels, files, fps, batch_bin_ms([name], None, events.get("bin_ms")), labels_path)
    events["bin_ms"] = check_event_bins(labels, files, [name], None, events.get("bin_ms"), labels_path)
    labs = {lab.clip: lab for lab in labels}
    clips = [lab.clip for lab in labels]
    if len(clips) < 3:
        raise InputError(labels_path, "experiment tune needs at least 3 labelled clips (outer and inner folds)")
    out = Path(out)
    cond = "clean"
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    counts = {"ran": 0, "reused": 0}
    errors: list[dict] = []

    def run_setting(setting: dict, on: Sequence[str]) -> str:
        key = setting_key(setting)
        tasks = [SweepTask(c, str(Path(files[c]).resolve()), name, tuple(setting.items()), key, cond, str(out), seed,
                           backend, arch, float(downscale), fps, color_order, **events) for c in on]
        done = run_sweep(tasks, workers=workers, scheduler=scheduler, arch=arch,
                         progress=f"tune {name} {key}" if progress else False)
        counts["ran"] += done.ran
        counts["reused"] += done.reused
        errors.extend(r for r in done.records if r.get("error"))
        return key

    fold = fold_assignment(len(clips), folds, seed)
    per_fold, per_clip = [], {}
    for f in range(int(fold.max()) + 1):
        train = [c for c, k in zip(clips, fold) if k != f]
        test = [c for c, k in zip(clips, fold) if k == f]

        def objective(trial, train=train) -> float:
            setting = {a.name: a.suggest(trial) for a in axes}
            try:
                cls.params_type(**setting)
            except (TypeError, ValueError) as e:
                raise optuna.TrialPruned(str(e).splitlines()[0]) from None
            key = run_setting(setting, train)
            fas, spec, default, _ = _first_alerts(out, name, key, setting, train, cond)
            _, cm = correctness_matrix(fas, labs, padding)
            return inner_cv_accuracy(cm, spec.values, folds, seed, default)

        study = optuna.create_study(direction="maximize", sampler=optuna.samplers.TPESampler(seed=seed + f))
        study.optimize(objective, n_trials=trials)
        done = [t for t in study.trials if t.value is not None]
        if not done:
            raise UserError(f"fold {f}: no trial gave a valid setting (check the --param ranges)")
        best = max(done, key=lambda t: (t.value, -t.number))
        setting = {a.name: best.params[a.name] for a in axes}
        setting = {k: (float(f"{v:.6g}") if isinstance(v, float) else v) for k, v in setting.items()}
        key = run_setting(setting, train + test)
        fas_tr, spec, default, _ = _first_alerts(out, name, key, setting, train, cond)
        _, cm = correctness_matrix(fas_tr, labs, padding)
        j = choose_level(cm, spec.values, default)
        fas_te, _, _, fps_te = _first_alerts(out, name, key, setting, test, cond, spec)
        _, ct = correctness_matrix(fas_te, labs, padding)
        for i, c in enumerate(test):
            fa, lab = fas_te[c][j], labs[c]
            lead = None
            if lab.collision and lab.contact_frame is not None and fa is not None:
                lead = (lab.contact_frame - fa) / fps_te[c]
            per_clip[c] = {"fold": f, "correct": bool(ct[i, j]), "first_alert": fa, "lead_s": lead,
                           "collision": lab.collision}
        per_fold.append({"fold": f, "test_clips": test, "setting": setting, "key": key,
                         "level": float(spec.values[j]), "alert_parameter": spec.parameter,
                         "inner_accuracy": float(best.value), "trials": len(study.trials)})
    correct = [per_clip[c]["correct"] for c in clips]
    iv = bootstrap_accuracy(correct, seed=seed)
    leads = [d["lead_s"] for d in per_clip.values() if d["lead_s"] is not None]
    n_col = sum(1 for lab in labels if lab.collision and lab.contact_frame is not None)
    result = {
        "model": name, "search": [dataclasses.asdict(a) for a in axes], "trials_per_fold": trials,
        "scheme": "leave-one-out" if folds == 0 or folds >= len(clips) else f"{folds}-fold (seed {seed})",
        "sampler": f"optuna TPESampler(seed=seed + fold), seed {seed}", "optuna_version": optuna.__version__,
        "accuracy": iv.value, "ci_lo": iv.lo, "ci_hi": iv.hi, "clips": len(clips), "folds": per_fold,
        "per_clip": per_clip,
        "lead_times_s": {"leads": leads, "collision_clips": n_col,
                         "median_s": float(np.median(leads)) if leads else None,
                         "shares": {f"{s:g}": (sum(v >= s - 1e-9 for v in leads) / n_col if n_col else None)
                                    for s in (0.5, 1.0, 1.5)}},
        "ran": counts["ran"], "reused": counts["reused"], "errors": errors,
        "dataset": str(folder), "labels": str(labels_path),
    }
    atomic_write_json(out / "tune.json", result)
    atomic_write_text(out / "tune.md", tune_markdown(result))
    return result


def tune_markdown(res: dict) -> str:
    """tune.md: the out-of-sample score, lead times in seconds, and what each outer fold chose."""
    def pct(v):
        return "n/a" if v is None else f"{100 * v:.2f}%"

    lt = res["lead_times_s"]
    median = "n/a" if lt["median_s"] is None else f"{lt['median_s']:+.2f}"
    L = [f"# experiment tune: {res['model']}", "",
         f"- search: Optuna TPE, {res['trials_per_fold']} trials per outer fold ({res['sampler']}); "
         f"{res['scheme']} outer folds; each trial scored by its inner cross-validated accuracy on the "
         "training clips only; the held-out clips are scored at the chosen setting and alert level.",
         f"- out-of-sample accuracy: {pct(res['accuracy'])} [{pct(res['ci_lo'])}, {pct(res['ci_hi'])}] "
         f"(bootstrap 95%) over {res['clips']} clips",
         f"- lead time before contact of the held-out collision clips (s): median {median}; "
         "warned >= 0.5 / 1 / 1.5 s: "
         + " / ".join(pct(lt["shares"][k]) for k in ("0.5", "1", "1.5")),
         f"- tasks run now: {res['ran']}; reused from the cache: {res['reused']}", "",
         "## What each outer fold chose", ""]
    rows = [[d["fold"], ", ".join(d["test_clips"]), d["key"], f"{d['level']:.4g} ({d['alert_parameter']})",
             pct(d["inner_accuracy"]), ", ".join("ok" if res["per_clip"][c]["correct"] else "wrong"
                                                 for c in d["test_clips"])] for d in res["folds"]]
    L += markdown_table(["Fold", "Held-out clips", "Chosen setting", "Alert level", "Inner CV accuracy",
                         "Held-out result"], rows)
    return "\n".join(L) + "\n"
