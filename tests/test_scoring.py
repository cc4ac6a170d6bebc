"""Scoring rules of docs/EVALUATION.md on hand-made first alerts, and the threshold sweep."""
from __future__ import annotations

import numpy as np
import pytest

from cdnf_ti.experiments.labels import ClipLabel
from cdnf_ti.experiments.scoring import Padding, Tally, accuracy, score_clip, tally
from cdnf_ti.models.base import Trace

COL = ClipLabel("c", "collision", True, 40, 50, 47, 2)
NONCOL = ClipLabel("n", "non-collision", False, None, None, None, 3)


@pytest.mark.parametrize("first, outcome, reason", [
    (40, "TP", ""), (45, "TP", ""), (50, "TP", ""),
    (39, "FN", "early"), (0, "FN", "early"), (51, "FN", "late"), (None, "FN", "none"),
])
def test_collision_clip_outcomes(first, outcome, reason):
    s = score_clip(first, COL)
    assert (s.outcome, s.fn_reason) == (outcome, reason)


def test_non_collision_clip_is_tn_without_alert_and_fp_with_one():
    assert score_clip(None, NONCOL).outcome == "TN"
    s = score_clip(3, NONCOL)
    assert (s.outcome, s.fn_reason, s.window_lo) == ("FP", "", None)


def test_padding_widens_the_window_on_each_side():
    pad = Padding(before=5, after=2)
    assert score_clip(35, COL, padding=pad).outcome == "TP"
    assert score_clip(34, COL, padding=pad).fn_reason == "early"
    assert score_clip(52, COL, padding=pad).outcome == "TP"
    assert score_clip(53, COL, padding=pad).fn_reason == "late"
    s = score_clip(45, COL, padding=pad)
    assert (s.window_lo, s.window_hi) == (35, 52)


def test_padding_before_stops_at_frame_zero():
    assert score_clip(0, COL, padding=Padding(before=100)).window_lo == 0


def test_negative_padding_is_refused():
    with pytest.raises(ValueError, match="padding"):
        Padding(before=-1)


def test_lead_time_is_milliseconds_before_contact():
    assert score_clip(44, COL, fps=30.0).lead_time_ms == pytest.approx(100.0)
    assert score_clip(49, COL, fps=25.0).lead_time_ms == pytest.approx(-80.0)
    assert score_clip(None, COL).lead_time_ms is None
    no_contact = ClipLabel("c", "collision", True, 40, 50, None, 2)
    assert score_clip(45, no_contact).lead_time_ms is None


def test_accuracy_is_correct_over_all_scored():
    assert accuracy(["TP", "TN", "FP", "FN"]) == 0.5
    assert accuracy(["TP", "TP", "TN", "FN"]) == 0.75
    assert accuracy([]) is None


def test_tally_groups_counts_and_leaves_errors_out_of_accuracy():
    rows = [
        dict(model="m", condition="clean", outcome="TP", fn_reason="", lead_time_ms=100.0, error=""),
        dict(model="m", condition="clean", outcome="FN", fn_reason="early", lead_time_ms="", error=""),
        dict(model="m", condition="clean", outcome="FN", fn_reason="none", lead_time_ms="", error=""),
        dict(model="m", condition="clean", outcome="TN", fn_reason="", lead_time_ms="", error=""),
        dict(model="m", condition="clean", outcome="", fn_reason="", lead_time_ms="", error="x.mp4: corrupt"),
        dict(model="m", condition="rain", outcome="FP", fn_reason="", lead_time_ms="", error=""),
    ]
    t = tally(rows)
    d = t[("m", "clean")].to_dict()
    assert (d["TP"], d["TN"], d["FP"], d["FN"], d["FN_early"], d["FN_none"], d["errors"]) == (1, 1, 0, 2, 1, 1, 1)
    assert d["accuracy"] == 0.5 and d["mean_lead_time_ms"] == 100.0
    assert t[("m", "rain")].accuracy == 0.0


def test_tally_rejects_unknown_outcome():
    with pytest.raises(ValueError):
        Tally().add("XX")


# --- threshold sweep -------------------------------------------------------

