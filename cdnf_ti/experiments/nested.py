"""Nested cross-validation of a parameter sweep: the setting *and* the alert level chosen out of sample.

A sweep scores many settings on the same clips. Its best row is optimistic
twice over: the alert level and the setting were both picked by looking at
the clips they are scored on. The leave-one-out accuracy of a single row
(:func:`cdnf_ti.experiments.clipscores.cross_validated_accuracy`) removes the
first optimism only. Nested cross-validation removes both: for every outer
fold (by default one held-out clip),

1. on the remaining clips, each setting gets an *inner* cross-validated
   accuracy (its alert level chosen on the inner training folds, scored on the
   inner held-out folds);
2. the setting with the best inner accuracy is chosen (ties: the higher
   accuracy at its best level on the remaining clips, then the first setting in
   grid order), and its alert level is chosen on all remaining clips
   (:func:`cdnf_ti.experiments.clipscores.choose_level`; ties: the level
   closest to the setting's own);
3. the held-out clips are scored with that setting at that level.

The share of held-out clips scored correctly estimates what the whole
procedure "sweep, then pick the best setting and level" would score on clips
it has not seen. How often each setting was chosen shows how stable the pick
is. Everything here is a pure function of correctness tables (clip x alert
level, one per setting), so it can be checked on tables built by hand.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from .clipscores import bootstrap_accuracy, choose_level, correctness_matrix, fold_assignment
from .labels import ClipLabel
from .scoring import Padding

#: One sentence for the reports: what the nested figure means.
NESTED_MEANING = ("Nested cross-validation chooses the parameter setting and the alert level on the other clips "
                  "for every held-out clip, so its accuracy estimates what the whole procedure (sweep, then "
                  "pick the best setting and level) would score on new clips of this kind; the best row of the "
                  "per-setting table was picked on the clips it is scored on and is optimistic.")


@dataclass(frozen=True)
class SettingTable:
    """One setting's correctness table.

    Attributes
    ----------
    key : str
        The setting's name (e.g. ``h=0.1,alpha_off=0.7``).
    levels : tuple of float
        Its alert levels, length ``n_levels``.
    correct : ndarray of bool, shape (n_clips, n_levels)
        ``correct[i, j]``: clip ``i`` is scored TP or TN at level ``j``. Every
        table of one nested run has the same clips in the same order.
    default : float or None
        The setting's own alert level (tie-break of the level choice).
    """

    key: str
    levels: tuple
    correct: np.ndarray
    default: float | None = None


@dataclass
class NestedCVResult:
    """The outcome of :func:`nested_cross_validation`.

    Attributes
    ----------
    accuracy : float or None
        Share of held-out clips scored correctly, in [0, 1].
    ci_lo, ci_hi : float or None
        Seeded percentile bootstrap interval of ``accuracy`` over clips.
    folds : int
        Number of outer folds (= clips for leave-one-out).
    scheme : str
        ``"leave-one-out"`` or ``"k-fold (seed s)"`` (outer and inner alike).
    chosen : dict of str -> int
        Outer folds in which each setting was chosen (settings never chosen
        are left out), most often first.
    per_clip : dict of clip -> dict
        For each held-out clip: ``setting``, ``level`` and ``correct``.
    settings : int
        Settings compared.
    n_boot, seed : int
    """

    accuracy: float | None
    ci_lo: float | None
    ci_hi: float | None
    folds: int
    scheme: str
    chosen: dict = field(default_factory=dict)
    per_clip: dict = field(default_factory=dict)
    settings: int = 0
    n_boot: int = 0
    seed: int = 0

    def to_dict(self) -> dict:
        return {"accuracy": self.accuracy, "ci_lo": self.ci_lo, "ci_hi": self.ci_hi, "ci_level": 0.95,
                "n_boot": self.n_boot, "seed": self.seed, "folds": self.folds, "scheme": self.scheme,
                "settings": self.settings, "chosen": dict(self.chosen), "per_clip": self.per_clip}


def inner_cv_accuracy(correct: np.ndarray, levels: Sequence[float], folds: int = 0, seed: int = 0,
                      default: float | None = None) -> float:
    """Cross-validated accuracy of one setting on the clips (rows) of ``correct``.

    Each inner fold is scored at the level chosen on the other inner folds
    (:func:`choose_level`). With one clip there is nothing to choose on, so
    that clip is scored at the level chosen on no clip (the default's).

    Parameters
    ----------
    correct : ndarray of bool, shape (n_clips, n_levels)
    levels : sequence of float
    folds : int
        0 = leave-one-out; k >= 2 = k folds of a seeded shuffle.
    seed : int
    default : float, optional
        Tie-break of the level choice.
    """
    n = correct.shape[0]
    if n == 0:
        return 0.0
    fold = fold_assignment(n, folds, seed)
    hits = 0
    for f in range(int(fold.max()) + 1):
        test = fold == f
        j = choose_level(correct[~test], levels, default)
        hits += int(correct[test, j].sum())
    return hits / n


def choose_setting(tables: Sequence[SettingTable], rows: np.ndarray, folds: int = 0,
                   seed: int = 0) -> tuple[int, int, list[float]]:
    """Pick a setting and its alert level using only the clips ``rows``.

    Parameters
    ----------
    tables : sequence of SettingTable
    rows : ndarray of int or bool
        The training clips (row indices or a mask into every table).
    folds, seed : int
        Inner cross-validation scheme (see :func:`inner_cv_accuracy`).

    Returns
    -------
    (setting index, level index, inner accuracy of every setting)
        The setting with the best inner cross-validated accuracy (ties: the
        higher accuracy at its best level on ``rows``, then the lower index),
        and its level chosen on all of ``rows``.
    """
    if not tables:
        raise ValueError("no setting to choose from")
    inner, fitted, levels = [], [], []
    for t in tables:
        c = np.asarray(t.correct, dtype=bool)[rows]
        inner.append(inner_cv_accuracy(c, t.levels, folds, seed, t.default))
        j = choose_level(c, t.levels, t.default)
        levels.append(j)
        fitted.append(float(c[:, j].mean()) if c.shape[0] else 0.0)
    # fractions of the same clip count compare exactly
    best = max(range(len(tables)), key=lambda s: (inner[s], fitted[s], -s))
    return best, levels[best], inner


def nested_cross_validation(tables: Sequence[SettingTable], clips: Sequence[str], folds: int = 0, seed: int = 0,
                            n_boot: int = 2000) -> NestedCVResult:
    """Nested cross-validated accuracy of choosing a setting and an alert level (module docstring).

    Parameters
    ----------
    tables : sequence of SettingTable
        One per setting, rows in the order of ``clips``.
    clips : sequence of str
        Clip names (rows of every table).
    folds : int
        0 = leave-one-out (outer and inner); k >= 2 = k outer folds of a seeded
        shuffle, and k inner folds on each training part.
    seed : int
        Fold shuffle and bootstrap seed.
    n_boot : int
        Bootstrap resamples of the interval.

    Raises
    ------
    ValueError
        A table whose row count differs from ``len(clips)``.
    """
    n = len(clips)
    for t in tables:
        if np.asarray(t.correct).shape[0] != n:
            raise ValueError(f"setting {t.key}: {np.asarray(t.correct).shape[0]} rows for {n} clips")
    if n < 2 or not tables:
        return NestedCVResult(None, None, None, 0, "none", settings=len(tables), n_boot=n_boot, seed=seed)
    fold = fold_assignment(n, folds, seed)
    k = int(fold.max()) + 1
    per_clip: dict[str, dict] = {}
    counts: Counter = Counter()
    for f in range(k):
        test = fold == f
        s, j, _ = choose_setting(tables, np.flatnonzero(~test), folds, seed)
        counts[tables[s].key] += 1
        for i in np.flatnonzero(test):
            per_clip[clips[i]] = {"setting": tables[s].key, "level": float(tables[s].levels[j]),
                                  "correct": bool(np.asarray(tables[s].correct, dtype=bool)[i, j])}
    correct = [per_clip[c]["correct"] for c in clips]
    iv = bootstrap_accuracy(correct, n_boot=n_boot, seed=seed)
    order = {t.key: i for i, t in enumerate(tables)}
    chosen = dict(sorted(counts.items(), key=lambda kv: (-kv[1], order[kv[0]])))
    scheme = "leave-one-out" if k == n else f"{k}-fold (seed {seed})"
    return NestedCVResult(iv.value, iv.lo, iv.hi, k, scheme, chosen, per_clip, len(tables), n_boot, seed)


def tables_from_first_alerts(by_setting: Mapping[str, tuple], labels: Mapping[str, ClipLabel],
                             padding: Padding = Padding()) -> tuple[list[str], list[SettingTable]]:
    """Correctness tables of a sweep's settings on the clips every setting has.

    Parameters
    ----------
    by_setting : mapping of setting key -> (first_alerts, levels, default)
        ``first_alerts`` maps clip -> first alert frame (or None) per level, as
        :func:`cdnf_ti.experiments.sweep.sweep_first_alerts` returns it.
    labels : mapping of clip -> ClipLabel
        (e.g. cut to end before contact, to score before-contact hits only).
    padding : Padding

    Returns
    -------
    (clips, tables)
    """
    common: set | None = None
    for fas, _, _ in by_setting.values():
        common = set(fas) if common is None else common & set(fas)
    clips = sorted(common or ())
    tables = []
    for key, (fas, levels, default) in by_setting.items():
        if not clips:
            break
        _, c = correctness_matrix({cl: fas[cl] for cl in clips}, labels, padding)
        tables.append(SettingTable(key, tuple(float(v) for v in levels), c, default))
    return clips, tables


def sweep_nested_cv(by_condition: Mapping[str, Mapping[str, tuple]], labels: Mapping[str, ClipLabel],
                    labels_before_contact: Mapping[str, ClipLabel], padding: Padding = Padding(), folds: int = 0,
                    seed: int = 0) -> dict:
    """The ``nested_cv`` entry of a sweep's summary.

    Parameters
    ----------
    by_condition : mapping of condition -> (mapping of setting key -> (first_alerts, levels, default))
    labels : mapping of clip -> ClipLabel
    labels_before_contact : mapping of clip -> ClipLabel
        The same windows cut to end before contact (hits before contact only).
    padding : Padding
    folds, seed : int

    Returns
    -------
    dict
        The first condition's result (``accuracy``, ``ci_lo``, ``ci_hi``,
        ``chosen``, ``per_clip``, ...) with ``condition`` and
        ``before_contact`` (the same for before-contact hits only) at the top
        level, and every condition's under ``by_condition``.
    """
    out: dict = {}
    for cond, by_setting in by_condition.items():
        clips, tables = tables_from_first_alerts(by_setting, labels, padding)
        res = nested_cross_validation(tables, clips, folds, seed).to_dict()
        clips_pre, tables_pre = tables_from_first_alerts(by_setting, labels_before_contact, padding)
        res["before_contact"] = nested_cross_validation(tables_pre, clips_pre, folds, seed).to_dict()
        res["condition"] = cond
        out[cond] = res
    if not out:
        return {"accuracy": None, "chosen": {}, "by_condition": {}}
    first = next(iter(out.values()))
    return {**first, "by_condition": out}
