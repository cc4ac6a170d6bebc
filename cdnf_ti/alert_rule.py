"""How close a model came to alerting: its alert rule, the peak of what the rule compares, and the first alert.

Each model states its own rule (:meth:`cdnf_ti.models.base.Model.alert_rule`, an
:class:`AlertRule`): the value it compares (a column of its :class:`~cdnf_ti.models.base.Trace`,
the output or a diagnostic), the level that value must pass and the rule in words. Everything
that says how close a run came (``run``'s line and summary.csv, ``live``'s ``start`` event)
reads it from the model, so a new model gets it by stating its rule:

* a level on the output (C-DNF, and any model with a fixed ``threshold``; the default):
  ``I_v > 0.506``, peak ``max I_v``;
* LGMD1, LGMD2, F-LGMD ONn: ``spike count >= n_ts`` (``count``);
* SDNF: ``I > max(0.5 + epsilon, I(t-1) + delta)`` on ``n_persist`` frames in a row (``run``);
* oLGMD: the 4-frame sum of ``exp(4 (K - 0.78)) >= 3`` (``spike_sum``);
* EMD-LPLC2: the giant fibre's ``V > -50 mV`` in a substep (``V_peak``: V before the spike reset).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class AlertRule:
    """A model's alert rule: which value of its trace it compares, and against what.

    Attributes
    ----------
    rule : str
        The rule in words, e.g. ``"I_v > 0.506"`` or ``"spike count >= 8"``.
    quantity : str
        What the rule compares, in words (``"I_v"``, ``"spike count"``).
    column : str
        The trace column holding it per frame: the output's name or a diagnostic's.
    level : float
        The value ``quantity`` must exceed (``strict``) or reach for an alert.
    strict : bool
        ``value > level`` alerts; else ``value >= level`` does.
    """

    rule: str
    quantity: str
    column: str
    level: float
    strict: bool = False

    def values(self, trace: Any) -> np.ndarray:
        """``column`` of ``trace`` per frame, shape (T,) (nan where the trace lacks it)."""
        if self.column == getattr(trace, "output_name", None):
            return np.asarray(trace.output, dtype=float)
        if self.column == "spike":
            return np.asarray(trace.spike, dtype=float)
        diag = getattr(trace, "diagnostics", {}) or {}
        if self.column in diag:
            return np.asarray(diag[self.column], dtype=float)
        return np.full(int(getattr(trace, "n_frames", 0)), np.nan)

    def peak(self, trace: Any) -> float:
        """The largest finite value of ``column`` over ``trace`` (nan when there is none)."""
        v = self.values(trace)
        v = v[np.isfinite(v)]
        return float(v.max()) if v.size else float("nan")

    def as_dict(self) -> dict:
        """``{"rule", "quantity", "column", "level", "strict"}`` (for JSON records)."""
        return {"rule": self.rule, "quantity": self.quantity, "column": self.column, "level": self.level,
                "strict": self.strict}


@dataclass(frozen=True)
class AlertSummary:
    """One run's alert rule and how close the model came to it.

    Attributes
    ----------
    rule : str
        The rule in words (:attr:`AlertRule.rule`).
    quantity : str
        What the rule compares (:attr:`AlertRule.quantity`).
    peak : float
        The largest value of ``quantity`` over the run (nan for an empty trace).
    level : float
        The value ``quantity`` must exceed (``strict``) or reach for an alert.
    strict : bool
        ``peak > level`` alerts; else ``peak >= level`` does.
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


def alert_summary(trace: Any, rule: AlertRule, fps: float = 30.0) -> AlertSummary:
    """How close ``trace`` came to ``rule`` (its model's :meth:`~cdnf_ti.models.base.Model.alert_rule`).

    Parameters
    ----------
    trace : Trace
        A finished run (output, spike and diagnostic columns).
    rule : AlertRule
        The rule of the model that made it.
    fps : float
        Frame rate of the input (frames/s), for the first alert in seconds.
    """
    fa = trace.first_alert
    fa_s = None if fa is None or not fps or fps <= 0 else fa / float(fps)
    return AlertSummary(rule.rule, rule.quantity, rule.peak(trace), float(rule.level), rule.strict, fa, fa_s)
