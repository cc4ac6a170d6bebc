"""How close a model came to alerting: its alert rule, the peak of what the rule compares, and the first alert.

Each model family alerts by its own rule, read here from a finished
:class:`~cdnf_ti.models.base.Trace` (its output and diagnostic columns) and the model's
parameters:

* **a level on the output** (C-DNF, and any model with a fixed ``threshold``): alert while
  ``I_v > I_thre``, ``I_thre = 0.5 + epsilon`` (0.506 by default; ``0.5 = sigmoid(0)`` is the rest
  output). The peak is ``max I_v``.
* **a spike count** (LGMD1, LGMD2, F-LGMD ONn: a ``count`` column and a parameter ``n_ts``):
  alert while the spike count is at least ``n_ts`` (8). The peak is the largest spike count.
* **a dynamic threshold held for some frames** (SDNF: ``dyn_threshold`` and ``run`` columns):
  a frame counts when ``I(t) > max(0.5 + epsilon, I(t-1) + delta)``; alert after ``n_persist``
  (3) such frames in a row. The peak is the longest such run of frames.

The rule is chosen by what the trace records, so a new model that records the same columns
gets the same description without a change here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class AlertSummary:
    """One run's alert rule and how close the model came to it.

    Attributes
    ----------
    rule : str
        The rule in words, e.g. ``"I_v > 0.506"`` or ``"spike count >= 8"``.
    quantity : str
        What the rule compares (``"I_v"``, ``"spike count"``, ``"frames in a row above the dynamic threshold"``).
    peak : float
        The largest value of ``quantity`` over the run (nan for an empty trace).
    level : float
        The value ``quantity`` must exceed (``strict``) or reach for an alert.
    strict : bool
        ``peak > level`` alerts (a level on the output); else ``peak >= level`` does.
    first_alert : int or None
        The first frame with an alert (frames from 0).
    first_alert_s : float or None
        The same in seconds (frame / frame rate).
    """

    rule: str
    quantity: str
    peak: float
    level: float
    strict: bool
    first_alert: int | None
    first_alert_s: float | None

    @property
    def reached(self) -> bool:
        """Whether the peak met the rule's level."""
        return self.peak > self.level if self.strict else self.peak >= self.level

    def text(self) -> str:
        """``max <quantity> <peak>, alert when <rule>`` (and how far short it stayed)."""
        gap = "" if self.reached or not math.isfinite(self.peak) else f", {_num(self.level - self.peak)} short"
        return f"max {self.quantity} {_num(self.peak)}, alert when {self.rule}{gap}"


def _num(x: float) -> str:
    if not math.isfinite(x):
        return "n/a"
    return f"{int(x)}" if float(x).is_integer() and abs(x) < 1e9 else f"{x:.4f}"


def _param(params: Any, name: str, default: Any = None) -> Any:
    return getattr(params, name, default) if params is not None else default


def _peak(values: np.ndarray) -> float:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.max()) if v.size else float("nan")


def alert_summary(trace: Any, params: Any = None, fps: float = 30.0) -> AlertSummary:
    """The alert rule of ``trace``'s model and the peak of what it compares.

    Parameters
    ----------
    trace : Trace
        A finished run (output, spike and diagnostic columns).
    params : parameter dataclass, optional
        The model's parameters (``n_ts``, ``n_persist``, ``epsilon``, ``delta``); the model's
        defaults where absent.
    fps : float
        Frame rate of the input (frames/s), for the first alert in seconds.
    """
    diag = getattr(trace, "diagnostics", {}) or {}
    fa = trace.first_alert
    fa_s = None if fa is None or not fps or fps <= 0 else fa / float(fps)
    name = getattr(trace, "output_name", "output") or "output"
    if "count" in diag:
        n_ts = _param(params, "n_ts", 8)
        return AlertSummary(f"spike count >= {int(n_ts)}", "spike count", _peak(diag["count"]), float(n_ts),
                            False, fa, fa_s)
    if "dyn_threshold" in diag and "run" in diag:
        static = trace.threshold if trace.threshold is not None else 0.5 + float(_param(params, "epsilon", 0.006))
        delta = float(_param(params, "delta", 0.0))
        n = int(_param(params, "n_persist", 3))
        prev = f"{name}(t-1)" + (f" + {delta:g}" if delta else "")
        return AlertSummary(f"{name} > max({static:.4g}, {prev}) on {n} frames in a row",
                            "frames in a row above the dynamic threshold", _peak(diag["run"]), float(n), False,
                            fa, fa_s)
    if trace.threshold is not None:
        thr = float(trace.threshold)
        return AlertSummary(f"{name} > {thr:.4g}", name, _peak(trace.output), thr, True, fa, fa_s)
    return AlertSummary("spike", "spike", _peak(np.asarray(trace.spike, dtype=float)), 1.0, False, fa, fa_s)
