"""Threshold-free and honest clip-level scores (issue 10).

Every function here works on *first alerts per alert level*: for each clip, the
frame of the model's first alert (or None) at each value of its alert level
(C-DNF's ``epsilon``, the LGMD family's spike-count threshold ``n_ts``, SDNF's
``epsilon``), replayed exactly from the saved traces
(:func:`cdnf_ti.experiments.sweep.sweep_first_alerts`).

* :func:`roc` -- clip-level ROC: at each level the hit rate on collision clips
  (first alert inside the window) against the false-alarm rate on
  non-collision clips (any alert), and its area (AUC);
* :func:`bootstrap_accuracy` -- accuracy with a seeded percentile bootstrap
  interval over clips;
* :func:`cross_validated_accuracy` -- leave-one-out or k-fold accuracy where
  each fold's alert level is chosen on the other folds only (out-of-sample);
* :func:`lead_times` -- lead time before contact of the alerts on collision
  clips, hits at or after contact counted separately;
* :func:`warning_shares` -- the share of collision clips warned at least 0.5 s
  and 1 s before contact, and every first alert's time relative to contact;
* :func:`never_alerts_accuracy` -- the score of a model that never alerts.

Anything chosen on the same clips it is scored on is called *in-sample*.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from .labels import ClipLabel
from .scoring import Padding, score_clip

IN_SAMPLE_NOTE = ("in-sample: this alert level was chosen on the same clips it is scored on, "
                  "so the accuracy is optimistic")


def _correct(first_alert: int | None, label: ClipLabel, padding: Padding) -> bool:
    return score_clip(first_alert, label, 30.0, padding).outcome in ("TP", "TN")


def correctness_matrix(first_alerts: Mapping[str, Sequence[int | None]], labels: Mapping[str, ClipLabel],
                       padding: Padding = Padding()) -> tuple[list[str], np.ndarray]:
    """``(clips, C)`` with ``C[i, j]`` True when clip ``i`` is scored TP/TN at level ``j``.

    Parameters
    ----------
    first_alerts : mapping of clip -> sequence of (int or None), length n_levels
    labels : mapping of clip -> ClipLabel
    padding : Padding
    """
    clips = list(first_alerts)
    n_lev = len(next(iter(first_alerts.values()))) if clips else 0
    c = np.zeros((len(clips), n_lev), dtype=bool)
    for i, clip in enumerate(clips):
        for j, fa in enumerate(first_alerts[clip]):
            c[i, j] = _correct(fa, labels[clip], padding)
    return clips, c


@dataclass
class ROC:
    """A clip-level ROC.

    Attributes
    ----------
    levels : list of float
        Alert levels, in the order given.
    hit_rate, false_alarm_rate : list of float
        Per level: TP / collision clips; alerted non-collision clips / non-collision clips.
    auc : float or None
        Area under the curve through (0, 0), every level's point (upper envelope
        at equal false-alarm rates) and (1, hit rate of the most permissive
        level); None without both classes. An alert outside the window is a
        miss, so a model that alerts too early can score below 0.5.
    """

    levels: list[float]
    hit_rate: list[float]
    false_alarm_rate: list[float]
    auc: float | None
    n_collision: int = 0
    n_non_collision: int = 0

    def to_dict(self) -> dict:
        return {"levels": self.levels, "hit_rate": self.hit_rate, "false_alarm_rate": self.false_alarm_rate,
                "auc": self.auc, "n_collision": self.n_collision, "n_non_collision": self.n_non_collision}


def roc(first_alerts: Mapping[str, Sequence[int | None]], labels: Mapping[str, ClipLabel],
        levels: Sequence[float], padding: Padding = Padding()) -> ROC:
    """Clip-level ROC over alert levels (see :class:`ROC`)."""
    col = [c for c in first_alerts if labels[c].collision]
    non = [c for c in first_alerts if not labels[c].collision]
    hits, fas = [], []
    for j in range(len(levels)):
        h = sum(_correct(first_alerts[c][j], labels[c], padding) for c in col)
        f = sum(first_alerts[c][j] is not None for c in non)
        hits.append(h / len(col) if col else float("nan"))
        fas.append(f / len(non) if non else float("nan"))
    xs, ys = roc_envelope(hits, fas)
    auc = None
    if col and non and len(levels):
        auc = float(np.sum((np.diff(xs)) * (np.asarray(ys[1:]) + np.asarray(ys[:-1])) / 2.0))
    return ROC([float(v) for v in levels], hits, fas, auc, len(col), len(non))


def roc_envelope(hit_rate: Sequence[float], false_alarm_rate: Sequence[float]) -> tuple[list[float], list[float]]:
    """The curve whose area is the AUC: (0, 0), the best hit rate at each false-alarm
    rate (made non-decreasing: a more permissive level can always be ignored) and
    (1, hit rate of the most permissive level)."""
    pts = [(f, h) for f, h in zip(false_alarm_rate, hit_rate) if np.isfinite(f) and np.isfinite(h)]
    if not pts:
        return [0.0, 1.0], [0.0, 0.0]
    best: dict[float, float] = {0.0: 0.0}
    for f, h in pts:
        best[f] = max(best.get(f, 0.0), h)
    f_perm, h_perm = max(pts)
    best[1.0] = max(best.get(1.0, 0.0), h_perm)
    xs = sorted(best)
    ys = list(np.maximum.accumulate([best[x] for x in xs]))
    return [float(x) for x in xs], [float(y) for y in ys]


@dataclass
class Interval:
    """A point estimate and its bootstrap interval (fractions in [0, 1])."""

    value: float | None
    lo: float | None
    hi: float | None
    n_boot: int = 0
    seed: int = 0
    level: float = 0.95

    def to_dict(self) -> dict:
        return {"value": self.value, "ci_lo": self.lo, "ci_hi": self.hi, "n_boot": self.n_boot, "seed": self.seed,
                "ci_level": self.level}


def bootstrap_accuracy(correct: Sequence[bool], n_boot: int = 2000, seed: int = 0, level: float = 0.95) -> Interval:
    """Accuracy and its percentile bootstrap interval over clips (seeded).

    Parameters
    ----------
    correct : sequence of bool
        One entry per scored clip (TP or TN).
    n_boot : int
        Bootstrap resamples.
    seed : int
        Seed of the resampling (same seed, same interval).
    level : float
        Coverage of the interval (0.95 = 95%).
    """
    x = np.asarray(correct, dtype=np.float64)
    if x.size == 0:
        return Interval(None, None, None, n_boot, seed, level)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, x.size, size=(n_boot, x.size))
    means = x[idx].mean(axis=1)
    a = (1.0 - level) / 2.0
    return Interval(float(x.mean()), float(np.quantile(means, a)), float(np.quantile(means, 1.0 - a)),
                    n_boot, seed, level)


@dataclass
class CVResult:
    """Cross-validated accuracy: each fold's alert level chosen on the other folds.

    Attributes
    ----------
    accuracy : float or None
        Share of clips scored correctly at the level chosen without them.
    folds : int
        Number of folds (= clips for leave-one-out).
    chosen : dict of clip -> float
        The level used for each clip (chosen on the other folds).
    correct : dict of clip -> bool
    """

    accuracy: float | None
    folds: int
    scheme: str
    chosen: dict = field(default_factory=dict)
    correct: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"accuracy": self.accuracy, "folds": self.folds, "scheme": self.scheme, "chosen_levels": self.chosen,
                "correct": self.correct}


def choose_level(c: np.ndarray, levels: Sequence[float], default: float | None = None) -> int:
    """Index of the level with the highest accuracy on the rows of ``c``.

    Ties go to the level closest to ``default`` (then the lower index), so the
    choice is deterministic.
    """
    acc = c.mean(axis=0) if c.shape[0] else np.zeros(c.shape[1])
    best = acc.max()
    cand = [j for j in range(len(levels)) if acc[j] >= best - 1e-12]
    if default is not None:
        return min(cand, key=lambda j: (abs(levels[j] - default), j))
    return cand[0]


def fold_assignment(n: int, folds: int = 0, seed: int = 0) -> np.ndarray:
    """Fold index of each of ``n`` clips: ``folds`` <= 0 or >= n is leave-one-out;
    otherwise a seeded shuffle split into ``folds`` nearly equal folds."""
    if folds <= 0 or folds >= n:
        return np.arange(n)
    perm = np.random.default_rng(seed).permutation(n)
    out = np.empty(n, dtype=int)
    for k, part in enumerate(np.array_split(perm, folds)):
        out[part] = k
    return out


def cross_validated_accuracy(first_alerts: Mapping[str, Sequence[int | None]], labels: Mapping[str, ClipLabel],
                             levels: Sequence[float], padding: Padding = Padding(), folds: int = 0,
                             seed: int = 0, default: float | None = None) -> CVResult:
    """Out-of-sample accuracy of choosing the alert level on held-in clips.

    Parameters
    ----------
    first_alerts : mapping of clip -> first alert per level
    labels : mapping of clip -> ClipLabel
    levels : sequence of float
    padding : Padding
    folds : int
        0 (default) = leave-one-out; k >= 2 = k folds of a seeded shuffle.
    seed : int
        Shuffle seed for k-fold.
    default : float, optional
        Tie-break: among equally good levels the one closest to this.
    """
    clips, c = correctness_matrix(first_alerts, labels, padding)
    n = len(clips)
    if n < 2 or not len(levels):
        return CVResult(None, 0, "none")
    fold = fold_assignment(n, folds, seed)
    k = int(fold.max()) + 1
    chosen, correct = {}, {}
    for f in range(k):
        test = fold == f
        j = choose_level(c[~test], levels, default)
        for i in np.flatnonzero(test):
            chosen[clips[i]] = float(levels[j])
            correct[clips[i]] = bool(c[i, j])
    scheme = "leave-one-out" if k == n else f"{k}-fold (seed {seed})"
    return CVResult(float(np.mean(list(correct.values()))), k, scheme, chosen, correct)


def never_alerts_accuracy(labels: Sequence[ClipLabel]) -> float | None:
    """Accuracy of a model that never alerts: the share of non-collision clips."""
    labels = list(labels)
    return (sum(not lab.collision for lab in labels) / len(labels)) if labels else None


@dataclass
class LeadTimes:
    """Lead times (ms before contact) of the first alerts on collision clips with a known contact frame.

    Attributes
    ----------
    before_contact_ms : list of float
        Alerts strictly before contact (a warning).
    at_or_after_contact : int
        Alerts at or after contact (they warn of nothing).
    hits_before, hits_at_or_after : int
        Of the true positives (first alert inside the window): before contact, at or after.
    """

    before_contact_ms: list[float] = field(default_factory=list)
    at_or_after_contact: int = 0
    hits_before: int = 0
    hits_at_or_after: int = 0
    hit_leads_ms: list[float] = field(default_factory=list)

    def add(self, lead_ms: float | None, hit: bool) -> None:
        if lead_ms is None:
            return
        if lead_ms > 0:
            self.before_contact_ms.append(float(lead_ms))
            self.hits_before += int(hit)
        else:
            self.at_or_after_contact += 1
            self.hits_at_or_after += int(hit)
        if hit:
            self.hit_leads_ms.append(float(lead_ms))

    def to_dict(self) -> dict:
        hb = [x for x in self.hit_leads_ms if x > 0]
        return {
            "hits_before_contact": self.hits_before, "hits_at_or_after_contact": self.hits_at_or_after,
            "hit_lead_median_ms": float(np.median(hb)) if hb else None,
            "hit_lead_min_ms": min(hb) if hb else None, "hit_lead_max_ms": max(hb) if hb else None,
            "alerts_before_contact": len(self.before_contact_ms),
            "alerts_at_or_after_contact": self.at_or_after_contact,
            "alert_lead_median_ms": float(np.median(self.before_contact_ms)) if self.before_contact_ms else None,
        }


def lead_times(rows: Sequence[Mapping]) -> LeadTimes:
    """Lead times of result rows (one model and condition): uses ``lead_time_ms`` and ``outcome``."""
    lt = LeadTimes()
    for r in rows:
        if r.get("error"):
            continue
        v = r.get("lead_time_ms")
        if v in (None, ""):
            continue
        lt.add(float(v), r.get("outcome") == "TP")
    return lt


#: Lead times (s before contact) whose share of warned collision clips is reported.
WARNING_SECONDS = (0.5, 1.0)


def warning_shares(rows: Sequence[Mapping], seconds: Sequence[float] = WARNING_SECONDS) -> dict:
    """How far ahead of contact a model warns, over the collision clips with a known contact frame.

    A clip is *warned at least s seconds before contact* when its first alert
    comes ``s`` or more before the contact frame. Whether that alert was also
    inside the labelled window (a hit) is counted alongside: a first alert far
    ahead of the window is scored as an early miss, so a model that alerts on
    anything would be "warned" on every clip and score nothing.

    Parameters
    ----------
    rows : sequence of mapping
        Result rows of one model and condition (``label``, ``contact_frame``,
        ``outcome``, ``lead_time_ms``, ``error``); non-collision rows, failed
        rows and collision rows without a contact frame are skipped.
    seconds : sequence of float
        Lead times to report (s).

    Returns
    -------
    dict
        ``collision_clips`` (with a contact frame), ``never_alerted``,
        ``alert_minus_contact_s`` (clip -> first alert time minus contact time
        in s, negative = before contact; clips that never alerted left out),
        ``hit`` (clip -> first alert in the window), and per ``s`` (key
        ``f"{s:g}"``) ``{"seconds", "warned", "share", "warned_hits", "share_hits"}``:
        clips warned at least ``s`` before contact, their share of
        ``collision_clips``, and the same for warnings that were also hits.
    """
    rel: dict[str, float] = {}
    hit: dict[str, bool] = {}
    n = never = 0
    for r in rows:
        if r.get("error") or r.get("outcome") not in ("TP", "FN") or r.get("contact_frame") in (None, ""):
            continue
        n += 1
        lead = r.get("lead_time_ms")
        if lead in (None, ""):
            never += 1
            continue
        rel[str(r["clip"])] = -float(lead) / 1000.0
        hit[str(r["clip"])] = r["outcome"] == "TP"
    out: dict[str, Any] = {"collision_clips": n, "never_alerted": never, "alert_minus_contact_s": rel,
                           "hit": hit}
    for s in seconds:
        warned = [c for c, t in rel.items() if -t >= s - 1e-9]
        hits = [c for c in warned if hit[c]]
        out[f"{s:g}"] = {"seconds": float(s), "warned": len(warned), "share": len(warned) / n if n else None,
                         "warned_hits": len(hits), "share_hits": len(hits) / n if n else None}
    return out


def pct_ci(iv: Mapping | Interval | None) -> str:
    """``"45.45% [18.18, 72.73]"`` (percent, bootstrap 95% interval)."""
    if iv is None:
        return "n/a"
    d = iv.to_dict() if isinstance(iv, Interval) else iv
    if d.get("value") is None:
        return "n/a"
    return f"{100 * d['value']:.2f}% [{100 * d['ci_lo']:.1f}, {100 * d['ci_hi']:.1f}]"
