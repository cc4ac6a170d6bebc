"""Nested cross-validation: the setting and the alert level chosen without the held-out clip.

Every table here is small enough that the nested answer follows by hand; each
test says how.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cdnf_ti.experiments.labels import ClipLabel
from cdnf_ti.experiments.nested import (
    SettingTable,
    choose_setting,
    inner_cv_accuracy,
    nested_cross_validation,
    sweep_nested_cv,
    tables_from_first_alerts,
)

CLIPS = [f"c{i}" for i in range(6)]


def right_except(n: int, wrong: set[int]) -> np.ndarray:
    """A one-level column: every clip correct except those in ``wrong``."""
    return np.array([[i not in wrong] for i in range(n)])


def test_one_setting_chooses_the_level_on_the_other_clips():
    """Level 0 is right on every clip but c0, level 1 only on c0. Holding out c0, level 0 is
    perfect on the rest, so c0 is missed; holding out any other clip, level 0 wins 4/5 to 1/5
    and the clip is right: 5/6."""
    c = np.column_stack([right_except(6, {0})[:, 0], ~right_except(6, {0})[:, 0]])
    res = nested_cross_validation([SettingTable("A", (0.0, 1.0), c)], CLIPS)
    assert res.accuracy == pytest.approx(5 / 6)
    assert res.chosen == {"A": 6}
    assert [res.per_clip[k]["level"] for k in CLIPS] == [0.0] * 6
    assert [res.per_clip[k]["correct"] for k in CLIPS] == [False] + [True] * 5


def test_choosing_among_equally_good_settings_scores_below_every_setting():
    """Setting s_i is wrong on clip i only, so every row of the table scores 5/6. Holding out
    clip i, s_i is the only setting perfect on the other five, so it is chosen, and it is wrong
    on clip i: the procedure scores 0 although every setting scores 5/6."""
    tables = [SettingTable(f"s{i}", (0.0,), right_except(6, {i})) for i in range(6)]
    assert all(t.correct.mean() == pytest.approx(5 / 6) for t in tables)
    res = nested_cross_validation(tables, CLIPS)
    assert res.accuracy == 0.0
    assert res.chosen == {f"s{i}": 1 for i in range(6)}
    assert all(res.per_clip[f"c{i}"]["setting"] == f"s{i}" for i in range(6))


def test_a_setting_better_on_every_subset_is_chosen_in_every_fold():
    """A is right on all clips but c5, B on c0-c2 only: A beats B on any five clips, so A is
    chosen in all six folds and the nested accuracy is A's own, 5/6."""
    a = SettingTable("A", (0.0,), right_except(6, {5}))
    b = SettingTable("B", (0.0,), right_except(6, {3, 4, 5}))
    res = nested_cross_validation([b, a], CLIPS)
    assert res.chosen == {"A": 6}
    assert res.accuracy == pytest.approx(5 / 6)
    assert res.folds == 6 and res.scheme == "leave-one-out" and res.settings == 2


def test_the_setting_is_chosen_by_inner_cross_validation_not_by_its_best_level_in_sample():
    """On the four training clips c1-c4, A's two levels are each right on two of them, so a level
    chosen on any three is wrong on the fourth: A's inner accuracy is 0/4. B's one level is right
    on c1-c3: inner 3/4. B must win, at its only level."""
    a = np.array([[True, True], [True, False], [True, False], [False, True], [False, True]])
    b = np.array([[False], [True], [True], [True], [False]])
    tables = [SettingTable("A", (0.0, 1.0), a), SettingTable("B", (0.0,), b)]
    rows = np.array([1, 2, 3, 4])
    assert inner_cv_accuracy(a[rows], (0.0, 1.0)) == 0.0
    assert inner_cv_accuracy(b[rows], (0.0,)) == pytest.approx(3 / 4)
    s, j, inner = choose_setting(tables, rows)
    assert (s, j) == (1, 0) and inner == [0.0, pytest.approx(0.75)]


def test_ties_go_to_the_better_fit_then_to_the_first_setting_in_grid_order():
    same = right_except(6, {0, 1})
    tables = [SettingTable("first", (0.0,), same), SettingTable("second", (0.0,), same.copy())]
    assert nested_cross_validation(tables, CLIPS).chosen == {"first": 6}


