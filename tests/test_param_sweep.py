"""Parameter sweeps: grid parsing, one clear error before any work, identical results on local
processes and a Dask LocalCluster, resume, and the reports."""
from __future__ import annotations

import csv
import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest

from cdnf_ti.experiments.paramsweep import build_grid, parse_param, run_param_sweep, setting_key
from cdnf_ti.experiments.synthetic import make_synthetic_dataset
from cdnf_ti.params import CDNFParams

GRID = ["h=0.15:0.2:2", "alpha_off=0.5,0.9"]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    ds = tmp_path_factory.mktemp("ds")
    make_synthetic_dataset(ds, size=48, clips=("dark_looming", "light_translating", "dark_receding"))
    return ds


def _traces(out: Path) -> dict[str, str]:
    return {str(p.relative_to(out)): p.read_text() for p in sorted((out / "settings").rglob("*.csv"))}


def _rows(out: Path) -> list[dict]:
    with open(out / "param_sweep.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_a_range_gives_n_evenly_spaced_values_both_ends_included():
    assert parse_param("h=0.1:0.3:5", CDNFParams).values == (0.1, 0.15, 0.2, 0.25, 0.3)


@dataclasses.dataclass(frozen=True)
class _Flagged:
    """A parameter set with a bool (no model has one today)."""

    flag: bool = True


def test_a_list_is_typed_like_the_parameter():
    assert parse_param("max_iter=50,100", CDNFParams).values == (50, 100)
    assert parse_param("flag=true,off", _Flagged).values == (True, False)
    assert parse_param("start=local,rest", CDNFParams).values == ("local", "rest")
    assert parse_param("border=reflect,zero", CDNFParams).values == ("reflect", "zero")


def test_the_grid_is_the_product_of_every_param():
    _t, axes, settings = build_grid("cdnf", GRID)
    assert [a.name for a in axes] == ["h", "alpha_off"]
    assert settings == [{"h": 0.15, "alpha_off": 0.5}, {"h": 0.15, "alpha_off": 0.9},
                        {"h": 0.2, "alpha_off": 0.5}, {"h": 0.2, "alpha_off": 0.9}]
    assert setting_key(settings[1]) == "h=0.15,alpha_off=0.9"


@pytest.mark.parametrize("spec, words", [
    ("hh=0.1", "unknown parameter of CDNFParams"),
    ("h=0.3:0.1:3", "START must be below STOP"),
    ("h=0.1:0.3", "three parts"),
    ("h=0.1:0.3:1", "N must be at least 2"),
    ("h=0.1:0.3:x", "N must be a whole number"),
    ("h=a,b", "'a' is not a number"),
    ("h=0.1,0.1", "repeated"),
    ("max_iter=1.5", "whole number"),
    ("sigma_c=0,1", "sigma_c must be > 0"),
    ("h", "expected NAME=START:STOP:N"),
])
def test_bad_grids_are_rejected_with_one_line_naming_the_param(spec, words):
    with pytest.raises(ValueError) as e:
        build_grid("cdnf", [spec])
    assert words in str(e.value) and "\n" not in str(e.value)


def test_other_models_parameters_can_be_swept():
    _t, axes, settings = build_grid("lgmd2", ["n_ts=4,8"])
    assert settings == [{"n_ts": 4}, {"n_ts": 8}]


@pytest.mark.parametrize("args, words", [
    (["--param", "nope=1"], "unknown parameter"),
    (["--param", "h=0.3:0.1:3"], "START must be below STOP"),
    (["--param", "alpha_on=-1"], "alpha_on/alpha_off must be >= 0"),
    ([], "needs at least one --param"),
    (["--param", "h=0.1", "--model", "cdnf,lgmd2"], "exactly one --model"),
])
def test_command_line_exits_2_with_one_line_before_any_work(dataset, tmp_path, args, words):
    out = tmp_path / "out"
    p = subprocess.run([sys.executable, "-m", "cdnf_ti.run", "experiment", "sweep", str(dataset), "--out", str(out),
                        "--no-progress", *args], capture_output=True, text=True)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and words in lines[0]
    assert not (out / "settings").exists()


def test_local_processes_and_a_dask_local_cluster_give_identical_results_and_reruns_resume(dataset, tmp_path):
    distributed = pytest.importorskip("distributed")
    local = run_param_sweep(dataset, None, tmp_path / "local", "cdnf", GRID, workers=2, progress=False,
                            figures=False)
    assert local.ran == 12 and local.skipped == 0 and not local.errors
    with distributed.LocalCluster(n_workers=1, processes=True, threads_per_worker=1, dashboard_address=None,
                                  silence_logs=40) as cluster:
        dask = run_param_sweep(dataset, None, tmp_path / "dask", "cdnf", GRID,
                               scheduler=cluster.scheduler_address, progress=False, figures=False)
    assert dask.ran == 12
    assert _traces(tmp_path / "dask") == _traces(tmp_path / "local")
    assert _rows(tmp_path / "dask") == _rows(tmp_path / "local")
    # a rerun reuses every finished task; a lost one is recomputed alone
    again = run_param_sweep(dataset, None, tmp_path / "local", "cdnf", GRID, workers=0, progress=False,
                            figures=False)
    assert again.ran == 0 and again.skipped == 12
    lost = tmp_path / "local" / "settings" / "h=0.2,alpha_off=0.9" / "traces" / "clean" / "dark_looming.cdnf.json"
    lost.unlink()
    again = run_param_sweep(dataset, None, tmp_path / "local", "cdnf", GRID, workers=0, progress=False,
                            figures=False)
    assert again.ran == 1 and again.skipped == 11
    assert _rows(tmp_path / "local") == _rows(tmp_path / "dask")


def test_sweep_reports_scores_per_setting_and_marks_in_sample(dataset, tmp_path):
    run = run_param_sweep(dataset, None, tmp_path / "s", "cdnf", ["h=0.15,0.25"], workers=0, progress=False)
    rows = _rows(tmp_path / "s")
    assert [r["h"] for r in rows] == ["0.15", "0.25"]
    for r in rows:
        assert r["clips"] == "3" and r["cv_scheme"] == "leave-one-out"
        assert 0 <= float(r["auc"]) <= 1 and 0 <= float(r["cv_accuracy"]) <= 1
        assert float(r["best_in_sample_accuracy"]) >= float(r["cv_accuracy"])
    md = (tmp_path / "s" / "param_sweep.md").read_text()
    assert "in-sample" in md and "never-alerts baseline: 66.67%" in md
    data = json.loads((tmp_path / "s" / "param_sweep.json").read_text())
    assert data["never_alerts_accuracy"] == pytest.approx(2 / 3)
    assert (tmp_path / "s" / "figures" / "param_sweep_clean.png").stat().st_size > 5000
    html = (tmp_path / "s" / "report.html").read_text()
    assert "data:image/png;base64," in html and "<table" in html and "in-sample" in html
    assert len(run.rows) == 2


def test_sweep_reports_nested_cross_validation_beside_the_per_setting_rows(dataset, tmp_path):
    """The command of the issue: a 2 x 2 grid writes ``nested_cv`` (accuracy as a fraction, the
    settings chosen) into the JSON summary and a "nested" section into the Markdown and HTML."""
    from cdnf_ti.experiments.nested import nested_cross_validation, tables_from_first_alerts
    from cdnf_ti.run import main

    out = tmp_path / "n"
    rc = main(["experiment", "sweep", str(dataset), "--model", "cdnf", "--param", "h=0.1,0.2", "--param",
               "alpha_off=0.5,0.7", "--out", str(out), "--workers", "0", "--no-progress", "--no-figures"])
    assert rc == 0
    data = json.loads((out / "param_sweep.json").read_text())
    nested = data["nested_cv"]
    assert 0.0 <= nested["accuracy"] <= 1.0 and nested["ci_lo"] <= nested["accuracy"] <= nested["ci_hi"]
    assert sum(nested["chosen"].values()) == nested["folds"] == 3
    assert set(nested["chosen"]) <= {r["setting"] for r in data["rows"]}
    assert 0.0 <= nested["before_contact"]["accuracy"] <= 1.0
    md = (out / "param_sweep.md").read_text()
    assert "Nested cross-validation" in md and "nested CV accuracy" in md
    assert "nested" in (out / "report.html").read_text().lower()
    # the same figure, recomputed from the saved traces through the pure functions
    from cdnf_ti.experiments.labels import read_labels
    from cdnf_ti.experiments.paramsweep import evaluate
    from cdnf_ti.experiments.scoring import Padding

    labels = read_labels(dataset / "labels.csv")
    _t, _a, settings = build_grid("cdnf", ["h=0.1,0.2", "alpha_off=0.5,0.7"])
    alerts: dict = {}
    evaluate(out, "cdnf", settings, ["clean"], labels, Padding(), alerts=alerts)
    clips, tables = tables_from_first_alerts(alerts["clean"], {lab.clip: lab for lab in labels})
    assert nested_cross_validation(tables, clips).accuracy == nested["accuracy"]


def test_progress_lines_name_the_clip_the_setting_and_the_condition():
    from cdnf_ti.experiments.paramsweep import SweepTask, describe_task

    t = SweepTask("c01", "/x/c01.mp4", "cdnf", (("h", 0.1),), "h=0.1", "clean", "/out")
    assert describe_task(t) == "c01 [cdnf h=0.1, clean]"
    assert describe_task(t, {"seconds": 12.34, "error": ""}) == "c01 [cdnf h=0.1, clean]: 12.3 s"
    assert describe_task(t, {"error": "bad"}).endswith("error: bad")
