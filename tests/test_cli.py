"""The command line: per-video traces and summaries, the demo, and user errors (exit 2)."""
import csv
import subprocess
import sys

import numpy as np
import pytest

from cdnf_ti.run import main
from cdnf_ti.stimuli.basic import basic_stimulus


@pytest.fixture
def looming_npy(tmp_path):
    s = basic_stimulus("dark_looming", height=64, width=64, start_half_size=1.5)
    path = tmp_path / "looming.npy"
    np.save(path, np.stack(list(s.frames())))
    return path


def test_video_run_writes_a_trace_csv_per_video(looming_npy, tmp_path, capsys):
    out = tmp_path / "out"
    assert main([str(looming_npy), "--out", str(out)]) == 0
    rows = list(csv.DictReader(open(out / "looming.cdnf.csv")))
    assert len(rows) == 46
    assert {"frame", "I_v", "spike", "iterations_on", "iterations_off", "iterations_sum",
            "residual_on", "residual_off", "residual_sum"} <= set(rows[0])
    assert float(rows[0]["I_v"]) == 0.5


def test_video_run_prints_one_summary_line_per_video(looming_npy, tmp_path, capsys):
    main([str(looming_npy), "--out", str(tmp_path / "o")])
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.strip()]
    assert len(lines) == 1
    assert "46 frames" in lines[0] and "first alert" in lines[0] and "max I_v" in lines[0] and "fps" in lines[0]


