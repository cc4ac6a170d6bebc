"""One meaning per option in every subcommand: ``run`` as a subcommand, ``--rain``, seeds, ``--param``,
``--fps``/``--color-order`` where files are read, ``--out``, and what each command says about its alert rule."""
from __future__ import annotations

import csv
import json

import cv2
import numpy as np
import pytest

from cdnf_ti.experiments.synthetic import make_synthetic_dataset
from cdnf_ti.run import main
from cdnf_ti.stimuli.basic import basic_stimulus


@pytest.fixture
def looming_npy(tmp_path):
    s = basic_stimulus("dark_looming", height=48, width=48, start_half_size=1.5)
    path = tmp_path / "looming.npy"
    np.save(path, np.stack(list(s.frames())))
    return path


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    folder = tmp_path_factory.mktemp("opt_ds")
    make_synthetic_dataset(folder, size=32, clips=("dark_looming", "light_translating"))
    return folder


def _summary(folder):
    return list(csv.DictReader(open(folder / "summary.csv")))


def _trace(path):
    return list(csv.DictReader(open(path)))


# --- the run subcommand ----------------------------------------------------------------------------------

def test_run_subcommand_runs_inputs_as_the_bare_form_does(looming_npy, tmp_path, capsys):
    assert main(["run", str(looming_npy), "--out", str(tmp_path / "a"), "--no-progress"]) == 0
    assert main([str(looming_npy), "--out", str(tmp_path / "b"), "--no-progress"]) == 0
    a, b = _trace(tmp_path / "a" / "looming.cdnf.csv"), _trace(tmp_path / "b" / "looming.cdnf.csv")
    assert [r["I_v"] for r in a] == [r["I_v"] for r in b]


