"""One "how close did it come" line for every model, from the model (:meth:`Model.alert_rule`): ``run``'s
line and summary.csv, and ``live``'s ``start`` event, give each model's alert rule, the value the rule
compares, its peak and its level."""
from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from cdnf_ti.live import main as live_main
from cdnf_ti.models import MODELS, LPLC2Params, create_model
from cdnf_ti.models.lplc2 import gf_frame
from cdnf_ti.run import main
from cdnf_ti.stimuli.basic import basic_stimulus

#: The rule of each model that its paper or code states (docs/MODELS.md), with default parameters, and the
#: trace column it compares. A model added later states its own in its tests; every registered model runs below.
RULES = {
    "cdnf": ("I_v > 0.506", "I_v"),
    "sdnf": ("I > max(0.506, I(t-1)) on 3 frames in a row", "run"),
    "lgmd2": ("spike count >= 8", "count"),
    "lgmd1": ("spike count >= 8", "count"),
    "flgmd_onn": ("spike count >= 8", "count"),
    "olgmd": ("4-frame sum of exp(4(K - 0.78)) >= 3", "spike_sum"),
    "lplc2": ("V > -50 mV in a substep (a GF spike)", "V_peak"),
}


@pytest.mark.parametrize("name", list(RULES))
def test_the_published_models_state_their_published_rule(name):
    rule = create_model(name, backend="numpy").alert_rule()
    assert (rule.rule, rule.column) == RULES[name]


@pytest.mark.parametrize("name", list(MODELS))
def test_every_registered_model_states_a_rule_on_a_column_of_its_trace(name):
    model = create_model(name, backend="numpy")
    rule = model.alert_rule()
    trace = model.run(np.zeros((3, 24, 24), np.uint8))
    assert rule.rule and rule.quantity and np.isfinite(rule.level)
    assert rule.column in {"spike", model.output_name, *trace.diagnostics}


@pytest.fixture(scope="module")
def looming_npy(tmp_path_factory):
    s = basic_stimulus("dark_looming", height=48, width=48, start_half_size=1.5)
    path = tmp_path_factory.mktemp("lines") / "looming.npy"
    np.save(path, np.stack(list(s.frames()))[:24])
    return path


def _number(text: str) -> float:
    return float("nan") if text == "n/a" else float(text)


@pytest.mark.parametrize("name", list(MODELS))
def test_run_line_and_summary_give_the_models_rule_peak_and_level(name, looming_npy, tmp_path, capsys):
    rule = create_model(name, backend="numpy").alert_rule()
    rule_text, column = rule.rule, rule.column
    out = tmp_path / "o"
    assert main([str(looming_npy), "--model", name, "--backend", "numpy", "--out", str(out), "--no-progress"]) == 0
    line = capsys.readouterr().out.strip()
    row = next(csv.DictReader(open(out / "summary.csv")))
    trace = list(csv.DictReader(open(out / row["trace"])))
    peak = max(float(r[column]) for r in trace)
    assert f"alert when {rule_text}" in line and row["alert_rule"] == rule_text
    shown = line.split(f"max {rule.quantity} ", 1)[1].split(",", 1)[0]
    assert _number(shown) == pytest.approx(peak, abs=5e-5)
    assert float(row["alert_peak"]) == pytest.approx(peak, rel=1e-5)
    assert float(row["alert_level"]) == rule.level


def test_a_parameter_changes_the_stated_rule():
    assert create_model("lgmd2", params=type(create_model("lgmd2").params)(n_ts=3), backend="numpy") \
        .alert_rule().rule == "spike count >= 3"
    assert create_model("lplc2", params=LPLC2Params(v_threshold=-55.0), backend="numpy").alert_rule().level == -55.0


def test_lplc2_records_V_before_the_spike_reset():
    p = LPLC2Params()
    v_end, spikes, v_peak = gf_frame(p.v_rest, 1000.0, 0.01, p)  # a strong input: the fibre spikes
    assert spikes > 0 and v_end <= p.v_threshold < v_peak


def test_lplc2_V_peak_is_below_threshold_on_a_frame_without_a_spike():
    p = LPLC2Params()
    v_end, spikes, v_peak = gf_frame(p.v_rest, 0.5, 0.01, p)
    assert spikes == 0 and v_end <= v_peak <= p.v_threshold


def test_an_alerting_lplc2_run_shows_its_peak_above_the_threshold(tmp_path, capsys):
    frames = np.stack(list(basic_stimulus("dark_looming", height=96, width=128, fps=100.0, duration=1.0).frames()))
    path = tmp_path / "loom.npy"
    np.save(path, frames)
    assert main([str(path), "--model", "lplc2", "--backend", "numpy", "--fps", "100", "--out", str(tmp_path / "o"),
                 "--no-progress"]) == 0
    line = capsys.readouterr().out
    assert "first alert none" not in line
    shown = float(line.split("max V before reset ", 1)[1].split(",", 1)[0])
    assert shown > LPLC2Params().v_threshold


@pytest.mark.parametrize("name", ["lgmd2", "olgmd"])
def test_live_start_event_gives_the_models_threshold_and_rule(name, capsys):
    code = live_main(["stim:dark_looming?size=48&duration=0.1", "--model", name, "--backend", "numpy",
                      "--no-progress"])
    assert code == 0
    start = next(r for r in map(json.loads, capsys.readouterr().out.splitlines()) if r["event"] == "start")
    (model,) = start["models"]
    rule = create_model(name, backend="numpy").alert_rule()
    assert model["rule"] == RULES[name][0] and model["threshold"] == rule.level and model["compares"] == RULES[name][1]
