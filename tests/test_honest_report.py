"""summary.json/md of a dataset run carry ROC/AUC, bootstrap intervals, cross-validated accuracy,
lead times, frames held at rest, the never-alerts baseline and in-sample marks; per-clip figures
follow the labels file in use."""
from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from cdnf_ti.experiments.dataset import run_dataset
from cdnf_ti.experiments.synthetic import make_synthetic_dataset


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    ds = tmp_path_factory.mktemp("ds")
    make_synthetic_dataset(ds, size=32, clips=("dark_looming", "light_translating", "light_looming"))
    out = tmp_path_factory.mktemp("out")
    return ds, run_dataset(ds, None, out, models=["cdnf", "lgmd1"], rain="both", workers=0, progress=False)


def test_summary_json_carries_every_honest_score(run):
    _ds, r = run
    s = json.loads((r.out / "summary.json").read_text())
    assert s["never_alerts_accuracy"] == pytest.approx(1 / 3)
    for m in ("cdnf", "lgmd1"):
        for c in ("clean", "rain"):
            d = s["scores"][m][c]
            ci = d["accuracy_ci"]
            assert ci["ci_lo"] <= ci["value"] <= ci["ci_hi"] and ci["n_boot"] == 2000
            assert ci["value"] == pytest.approx(s["results"][m][c]["accuracy"])
            assert d["auc"] is not None and 0.0 <= d["auc"] <= 1.0  # both classes are present: AUC is defined
            assert d["cv"]["scheme"] == "leave-one-out" and set(d["cv"]["chosen_levels"]) == {
                "dark_looming", "light_translating", "light_looming"}
            assert "in-sample" in d["in_sample_best"]["note"]
            assert {"hits_before_contact", "hits_at_or_after_contact"} <= set(d["lead_times"])
    assert "held" not in s["scores"]["cdnf"]["clean"]
    held = s["scores"]["lgmd1"]["rain"]["held"]
    assert held["frames"] == 3 * 46 and 0 <= held["held_frames"] <= held["frames"]
    assert "in-sample" in s["threshold_sweep_note"]
    assert all(v["best_is_in_sample"] for per in s["threshold_sweep"].values() for v in per.values())


def test_summary_md_marks_in_sample_and_shows_the_baseline(run):
    _ds, r = run
    md = (r.out / "summary.md").read_text()
    assert "## Threshold sweep (in-sample)" in md
    assert "| never alerts (baseline) | any | 33.33%" in md
    assert "(in-sample)" in md and "CV accuracy" in md and "ROC AUC" in md


def test_lead_time_shares_and_figure_are_in_the_summaries_and_the_report(run):
    """Every model and condition reports the share of collision clips warned >= 0.5 s and >= 1 s
    before contact, recomputed here from results.csv, and the lead-time figure is drawn and shown."""
    import csv

    _ds, r = run
    s = json.loads((r.out / "summary.json").read_text())
    with open(r.out / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    for m in ("cdnf", "lgmd1"):
        for c in ("clean", "rain"):
            w = s["scores"][m][c]["warning"]
            mine = [x for x in rows if x["model"] == m and x["condition"] == c and x["label"] == "collision"]
            assert w["collision_clips"] == len(mine) == 2
            for sec in (0.5, 1.0):
                warned = [x for x in mine if x["lead_time_ms"] and float(x["lead_time_ms"]) >= 1000 * sec]
                assert w[f"{sec:g}"]["warned"] == len(warned)
                assert w[f"{sec:g}"]["share"] == pytest.approx(len(warned) / 2)
    md = (r.out / "summary.md").read_text()
    assert "## Lead time" in md and "Warned >= 0.5 s before contact" in md and "Warned >= 1 s" in md
    assert (r.out / "figures" / "lead_times.png").stat().st_size > 5000
    html = (r.out / "report.html").read_text()
    assert "Warned &gt;= 1 s before contact" in html or "Warned >= 1 s before contact" in html
    assert "First alert time relative to contact" in html


def test_per_clip_figures_are_redrawn_after_a_labels_edit(run):
    ds, r = run
    png = r.out / "figures" / "traces_dark_looming.png"
    other = r.out / "figures" / "traces_light_translating.png"
    old = png.stat().st_mtime_ns
    for trace in (r.out / "traces").rglob("*"):  # inputs clearly older than the figures, however slow the run
        if trace.is_file():
            os.utime(trace, ns=(old - 20 * 10**9, old - 20 * 10**9))
    os.utime(png, ns=(old - 10 * 10**9, old - 10 * 10**9))
    os.utime(other, ns=(old - 10 * 10**9, old - 10 * 10**9))
    before, before_other = png.stat().st_mtime_ns, other.stat().st_mtime_ns
    labels = (ds / "labels.csv").read_text().replace("dark_looming,collision,32,45", "dark_looming,collision,30,44")
    assert "dark_looming,collision,30,44" in labels
    (ds / "labels.csv").write_text(labels)
    again = run_dataset(ds, None, r.out, models=["cdnf", "lgmd1"], rain="both", workers=0, progress=False)
    assert again.ran == 0
    assert png.stat().st_mtime_ns > before  # its window changed: redrawn
    assert other.stat().st_mtime_ns == before_other  # unchanged label: reused
    assert Path(again.out / "report.html").is_file()


def test_threshold_sweep_headings_name_the_model_and_its_parameter_only(run):
    """Each heading is ``### <model>: <swept parameter>``; how it is scored is said once, in words, below it."""
    _ds, r = run
    md = (r.out / "summary.md").read_text()
    section = md.split("## Threshold sweep (in-sample)", 1)[1].split("\n## ", 1)[0]
    headings = [ln for ln in section.splitlines() if ln.startswith("### ")]
    assert [h.split(":")[0] for h in headings] == ["### cdnf", "### lgmd1"]
    for h in headings:
        parameter = h.split(": ", 1)[1]
        assert "sweep_alerts" not in h and h.count(parameter) == 1 and "`" not in h
    assert "sweep_alerts" not in section