def test_cdnf_epsilon_sweep_matches_rerunning_the_model():
    """C-DNF's I_v does not depend on epsilon, so re-thresholding the saved trace
    gives the same first alert as running the model with that epsilon."""
    from conftest import small_stimulus

    from cdnf_ti.experiments.sweep import SweepSpec, sweep_first_alerts
    from cdnf_ti.models import CDNF
    from cdnf_ti.params import CDNFParams

    frames = list(small_stimulus("dark_looming", size=64).frames())
    base = CDNF().run(frames)
    eps = (0.0, 0.004, 0.012)
    spec = SweepSpec("cdnf", "epsilon", eps, 0.006, "cdnf-epsilon")
    swept = sweep_first_alerts(spec, base)
    rerun = [CDNF(CDNFParams(epsilon=e)).run(frames).first_alert for e in eps]
    assert swept == rerun
    assert len(set(swept)) > 1  # the sweep does change the alert


def _trace(out) -> Trace:
    out = np.asarray(out, float)
    return Trace("fake", "K", 0.7, out, out > 0.7, np.ones(out.size, bool), {})


def test_model_without_sweep_alerts_falls_back_to_output_threshold(monkeypatch):
    from cdnf_ti import models as reg
    from cdnf_ti.experiments.sweep import sweep_first_alerts, sweep_spec
    from cdnf_ti.models.base import Model

    class Fake(Model):
        name = "fake"
        output_name = "K"

        @property
        def threshold(self):
            return 0.7

        def step(self, frame):  # pragma: no cover - not run
            raise NotImplementedError

        def reset(self):  # pragma: no cover
            pass

        def fields(self):  # pragma: no cover
            return {}

    monkeypatch.setitem(reg.MODELS, "fake", Fake)
    tr = _trace([0.5, 0.6, 0.8, 0.95, 0.5])
    spec = sweep_spec("fake", [tr])
    assert spec.method == "fallback" and spec.default == 0.7 and 0.7 in spec.values
    firsts = dict(zip(spec.values, sweep_first_alerts(spec, tr)))
    assert firsts[0.7] == 2
    assert firsts[max(spec.values)] is None


def test_model_sweep_alerts_is_used_when_defined(monkeypatch):
    from cdnf_ti import models as reg
    from cdnf_ti.experiments.sweep import sweep_first_alerts, sweep_spec
    from cdnf_ti.models.base import Model

    class Counted(Model):
        name = "counted"
        sweep_parameter = "count"
        sweep_values = (1, 2, 3)

        @classmethod
        def sweep_alerts(cls, trace, values):
            # alert once the running number of frames above 0.5 reaches the count
            c = np.cumsum(trace.output > 0.5)
            return [c >= v for v in values]

        def step(self, frame):  # pragma: no cover
            raise NotImplementedError

        def reset(self):  # pragma: no cover
            pass

        def fields(self):  # pragma: no cover
            return {}

    monkeypatch.setitem(reg.MODELS, "counted", Counted)
    spec = sweep_spec("counted")
    assert (spec.method, spec.parameter, spec.values) == ("model", "count", (1.0, 2.0, 3.0))
    assert sweep_first_alerts(spec, _trace([0.6, 0.4, 0.6, 0.1, 0.9])) == [0, 2, 4]


def test_sweep_dataset_counts_hits_and_false_alarms():
    from cdnf_ti.experiments.sweep import SweepSpec, sweep_dataset

    labels = {"c": COL, "n": NONCOL}
    out_c = np.full(60, 0.5)
    out_c[45:] = 0.51      # crosses 0.5 + eps inside the window for eps < 0.01
    out_c[10] = 0.503      # an early blip above eps < 0.003
    out_n = np.full(60, 0.5)
    out_n[20] = 0.505
    mk = lambda o: Trace("cdnf", "I_v", 0.506, o, o > 0.506, np.ones(60, bool), {})  # noqa: E731
    traces = {("c", "cdnf", "clean"): mk(out_c), ("n", "cdnf", "clean"): mk(out_n)}
    spec = SweepSpec("cdnf", "epsilon", (0.001, 0.004, 0.006, 0.012), 0.006, "cdnf-epsilon")
    rows = sweep_dataset({"cdnf": spec}, traces, labels, {}, Padding())
    got = {r["value"]: (r["hits"], r["false_alarms"], r["accuracy"]) for r in rows}
    assert got == {0.001: (0, 2, 0.0), 0.004: (1, 1, 0.5), 0.006: (1, 0, 1.0), 0.012: (0, 0, 0.5)}
    assert [r["is_default"] for r in rows] == [False, False, True, False]
