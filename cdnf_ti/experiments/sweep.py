"""Threshold sweeps: how accuracy, hits and false alarms change with a model's alert level.

A single published threshold may not transfer to other footage, so every
model's alert level is swept over a range and the dataset re-scored from the
saved traces (no re-run):

* a model class that satisfies :class:`~cdnf_ti.models.base.Sweepable`
  (defines ``sweep_alerts(trace, values)``, a classmethod returning, per
  value, the first-alert frame or a boolean spike array over frames, with
  ``sweep_parameter``, ``sweep_values`` and ``sweep_default``) is swept with
  its own rule. C-DNF's: the alert is ``I_v > 0.5 + epsilon`` and ``I_v`` does
  not depend on ``epsilon``, so ``epsilon`` is swept from 0 to 0.02 on the
  saved ``I_v``;
* any other model falls back to thresholding its saved ``output``
  (``output > value``) over a data-driven range; the report says so.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..models import get_model_class
from ..models.base import Sweepable, Trace
from ..models.cdnf import CDNF
from .scoring import Tally, score_clip

#: C-DNF's epsilon range (the issue: 0 to 0.02).
CDNF_EPSILONS = tuple(CDNF.sweep_values)


@dataclass(frozen=True)
class SweepSpec:
    """What is swept for one model.

    Attributes
    ----------
    model : str
    parameter : str
        Name of the swept quantity (``epsilon`` for C-DNF).
    values : tuple of float
    default : float or None
        The model's default value of ``parameter`` (marked in plots).
    method : str
        ``"model"`` (the class's ``sweep_alerts``) or ``"fallback"``
        (threshold on the saved output). ``"cdnf-epsilon"`` (older runs) is
        C-DNF's own rule.
    """

    model: str
    parameter: str
    values: tuple[float, ...]
    default: float | None
    method: str


def _class(model: str):
    return get_model_class(model)


def sweep_spec(model: str, traces: Sequence[Trace] = (), n_values: int = 21) -> SweepSpec:
    """The sweep used for ``model``.

    Parameters
    ----------
    model : str
        Registry name.
    traces : sequence of Trace
        The dataset's traces of this model (used only by the fallback, to
        choose a threshold range covering its outputs).
    n_values : int
        Number of values in a fallback range.
    """
    cls = _class(model)
    if isinstance(cls, Sweepable):
        vals = cls.sweep_values
        if callable(vals):
            vals = vals()
        default = cls.sweep_default()
        if vals is None:
            vals = _fallback_values(traces, n_values, None)
        return SweepSpec(cls.name, str(cls.sweep_parameter), tuple(float(v) for v in vals),
                         None if default is None else float(default), "model")
    default = None
    try:
        default = cls().threshold
    except Exception:  # noqa: BLE001 - some models may need arguments; the default is only for plots
        default = None
    return SweepSpec(cls.name, f"{traces[0].output_name if traces else 'output'} threshold",
                     _fallback_values(traces, n_values, default), default, "fallback")


def _fallback_values(traces: Sequence[Trace], n: int, default: float | None) -> tuple[float, ...]:
    outs = [t.output[np.isfinite(t.output)] for t in traces if t.n_frames]
    outs = [o for o in outs if o.size]
    if not outs:
        return (default,) if default is not None else (0.0,)
    allv = np.concatenate(outs)
    lo = float(np.median(allv))
    hi = float(allv.max())
    if default is not None:
        lo, hi = min(lo, default), max(hi, default)
    if hi <= lo:
        hi = lo + 1e-6
    vals = np.linspace(lo, hi, n)
    if default is not None:
        vals = np.unique(np.append(vals, default))
    return tuple(float(v) for v in vals)


def _first(spikes: np.ndarray) -> int | None:
    idx = np.flatnonzero(np.asarray(spikes, dtype=bool))
    return int(idx[0]) if idx.size else None


def sweep_first_alerts(spec: SweepSpec, trace: Trace) -> list[int | None]:
    """First-alert frame of ``trace`` at each of ``spec.values`` (None = never alerts)."""
    if spec.method == "fallback":
        out = np.asarray(trace.output, dtype=np.float64)
        return [_first(out > v) for v in spec.values]
    res = _class(spec.model).sweep_alerts(trace, list(spec.values))
    firsts: list[int | None] = []
    for r in res:
        if r is None or isinstance(r, (int, np.integer)):
            firsts.append(None if r is None or int(r) < 0 else int(r))
        else:
            firsts.append(_first(r))
    if len(firsts) != len(spec.values):
        raise ValueError(f"{spec.model}.sweep_alerts returned {len(firsts)} results for {len(spec.values)} values")
    return firsts


def sweep_dataset(specs: Mapping[str, SweepSpec], traces: Mapping[tuple[str, str, str], Trace],
                  labels: Mapping[str, object], fps: Mapping[str, float], padding) -> list[dict]:
    """Re-score the dataset at every swept value.

    Parameters
    ----------
    specs : mapping of model -> SweepSpec
    traces : mapping of (clip, model, condition) -> Trace
        The saved traces (error clips absent).
    labels : mapping of clip -> ClipLabel
    fps : mapping of clip -> float
    padding : Padding

    Returns
    -------
    list of dict
        One row per (model, condition, value): ``model, condition, parameter,
        value, is_default, TP, TN, FP, FN, FN_early, FN_late, FN_none, clips,
        accuracy, hits (= TP), false_alarms (= FP + FN_early: alerts on a
        non-collision clip or before the collision window)``.
    """
    rows: list[dict] = []
    conditions = sorted({k[2] for k in traces}, key=lambda c: (c != "clean", c))
    for model, spec in specs.items():
        for cond in conditions:
            tallies = [Tally() for _ in spec.values]
            for (clip, m, c), tr in traces.items():
                if m != model or c != cond:
                    continue
                for tl, fa in zip(tallies, sweep_first_alerts(spec, tr)):
                    s = score_clip(fa, labels[clip], fps.get(clip, 30.0), padding)
                    tl.add(s.outcome, s.fn_reason)
            if not tallies or tallies[0].n == 0:
                continue
            for v, tl in zip(spec.values, tallies):
                d = tl.to_dict()
                rows.append({
                    "model": model, "condition": cond, "parameter": spec.parameter, "value": v,
                    "is_default": spec.default is not None and abs(v - spec.default) < 1e-12,
                    "TP": d["TP"], "TN": d["TN"], "FP": d["FP"], "FN": d["FN"],
                    "FN_early": d["FN_early"], "FN_late": d["FN_late"], "FN_none": d["FN_none"],
                    "clips": d["clips"], "accuracy": d["accuracy"],
                    "hits": d["TP"], "false_alarms": d["FP"] + d["FN_early"], "method": spec.method,
                })
    return rows


def alert_levels(spec, traces, setting: dict | None = None) -> list[float]:
    """Alert levels to score: the model's sweep values, plus for C-DNF log-spaced
    epsilons up to the largest ``I_v - 0.5`` seen (so the ROC reaches "never alerts")."""
    vals = set(float(v) for v in spec.values)
    if spec.method == "cdnf-epsilon":
        top = max((float(np.nanmax(t.output)) - 0.5 for t in traces if t.n_frames), default=0.0)
        if top > 1e-6:
            vals.update(float(v) for v in np.round(np.geomspace(1e-6, top * 1.05, 40), 9))
        if setting and "epsilon" in setting:
            vals.add(float(setting["epsilon"]))
    return sorted(vals)


def setting_default_level(spec, setting: dict) -> float | None:
    """The alert level the setting itself uses (C-DNF/SDNF ``epsilon``, LGMD ``n_ts``)."""
    if spec.method == "cdnf-epsilon":
        return float(setting.get("epsilon", spec.default))
    if spec.parameter.startswith("n_ts") and "n_ts" in setting:
        return float(setting["n_ts"])
    if spec.parameter.startswith("epsilon") and "epsilon" in setting:
        return float(setting["epsilon"])
    return spec.default
