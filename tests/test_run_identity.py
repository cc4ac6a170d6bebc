"""Every option that changes a result is part of a ``run``'s identity: a rerun into the same folder
that replaces a trace made with other settings names each difference in a ``note:``
(docs/EXPERIMENTS.md, "Run identity")."""
from __future__ import annotations

import csv

import numpy as np
import pytest
from event_encoders import random_events

from cdnf_ti.run import main
from cdnf_ti.stimuli.basic import basic_stimulus


@pytest.fixture
def looming_npy(tmp_path):
    s = basic_stimulus("dark_looming", height=32, width=32, start_half_size=1.5)
    path = tmp_path / "looming.npy"
    np.save(path, np.stack(list(s.frames()))[:12])
    return path


@pytest.fixture
def recording(tmp_path):
    path = tmp_path / "rec.npy"
    np.save(path, random_events(2000, (32, 24), duration_us=400_000, seed=1))
    return path


def _run_twice(capsys, inp, out, first: list[str], second: list[str]) -> str:
    """Run ``inp`` into ``out`` with ``first``, then again with ``second``; the second run's stderr."""
    base = [str(inp), "--backend", "numpy", "--out", str(out), "--no-progress"]
    assert main(base + first) == 0
    capsys.readouterr()
    assert main(base + second) == 0
    return capsys.readouterr().err


def _replacement_notes(err: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln.startswith("note:") and "replaces the trace" in ln]


@pytest.mark.parametrize("first, second, change", [
    (["--fps", "30"], ["--fps", "10"], "fps 30 -> 10"),
    (["--param", "epsilon=0.006"], ["--param", "epsilon=0.01"], "params defaults -> epsilon=0.01"),
    (["--rain", "--rain-drops", "9"], ["--rain", "--rain-drops", "7"], "rain_drops 9 -> 7"),
    (["--rain", "--rain-seed", "1"], ["--rain", "--rain-seed", "2"], "rain_seed 1 -> 2"),
    (["--color-order", "bgr"], ["--color-order", "rgb"], "color_order bgr -> rgb"),
])
def test_a_rerun_with_other_frame_settings_names_each_difference(looming_npy, tmp_path, capsys, first, second,
                                                                   change):
    notes = _replacement_notes(_run_twice(capsys, looming_npy, tmp_path / "o", first, second))
    assert len(notes) == 1 and change in notes[0]


@pytest.mark.parametrize("first, second, change", [
    (["--bin-ms", "20"], ["--bin-ms", "10"], "bin_ms 20 -> 10"),
    (["--event-threshold", "0.2"], ["--event-threshold", "0.3"], "event_threshold 0.2 -> 0.3"),
    (["--sensor-size", "32x24"], ["--sensor-size", "40x30"], "sensor_size 32x24 -> 40x30"),
])
def test_a_rerun_with_other_event_settings_names_each_difference(recording, tmp_path, capsys, first, second,
                                                                   change):
    notes = _replacement_notes(_run_twice(capsys, recording, tmp_path / "o", first, second))
    assert len(notes) == 1 and change in notes[0]


def test_a_rerun_with_the_same_settings_replaces_its_trace_without_a_note(looming_npy, tmp_path, capsys):
    assert _replacement_notes(_run_twice(capsys, looming_npy, tmp_path / "o", ["--fps", "20"], ["--fps", "20"])) == []


def test_summary_records_the_settings_of_each_run(looming_npy, tmp_path, capsys):
    assert main([str(looming_npy), "--backend", "numpy", "--fps", "12", "--rain", "--rain-drops", "5",
                 "--rain-seed", "3", "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    row = next(csv.DictReader(open(tmp_path / "o" / "summary.csv")))
    assert dict(kv.split("=") for kv in row["settings"].split(";")) == {
        "backend": "numpy", "fps": "12", "color_order": "bgr", "rain_drops": "5", "rain_seed": "3"}


def test_a_row_written_before_the_settings_column_is_compared_by_its_frame_rate():
    from cdnf_ti.run import identity_changes

    old = {"params": "", "video_fps": "30"}
    new = {"params": "", "settings": "backend=taichi;fps=10"}
    assert identity_changes(old, new) == ["fps 30 -> 10", "backend (not recorded) -> taichi"]
