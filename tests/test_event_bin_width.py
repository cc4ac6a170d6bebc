"""A model states its own event-bin width: ``Model.event_bin_ms``, and ``--bin-ms`` when given wins.

Without ``--bin-ms`` each model bins an event recording at its own width (the event-based looming
detector at its ``dt``, 10 ms; the others at the default 1000/30 ms); models of one width share one
pass over the recording. The recordings are emulated from a small generated stimulus (64x48 px,
0.8 s). The bin counts expected are computed from the events' timestamps (an ``.npy`` recording's
bins start at its clock zero), not from the binning code.
"""
from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from cdnf_ti.events import open_event_source
from cdnf_ti.events.binning import DEFAULT_BIN_MS
from cdnf_ti.experiments.clip_tasks import batch_bin_ms
from cdnf_ti.models import Model, get_model_class
from cdnf_ti.models.base import Trace, bin_ms_for
from cdnf_ti.models.event_looming import EventLooming, EventLoomingParams
from cdnf_ti.run import input_passes, main

REPO = Path(__file__).resolve().parents[1]
SIZE = "64x48"
STIMULUS = "stim:dark_looming?width=64&height=48&duration=0.8"
QUIET = ["--no-progress", "--sensor-size", SIZE]


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """An emulated recording of a looming square (.npy, t in µs from 0)."""
    path = tmp_path_factory.mktemp("bin_width") / "loom.npy"
    assert main(["events", STIMULUS, "--out", str(path), "--no-progress"]) == 0
    return path


