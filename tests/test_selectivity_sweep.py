"""experiment selectivity: the grid, Table I expectations, batching, resumable runs, report."""
from __future__ import annotations

import json

import pytest

from cdnf_ti.experiments.selectivity import (
    GridTask,
    agreement_table,
    grid,
    make_batches,
    make_grid_stimulus,
    selectivity_sweep,
)
from cdnf_ti.paper import TABLE1


@pytest.mark.parametrize("which", ["quick", "full"])
def test_grid_covers_every_class_polarity_and_parameter(which):
    pts = grid(which)
    classes = {(p.cls, p.polarity) for p in pts}
    assert classes == {(c, pol) for c in ("looming", "receding", "translating", "grating")
                       for pol in ("dark", "light")}
    params = {p.parameter for p in pts if p.cls == "looming"}
    for want in ("frame size (px)", "frame rate (fps)", "duration (s)", "size law", "start half-size (side)",
                 "end half-size (side)", "grey levels", "coherence"):
        assert want in params
    assert {p.parameter for p in pts if p.cls == "translating"} >= {"speed (widths/s)", "bar width (side)"}
    assert len({p.spec + (p.cls, p.polarity) for p in pts}) == len(pts)  # no duplicate stimulus


@pytest.mark.parametrize("which", ["quick", "full"])
def test_incoherent_translating_rows_come_with_flickering_and_static_dots(which):
    pts = [p for p in grid(which) if p.cls == "translating" and "coherence" in p.kwargs]
    flicker = {(p.polarity, p.value) for p in pts if p.kwargs.get("scatter", "flicker") == "flicker"}
    static = {(p.polarity, p.value) for p in pts if p.kwargs.get("scatter") == "static"}
    assert flicker and flicker == static
    for p in pts:
        assert make_grid_stimulus(p).scatter == p.kwargs.get("scatter", "flicker")


def test_full_grid_spans_the_issues_ranges():
    pts = grid("full")
    sizes = {p.kwargs.get("height") for p in pts}
    fps = {p.kwargs.get("fps", 30.0) for p in pts}
    durs = {p.kwargs.get("duration", 1.5) for p in pts if p.cls == "looming"}
    assert min(sizes) == 120 and max(sizes) == 600
    assert min(fps) == 15 and max(fps) == 60
    assert min(durs) == 0.5 and max(durs) == 3.0


def test_expected_alert_is_table_one_and_no_alert_on_gratings():
    pts = grid("quick")
    loom = next(p for p in pts if p.stimulus == "light_looming")
    grat = next(p for p in pts if p.cls == "grating")
    assert loom.expected("lgmd2") == TABLE1["lgmd2"]["light_looming"] == 0
    assert loom.expected("cdnf") == 1
    assert grat.expected("cdnf") == 0 and grat.expected("lgmd1") == 0
    assert loom.expected("lgmd1") is None  # not in the paper's table


def test_every_grid_point_builds_a_valid_stimulus():
    for p in grid("full"):
        s = make_grid_stimulus(p)
        assert s.n_frames >= 2 and s.fps > 0


def test_batches_hold_one_model_at_one_frame_size():
    tasks = [GridTask(m, p, 0, "out") for p in grid("quick") for m in ("lgmd2", "sdnf")]
    batches = make_batches(tasks, chunk=5)
    assert sorted(t.key for b in batches for t in b.tasks) == sorted(t.key for t in tasks)
    for b in batches:
        assert len(b.tasks) <= 5
        assert len({(t.model, t.point.kwargs["height"], t.point.kwargs["width"]) for t in b.tasks}) == 1


def test_sweep_writes_report_and_resumes(tmp_path):
    out = tmp_path / "sel"
    res = selectivity_sweep(["lgmd2"], out, which="quick", classes=["grating"], workers=0, progress=False)
    n = len([p for p in grid("quick") if p.cls == "grating"])
    assert res["ran"] == n and res["reused"] == 0
    assert len(list((out / "tasks").glob("*.json"))) == n
    assert (out / "figures" / "selectivity_grid.png").stat().st_size > 1000
    md = (out / "selectivity.md").read_text()
    assert "| Stimulus class | lgmd2 |" in md and "dark-bar grating" in md
    rows = json.loads((out / "selectivity.json").read_text())["rows"]
    assert all(r["expected"] == 0 and r["alert"] in (0, 1) for r in rows)
    again = selectivity_sweep(["lgmd2"], out, which="quick", classes=["grating"], workers=0, progress=False,
                              figures=False)
    assert again["ran"] == 0 and again["reused"] == n
    assert [r["alert"] for r in again["rows"]] == [r["alert"] for r in res["rows"]]


def test_sweep_reruns_a_task_whose_result_file_is_damaged(tmp_path):
    out = tmp_path / "sel"
    selectivity_sweep(["sdnf"], out, which="quick", classes=["grating"], workers=0, progress=False, figures=False)
    victim = min((out / "tasks").glob("*.json"))
    victim.write_text("{not json")
    again = selectivity_sweep(["sdnf"], out, which="quick", classes=["grating"], workers=0, progress=False,
                              figures=False)
    assert again["ran"] == 1
    assert json.loads(victim.read_text())["alert"] in (0, 1)


def test_agreement_counts_matches_per_model_and_class():
    rows = [{"model": "m", "class": "looming", "polarity": "dark", "match": 1},
            {"model": "m", "class": "looming", "polarity": "dark", "match": 0},
            {"model": "m", "class": "grating", "polarity": "dark", "match": 1},
            {"model": "x", "class": "looming", "polarity": "dark", "match": None}]
    assert agreement_table(rows) == {"m": {"dark looming": [1, 2], "dark grating": [1, 1]}}


def test_unknown_class_or_grid_is_refused(tmp_path):
    with pytest.raises(ValueError, match="class"):
        selectivity_sweep(["lgmd2"], tmp_path, classes=["spiral"], workers=0, progress=False)
    with pytest.raises(ValueError, match="grid"):
        grid("huge")


def test_experiment_selectivity_command_prints_the_agreement_table(tmp_path, capsys):
    from cdnf_ti.run import main

    rc = main(["experiment", "selectivity", "--models", "lgmd2", "--classes", "grating", "--quick",
               "--out", str(tmp_path), "--workers", "0", "--no-progress", "--no-figures"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "| dark-bar grating |" in out
    assert (tmp_path / "selectivity.md").is_file() and (tmp_path / "selectivity.csv").is_file()


def test_experiment_selectivity_rejects_bad_coherences(tmp_path):
    from cdnf_ti.run import main

    assert main(["experiment", "selectivity", "--coherences", "0,0.5", "--out", str(tmp_path)]) == 2
