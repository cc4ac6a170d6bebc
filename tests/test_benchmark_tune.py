"""``experiment tune``: search spaces, the nested procedure (held-out clips never seen while choosing),
the out-of-sample score and resuming through the task cache."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from cdnf_ti.errors import UserError
from cdnf_ti.experiments.clip_tasks import setting_folder
from cdnf_ti.experiments.layout import trace_path
from cdnf_ti.experiments.synthetic import make_synthetic_dataset
from cdnf_ti.experiments.tune import parse_search, run_tune
from cdnf_ti.models.cdnf import CDNFParams
from cdnf_ti.run import main

pytest.importorskip("optuna", reason="experiment tune needs Optuna (the 'tune' extra)")

CLIPS = ("dark_looming", "light_translating", "light_looming", "dark_receding", "dark_translating")


def test_search_spaces_parse_ranges_log_ranges_and_choices():
    a = parse_search("h=0.05:0.3", CDNFParams)
    assert (a.kind, a.low, a.high, a.log) == ("float", 0.05, 0.3, False)
    assert parse_search("h=0.01:0.3:log", CDNFParams).log
    assert parse_search("alpha_on=0.3,0.5", CDNFParams).choices == (0.3, 0.5)


@pytest.mark.parametrize("spec, problem", [("h=0.3:0.1", "LO must be below HI"), ("h=0:0.3:log", "LO > 0"),
                                           ("h=1:2:3", "LO:HI or LO:HI:log"), ("nope=1:2", "nope"),
                                           ("h=0.1,0.1", "repeated")])
def test_bad_search_spaces_are_one_line_errors(spec, problem):
    with pytest.raises(UserError, match=problem):
        parse_search(spec, CDNFParams)


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tune_ds")
    make_synthetic_dataset(folder, size=64, clips=CLIPS)
    out = tmp_path_factory.mktemp("tune_out")
    res = run_tune(folder, None, out, "cdnf", ["h=0.05:0.3", "alpha_on=0.3,0.5"], trials=3, folds=2, seed=0,
                   workers=0, progress=False)
    return folder, out, res


def test_out_of_sample_accuracy_is_the_share_of_held_out_clips_scored_correctly(tuned):
    _, out, res = tuned
    held = [c for d in res["folds"] for c in d["test_clips"]]
    assert sorted(held) == sorted(CLIPS)  # every clip held out exactly once
    assert res["accuracy"] == pytest.approx(sum(res["per_clip"][c]["correct"] for c in CLIPS) / len(CLIPS))
    assert json.loads((out / "tune.json").read_text())["accuracy"] == res["accuracy"]
    assert "What each outer fold chose" in (out / "tune.md").read_text()


def test_held_out_clips_are_run_only_with_the_setting_their_fold_chose(tuned):
    """The trials of a fold run on its training clips only: a held-out clip has a trace of the chosen
    setting and of no other setting that fold tried and did not choose elsewhere."""
    _, out, res = tuned
    chosen = {d["key"] for d in res["folds"]}
    for d in res["folds"]:
        for c in d["test_clips"]:
            assert trace_path(setting_folder(out, d["key"]), "clean", c, "cdnf").is_file()
    tried = {p.name for p in (Path(out) / "settings").iterdir()}
    for key in tried - chosen:
        ran_on = {p.name.split(".cdnf")[0] for p in (setting_folder(out, key) / "traces" / "clean").glob("*.csv")}
        folds_with_key = [d for d in res["folds"] if not set(d["test_clips"]) & ran_on]
        assert folds_with_key, f"{key} ran on a held-out clip of every fold"


def test_a_rerun_reuses_every_trace_and_chooses_the_same(tuned):
    folder, out, res = tuned
    again = run_tune(folder, None, out, "cdnf", ["h=0.05:0.3", "alpha_on=0.3,0.5"], trials=3, folds=2, seed=0,
                     workers=0, progress=False)
    assert again["ran"] == 0 and again["reused"] > 0
    assert [d["key"] for d in again["folds"]] == [d["key"] for d in res["folds"]]
    assert again["accuracy"] == res["accuracy"]


def test_tune_command_needs_one_model_and_a_search_space(tuned, tmp_path, capsys):
    folder, _, _ = tuned
    assert main(["experiment", "tune", str(folder), "--models", "cdnf,lgmd2", "--param", "h=0.1:0.2",
                 "--out", str(tmp_path / "a")]) == 2
    assert main(["experiment", "tune", str(folder), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "exactly one --model" in err and "at least one --param" in err


def test_a_dask_cluster_chooses_and_scores_as_the_local_run(tuned, tmp_path):
    distributed = pytest.importorskip("distributed")
    folder, _, res = tuned
    with distributed.LocalCluster(n_workers=1, processes=True, threads_per_worker=1, dashboard_address=None,
                                  silence_logs=40) as cluster:
        dask = run_tune(folder, None, tmp_path, "cdnf", ["h=0.05:0.3", "alpha_on=0.3,0.5"], trials=3, folds=2,
                        seed=0, scheduler=cluster.scheduler_address, progress=False)
    assert dask["ran"] > 0 and not dask["errors"]
    assert [d["key"] for d in dask["folds"]] == [d["key"] for d in res["folds"]]
    assert dask["per_clip"] == res["per_clip"] and dask["accuracy"] == res["accuracy"]