def bins_in(path: Path, bin_ms: float) -> int:
    """Bins of ``bin_ms`` from the recording's clock zero to its last event."""
    return int(np.load(path)["t"].max() // (bin_ms * 1000.0)) + 1


def run(recording: Path, out: Path, *extra: str) -> int:
    return main([str(recording), "--out", str(out), *QUIET, *extra])


def summary(out: Path) -> dict[str, dict]:
    with open(out / "summary.csv", newline="") as f:
        return {r["model"]: r for r in csv.DictReader(f)}


def settings(row: dict) -> dict[str, str]:
    return dict(item.split("=", 1) for item in row["settings"].split(";"))


def test_the_bin_width_hook_is_documented_with_its_unit_and_its_default():
    doc = Model.event_bin_ms.__doc__
    assert "ms" in doc and "None" in doc and "--bin-ms" in doc
    assert Model.event_bin_ms() is None
    assert "event_bin_ms" in (REPO / "docs" / "EVENTS.md").read_text(encoding="utf-8")


def test_a_model_without_a_width_of_its_own_bins_at_the_default():
    assert get_model_class("cdnf").event_bin_ms() is None
    assert bin_ms_for(get_model_class("cdnf")) == DEFAULT_BIN_MS


def test_bin_ms_given_wins_over_the_model_s_own_width():
    assert bin_ms_for(EventLooming, None, 20.0) == 20.0


def test_event_looming_bins_at_its_dt():
    assert EventLooming.event_bin_ms() == 10.0  # their PyTorch DT
    assert EventLooming.event_bin_ms(EventLoomingParams(variant="paper")) == 1.0  # their GeNN DT_MS
    assert EventLooming.event_bin_ms(EventLoomingParams(dt=5.0)) == 5.0
    assert bin_ms_for(EventLooming(EventLoomingParams(dt=5.0), backend="numpy")) == 5.0  # an instance: its params


def test_models_sharing_a_width_share_one_pass(recording):
    src = open_event_source(recording, (64, 48))
    passes = input_passes(src, ["cdnf", "event_looming", "lgmd2"], {}, None)
    assert [(s.bin_ms, idx) for s, idx in passes] == [(DEFAULT_BIN_MS, [0, 2]), (10.0, [1])]
    assert [idx for _, idx in input_passes(src, ["cdnf", "event_looming"], {}, 20.0)] == [[0, 1]]


def test_event_looming_on_a_recording_without_bin_ms_runs_at_10_ms_bins(recording, tmp_path):
    assert run(recording, tmp_path / "own", "--model", "event_looming") == 0
    assert run(recording, tmp_path / "given", "--model", "event_looming", "--bin-ms", "10") == 0
    own = Trace.from_csv(tmp_path / "own" / "loom.event_looming.csv")
    given = Trace.from_csv(tmp_path / "given" / "loom.event_looming.csv")
    assert own.n_frames == bins_in(recording, 10.0) > bins_in(recording, DEFAULT_BIN_MS)
    np.testing.assert_array_equal(own.output, given.output)
    np.testing.assert_array_equal(own.spike, given.spike)
    row = summary(tmp_path / "own")["event_looming"]
    assert settings(row)["bin_ms"] == "10" and float(row["video_fps"]) == 100.0


def test_a_mixed_run_bins_each_model_at_its_own_width(recording, tmp_path):
    out = tmp_path / "out"
    assert run(recording, out, "--model", "cdnf,event_looming", "--backend", "numpy") == 0
    rows = summary(out)
    for name, width in (("cdnf", DEFAULT_BIN_MS), ("event_looming", 10.0)):
        assert Trace.from_csv(out / f"loom.{name}.csv").n_frames == bins_in(recording, width)
        assert float(settings(rows[name])["bin_ms"]) == pytest.approx(width, rel=1e-5)
        assert float(rows[name]["video_fps"]) == pytest.approx(1000.0 / width, rel=1e-5)


def test_bin_ms_given_bins_every_model_at_it(recording, tmp_path):
    out = tmp_path / "out"
    assert run(recording, out, "--model", "cdnf,event_looming", "--backend", "numpy", "--bin-ms", "20") == 0
    rows = summary(out)
    for name in ("cdnf", "event_looming"):
        assert Trace.from_csv(out / f"loom.{name}.csv").n_frames == bins_in(recording, 20.0)
        assert settings(rows[name])["bin_ms"] == "20"


def test_render_bins_a_recording_at_the_model_s_width(recording, tmp_path, capsys):
    movie = tmp_path / "m.avi"
    assert main(["render", str(recording), "--model", "event_looming", "--backend", "numpy", "--out", str(movie),
                 *QUIET]) == 0
    assert f"{movie}: {bins_in(recording, 10.0)} frames" in capsys.readouterr().out


# --- batch runs: one width per run, the labels' bins --------------------------------------------------

def dataset(folder: Path, out: Path, *extra: str) -> int:
    return main(["dataset", str(folder), "--out", str(out), "--workers", "0", "--no-figures", "--backend", "numpy",
                 *QUIET, *extra])


def labelled(recording: Path, tmp_path: Path, labels: str) -> Path:
    folder = tmp_path / "data"
    folder.mkdir()
    shutil.copy(recording, folder / "loom.npy")
    (folder / "labels.csv").write_text(labels)
    return folder


SECONDS = "clip,label,window_start_s,window_end_s\nloom,collision,0.3,0.7\n"
FRAMES = "clip,label,window_start,window_end\nloom,collision,10,20\n"


def test_a_dataset_bins_at_the_model_s_width_and_converts_windows_in_seconds(recording, tmp_path):
    out = tmp_path / "out"
    assert dataset(labelled(recording, tmp_path, SECONDS), out, "--model", "event_looming") == 0
    with open(out / "results.csv", newline="") as f:
        row = next(csv.DictReader(f))
    assert int(row["frames"]) == bins_in(recording, 10.0) and float(row["video_fps"]) == 100.0
    assert (int(row["window_start"]), int(row["window_end"])) == (30, 69)  # 0.3-0.7 s in 10 ms bins


def test_the_dataset_fingerprint_changes_with_the_width(recording, tmp_path, capsys):
    data, out = labelled(recording, tmp_path, SECONDS), tmp_path / "out"
    assert dataset(data, out, "--model", "event_looming") == 0
    record = out / "traces" / "clean" / "loom.event_looming.json"
    assert json.loads(record.read_text())["fingerprint"]["bin_ms"] == 10.0
    capsys.readouterr()
    assert dataset(data, out, "--model", "event_looming", "--bin-ms", "20") == 0
    o, err = capsys.readouterr()
    assert "1 run now, 0 reused" in o and "loom.event_looming [clean]: --bin-ms" in err
    assert json.loads(record.read_text())["fingerprint"]["bin_ms"] == 20.0


def test_a_dataset_of_models_with_different_widths_bins_all_at_the_default_with_a_note(recording, tmp_path, capsys):
    data, out = labelled(recording, tmp_path, SECONDS), tmp_path / "out"
    assert dataset(data, out, "--model", "cdnf,event_looming") == 0
    err = capsys.readouterr().err
    assert "note: " in err and "event_looming 10 ms" in err and "--bin-ms" in err
    with open(out / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert {r["model"] for r in rows} == {"cdnf", "event_looming"}
    assert all(int(r["frames"]) == bins_in(recording, 1000.0 / 30.0) for r in rows)


def test_windows_in_bins_are_refused_at_a_model_s_own_width_other_than_the_default(recording, tmp_path, capsys):
    data, out = labelled(recording, tmp_path, FRAMES), tmp_path / "out"
    assert dataset(data, out, "--model", "event_looming") == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {data / 'labels.csv'}: ") and err.count("\n") == 1 and "window_start_s" in err
    assert dataset(data, out, "--model", "event_looming", "--bin-ms", "10") == 0


def test_a_batch_takes_the_width_of_the_models_that_take_events():
    assert batch_bin_ms(["event_looming", "olgmd"]) == 10.0  # oLGMD reads no recording: its width is moot
    assert batch_bin_ms(["cdnf", "event_looming"]) is None
    assert batch_bin_ms(["cdnf", "event_looming"], None, 20.0) == 20.0