def _image_folder(folder, n=12, size=16):
    folder.mkdir()
    for t in range(n):
        img = np.full((size, size), 200, np.uint8)
        img[4:4 + t // 2, 4:4 + t // 2] = 20
        cv2.imwrite(str(folder / f"{t:03d}.png"), img)


def test_an_input_named_like_a_subcommand_runs_under_the_run_subcommand(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _image_folder(tmp_path / "demo")
    assert main(["run", "demo", "--out", "o", "--no-progress"]) == 0
    assert (tmp_path / "o" / "demo.cdnf.csv").is_file()


def test_a_subcommand_name_that_is_also_an_input_prints_a_note(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _image_folder(tmp_path / "rain")
    with pytest.raises(SystemExit) as e:
        main(["rain", "--no-such-option"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("note: 'rain' is taken as the subcommand") and "'run rain'" in err


# --- rain -------------------------------------------------------------------------------------------------

def test_rain_both_writes_a_clean_and_a_rain_trace_and_two_summary_rows(looming_npy, tmp_path, capsys):
    out = tmp_path / "o"
    assert main([str(looming_npy), "--rain", "both", "--rain-drops", "20", "--out", str(out), "--no-progress"]) == 0
    assert (out / "looming.cdnf.csv").is_file() and (out / "looming.cdnf.rain.csv").is_file()
    rows = _summary(out)
    assert sorted(r["condition"] for r in rows) == ["clean", "rain"]
    assert [r["rain_snr_db"] != "" for r in rows if r["condition"] == "rain"] == [True]


def test_rain_flag_before_an_input_is_rain_on_that_input(looming_npy, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["run", "--rain", str(looming_npy), "--out", str(out), "--no-progress"]) == 0
    assert [r["condition"] for r in _summary(out)] == ["rain"]


def test_the_old_rain_words_are_deprecated_aliases_with_a_note(capsys):
    from cdnf_ti.cli_common import rain_word

    assert (rain_word("none"), rain_word("only"), rain_word("both")) == ("off", "on", "both")
    err = capsys.readouterr().err.splitlines()
    assert err == ["note: --rain none is deprecated; use --rain off", "note: --rain only is deprecated; use --rain on"]


def test_drops_is_a_deprecated_alias_of_rain_drops(looming_npy, tmp_path, capsys):
    assert main(["rain", str(looming_npy), "--drops", "7", "--out", str(tmp_path / "r"), "--no-progress"]) == 0
    assert "note: --drops is deprecated; use --rain-drops" in capsys.readouterr().err
    meta = json.loads((tmp_path / "r" / "looming_rain.json").read_text())
    assert meta["rain"]["drops_per_frame"] == 7


def _rain_snr(looming_npy, out, *opts):
    assert main([str(looming_npy), "--rain", "--out", str(out), "--no-progress", *opts]) == 0
    return _summary(out)[0]["rain_snr_db"]


def test_seed_is_the_default_of_the_rain_seed(looming_npy, tmp_path, capsys):
    assert _rain_snr(looming_npy, tmp_path / "a", "--seed", "5") == _rain_snr(looming_npy, tmp_path / "b",
                                                                              "--rain-seed", "5")
    assert _rain_snr(looming_npy, tmp_path / "c", "--seed", "5") != _rain_snr(looming_npy, tmp_path / "d",
                                                                              "--seed", "6")


def test_rain_seed_wins_over_seed(looming_npy, tmp_path, capsys):
    assert _rain_snr(looming_npy, tmp_path / "a", "--seed", "9", "--rain-seed", "5") == \
        _rain_snr(looming_npy, tmp_path / "b", "--rain-seed", "5")


def test_generate_seed_is_the_default_of_the_stimulus_seed(tmp_path, capsys):
    metas = []
    for name, opt in (("a", "--seed"), ("b", "--stimulus-seed")):
        out = tmp_path / f"{name}.avi"
        assert main(["generate", "dark_looming", "--coherence", "0.5", "--size", "32", opt, "4", "--out", str(out),
                     "--no-progress"]) == 0
        metas.append(json.loads((tmp_path / f"{name}.json").read_text()))
    assert metas[0]["seed"] == metas[1]["seed"] == 4


# --- how close a model came -----------------------------------------------------------------------------

def test_summary_gives_cdnf_rule_threshold_and_peak_I_v(looming_npy, tmp_path, capsys):
    from cdnf_ti.params import CDNFParams

    out = tmp_path / "o"
    assert main([str(looming_npy), "--out", str(out), "--no-progress"]) == 0
    row = _summary(out)[0]
    trace = _trace(out / row["trace"])
    assert row["alert_rule"] == f"I_v > {CDNFParams().threshold:.4g}"
    assert float(row["alert_level"]) == pytest.approx(CDNFParams().threshold)
    assert float(row["alert_peak"]) == pytest.approx(max(float(r["I_v"]) for r in trace), abs=1e-6)


def test_summary_gives_lgmd_rule_as_spike_count_against_n_ts(looming_npy, tmp_path, capsys):
    out = tmp_path / "o"
    assert main([str(looming_npy), "--model", "lgmd2", "--param", "n_ts=3", "--out", str(out), "--no-progress"]) == 0
    row = _summary(out)[0]
    trace = _trace(out / row["trace"])
    assert row["alert_rule"] == "spike count >= 3" and float(row["alert_level"]) == 3
    assert float(row["alert_peak"]) == max(int(r["count"]) for r in trace)


def test_summary_gives_sdnf_rule_as_frames_in_a_row_above_its_dynamic_threshold(looming_npy, tmp_path, capsys):
    out = tmp_path / "o"
    assert main([str(looming_npy), "--model", "sdnf", "--out", str(out), "--no-progress"]) == 0
    row = _summary(out)[0]
    trace = _trace(out / row["trace"])
    assert "on 3 frames in a row" in row["alert_rule"] and float(row["alert_level"]) == 3
    assert float(row["alert_peak"]) == max(int(r["run"]) for r in trace)


def test_first_alert_in_seconds_is_the_frame_over_the_frame_rate(looming_npy, tmp_path, capsys):
    out = tmp_path / "o"
    assert main([str(looming_npy), "--fps", "20", "--out", str(out), "--no-progress"]) == 0
    row = _summary(out)[0]
    assert row["first_alert"] != "" and float(row["first_alert_s"]) == pytest.approx(int(row["first_alert"]) / 20)


def test_run_line_names_the_rule_and_the_peak(looming_npy, tmp_path, capsys):
    assert main([str(looming_npy), "--model", "lgmd2", "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    line = capsys.readouterr().out.strip()
    assert "alert when spike count >= 8" in line and "max spike count" in line and "max K" in line


def test_a_peak_short_of_the_level_says_how_far(capsys):
    from cdnf_ti.alert_rule import AlertRule, alert_summary
    from cdnf_ti.models.base import Trace

    n = 4
    tr = Trace("cdnf", "I_v", 0.506, np.array([0.5, 0.502, 0.504, 0.501]), np.zeros(n, bool), np.ones(n, bool), {})
    s = alert_summary(tr, AlertRule("I_v > 0.506", "I_v", "I_v", 0.506, strict=True), fps=30)
    assert not s.reached and s.first_alert is None
    assert s.text() == "max I_v 0.5040, alert when I_v > 0.506, 0.0020 short"


# --- sizes ------------------------------------------------------------------------------------------------

def test_frames_smaller_than_the_widest_kernel_are_an_error(tmp_path, capsys):
    path = tmp_path / "tiny.npy"
    np.save(path, np.zeros((5, 6, 6), np.uint8))
    assert main([str(path), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "tiny.npy" in err and "widest kernel" in err and "7x7" in err
    assert not (tmp_path / "o").exists()


def test_a_dataset_clip_smaller_than_the_widest_kernel_is_an_error_row(dataset, tmp_path, capsys):
    ds = tmp_path / "ds"
    ds.mkdir()
    for p in dataset.iterdir():
        (ds / p.name).write_bytes(p.read_bytes())
    np.save(ds / "tiny.npy", np.zeros((10, 6, 6), np.uint8))
    with open(ds / "labels.csv", "a") as f:
        f.write("tiny,non-collision,,,,,\n")
    assert main(["dataset", str(ds), "--out", str(tmp_path / "o"), "--workers", "0", "--no-progress",
                 "--no-figures"]) == 1
    row = next(r for r in _results(tmp_path / "o") if r["clip"] == "tiny")
    assert "widest kernel" in row["error"] and row["outcome"] == ""


def test_the_minimum_frame_side_is_the_widest_default_kernel():
    from cdnf_ti.limits import MIN_SIDE
    from cdnf_ti.params import CDNFParams

    assert MIN_SIDE == 2 * CDNFParams().radius_s + 1


# --- dataset ----------------------------------------------------------------------------------------------

def _results(out):
    return list(csv.DictReader(open(out / "results.csv")))


def test_dataset_applies_param_and_epsilon(dataset, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["dataset", str(dataset), "--epsilon", "0.49", "--out", str(out), "--workers", "0",
                 "--no-progress", "--no-figures"]) == 0
    rows = _results(out)
    assert [float(r["threshold"]) for r in rows] == pytest.approx([0.99] * len(rows))
    assert all(r["first_alert"] == "" for r in rows)  # I_v < 0.99 on every frame


def test_dataset_reads_clips_at_the_given_fps(dataset, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["dataset", str(dataset), "--fps", "25", "--out", str(out), "--workers", "0", "--no-progress",
                 "--no-figures"]) == 0
    assert {float(r["video_fps"]) for r in _results(out)} == {25.0}


def test_dataset_results_name_the_video_frame_rate_video_fps(dataset, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["dataset", str(dataset), "--out", str(out), "--workers", "0", "--no-progress",
                 "--no-figures"]) == 0
    row = _results(out)[0]
    assert "fps" not in row and float(row["video_fps"]) == 30


def test_dataset_recomputes_when_a_param_changes(dataset, tmp_path, capsys):
    out = tmp_path / "o"
    base = ["dataset", str(dataset), "--out", str(out), "--workers", "0", "--no-progress", "--no-figures"]
    assert main(base) == 0
    capsys.readouterr()
    assert main(base + ["--param", "cdnf.h=0.25"]) == 0
    assert "2 run now, 0 reused" in capsys.readouterr().out


def test_skip_missing_runs_the_clips_whose_video_exists(dataset, tmp_path, capsys):
    labels = tmp_path / "labels.csv"
    labels.write_text((dataset / "labels.csv").read_text() + 'ghost,collision,3,5,5,10,"no video"\n')
    out = tmp_path / "o"
    assert main(["dataset", str(dataset), "--labels", str(labels), "--skip-missing", "--out", str(out),
                 "--workers", "0", "--no-progress", "--no-figures"]) == 0
    assert "ghost" in capsys.readouterr().err
    assert sorted(r["clip"] for r in _results(out)) == ["dark_looming", "light_translating"]


def test_a_missing_video_is_still_an_error_without_skip_missing(dataset, tmp_path, capsys):
    labels = tmp_path / "labels.csv"
    labels.write_text((dataset / "labels.csv").read_text() + 'ghost,collision,3,5,5,10,"no video"\n')
    assert main(["dataset", str(dataset), "--labels", str(labels), "--out", str(tmp_path / "o"),
                 "--workers", "0", "--no-progress", "--no-figures"]) == 2
    assert "ghost" in capsys.readouterr().err


def test_sweep_reads_clips_at_the_given_fps_and_skips_missing_videos(dataset, tmp_path, capsys):
    import json

    labels = tmp_path / "labels.csv"
    labels.write_text((dataset / "labels.csv").read_text() + 'ghost,collision,3,5,5,10,"no video"\n')
    out = tmp_path / "o"
    assert main(["experiment", "sweep", str(dataset), "--labels", str(labels), "--skip-missing", "--fps", "25",
                 "--param", "h=0.1", "--backend", "numpy", "--out", str(out), "--workers", "0", "--no-progress",
                 "--no-figures", "--no-html"]) == 0
    assert "ghost" in capsys.readouterr().err
    metas = [json.loads(p.read_text()) for p in out.rglob("traces/clean/*.json")]
    assert sorted(m["clip"] for m in metas) == ["dark_looming", "light_translating"]
    assert {float(m["fps"]) for m in metas} == {25.0}


def test_the_task_log_counts_the_failures_that_the_results_report(dataset, tmp_path, capsys):
    ds = tmp_path / "ds"
    ds.mkdir()
    for p in dataset.iterdir():
        (ds / p.name).write_bytes(p.read_bytes())
    (ds / "bad.avi").write_bytes(b"junk" * 100)
    with open(ds / "labels.csv", "a") as f:
        f.write("bad,non-collision,,,,,\n")
    assert main(["dataset", str(ds), "--out", str(tmp_path / "o"), "--workers", "0", "--no-figures"]) == 1
    err = capsys.readouterr().err
    assert "clips: 3 of 3 tasks finished, 1 failed" in err and "1 of 3 clip x model x condition run(s) failed" in err


# --- help texts -------------------------------------------------------------------------------------------

def test_sweep_help_says_it_takes_one_model(capsys):
    with pytest.raises(SystemExit):
        main(["experiment", "sweep", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "the one model whose parameters are swept" in out and "comma separated" not in out


def test_experiment_table1_applies_param(tmp_path, capsys):
    assert main(["experiment", "table1", "--models", "cdnf", "--size", "32", "--param", "epsilon=0.49",
                 "--out", str(tmp_path), "--workers", "0", "--no-progress", "--no-figures"]) == 0
    res = json.loads((tmp_path / "table1.json").read_text())["result"]["cdnf"]
    assert {r["alert"] for r in res.values()} == {0} and {r["threshold"] for r in res.values()} == {0.99}


# --- bench ------------------------------------------------------------------------------------------------

def test_bench_progress_is_one_line_per_finished_run_in_a_log(capsys):
    from cdnf_ti.bench.cli import Progress

    bar = Progress(2)
    bar.update(1, "cdnf chebyshev (taichi) standin 426x240: 50.0 frames/s")
    bar.update(1, "lgmd2 (taichi) standin 426x240: 90.0 frames/s")
    bar.close()
    assert capsys.readouterr().err.splitlines() == [
        "bench [1/2] cdnf chebyshev (taichi) standin 426x240: 50.0 frames/s",
        "bench [2/2] lgmd2 (taichi) standin 426x240: 90.0 frames/s"]


def test_bench_explains_its_stand_in_clip(monkeypatch, capsys):
    from cdnf_ti.bench import cli

    def fake_bench(models, *a, **kw):
        return [cli.BenchRow(m, inp, "64x48", 100.0) for m in models for inp in ("basic:dark_looming", "standin")]

    monkeypatch.setattr(cli, "run_bench", fake_bench)
    assert main(["bench", "--model", "cdnf", "--sizes", "64x48", "--no-reference"]) == 0
    out = capsys.readouterr().out
    assert "| standin |" in out and "input 'standin' is a generated dashcam-like clip" in out


def test_experiment_selectivity_applies_param_and_does_not_reuse_other_params(tmp_path, capsys):
    base = ["experiment", "selectivity", "--models", "lgmd2", "--classes", "grating", "--quick", "--out",
            str(tmp_path), "--workers", "0", "--no-progress", "--no-figures"]
    assert main(base) in (0, 1)
    capsys.readouterr()
    assert main(base + ["--param", "n_ts=1"]) in (0, 1)
    assert " 0 reused" in capsys.readouterr().err
    rows = json.loads((tmp_path / "selectivity.json").read_text())["rows"]
    specs = [json.loads(p.read_text())["spec"] for p in (tmp_path / "tasks").glob("*.json")]
    assert len(specs) == 2 * len(rows) and sum(s.get("model_params") == {"n_ts": 1} for s in specs) == len(rows)


def test_rain_options_without_rain_get_a_note(looming_npy, tmp_path, capsys):
    assert main([str(looming_npy), "--rain-drops", "20", "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    assert "note: --rain-drops changes nothing without --rain" in capsys.readouterr().err
    assert [r["condition"] for r in _summary(tmp_path / "o")] == ["clean"]


@pytest.mark.parametrize("command", [[], ["dataset"]], ids=["run", "dataset"])
def test_a_wrong_rain_word_lists_the_valid_choices(command, looming_npy, tmp_path, capsys):
    target = [str(tmp_path)] if command else [str(looming_npy)]
    with pytest.raises(SystemExit) as e:
        main(command + target + ["--rain", "maybe", "--out", str(tmp_path / "o")])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "'maybe'" in err and "on, off, both" in err
    assert not (tmp_path / "o").exists()


def test_rain_before_an_input_file_is_still_the_flag(looming_npy, tmp_path, capsys):
    assert main(["--rain", str(looming_npy), "--backend", "numpy", "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    assert (tmp_path / "o" / "looming.cdnf.rain.csv").exists()
