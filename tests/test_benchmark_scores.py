"""The benchmark scorers against independent computations: scikit-learn's AP / ROC AUC, brute-force loops
and hand-worked examples (docs/EVALUATION.md, "Benchmark scores")."""
from __future__ import annotations

import numpy as np
import pytest

from cdnf_ti.experiments.annotations import Annotation, from_clip_label
from cdnf_ti.experiments.benchmark_scores import (
    ClipOutput,
    anticipation,
    average_precision,
    bootstrap_metric,
    by_condition,
    frame_level,
    horizon_scores,
    lead_times_s,
    nexar_ap,
    roc_auc,
)
from cdnf_ti.experiments.labels import ClipLabel

metrics = pytest.importorskip("sklearn.metrics", reason="scikit-learn (the 'test' extra) is the reference")


def _clip(name, scores, fps=10.0, event=None, labels=None, first_alert=None, **cond):
    return ClipOutput(Annotation(name, None, event, frame_labels=labels, conditions=cond),
                      np.asarray(scores, dtype=np.float64), fps, first_alert)


def _random_clips(seed: int, n: int = 12, ties: bool = True) -> list[ClipOutput]:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        t = int(rng.integers(20, 60))
        s = rng.random(t)
        if ties:
            s = np.round(s, 1)  # many tied scores
        event = float(rng.uniform(0.5, t / 10.0)) if i % 3 else None
        out.append(_clip(f"c{i}", s, 10.0, event, first_alert=int(rng.integers(0, t)) if i % 4 else None,
                         weather="rain" if i % 2 else "clear"))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_average_precision_equals_sklearn_with_tied_scores(seed):
    rng = np.random.default_rng(seed)
    y = rng.integers(0, 2, 300)
    s = np.round(rng.random(300), 1)
    assert average_precision(y, s) == pytest.approx(metrics.average_precision_score(y, s), abs=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_roc_auc_equals_sklearn_with_tied_scores(seed):
    rng = np.random.default_rng(seed)
    y = rng.integers(0, 2, 300)
    s = np.round(rng.random(300), 1)
    assert roc_auc(y, s) == pytest.approx(metrics.roc_auc_score(y, s), abs=1e-12)


def test_all_tied_scores_give_the_share_of_positives_and_auc_one_half():
    y = [1, 0, 0, 1, 0]
    assert average_precision(y, [0.3] * 5) == pytest.approx(0.4, abs=1e-15)
    assert roc_auc(y, [0.3] * 5) == 0.5


def test_scores_are_undefined_without_both_classes():
    assert average_precision([0, 0, 0], [0.1, 0.5, 0.2]) is None
    assert roc_auc([1, 1], [0.1, 0.5]) is None


def test_frame_level_scores_equal_sklearn_on_pooled_frames():
    clips = _random_clips(3)
    clips = [ClipOutput(Annotation(c.annotation.clip, None, c.annotation.event_s), c.scores, c.fps) for c in clips]
    # a frame is an event frame from the one holding the event on: it ends after the event
    y = np.concatenate([((np.arange(c.scores.size) + 1) / c.fps > c.annotation.event_s + 1e-9).astype(int)
                        if c.annotation.event_s is not None else np.zeros(c.scores.size, int) for c in clips])
    s = np.concatenate([c.scores for c in clips])
    fl = frame_level(clips)
    assert fl["frames"] == y.size and fl["positive_frames"] == y.sum()
    assert fl["ap"] == pytest.approx(metrics.average_precision_score(y, s), abs=1e-12)
    assert fl["auc"] == pytest.approx(metrics.roc_auc_score(y, s), abs=1e-12)


def test_a_video_with_no_positive_frame_adds_only_negative_frames():
    pos = _clip("p", [0.1, 0.9, 0.8], labels=(0, 1, 1))
    neg = _clip("n", [0.95, 0.2], labels=(0, 0))
    y = [0, 1, 1, 0, 0]
    s = [0.1, 0.9, 0.8, 0.95, 0.2]
    fl = frame_level([pos, neg])
    assert fl["ap"] == pytest.approx(metrics.average_precision_score(y, s), abs=1e-12)
    assert fl["auc"] == pytest.approx(metrics.roc_auc_score(y, s), abs=1e-12)


def _nexar_by_loop(clips, h):
    """Nexar's per-video scores written out frame by frame (the protocol of docs/EVALUATION.md)."""
    y, s = [], []
    for c in clips:
        if c.annotation.event_s is None:
            y.append(0)
            s.append(max(c.scores))
            continue
        seen = [c.scores[k] for k in range(c.scores.size) if k / c.fps <= c.annotation.event_s - h + 1e-9]
        if seen:
            y.append(1)
            s.append(max(seen))
    return y, s


@pytest.mark.parametrize("seed", [0, 4])
def test_nexar_ap_equals_sklearn_on_the_frames_seen_by_each_horizon(seed):
    clips = _random_clips(seed)
    res = nexar_ap(clips)
    aps = []
    for h in (0.5, 1.0, 1.5):
        y, s = _nexar_by_loop(clips, h)
        ap = metrics.average_precision_score(y, s)
        aps.append(ap)
        assert res[f"{h:g}"] == pytest.approx(ap, abs=1e-12)
    assert res["mean"] == pytest.approx(np.mean(aps), abs=1e-12)


def test_nexar_score_stops_at_the_last_frame_seen_by_the_horizon():
    """Event at 2.0 s, 10 fps: at 0.5 s ahead frames 0..15 count (frame 15 is seen at 1.5 s), so the peak at
    frame 16 is not yet seen; at 1.0 s ahead frames 0..10."""
    s = np.zeros(25)
    s[16], s[10], s[11] = 0.9, 0.5, 0.7
    c = _clip("p", s, 10.0, event=2.0)
    assert horizon_scores([c], 0.5)[1].tolist() == [0.7]
    assert horizon_scores([c], 1.0)[1].tolist() == [0.5]


def test_an_event_before_the_first_frame_is_left_out():
    early = _clip("early", [0.9, 0.9, 0.9], 10.0, event=0.3)  # 0.3 - 0.5 < 0: no frame seen by then
    neg = _clip("neg", [0.1, 0.2, 0.3], 10.0)
    late = _clip("late", [0.0] * 30, 10.0, event=2.5)
    y, s, left = horizon_scores([early, neg, late], 0.5)
    assert left == ["early"] and y.tolist() == [0, 1]
    res = nexar_ap([early, neg, late])
    assert res["left_out"]["0.5"] == ["early"] and res["videos"]["0.5"] == 2
    ant = anticipation([_clip("before", [0.5, 0.5], 10.0, event=-0.2), neg, late])
    assert ant["left_out"] == ["before"] and ant["videos"] == 2


def test_mtta_hand_worked():
    """Two positive clips (events at 1.0 s, 10 fps) and one negative.

    A: scores before the event 0.2 at frames 0-3, 0.8 at frames 4-9; B: 0.5 at frames 0-9; N: 0.6 everywhere.
    Highest scores before the event: A 0.8, B 0.5, N 0.6.
    th = 0.8: A alerted at frame 4 -> TTA 1.0 - 0.4 = 0.6 s; recall 1/2.
    th = 0.6: A only (B's 0.5 < 0.6) -> recall 1/2 again, TTA 0.6 s.
    th = 0.5: A (frame 4, 0.6 s) and B (frame 0, 1.0 s) -> recall 1, mean TTA 0.8 s.
    mTTA = mean over the recalls 1/2 and 1 of the best TTA = (0.6 + 0.8) / 2 = 0.7 s.
    AP over videos (A 0.8 +, N 0.6 -, B 0.5 +): 1/2 * 1 + 1/2 * 2/3 = 5/6.
    """
    a = _clip("A", [0.2] * 4 + [0.8] * 6 + [0.0] * 5, 10.0, event=1.0)
    b = _clip("B", [0.5] * 10 + [1.0] * 5, 10.0, event=1.0)  # its 1.0s come at/after the event: ignored
    n = _clip("N", [0.6] * 15, 10.0)
    res = anticipation([a, b, n])
    assert res["mtta_s"] == pytest.approx(0.7, abs=1e-12)
    assert res["ap"] == pytest.approx(5 / 6, abs=1e-12)
    assert res["ap"] == pytest.approx(metrics.average_precision_score([1, 1, 0], [0.8, 0.5, 0.6]), abs=1e-12)


def _mtta_by_loop(clips):
    """mTTA written out: every threshold, every video, every frame that ends by the event."""
    per_recall: dict = {}
    pos = [c for c in clips if c.annotation.event_s is not None]
    tops = []
    for c in clips:
        frames = [k for k in range(c.scores.size)
                  if c.annotation.event_s is None or (k + 1) / c.fps <= c.annotation.event_s + 1e-9]
        if frames:
            tops.append(max(c.scores[k] for k in frames))
    for th in sorted(set(tops)):
        ttas = []
        for c in pos:
            hits = [k for k in range(c.scores.size)
                    if (k + 1) / c.fps <= c.annotation.event_s + 1e-9 and c.scores[k] >= th]
            if hits:
                ttas.append(c.annotation.event_s - hits[0] / c.fps)
        if ttas:
            r = len(ttas) / len(pos)
            per_recall[r] = max(per_recall.get(r, -1e9), sum(ttas) / len(ttas))
    return sum(per_recall.values()) / len(per_recall)


@pytest.mark.parametrize("seed", [0, 5])
def test_mtta_equals_a_brute_force_loop(seed):
    clips = _random_clips(seed)
    assert anticipation(clips)["mtta_s"] == pytest.approx(_mtta_by_loop(clips), abs=1e-12)


def test_lead_times_are_seconds_before_the_event():
    clips = [_clip("a", [0] * 30, 10.0, event=2.0, first_alert=5),    # 1.5 s ahead
             _clip("b", [0] * 30, 10.0, event=2.0, first_alert=15),   # 0.5 s ahead
             _clip("c", [0] * 30, 10.0, event=2.0, first_alert=25),   # 0.5 s after
             _clip("d", [0] * 30, 10.0, event=2.0, first_alert=None),  # never
             _clip("n", [0] * 30, 10.0, first_alert=3)]               # negative: not counted
    lt = lead_times_s(clips)
    assert lt["leads_s"] == pytest.approx({"a": 1.5, "b": 0.5, "c": -0.5})
    assert lt["positive_clips"] == 4 and lt["never_alerted"] == 1 and lt["median_s"] == pytest.approx(0.5)
    assert lt["shares"] == pytest.approx({"0.5": 0.5, "1": 0.25, "1.5": 0.25})


def test_per_condition_scores_use_only_that_conditions_clips():
    clips = _random_clips(7)
    rain = [c for c in clips if c.annotation.conditions["weather"] == "rain"]
    res = by_condition(clips, frame_level)
    assert set(res["weather"]) == {"rain", "clear"}
    assert res["weather"]["rain"] == frame_level(rain)


def test_bootstrap_interval_is_seeded_and_brackets_the_value():
    clips = _random_clips(8)
    a = bootstrap_metric(clips, lambda cs: frame_level(cs)["auc"], n_boot=200, seed=3)
    b = bootstrap_metric(clips, lambda cs: frame_level(cs)["auc"], n_boot=200, seed=3)
    assert a == b and a["ci_lo"] <= a["value"] <= a["ci_hi"]


def test_a_labels_row_maps_to_seconds_at_the_clips_rate():
    lab = ClipLabel("c01", "collision", True, 48, 65, 62, 2)
    ann = from_clip_label(lab, 30.0)
    assert ann.event_s == pytest.approx(62 / 30) and ann.alert_s == pytest.approx(48 / 30)
    assert ann.frame_label_array(70, 30.0).tolist() == [0] * 48 + [1] * 18 + [0] * 4
    neg = from_clip_label(ClipLabel("nc03", "non-collision", False, None, None, None, 3), 30.0)
    assert not neg.positive and neg.frame_label_array(5, 30.0).sum() == 0


def test_an_annotation_becomes_a_window_from_the_alert_to_the_event():
    lab = Annotation("v", None, 4.0, 2.5).to_clip_label(row=1)
    assert lab.collision and lab.window_s == (2.5, 4.0) and lab.contact_s == 4.0
    no_alert = Annotation("w", None, 1.0).to_clip_label(row=2)
    assert no_alert.window_s == (0.0, 1.0)  # 1.5 s before the event, clipped at the clip's start
    assert not Annotation("n", None, None).to_clip_label(row=3).collision
