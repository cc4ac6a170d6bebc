"""The benchmark readers on small folders in each published layout (made here from the basic stimuli):
what they read, what they refuse, and every model run through ``dataset --format ...`` with the
benchmark's own score equal to scikit-learn's on the saved traces."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from data.benchmarks.layouts import MAKERS

from cdnf_ti.errors import InputError
from cdnf_ti.experiments.benchmark_formats import read_benchmark
from cdnf_ti.experiments.dataset import run_dataset, trace_path
from cdnf_ti.models import MODELS
from cdnf_ti.models.base import Trace
from cdnf_ti.run import main

metrics = pytest.importorskip("sklearn.metrics", reason="scikit-learn (the 'test' extra) is the reference")


@pytest.fixture(scope="module")
def layouts(tmp_path_factory) -> dict:
    """``{format: (folder, what its maker wrote)}``."""
    out = {}
    for fmt, make in MAKERS.items():
        folder = tmp_path_factory.mktemp(fmt)
        out[fmt] = (folder, make(folder))
    return out


@pytest.mark.parametrize("fmt", list(MAKERS))
def test_reader_finds_every_clip_its_event_and_its_video(layouts, fmt):
    folder, made = layouts[fmt]
    anns = {a.clip: a for a in read_benchmark(fmt, folder)}
    assert set(anns) == set(made)
    for clip, (event, fps, labels) in made.items():
        a = anns[clip]
        assert a.path is not None and a.path.exists() and folder.resolve() in a.path.resolve().parents
        assert (a.event_s is None) == (event is None)
        if event is not None:
            assert a.event_s == pytest.approx(event / fps, abs=1e-9)
        assert a.frame_label_array(len(labels), fps).tolist() == labels


def test_nexar_reads_the_alert_time(layouts):
    anns = {a.clip: a for a in read_benchmark("nexar", layouts["nexar"][0])}
    assert anns["00001"].alert_s == 1.0 and anns["00002"].alert_s is None


def test_ccd_reads_weather_timing_and_ego_involvement(layouts):
    anns = {a.clip: a for a in read_benchmark("ccd", layouts["ccd"][0])}
    assert anns["crash_000002"].conditions == {"timing": "Night", "weather": "Rainy", "ego_involved": "no"}
    assert anns["normal_000001"].conditions == {}


def test_dad_and_dota_splits_select_their_clips(layouts):
    dad = read_benchmark("dad", layouts["dad"][0], split="testing")
    assert {a.clip for a in dad} == {"testing_positive_000001", "testing_positive_000002", "testing_negative_000001"}
    dota = read_benchmark("dota", layouts["dota"][0], split="val")
    assert {a.clip for a in dota} == {"bbbbbbbbbbb_000200", "ccccccccccc_000300"}
    assert {a.conditions["timing"] for a in dota} == {"night"}


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


def _one_error_line(capsys, argv) -> str:
    assert main(argv) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("error:")]
    assert len(err) == 1, err
    return err[0]


def test_a_nexar_id_that_leaves_the_folder_is_refused(layouts, tmp_path, capsys):
    folder = _copy(layouts["nexar"][0], tmp_path / "n")
    (folder / "train.csv").write_text("id,time_of_event,time_of_alert,target\n../../etc/passwd,1.0,0.5,1\n")
    line = _one_error_line(capsys, ["dataset", str(folder), "--format", "nexar", "--out", str(tmp_path / "o")])
    assert "train.csv:2" in line and "not a plain file name" in line


def test_a_dota_video_name_with_a_path_is_refused(layouts, tmp_path):
    folder = _copy(layouts["dota"][0], tmp_path / "d")
    (folder / "metadata_val.json").write_text(json.dumps({"../../outside": {"num_frames": 3}}))
    with pytest.raises(InputError, match="not a plain file name"):
        read_benchmark("dota", folder, split="val")


def test_a_malformed_ccd_line_is_one_error_naming_the_line(layouts, tmp_path, capsys):
    folder = _copy(layouts["ccd"][0], tmp_path / "c")
    with open(folder / "Crash-1500.txt", "a") as f:
        f.write("000009,[0, 1, 2],000001,77,Day,Normal,Yes\n")
    line = _one_error_line(capsys, ["dataset", str(folder), "--format", "ccd", "--out", str(tmp_path / "o")])
    assert "Crash-1500.txt:4" in line and "binlabels" in line


@pytest.mark.parametrize("text, problem", [("{not json", "not valid JSON"), ("[1, 2]", "expected a JSON object"),
                                           ('{"num_frames": 10, "anomaly_start": 8, "anomaly_end": 4}',
                                            "anomaly_start <= anomaly_end")])
def test_a_bad_dota_annotation_is_one_error(layouts, tmp_path, text, problem):
    folder = _copy(layouts["dota"][0], tmp_path / "d")
    (folder / "annotations" / "aaaaaaaaaaa_000100.json").write_text(text)
    with pytest.raises(InputError, match=problem) as e:
        read_benchmark("dota", folder)
    assert "aaaaaaaaaaa_000100.json" in str(e.value)


def test_an_oversized_annotation_file_is_refused_before_reading(layouts, tmp_path, monkeypatch):
    import cdnf_ti.experiments.benchmark_formats as bf

    monkeypatch.setattr(bf, "MAX_ANNOTATION_BYTES", 64)
    with pytest.raises(InputError, match="larger than"):
        read_benchmark("nexar", layouts["nexar"][0])


def test_an_annotated_video_that_is_absent_is_an_error_unless_skipped(layouts, tmp_path, capsys):
    folder = _copy(layouts["nexar"][0], tmp_path / "n")
    (folder / "train" / "00004.mp4").unlink()
    line = _one_error_line(capsys, ["dataset", str(folder), "--format", "nexar", "--out", str(tmp_path / "o")])
    assert "00004" in line and "--skip-missing" in line
    run = run_dataset(folder, None, tmp_path / "o2", models=["cdnf"], workers=0, progress=False, figures=False,
                      fmt="nexar", skip_missing=True)
    assert [lab.clip for lab in run.labels] == ["00001", "00002", "00003"]


def _independent(fmt: str, made: dict, scores: dict[str, np.ndarray]) -> dict:
    """The benchmark's headline numbers computed here from the traces, with scikit-learn."""
    if fmt == "nexar":
        aps = {}
        for h in (0.5, 1.0, 1.5):
            y, s = [], []
            for clip, (event, fps, _) in made.items():
                sc = scores[clip]
                if event is None:
                    y.append(0)
                    s.append(sc.max())
                    continue
                seen = [sc[k] for k in range(sc.size) if k / fps <= event / fps - h + 1e-9]
                if seen:
                    y.append(1)
                    s.append(max(seen))
            aps[h] = metrics.average_precision_score(y, s)
        return {"nexar_mean": float(np.mean(list(aps.values()))), **{f"nexar_{h:g}": v for h, v in aps.items()}}
    if fmt in ("ccd", "dota"):
        y = np.concatenate([np.asarray(lab[:scores[c].size] + [0] * (scores[c].size - len(lab)))
                            for c, (_, _, lab) in made.items()])
        s = np.concatenate([scores[c] for c in made])
        return {"frame_ap": metrics.average_precision_score(y, s), "frame_auc": metrics.roc_auc_score(y, s)}
    y = [int(ev is not None) for ev, _, _ in made.values()]
    s = [scores[c][:ev].max() if ev is not None else scores[c].max() for c, (ev, _, _) in made.items()]
    return {"video_ap": metrics.average_precision_score(y, s)}


