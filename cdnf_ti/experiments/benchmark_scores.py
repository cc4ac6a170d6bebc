"""The benchmarks' own scores from every model's per-frame output (docs/EVALUATION.md, "Benchmark scores").

A model's *per-frame score* is its continuous output on each frame (C-DNF's ``I_v``, the LGMD family's
``K``, ...), saved beside its alerts in every trace. The scores here are rank statistics of it, so no
alert level is chosen:

* :func:`average_precision` and :func:`roc_auc` -- AP (step-wise: the sum of precision times the rise
  in recall at each distinct score, ties taken together) and the area under the ROC curve (ties count
  one half);
* :func:`nexar_ap` -- Nexar's AP at 0.5, 1.0 and 1.5 s before the event, and their mean;
* :func:`frame_level` -- frame-level AP and AUC on per-frame labels (DoTA, CCD's ``binlabels``);
* :func:`anticipation` -- DAD / CCD / DoTA video-level AP and mean time-to-accident (mTTA);
* :func:`lead_times_s` -- the first alert's lead time before the event, in seconds;
* :func:`bootstrap_metric` -- a seeded percentile bootstrap interval over clips of any of them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from .annotations import Annotation
from .labels import frame_at

#: Nexar's horizons: seconds before the event at which the score is taken.
NEXAR_HORIZONS = (0.5, 1.0, 1.5)
#: Lead times (s before the event) whose share of warned clips is reported.
LEAD_SHARES = (0.5, 1.0, 1.5)


@dataclass(frozen=True)
class ClipOutput:
    """One model's result on one clip, with the clip's annotation.

    Attributes
    ----------
    annotation : Annotation
    scores : ndarray, shape (T,)
        The per-frame score (the model's output); frame ``k`` is seen at ``k / fps`` s.
    fps : float
        The clip's frame rate, frames/s.
    first_alert : int or None
        The model's first alert frame.
    """

    annotation: Annotation
    scores: np.ndarray
    fps: float
    first_alert: int | None = None


def _finite(scores: np.ndarray) -> np.ndarray:
    """Scores with NaN (a step that produced none) ranked lowest."""
    s = np.asarray(scores, dtype=np.float64)
    return np.where(np.isnan(s), -np.inf, s)


def average_precision(labels: Sequence[int], scores: Sequence[float]) -> float | None:
    """Average precision: ``sum_k (R_k - R_{k-1}) P_k`` over the distinct scores, highest first.

    ``P_k`` and ``R_k`` are the precision and recall of calling positive every item scored at or above
    the k-th distinct score (tied items enter together). ``None`` without a positive item.
    """
    y = np.asarray(labels, dtype=np.int64) > 0
    s = _finite(np.asarray(scores))
    n_pos = int(y.sum())
    if n_pos == 0:
        return None
    order = np.argsort(-s, kind="mergesort")
    s, y = s[order], y[order]
    last = np.r_[np.flatnonzero(np.diff(s) != 0), s.size - 1]  # the last item of each run of ties
    tp = np.cumsum(y)[last]
    precision = tp / (last + 1)
    recall = tp / n_pos
    return float(np.sum(np.diff(np.r_[0.0, recall]) * precision))


def roc_auc(labels: Sequence[int], scores: Sequence[float]) -> float | None:
    """Area under the ROC curve: the chance that a positive item outscores a negative one (a tie counts
    one half). ``None`` unless both classes are present."""
    y = np.asarray(labels, dtype=np.int64) > 0
    s = _finite(np.asarray(scores))
    pos, neg = s[y], s[~y]
    if pos.size == 0 or neg.size == 0:
        return None
    neg_sorted = np.sort(neg)
    below = np.searchsorted(neg_sorted, pos, side="left")
    equal = np.searchsorted(neg_sorted, pos, side="right") - below
    return float((below.sum() + 0.5 * equal.sum()) / (pos.size * neg.size))


def frames_seen_by(seconds: float, fps: float) -> int:
    """How many frames have been seen at time ``seconds``: frames ``0 .. frame_at(seconds)``; 0 before the
    first frame."""
    return 0 if seconds < 0 else frame_at(seconds, fps) + 1


def horizon_scores(clips: Sequence[ClipOutput], horizon_s: float) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Nexar's one score per video at ``horizon_s`` before the event.

    A positive clip (event at ``t_e``) is scored on the frames seen by ``t_e - horizon_s``: frames ``k`` with
    ``k / fps <= t_e - horizon_s``, as if the video ended there; its score is the highest per-frame score on
    them (an alert rule on the score fires by then exactly when the threshold is at or below it). A negative
    clip is scored on all its frames. A positive clip with no frame by then (the event comes less than
    ``horizon_s`` after its first frame) cannot be scored and is left out.

    Returns
    -------
    (labels, scores, left_out)
        0/1 per scored clip, its score, and the names of the positive clips left out.
    """
    ys, ss, left = [], [], []
    for c in clips:
        s = _finite(c.scores)
        if c.annotation.event_s is None:
            if s.size:
                ys.append(0)
                ss.append(float(s.max()))
            continue
        n = min(s.size, frames_seen_by(c.annotation.event_s - horizon_s, c.fps))
        if n == 0:
            left.append(c.annotation.clip)
            continue
        ys.append(1)
        ss.append(float(s[:n].max()))
    return np.asarray(ys, dtype=np.int64), np.asarray(ss, dtype=np.float64), left


def nexar_ap(clips: Sequence[ClipOutput], horizons: Sequence[float] = NEXAR_HORIZONS) -> dict:
    """AP of the per-video score at each horizon before the event (:func:`horizon_scores`) and their mean.

    Returns
    -------
    dict
        ``{"0.5": AP or None, "1": ..., "1.5": ..., "mean": mean of the defined APs or None,
        "left_out": {horizon: [clips]}, "videos": {horizon: scored clips}, "positives": {horizon: of them
        positive}}`` (a random ranking's AP is ``positives / videos``).
    """
    out: dict = {"left_out": {}, "videos": {}, "positives": {}}
    aps = []
    for h in horizons:
        y, s, left = horizon_scores(clips, h)
        ap = average_precision(y, s) if y.size else None
        out[f"{h:g}"] = ap
        out["left_out"][f"{h:g}"] = left
        out["videos"][f"{h:g}"] = int(y.size)
        out["positives"][f"{h:g}"] = int(y.sum())
        if ap is not None:
            aps.append(ap)
    out["mean"] = float(np.mean(aps)) if aps else None
    return out


def pooled_frames(clips: Sequence[ClipOutput]) -> tuple[np.ndarray, np.ndarray]:
    """Every frame of every clip: its label (:meth:`Annotation.frame_label_array`) and score."""
    ys = [c.annotation.frame_label_array(len(c.scores), c.fps) for c in clips]
    ss = [_finite(c.scores) for c in clips]
    if not ys:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    return np.concatenate(ys), np.concatenate(ss)


def frame_level(clips: Sequence[ClipOutput]) -> dict:
    """Frame-level AP and ROC AUC of the per-frame score on the per-frame labels, all frames of all clips
    pooled: ``{"ap", "auc", "frames", "positive_frames"}``."""
    y, s = pooled_frames(clips)
    return {"ap": average_precision(y, s), "auc": roc_auc(y, s), "frames": int(y.size),
            "positive_frames": int(y.sum())}


def scores_before_event(c: ClipOutput) -> np.ndarray:
    """The scores a clip offers for anticipation: a positive clip's frames that end by its event (those
    before the frame holding it, :func:`~.labels.frame_at`), a negative clip's all frames."""
    s = _finite(c.scores)
    if c.annotation.event_s is None:
        return s
    return s[:max(0, min(s.size, frames_seen_by(c.annotation.event_s, c.fps) - 1))]


def anticipation(clips: Sequence[ClipOutput]) -> dict:
    """Video-level anticipation AP and mean time-to-accident (mTTA), as DAD, CCD and DoTA report them.

    At a threshold ``th`` a video is *alerted* when a frame before its event (a frame that ends by the
    event time; any frame of a negative video) scores ``>= th``; a positive video alerted is a true
    positive, and its time-to-accident is ``t_e - k / fps`` s, ``k`` the first such frame. Precision and
    recall over videos give the AP (:func:`average_precision` of each video's highest score before its
    event); the TTA averaged over the
    true positives at each threshold, maximised over the thresholds of each distinct recall and averaged
    over the recalls above 0, gives the mTTA in seconds (Chan et al. 2016's ``evaluation``, in seconds;
    its AP there is trapezoidal and here step-wise). Positive clips with no frame before the event are
    left out.

    Returns
    -------
    dict
        ``{"ap", "mtta_s", "videos", "left_out"}``.
    """
    kept, left = [], []
    for c in clips:
        s = scores_before_event(c)
        if s.size == 0:
            if c.annotation.event_s is not None:
                left.append(c.annotation.clip)
            continue
        kept.append((c, s))
    y = np.asarray([int(c.annotation.event_s is not None) for c, _ in kept], dtype=np.int64)
    top = np.asarray([float(s.max()) for _, s in kept])
    ap = average_precision(y, top) if y.size else None
    n_pos = int(y.sum())
    best_tta: dict[float, float] = {}
    for th in np.unique(top):
        ttas = [c.annotation.event_s - int(np.argmax(s >= th)) / c.fps
                for (c, s), yy in zip(kept, y) if yy and s.max() >= th]
        if not ttas:
            continue
        r = len(ttas) / n_pos
        best_tta[r] = max(best_tta.get(r, -np.inf), float(np.mean(ttas)))
    mtta = float(np.mean(list(best_tta.values()))) if best_tta else None
    return {"ap": ap, "mtta_s": mtta, "videos": int(y.size), "left_out": left}


def lead_times_s(clips: Sequence[ClipOutput], shares: Sequence[float] = LEAD_SHARES) -> dict:
    """Lead time of each positive clip's first alert before its event, in seconds.

    ``lead = t_e - first_alert / fps`` (positive: before the event). Returns ``{"leads_s": {clip: s},
    "positive_clips", "never_alerted", "median_s", "shares": {"0.5": share of positive clips warned at least
    0.5 s ahead, ...}}``; a clip that never alerted counts as not warned.
    """
    leads: dict[str, float] = {}
    n = never = 0
    for c in clips:
        if c.annotation.event_s is None:
            continue
        n += 1
        if c.first_alert is None:
            never += 1
            continue
        leads[c.annotation.clip] = float(c.annotation.event_s - c.first_alert / c.fps)
    vals = list(leads.values())
    return {"leads_s": leads, "positive_clips": n, "never_alerted": never,
            "median_s": float(np.median(vals)) if vals else None,
            "shares": {f"{s:g}": (sum(v >= s - 1e-9 for v in vals) / n if n else None) for s in shares}}


def by_condition(clips: Sequence[ClipOutput], metric: Callable[[Sequence[ClipOutput]], dict],
                 keys: Sequence[str] = ("weather", "timing", "ego_involved")) -> dict:
    """``metric`` on the clips of each value of each condition: ``{key: {value: result}}`` (clips without
    the condition left out of that key)."""
    out: dict = {}
    for k in keys:
        values = sorted({c.annotation.conditions[k] for c in clips if k in c.annotation.conditions})
        for v in values:
            out.setdefault(k, {})[v] = metric([c for c in clips if c.annotation.conditions.get(k) == v])
    return out


def bootstrap_metric(clips: Sequence[ClipOutput], metric: Callable[[Sequence[ClipOutput]], float | None],
                     n_boot: int = 1000, seed: int = 0, level: float = 0.95) -> dict:
    """``metric`` on the clips and its seeded percentile bootstrap interval over clips (resampled with
    replacement; resamples where it is undefined are skipped): ``{"value", "ci_lo", "ci_hi", "n_boot",
    "seed", "ci_level", "used"}``."""
    value = metric(clips) if clips else None
    rng = np.random.default_rng(seed)
    vals = []
    for _ in range(n_boot if clips else 0):
        idx = rng.integers(0, len(clips), size=len(clips))
        v = metric([clips[i] for i in idx])
        if v is not None:
            vals.append(v)
    a = (1.0 - level) / 2.0
    lo, hi = (float(np.quantile(vals, a)), float(np.quantile(vals, 1.0 - a))) if vals else (None, None)
    return {"value": value, "ci_lo": lo, "ci_hi": hi, "n_boot": n_boot, "seed": seed, "ci_level": level,
            "used": len(vals)}


#: The metric each format reports first (its headline), as a function of the clips.
HEADLINE: Mapping[str, tuple[str, Callable[[Sequence[ClipOutput]], float | None]]] = {
    "labels": ("Nexar-style mean AP (0.5/1.0/1.5 s)", lambda cs: nexar_ap(cs)["mean"]),
    "nexar": ("mean AP (0.5/1.0/1.5 s)", lambda cs: nexar_ap(cs)["mean"]),
    "ccd": ("frame-level AUC", lambda cs: frame_level(cs)["auc"]),
    "dad": ("video-level AP", lambda cs: anticipation(cs)["ap"]),
    "dota": ("frame-level AUC", lambda cs: frame_level(cs)["auc"]),
}
