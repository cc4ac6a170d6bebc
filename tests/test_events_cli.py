"""``python -m cdnf_ti.run events``: emulate videos into event files, summarise recordings, bad inputs."""
from __future__ import annotations

import csv

import numpy as np
import pytest
from event_encoders import encode_evt3, random_events, raw_header

from cdnf_ti.events import open_event_source, open_events
from cdnf_ti.models import MODELS
from cdnf_ti.models.base import bin_ms_for
from cdnf_ti.run import main

STIM = "stim:dark_looming?size=48&duration=0.5"


def test_events_turns_a_stimulus_into_a_readable_npy_file(tmp_path, capsys):
    out = tmp_path / "dl.npy"
    assert main(["events", STIM, "--out", str(out), "--no-progress"]) == 0
    ev = np.concatenate(list(open_events(out).chunks()))
    assert ev.size > 0 and not ev["p"].any()
    assert f"-> {out}: {ev.size} events" in capsys.readouterr().out


def test_events_writes_dsec_hdf5_with_the_sensor_size(tmp_path):
    pytest.importorskip("h5py")
    assert main(["events", STIM, "--out", str(tmp_path / "dl.h5"), "--no-progress"]) == 0
    assert open_events(tmp_path / "dl.h5").sensor_size == (48, 48)


def test_events_writes_one_file_per_input_into_a_folder(tmp_path):
    assert main(["events", STIM, "stim:light_looming?size=48&duration=0.5", "--out", str(tmp_path / "ev"),
                 "--no-progress"]) == 0
    assert sorted(p.name for p in (tmp_path / "ev").iterdir()) == ["dark_looming_duration0.5_size48.npy",
                                                                  "light_looming_duration0.5_size48.npy"]


def test_a_bad_video_is_one_error_line_and_the_batch_goes_on(tmp_path, capsys):
    code = main(["events", str(tmp_path / "missing.mp4"), STIM, "--out", str(tmp_path / "ev"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 1
    assert err.count("error:") == 1 and f"error: {tmp_path / 'missing.mp4'}: no such file" in err
    assert len(list((tmp_path / "ev").iterdir())) == 1


def test_one_output_file_for_two_inputs_is_a_usage_error(tmp_path, capsys):
    assert main(["events", STIM, STIM, "--out", str(tmp_path / "x.npy")]) == 2
    assert capsys.readouterr().err.startswith("error: --out")


def test_info_reports_each_recording_and_names_the_byte_offset_of_a_truncated_one(tmp_path, capsys):
    ev = random_events(300, (64, 48), seed=0)
    good = tmp_path / "good.raw"
    good.write_bytes(raw_header({"evt": "3.0", "geometry": "64x48"}) + encode_evt3(ev))
    cut = tmp_path / "cut.raw"
    cut.write_bytes(good.read_bytes()[:-1])
    code = main(["events", "--info", str(cut), str(good)])
    out, err = capsys.readouterr()
    assert code == 1
    assert f"{good}: evt3, 64x48 (header), {ev.size} events" in out
    assert err.count("error:") == 1 and "byte offset" in err and str(cut) in err


def test_info_warns_of_events_outside_the_given_sensor_size(tmp_path, capsys):
    ev = random_events(300, (64, 48), seed=1)
    f = tmp_path / "ev.npy"
    np.save(f, ev)
    assert main(["events", "--info", str(f), "--sensor-size", "32x48"]) == 0
    err = capsys.readouterr().err
    assert f"warning: {f}: " in err and "outside the 32x48 sensor" in err


def test_running_the_models_on_an_event_file_gives_one_trace_row_per_bin_and_its_warnings(tmp_path, capsys):
    f = tmp_path / "ev.npy"
    np.save(f, random_events(300, (64, 48), seed=2, duration_us=400_000))
    out = tmp_path / "out"
    assert main([str(f), "--model", "all", "--sensor-size", "32x48", "--out", str(out), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "error:" not in err
    assert f"warning: {f}: " in err and "outside the 32x48 sensor" in err
    for name in [n for n, m in MODELS.items() if m.takes_events]:  # every model with an event input stage
        n_bins = sum(1 for _ in open_event_source(f, (32, 48), bin_ms_for(MODELS[name])).counts())  # at its width
        with open(out / f"ev.{name}.csv", newline="") as fh:
            assert len(list(csv.DictReader(fh))) == n_bins, name


def test_info_on_a_folder_reports_every_recording_in_it(tmp_path, capsys):
    for i in range(2):
        np.save(tmp_path / f"rec{i}.npy", random_events(50, (64, 48), seed=i))
    np.save(tmp_path / "frames.npy", np.zeros((2, 4, 4), dtype=np.uint8))  # not a recording: skipped
    assert main(["events", "--info", str(tmp_path), "--sensor-size", "64x48"]) == 0
    out = capsys.readouterr().out
    assert out.count(": npy, 64x48 (--sensor-size)") == 2 and "frames.npy" not in out


def test_events_progress_in_a_log_is_one_line_per_input(tmp_path, capsys):
    """stderr is not a terminal here (captured): no carriage-return bar, one line per input as the other commands."""
    assert main(["events", STIM, "stim:light_looming?size=48&duration=0.5", "--out", str(tmp_path / "ev")]) == 0
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("[")]
    assert [ln.split("]")[0] for ln in lines] == ["[1/2", "[2/2"]
    assert "dark_looming" in lines[0] and "light_looming" in lines[1]


def test_events_no_progress_writes_no_progress_lines(tmp_path, capsys):
    assert main(["events", STIM, "--out", str(tmp_path / "ev"), "--no-progress"]) == 0
    assert not [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("[")]


def test_an_emulated_video_has_one_bin_fewer_than_frames_and_says_how_they_map(tmp_path, capsys):
    """Events come from changes between frames: n frames give n - 1 bins, bin k holding the change from frame
    k to k + 1 (a frame model's frame k + 1); the line says so, and a step change at frame 5 lands in bin 4."""
    frames = np.full((12, 32, 32), 60, np.uint8)
    frames[5:, 8:24, 8:24] = 200  # one change: frame 4 -> 5
    np.save(tmp_path / "step.npy", frames)
    out = tmp_path / "step_events.npy"
    assert main(["events", str(tmp_path / "step.npy"), "--out", str(out), "--no-progress"]) == 0
    line = capsys.readouterr().out
    assert "12 frames -> 11 bins" in line and "frames s..e are bins s-1..e-1" in line
    counts = [int(on.sum() + off.sum()) for on, off in open_event_source(out, (32, 32)).contrast(0.2)]
    assert [k for k, c in enumerate(counts) if c] == [4]


def test_a_video_changing_on_every_frame_emulates_to_one_bin_fewer_than_its_frames(tmp_path, capsys):
    out = tmp_path / "dl.npy"
    assert main(["events", STIM, "--out", str(out), "--no-progress"]) == 0  # 16 frames, a change on each
    assert "16 frames -> 15 bins" in capsys.readouterr().out
    assert sum(1 for _ in open_event_source(out).contrast(0.2)) == 15