@pytest.mark.parametrize("fmt", list(MAKERS))
def test_every_model_runs_on_the_layout_and_scores_as_sklearn(layouts, fmt, tmp_path):
    folder, made = layouts[fmt]
    models = list(MODELS)
    run = run_dataset(folder, None, tmp_path, models=models, workers=0, progress=False, figures=False, fmt=fmt)
    assert not run.failed
    bench = json.loads((tmp_path / "summary.json").read_text())["benchmark"]
    assert bench["format"] == fmt and set(bench["results"]) == set(models)
    assert "Benchmark scores" in (tmp_path / "summary.md").read_text()
    for m in models:
        scores = {c: Trace.from_csv(trace_path(tmp_path, "clean", c, m)).output for c in made}
        ref = _independent(fmt, made, scores)
        got = bench["results"][m]["clean"]
        if fmt == "nexar":
            assert got["nexar"]["mean"] == pytest.approx(ref["nexar_mean"], abs=1e-12)
            assert got["headline"]["value"] == pytest.approx(ref["nexar_mean"], abs=1e-12)
            for h in (0.5, 1.0, 1.5):
                assert got["nexar"][f"{h:g}"] == pytest.approx(ref[f"nexar_{h:g}"], abs=1e-12)
        elif fmt in ("ccd", "dota"):
            assert got["frame_level"]["ap"] == pytest.approx(ref["frame_ap"], abs=1e-12)
            assert got["frame_level"]["auc"] == pytest.approx(ref["frame_auc"], abs=1e-12)
        else:
            assert got["anticipation"]["ap"] == pytest.approx(ref["video_ap"], abs=1e-12)
        lt = got["lead_times"]
        assert lt["positive_clips"] == sum(ev is not None for ev, _, _ in made.values())


def test_report_html_shows_the_benchmark_and_the_lead_time_distribution(layouts, tmp_path):
    folder, _ = layouts["nexar"]
    run_dataset(folder, None, tmp_path, models=["cdnf"], workers=0, progress=False, fmt="nexar")
    assert (tmp_path / "figures" / "lead_time_seconds.png").stat().st_size > 0
    page = (tmp_path / "report.html").read_text()
    assert "Benchmark scores (nexar)" in page and "Nexar AP 1.5 s" in page
    assert "Lead time before the event (s) per model" in page  # the figure's caption


def test_benchmark_clips_csv_keeps_each_clips_scores_beside_its_first_alert(layouts, tmp_path):
    import csv

    folder, made = layouts["nexar"]
    run_dataset(folder, None, tmp_path, models=["cdnf"], workers=0, progress=False, figures=False, fmt="nexar")
    with open(tmp_path / "benchmark_clips.csv", newline="") as f:
        rows = {r["clip"]: r for r in csv.DictReader(f)}
    assert set(rows) == set(made)
    for clip, (event, fps, _) in made.items():
        tr = Trace.from_csv(trace_path(tmp_path, "clean", clip, "cdnf"))
        r = rows[clip]
        assert r["first_alert"] == ("" if tr.first_alert is None else str(tr.first_alert))
        if event is None:
            assert r["score_1s_before"] == "" and r["lead_s"] == ""
            continue
        seen = [tr.output[k] for k in range(tr.n_frames) if k / fps <= event / fps - 1.0 + 1e-9]
        assert float(r["score_1s_before"]) == pytest.approx(max(seen), rel=1e-5)  # CSV cells: 6 digits
        if tr.first_alert is not None:
            assert float(r["lead_s"]) == pytest.approx(event / fps - tr.first_alert / fps, abs=1e-4)
