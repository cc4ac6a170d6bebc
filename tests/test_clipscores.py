"""Threshold-free and out-of-sample scores: ROC/AUC, bootstrap interval, cross-validation, lead times."""
from __future__ import annotations

import pytest

from cdnf_ti.experiments.clipscores import (
    bootstrap_accuracy,
    cross_validated_accuracy,
    lead_times,
    never_alerts_accuracy,
    roc,
    warning_shares,
)
from cdnf_ti.experiments.labels import ClipLabel


def _col(name, lo=10, hi=20, contact=18):
    return ClipLabel(name, "collision", True, lo, hi, contact, 2)


def _non(name):
    return ClipLabel(name, "non-collision", False, None, None, None, 3)


LABELS = {"c1": _col("c1"), "c2": _col("c2"), "n1": _non("n1"), "n2": _non("n2")}


def test_a_perfect_separator_has_auc_one():
    # level 0: everything alerts early-ish in window; level 1: only collisions alert (in window)
    fas = {"c1": [12, 15], "c2": [11, 14], "n1": [5, None], "n2": [7, None]}
    r = roc(fas, LABELS, [0.0, 1.0])
    assert r.hit_rate == [1.0, 1.0] and r.false_alarm_rate == [1.0, 0.0]
    assert r.auc == pytest.approx(1.0)


def test_the_curve_ends_at_the_most_permissive_levels_hit_rate_not_at_one():
    # no level reaches hit rate 1 (a lower level alerts earlier, not more often inside the window),
    # so the curve runs (0, 0) -> (0.5, 0.5) -> (1, 0.5): area 0.375, not the 0.5 of a full diagonal
    fas = {"c1": [12], "c2": [None], "n1": [3], "n2": [None]}
    r = roc(fas, LABELS, [0.0])
    assert (r.hit_rate, r.false_alarm_rate) == ([0.5], [0.5])
    assert r.auc == pytest.approx(0.375)


def test_alerts_before_the_window_are_misses_so_auc_can_fall_below_chance():
    fas = {"c1": [2], "c2": [3], "n1": [None], "n2": [4]}
    r = roc(fas, LABELS, [0.0])
    assert r.hit_rate == [0.0] and r.auc == pytest.approx(0.0)


def test_bootstrap_interval_is_seeded_and_contains_the_accuracy():
    correct = [True] * 6 + [False] * 5
    a = bootstrap_accuracy(correct, seed=3)
    b = bootstrap_accuracy(correct, seed=3)
    assert a == b
    assert a.value == pytest.approx(6 / 11) and a.lo < a.value < a.hi
    assert 0.2 < a.lo < 0.35 and 0.75 < a.hi < 0.9


def test_cross_validation_chooses_each_level_without_the_held_out_clip():
    # level 0 is right for c1, c2, n1 and wrong for n2; level 1 right only for n1, n2
    fas = {"c1": [12, None], "c2": [12, None], "n1": [None, None], "n2": [5, None]}
    cv = cross_validated_accuracy(fas, LABELS, [0.0, 1.0])
    assert cv.scheme == "leave-one-out" and cv.folds == 4
    # held-out c1: on c2, n1, n2 level 0 scores 2/3, level 1 scores 2/3 -> tie -> lower index (level 0)
    assert cv.chosen["c1"] == 0.0 and cv.correct["c1"]
    # held-out n2: on c1, c2, n1 level 0 scores 3/3 -> level 0 -> n2 wrong
    assert cv.chosen["n2"] == 0.0 and not cv.correct["n2"]
    assert cv.accuracy == pytest.approx(0.75)


def test_k_fold_is_seeded():
    fas = {"c1": [12, None], "c2": [12, None], "n1": [None, None], "n2": [5, None]}
    a = cross_validated_accuracy(fas, LABELS, [0.0, 1.0], folds=2, seed=1)
    assert a.folds == 2 and a.scheme.startswith("2-fold")
    assert a.chosen == cross_validated_accuracy(fas, LABELS, [0.0, 1.0], folds=2, seed=1).chosen


def test_never_alerts_scores_the_share_of_non_collision_clips():
    assert never_alerts_accuracy(LABELS.values()) == 0.5


def test_hits_at_or_after_contact_are_counted_apart_from_warnings():
    rows = [{"outcome": "TP", "lead_time_ms": "100"}, {"outcome": "TP", "lead_time_ms": "300"},
            {"outcome": "TP", "lead_time_ms": "0"}, {"outcome": "TP", "lead_time_ms": "-33.3"},
            {"outcome": "FN", "lead_time_ms": "900"}, {"outcome": "TN", "lead_time_ms": ""}]
    d = lead_times(rows).to_dict()
    assert d["hits_before_contact"] == 2 and d["hits_at_or_after_contact"] == 2
    assert d["hit_lead_median_ms"] == 200 and (d["hit_lead_min_ms"], d["hit_lead_max_ms"]) == (100, 300)
    assert d["alerts_before_contact"] == 3


def test_warning_shares_count_collision_clips_warned_half_a_second_and_a_second_ahead():
    """Six collision clips with a contact frame: first alerts 1.2 s (ahead of the window: an early
    miss), 0.6 s, 0.5 s and 0.1 s before contact (hits), 33 ms after it (late) and none.
    >= 0.5 s: 1.2, 0.6, 0.5 -> 3/6, of which 2 hits; >= 1 s: 1.2 -> 1/6, no hit. The non-collision,
    failed and contact-less rows are not collision clips with a known contact."""
    rows = [{"clip": "a", "outcome": "FN", "contact_frame": 50, "lead_time_ms": "1200"},
            {"clip": "b", "outcome": "TP", "contact_frame": 50, "lead_time_ms": "600"},
            {"clip": "c", "outcome": "TP", "contact_frame": 50, "lead_time_ms": 500.0},
            {"clip": "d", "outcome": "TP", "contact_frame": 50, "lead_time_ms": "100"},
            {"clip": "e", "outcome": "FN", "contact_frame": 50, "lead_time_ms": "-33.3"},
            {"clip": "f", "outcome": "FN", "contact_frame": 50, "lead_time_ms": ""},
            {"clip": "g", "outcome": "FP", "contact_frame": "", "lead_time_ms": ""},
            {"clip": "h", "outcome": "", "contact_frame": 50, "lead_time_ms": "", "error": "boom"},
            {"clip": "i", "outcome": "TP", "contact_frame": "", "lead_time_ms": ""}]
    w = warning_shares(rows)
    assert w["collision_clips"] == 6 and w["never_alerted"] == 1
    assert (w["0.5"]["warned"], w["0.5"]["warned_hits"]) == (3, 2) and w["0.5"]["share"] == pytest.approx(0.5)
    assert (w["1"]["warned"], w["1"]["warned_hits"]) == (1, 0) and w["1"]["share"] == pytest.approx(1 / 6)
    assert w["alert_minus_contact_s"] == pytest.approx({"a": -1.2, "b": -0.6, "c": -0.5, "d": -0.1, "e": 0.0333})
    assert w["hit"] == {"a": False, "b": True, "c": True, "d": True, "e": False}
