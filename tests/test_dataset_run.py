"""End-to-end dataset runs on videos generated here: layout, scoring, parallel = serial, resume, bad clips."""
from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from cdnf_ti.experiments.dataset import RESULT_COLUMNS, rain_seed, run_dataset, trace_path
from cdnf_ti.experiments.scoring import Padding
from cdnf_ti.experiments.synthetic import make_synthetic_dataset
from cdnf_ti.paper import TABLE1

SIZE = 96
CLIPS = ("dark_looming", "light_translating", "light_looming", "dark_receding")


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("ds")
    make_synthetic_dataset(folder, size=SIZE, clips=CLIPS)
    return folder


@pytest.fixture(scope="module")
def serial_run(dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    return run_dataset(dataset, None, out, models=["cdnf"], workers=0, progress=False)


def _rows(out: Path) -> list[dict]:
    with open(out / "results.csv", newline="") as f:
        return list(csv.DictReader(f))


def _traces(out: Path) -> dict[str, str]:
    return {str(p.relative_to(out)): p.read_text() for p in sorted((out / "traces").rglob("*.csv"))}


def test_run_writes_the_documented_layout(serial_run):
    out = serial_run.out
    for clip in CLIPS:
        assert trace_path(out, "clean", clip, "cdnf").is_file()
        assert trace_path(out, "clean", clip, "cdnf", "json").is_file()
    for name in ("results.csv", "summary.md", "summary.json", "threshold_sweep.csv"):
        assert (out / name).stat().st_size > 0
    with open(out / "results.csv", newline="") as f:
        assert tuple(next(csv.reader(f))) == RESULT_COLUMNS
    assert [r["clip"] for r in _rows(out)] == list(CLIPS)
    assert not list(out.rglob("*.tmp*"))


def test_outcomes_follow_the_models_selectivity(serial_run):
    """C-DNF alerts on looming (inside the window: TP) and receding (FP: labelled
    non-collision) but not on translating (TN): paper Table I."""
    by = {r["clip"]: r for r in _rows(serial_run.out)}
    assert TABLE1["cdnf"]["dark_receding"] == 1 and TABLE1["cdnf"]["light_translating"] == 0
    assert by["dark_looming"]["outcome"] == "TP" and by["light_looming"]["outcome"] == "TP"
    assert by["light_translating"]["outcome"] == "TN"
    assert by["dark_receding"]["outcome"] == "FP"
    assert float(by["dark_looming"]["lead_time_ms"]) > 0
    assert serial_run.summary["results"]["cdnf"]["clean"]["accuracy"] == 0.75


def test_first_alert_in_results_matches_the_saved_trace(serial_run):
    from cdnf_ti.models.base import Trace

    for r in _rows(serial_run.out):
        tr = Trace.from_csv(trace_path(serial_run.out, "clean", r["clip"], "cdnf"))
        assert (str(tr.first_alert) if tr.first_alert is not None else "") == r["first_alert"]


def test_summary_records_padding_and_paper_numbers(serial_run):
    s = json.loads((serial_run.out / "summary.json").read_text())
    assert s["padding_frames"] == {"before": 0, "after": 0}
    assert s["paper_table2"]["cdnf"] == {"clean": 77.14, "rain": 77.14}
    md = (serial_run.out / "summary.md").read_text()
    assert "window padding: 0 frames before" in md and "77.14%" in md


def test_local_processes_give_identical_results(serial_run, dataset, tmp_path):
    par = run_dataset(dataset, None, tmp_path, models=["cdnf"], workers=2, progress=False, figures=False)
    assert par.ran == len(CLIPS)
    assert _traces(tmp_path) == _traces(serial_run.out)
    drop = {"seconds"}
    strip = lambda rows: [{k: v for k, v in r.items() if k not in drop} for r in rows]  # noqa: E731
    assert strip(_rows(tmp_path)) == strip(_rows(serial_run.out))


def test_padding_rescores_from_saved_traces_without_rerunning(serial_run, tmp_path):
    out = tmp_path / "o"
    shutil.copytree(serial_run.out, out)
    before = {p: p.stat().st_mtime_ns for p in (out / "traces").rglob("*.csv")}
    ds = Path(json.loads((serial_run.out / "summary.json").read_text())["dataset"])
    run = run_dataset(ds, None, out, models=["cdnf"], workers=0, progress=False, figures=False,
                      padding=Padding(before=5, after=2))
    assert run.ran == 0 and run.skipped == len(CLIPS)
    assert {p: p.stat().st_mtime_ns for p in (out / "traces").rglob("*.csv")} == before
    row = {r["clip"]: r for r in _rows(out)}["dark_looming"]
    assert (row["window_lo"], row["window_hi"]) == (str(int(row["window_start"]) - 5), str(int(row["window_end"]) + 2))
    assert json.loads((out / "summary.json").read_text())["padding_frames"] == {"before": 5, "after": 2}


def test_resume_after_an_interruption_skips_finished_clips(serial_run, dataset, tmp_path):
    seen = []

    def interrupt(rec):
        seen.append(rec)
        if len(seen) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_dataset(dataset, None, tmp_path, models=["cdnf"], workers=0, progress=False, on_record=interrupt)
    assert not (tmp_path / "results.csv").exists()
    done = [r["clip"] for r in seen]
    stamps = {c: trace_path(tmp_path, "clean", c, "cdnf").stat().st_mtime_ns for c in done}
    run = run_dataset(dataset, None, tmp_path, models=["cdnf"], workers=0, progress=False, figures=False)
    assert (run.skipped, run.ran) == (2, len(CLIPS) - 2)
    assert {c: trace_path(tmp_path, "clean", c, "cdnf").stat().st_mtime_ns for c in done} == stamps
    assert _traces(tmp_path) == _traces(serial_run.out)
    assert [r["outcome"] for r in _rows(tmp_path)] == [r["outcome"] for r in _rows(serial_run.out)]


def test_truncated_record_is_not_taken_as_finished(serial_run, dataset, tmp_path):
    out = tmp_path / "o"
    shutil.copytree(serial_run.out, out)
    trace_path(out, "clean", "dark_looming", "cdnf", "json").write_text('{"model": "cd')  # cut mid-write
    run = run_dataset(dataset, None, out, models=["cdnf"], workers=0, progress=False, figures=False)
    assert (run.ran, run.skipped) == (1, len(CLIPS) - 1)


@pytest.mark.parametrize("bad", [b"not a video at all" * 100, b""])
def test_corrupt_clip_in_the_middle_becomes_an_error_row(dataset, tmp_path, bad):
    ds = tmp_path / "ds"
    shutil.copytree(dataset, ds)
    (ds / "broken.avi").write_bytes(bad)
    lines = (ds / "labels.csv").read_text().splitlines()
    lines.insert(2, "broken,collision,3,5,5,46,corrupt")
    (ds / "labels.csv").write_text("\n".join(lines) + "\n")
    run = run_dataset(ds, None, tmp_path / "o", models=["cdnf"], workers=0, progress=False, figures=False)
    rows = _rows(tmp_path / "o")
    assert [r["clip"] for r in rows] == [CLIPS[0], "broken", *CLIPS[1:]]
    broken = rows[1]
    assert "broken.avi" in broken["error"] and broken["outcome"] == "" and "\n" not in broken["error"]
    assert all(r["outcome"] for r in rows if r["clip"] != "broken")
    assert run.failed and run.n_errors == 1
    assert run.summary["results"]["cdnf"]["clean"]["errors"] == 1
    assert run.summary["results"]["cdnf"]["clean"]["clips"] == len(CLIPS)


def test_truncated_video_becomes_an_error_row(dataset, tmp_path):
    ds = tmp_path / "ds"
    shutil.copytree(dataset, ds)
    data = (ds / "dark_looming.avi").read_bytes()
    (ds / "dark_looming.avi").write_bytes(data[: len(data) // 3])
    run = run_dataset(ds, None, tmp_path / "o", models=["cdnf"], workers=0, progress=False, figures=False)
    row = {r["clip"]: r for r in run.rows}["dark_looming"]
    assert "dark_looming.avi" in row["error"]
    assert not trace_path(tmp_path / "o", "clean", "dark_looming", "cdnf", "json").exists()


def test_bad_labels_are_rejected_before_any_work(dataset, tmp_path):
    from cdnf_ti.errors import InputError

    bad = tmp_path / "labels.csv"
    bad.write_text("clip,label,window_start,window_end\ndark_looming,collision,40,30\n")
    with pytest.raises(InputError, match="row 2"):
        run_dataset(dataset, bad, tmp_path / "o", models=["cdnf"], workers=0, progress=False)
    assert not (tmp_path / "o").exists()


def test_rain_seed_depends_only_on_seed_and_clip():
    assert rain_seed(0, "a") == rain_seed(0, "a")
    assert len({rain_seed(0, "a"), rain_seed(1, "a"), rain_seed(0, "b")}) == 3


def test_rain_condition_is_deterministic_and_reports_snr(dataset, tmp_path):
    pytest.importorskip("cdnf_ti.stimuli.rain")
    kw = dict(models=["cdnf"], rain="both", workers=0, progress=False, figures=False, seed=3)
    ds = tmp_path / "ds"
    ds.mkdir()
    shutil.copy(dataset / "dark_looming.avi", ds)
    (ds / "labels.csv").write_text("clip,label,window_start,window_end\ndark_looming,collision,32,45\n")
    a = run_dataset(ds, None, tmp_path / "a", **kw)
    run_dataset(ds, None, tmp_path / "b", **kw)
    assert _traces(tmp_path / "a") == _traces(tmp_path / "b")
    rain = [r for r in a.rows if r["condition"] == "rain"][0]
    clean = [r for r in a.rows if r["condition"] == "clean"][0]
    assert rain["snr_db"] is not None and 5 < rain["snr_db"] < 80 and clean["snr_db"] in ("", None)
    ta = _traces(tmp_path / "a")
    assert ta["traces/rain/dark_looming.cdnf.csv"] != ta["traces/clean/dark_looming.cdnf.csv"]
    assert a.summary["mean_rain_snr_db"] == pytest.approx(rain["snr_db"])


def test_rerun_with_other_options_recomputes_instead_of_reusing(dataset, tmp_path):
    kw = dict(models=["cdnf"], rain="only", workers=0, progress=False, figures=False)
    ds = tmp_path / "ds"
    ds.mkdir()
    shutil.copy(dataset / "dark_looming.avi", ds)
    (ds / "labels.csv").write_text("clip,label,window_start,window_end\ndark_looming,collision,32,45\n")
    out = tmp_path / "o"
    first = run_dataset(ds, None, out, seed=0, **kw)
    same = run_dataset(ds, None, out, seed=0, **kw)
    assert (same.ran, same.skipped) == (0, 1)
    other = run_dataset(ds, None, out, seed=5, **kw)
    assert (other.ran, other.skipped) == (1, 0)
    assert other.rows[0]["snr_db"] != first.rows[0]["snr_db"]
    run_dataset(ds, None, tmp_path / "fresh", seed=5, **kw)
    assert _traces(out) == _traces(tmp_path / "fresh")