def test_k_fold_holds_out_every_clip_once_and_counts_folds():
    tables = [SettingTable("A", (0.0,), right_except(6, {5})), SettingTable("B", (0.0,), right_except(6, {0}))]
    res = nested_cross_validation(tables, CLIPS, folds=3, seed=4)
    assert res.folds == 3 and res.scheme == "3-fold (seed 4)"
    assert sorted(res.per_clip) == sorted(CLIPS) and sum(res.chosen.values()) == 3
    again = nested_cross_validation(tables, CLIPS, folds=3, seed=4)
    assert again.to_dict() == res.to_dict()


def test_the_interval_is_a_seeded_bootstrap_around_the_accuracy():
    res = nested_cross_validation([SettingTable("A", (0.0,), right_except(6, {0, 3}))], CLIPS, seed=1)
    assert res.accuracy == pytest.approx(4 / 6)
    assert 0.0 <= res.ci_lo <= res.accuracy <= res.ci_hi <= 1.0 and res.ci_lo < res.ci_hi
    assert nested_cross_validation([SettingTable("A", (0.0,), right_except(6, {0, 3}))], CLIPS,
                                   seed=1).ci_lo == res.ci_lo


def test_a_table_with_the_wrong_number_of_clips_is_refused():
    with pytest.raises(ValueError, match="rows"):
        nested_cross_validation([SettingTable("A", (0.0,), right_except(5, set()))], CLIPS)


def test_fewer_than_two_clips_give_no_estimate():
    res = nested_cross_validation([SettingTable("A", (0.0,), right_except(1, set()))], ["c0"])
    assert res.accuracy is None and res.chosen == {}


def _labels() -> dict[str, ClipLabel]:
    col = [ClipLabel(f"k{i}", "collision", True, 10, 20, 18, 2 + i) for i in range(3)]
    non = [ClipLabel("n0", "non-collision", False, None, None, None, 5)]
    return {lab.clip: lab for lab in col + non}


def test_tables_from_first_alerts_score_only_the_clips_every_setting_has():
    labels = _labels()
    by_setting = {"A": ({"k0": [15, None], "k1": [19, None], "n0": [None, None]}, (0.0, 1.0), None),
                  "B": ({"k0": [30, 30], "k1": [12, None], "k2": [11, 11], "n0": [5, None]}, (0.0, 1.0), None)}
    clips, tables = tables_from_first_alerts(by_setting, labels)
    assert clips == ["k0", "k1", "n0"]
    np.testing.assert_array_equal(tables[0].correct, [[True, False], [True, False], [True, True]])
    np.testing.assert_array_equal(tables[1].correct, [[False, False], [True, False], [False, True]])


def test_sweep_summary_scores_before_contact_hits_separately():
    """Setting A alerts at contact (frame 18) on every collision clip: right in the windows that
    run to frame 20, late once they are cut to end before contact; B alerts at frame 12 on every
    collision clip, right either way. Both stay silent on n0. Holding out any clip, A and B are
    both perfect on the rest, so A (first in grid order, equal fit) is chosen: 4/4 with the full
    windows. Before contact B is perfect and A scores only n0, so B is chosen: 4/4 again."""
    labels = _labels()
    pre = {c: (dataclasses.replace(lab, window_end=17) if lab.collision else lab) for c, lab in labels.items()}
    at_contact = {"k0": [18], "k1": [18], "k2": [18], "n0": [None]}
    early = {"k0": [12], "k1": [12], "k2": [12], "n0": [None]}
    summary = sweep_nested_cv({"clean": {"A": (at_contact, (0.0,), None), "B": (early, (0.0,), None)}}, labels, pre)
    assert summary["accuracy"] == 1.0 and summary["chosen"] == {"A": 4}
    assert summary["before_contact"]["accuracy"] == 1.0 and summary["before_contact"]["chosen"] == {"B": 4}
    assert summary["condition"] == "clean" and set(summary["by_condition"]) == {"clean"}