def test_missing_input_gives_one_line_error_and_exit_code_2(tmp_path, capsys):
    code = main([str(tmp_path / "missing.mp4"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err == [f"error: {tmp_path / 'missing.mp4'}: no such file or folder"]


def test_a_run_whose_every_input_is_missing_keeps_the_earlier_summary(looming_npy, tmp_path, capsys):
    out = tmp_path / "o"
    assert main([str(looming_npy), "--out", str(out), "--no-progress"]) == 0
    before = (out / "summary.csv").read_text()
    assert main([str(tmp_path / "mistyped.mp4"), "--out", str(out), "--no-progress"]) == 2
    assert (out / "summary.csv").read_text() == before


def test_bad_input_does_not_stop_the_other_videos(looming_npy, tmp_path, capsys):
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"\x00" * 1000)
    code = main([str(bad), str(looming_npy), "--out", str(tmp_path / "o")])
    assert code == 1  # partial failure: 1, as for `dataset` (issue 12); 2 only when nothing could run
    assert (tmp_path / "o" / "looming.cdnf.csv").exists()
    assert "bad.mp4" in capsys.readouterr().err


def test_invalid_option_value_is_a_one_line_error(looming_npy, tmp_path, capsys):
    code = main([str(looming_npy), "--out", str(tmp_path / "o"), "--epsilon", "-1"])
    assert code == 2
    assert "epsilon" in capsys.readouterr().err


def test_unknown_model_is_a_one_line_error(looming_npy, tmp_path, capsys):
    assert main([str(looming_npy), "--model", "nosuch"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --model: unknown model 'nosuch'") and err.count("\n") == 1


def test_a_model_list_naming_no_model_is_a_one_line_error(looming_npy, tmp_path, capsys):
    assert main([str(looming_npy), "--model", ",", "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == "error: --model names no model: got ','\n"


def test_demo_prints_the_table1_cdnf_column(capsys):
    assert main(["demo", "--size", "96", "--no-progress"]) == 0
    out = capsys.readouterr().out
    for label in ("Dark approaching", "Light approaching", "Dark receding", "Light receding",
                  "Dark translating", "Light translating"):
        assert label in out
    assert "differs" not in out


def test_module_entry_point_exits_2_without_traceback_on_bad_input(tmp_path):
    corrupt = tmp_path / "corrupt.mp4"
    corrupt.write_bytes(b"not a video at all" * 50)
    proc = subprocess.run([sys.executable, "-m", "cdnf_ti.run", str(corrupt), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    err_lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("error:")]
    assert len(err_lines) == 1 and "corrupt.mp4" in err_lines[0]


def test_unavailable_gpu_arch_is_a_clear_error_with_exit_code_2(looming_npy, tmp_path):
    import shutil

    if shutil.which("nvidia-smi"):
        pytest.skip("a CUDA device is present here; the error path cannot be exercised")
    proc = subprocess.run([sys.executable, "-m", "cdnf_ti.run", str(looming_npy), "--arch", "cuda",
                           "--out", str(tmp_path / "o")], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert "'cuda' is not available" in proc.stderr


def test_output_folder_that_is_a_file_is_a_one_line_error_before_any_work(looming_npy, tmp_path, capsys):
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    assert main([str(looming_npy), "--out", str(blocker)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {blocker}")


def test_result_files_are_readable_by_others(looming_npy, tmp_path):
    import os
    import stat

    out = tmp_path / "o"
    old = os.umask(0o022)
    try:
        assert main([str(looming_npy), "--out", str(out)]) == 0
    finally:
        os.umask(old)
    mode = stat.S_IMODE((out / "looming.cdnf.csv").stat().st_mode)
    assert mode == 0o644


def test_negative_seed_option_is_rejected_with_exit_code_2(looming_npy, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main([str(looming_npy), "--rain", "--rain-seed", "-2", "--out", str(tmp_path / "o")])
    assert e.value.code == 2
    assert "--rain-seed" in capsys.readouterr().err


def test_dataset_given_a_file_instead_of_a_folder_says_so(looming_npy, tmp_path, capsys):
    assert main(["dataset", str(looming_npy), "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err.strip() == (
        f"error: {looming_npy}: not a folder (give the folder that holds the videos and labels.csv)")


@pytest.mark.parametrize("argv", [["x.npy", "--epsilon", "nan"], ["demo", "--size", "abc"], ["experiment", "nosuch"],
                                  ["bench", "--frames", "x"], ["render"]])
def test_a_bad_option_is_one_error_line_pointing_to_help(capsys, argv):
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2
    assert err.startswith("error: ") and err.endswith("--help)\n") and err.count("\n") == 1


def _summary(out):
    return list(csv.DictReader(open(out / "summary.csv")))


def test_clean_and_rain_runs_into_one_folder_keep_both_traces(looming_npy, tmp_path, capsys):
    out = tmp_path / "o"
    assert main([str(looming_npy), "--out", str(out), "--no-progress"]) == 0
    clean = (out / "looming.cdnf.csv").read_text()
    assert main([str(looming_npy), "--out", str(out), "--no-progress", "--rain", "--rain-drops", "20"]) == 0
    assert (out / "looming.cdnf.csv").read_text() == clean
    assert (out / "looming.cdnf.rain.csv").read_text() != clean
    rows = _summary(out)
    assert [(r["clip"], r["condition"], r["trace"]) for r in rows] == [
        ("looming", "clean", "looming.cdnf.csv"), ("looming", "rain", "looming.cdnf.rain.csv")]


def test_summary_lists_every_run_made_into_the_folder(looming_npy, tmp_path, capsys):
    out = tmp_path / "o"
    other = tmp_path / "other.npy"
    other.write_bytes(looming_npy.read_bytes())
    assert main([str(looming_npy), "--out", str(out), "--no-progress"]) == 0
    assert main([str(other), "--out", str(out), "--no-progress", "--model", "lgmd2"]) == 0
    assert main([str(looming_npy), "--out", str(out), "--no-progress"]) == 0  # the same key again: replaced
    rows = _summary(out)
    assert sorted((r["clip"], r["model"]) for r in rows) == [("looming", "cdnf"), ("other", "lgmd2")]


def test_summary_names_video_and_processing_rates_apart(looming_npy, tmp_path, capsys):
    out = tmp_path / "o"
    assert main([str(looming_npy), "--out", str(out), "--no-progress", "--fps", "25"]) == 0
    row = _summary(out)[0]
    assert "fps" not in row and float(row["video_fps"]) == 25 and float(row["proc_fps"]) > 0


def test_run_removes_its_lock_and_says_where_it_wrote(looming_npy, tmp_path, capsys):
    out = tmp_path / "o"
    assert main([str(looming_npy), "--out", str(out), "--no-progress"]) == 0
    assert not (out / ".cdnf_ti.lock").exists()
    assert f"results in {out.resolve()}/" in capsys.readouterr().err


def test_a_folder_made_for_a_run_that_wrote_nothing_is_removed(tmp_path, capsys):
    out = tmp_path / "new" / "o"
    assert main([str(tmp_path / "missing.mp4"), "--out", str(out)]) == 2
    assert not out.exists()


def test_a_run_whose_every_input_is_missing_leaves_an_existing_folder_as_it_was(tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main([str(tmp_path / "missing.mp4"), "--out", str(out)]) == 2
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
