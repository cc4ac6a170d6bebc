"""Scoring a model's alerts against clip labels (paper Section III-C, docs/EVALUATION.md).

* collision clip: TP if the FIRST alert falls inside the (optionally padded)
  window, otherwise FN with the reason ``none`` (never alerts), ``early``
  (first alert before the window) or ``late`` (first alert after it);
* non-collision clip: TN if the model never alerts, FP otherwise;
* ``accuracy = (TP + TN) / (TP + TN + FP + FN)``.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Iterable, Mapping, Sequence

from .labels import ClipLabel

OUTCOMES = ("TP", "TN", "FP", "FN")
FN_REASONS = ("early", "late", "none")


@dataclass(frozen=True)
class Padding:
    """Frames added before the window start and after the window end (both >= 0)."""

    before: int = 0
    after: int = 0

    def __post_init__(self) -> None:
        if self.before < 0 or self.after < 0:
            raise ValueError(f"window padding must be >= 0 frames, got before={self.before}, after={self.after}")

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class ClipScore:
    """The outcome of one model on one clip.

    Attributes
    ----------
    outcome : {"TP", "TN", "FP", "FN"}
    fn_reason : {"early", "late", "none", ""}
        Why a collision clip was missed (empty unless ``outcome == "FN"``).
    window_lo, window_hi : int or None
        The padded window actually used (frames, inclusive); None for non-collision clips.
    lead_time_ms : float or None
        ``(contact_frame - first_alert) / fps`` in ms (positive = alert before
        contact); only for collision clips with an alert and a known contact frame.
    """

    outcome: str
    fn_reason: str
    window_lo: int | None
    window_hi: int | None
    lead_time_ms: float | None


def score_clip(first_alert: int | None, label: ClipLabel, fps: float = 30.0,
               padding: Padding = Padding()) -> ClipScore:
    """Score one first alert against one label.

    Parameters
    ----------
    first_alert : int or None
        Frame index (0-based) of the model's first alert; None if it never alerted.
    label : ClipLabel
    fps : float
        Frame rate of the clip (frames/s), for the lead time.
    padding : Padding
        Frames of tolerance before / after the labelled window.
    """
    if not label.collision:
        return ClipScore("TN" if first_alert is None else "FP", "", None, None, None)
    assert label.window_start is not None and label.window_end is not None
    lo = max(0, label.window_start - padding.before)
    hi = label.window_end + padding.after
    lead = None
    if first_alert is not None and label.contact_frame is not None:
        lead = (label.contact_frame - first_alert) / fps * 1000.0
    if first_alert is None:
        return ClipScore("FN", "none", lo, hi, None)
    if first_alert < lo:
        return ClipScore("FN", "early", lo, hi, lead)
    if first_alert > hi:
        return ClipScore("FN", "late", lo, hi, lead)
    return ClipScore("TP", "", lo, hi, lead)


@dataclass
class Tally:
    """Counts of one model on one condition.

    Attributes
    ----------
    TP, TN, FP, FN : int
    early, late, none : int
        FN broken down by reason.
    errors : int
        Clips that could not be run (not counted in the accuracy).
    lead_times_ms : list of float
        Lead times of the true positives.
    """

    TP: int = 0
    TN: int = 0
    FP: int = 0
    FN: int = 0
    early: int = 0
    late: int = 0
    none: int = 0
    errors: int = 0
    lead_times_ms: list = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.lead_times_ms is None:
            self.lead_times_ms = []

    def add(self, outcome: str, fn_reason: str = "", lead_time_ms: float | None = None) -> None:
        """Count one scored clip."""
        if outcome not in OUTCOMES:
            raise ValueError(f"unknown outcome {outcome!r}")
        setattr(self, outcome, getattr(self, outcome) + 1)
        if outcome == "FN":
            if fn_reason not in FN_REASONS:
                raise ValueError(f"unknown FN reason {fn_reason!r}")
            setattr(self, fn_reason, getattr(self, fn_reason) + 1)
        if outcome == "TP" and lead_time_ms is not None:
            self.lead_times_ms.append(float(lead_time_ms))

    @property
    def n(self) -> int:
        """Scored clips (errors excluded)."""
        return self.TP + self.TN + self.FP + self.FN

    @property
    def accuracy(self) -> float | None:
        """``(TP + TN) / (TP + TN + FP + FN)`` in [0, 1]; None when nothing was scored."""
        return (self.TP + self.TN) / self.n if self.n else None

    def to_dict(self) -> dict:
        lt = self.lead_times_ms
        return {
            "TP": self.TP, "TN": self.TN, "FP": self.FP, "FN": self.FN,
            "FN_early": self.early, "FN_late": self.late, "FN_none": self.none,
            "clips": self.n, "errors": self.errors,
            "accuracy": self.accuracy,
            "mean_lead_time_ms": (sum(lt) / len(lt)) if lt else None,
        }


def tally(rows: Iterable[Mapping], keys: Sequence[str] = ("model", "condition")) -> dict[tuple, Tally]:
    """Group result rows by ``keys`` and count outcomes.

    Parameters
    ----------
    rows : iterable of mapping
        Result rows with ``outcome``, ``fn_reason``, ``lead_time_ms`` and
        ``error`` (a row with a non-empty ``error`` counts as an error).
    keys : sequence of str
        Grouping columns.

    Returns
    -------
    dict of tuple to Tally
        In first-seen order of the groups.
    """
    out: dict[tuple, Tally] = {}
    for r in rows:
        k = tuple(r[key] for key in keys)
        t = out.setdefault(k, Tally())
        if r.get("error"):
            t.errors += 1
            continue
        lead = r.get("lead_time_ms")
        t.add(r["outcome"], r.get("fn_reason") or "", None if lead in (None, "") else float(lead))
    return out


def accuracy(outcomes: Iterable[str]) -> float | None:
    """Accuracy of a list of outcomes (``TP``/``TN``/``FP``/``FN``); None if empty."""
    t = Tally()
    for o in outcomes:
        t.add(o, "none" if o == "FN" else "")
    return t.accuracy
