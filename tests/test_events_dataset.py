"""Event recordings in the batch commands: ``dataset``, ``experiment table2``/``sweep`` and ``render``.

The recordings are made by the built-in emulator from small generated stimuli (64x48 px, under
a second: a few dozen bins), or written event by event where a test needs events at known pixels.
"""
from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from event_encoders import encode_evt3, random_events, raw_header

from cdnf_ti.events import EVENT_DTYPE, open_event_source
from cdnf_ti.experiments.labels import frame_at, last_frame_before
from cdnf_ti.models import create_model
from cdnf_ti.render import EVENT_GREY, EVENT_OFF, EVENT_ON, event_panel, render_frames
from cdnf_ti.run import main

SIZE = "64x48"
STIMULI = {"loom": "stim:dark_looming?width=64&height=48&duration=0.8",
           "translate": "stim:dark_translating?width=64&height=48&duration=0.8"}
LABELS = "clip,label,window_start,window_end\nloom,collision,10,23\ntranslate,non-collision,,\n"
QUIET = ["--workers", "0", "--no-progress", "--no-figures"]


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> Path:
    """A labelled folder of two emulated recordings (.npy; no sensor size in the file)."""
    folder = tmp_path_factory.mktemp("events_dataset")
    for name, spec in STIMULI.items():
        assert main(["events", spec, "--out", str(folder / f"{name}.npy"), "--no-progress"]) == 0
    (folder / "labels.csv").write_text(LABELS)
    return folder


def _copy(folder: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "data"
    shutil.copytree(folder, dst)
    return dst


def _rows(out: Path) -> dict[tuple[str, str], dict]:
    with open(out / "results.csv", newline="") as f:
        return {(r["clip"], r["model"]): r for r in csv.DictReader(f)}


def _n_bins(path: Path, bin_ms: float = 1000.0 / 30) -> int:
    return sum(1 for _ in open_event_source(path, (64, 48), bin_ms).counts())


def _dataset(folder: Path, out: Path, *extra: str) -> int:
    return main(["dataset", str(folder), "--out", str(out), "--sensor-size", SIZE, *QUIET, *extra])


@pytest.fixture(scope="module")
def first_run(recordings, tmp_path_factory):
    out = tmp_path_factory.mktemp("events_out") / "out"
    code = _dataset(recordings, out, "--model", "cdnf,lgmd2")
    return code, out


def test_dataset_runs_every_model_on_each_recording_with_one_trace_row_per_bin(recordings, first_run):
    code, out = first_run
    assert code == 0
    rows = _rows(out)
    assert set(rows) == {(c, m) for c in STIMULI for m in ("cdnf", "lgmd2")}
    for (clip, model), r in rows.items():
        n = _n_bins(recordings / f"{clip}.npy")
        assert r["error"] == "" and r["outcome"] in ("TP", "TN", "FP", "FN")
        assert int(r["frames"]) == n
        with open(out / "traces" / "clean" / f"{clip}.{model}.csv", newline="") as f:
            assert [int(t["frame"]) for t in csv.DictReader(f)] == list(range(n))


def test_dataset_scores_recordings_in_bins_of_bin_ms(first_run):
    _, out = first_run
    for r in _rows(out).values():
        assert float(r["video_fps"]) == pytest.approx(30.0)
        if r["first_alert"]:
            assert float(r["first_alert_s"]) == pytest.approx(int(r["first_alert"]) * (1 / 30), abs=1e-4)


def test_dataset_record_holds_the_event_options(first_run):
    _, out = first_run
    rec = json.loads((out / "traces" / "clean" / "loom.cdnf.json").read_text())
    assert rec["fingerprint"]["bin_ms"] == pytest.approx(1000 / 30)
    assert rec["fingerprint"]["event_threshold"] == 0.15
    assert rec["fingerprint"]["sensor_size"] == [64, 48]


def test_dataset_rerun_on_recordings_reuses_every_result(recordings, first_run, capsys):
    _, out = first_run
    capsys.readouterr()
    assert _dataset(recordings, out, "--model", "cdnf,lgmd2") == 0
    assert "0 run now, 4 reused" in capsys.readouterr().out


@pytest.mark.parametrize("option, value, what", [("--bin-ms", "50", "--bin-ms"),
                                                 ("--event-threshold", "0.3", "--event-threshold")])
def test_changing_an_event_option_recomputes_with_a_note(recordings, tmp_path, capsys, option, value, what):
    data = _copy(recordings, tmp_path)
    out = tmp_path / "out"
    assert _dataset(data, out) == 0
    capsys.readouterr()
    assert _dataset(data, out, option, value) == 0
    o, err = capsys.readouterr()
    assert "2 run now, 0 reused" in o
    assert "note: 2 finished result(s)" in err and f"loom.cdnf [clean]: {what}" in err
    if option == "--bin-ms":
        assert int(_rows(out)[("loom", "cdnf")]["frames"]) == _n_bins(data / "loom.npy", 50.0)


def test_a_recording_without_sensor_size_gets_one_note_naming_it(recordings, tmp_path, capsys):
    assert main(["dataset", str(recordings), "--out", str(tmp_path / "out"), *QUIET]) == 0
    err = capsys.readouterr().err
    assert err.count("state no sensor size") == 1 and "loom" in err and "--sensor-size" in err


def test_rain_only_on_a_folder_of_recordings_is_an_error_before_any_work(recordings, tmp_path, capsys):
    out = tmp_path / "out"
    assert _dataset(recordings, out, "--rain") == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --rain applies to frames only") and "--rain off" in err
    assert not (out / "traces").exists()


def test_rain_both_on_a_folder_of_recordings_runs_them_clean_with_a_note(recordings, tmp_path, capsys):
    out = tmp_path / "out"
    assert _dataset(recordings, out, "--rain", "both") == 0
    assert "note: --rain applies to frames only" in capsys.readouterr().err
    assert {r["condition"] for r in _rows(out).values()} == {"clean"}


def test_a_mixed_folder_runs_videos_and_recordings(recordings, tmp_path):
    data = _copy(recordings, tmp_path)
    frames = np.zeros((12, 48, 64), np.uint8) + 200
    for t in range(12):  # a dark square growing from the centre
        r = 2 + 2 * t
        frames[t, 24 - r // 2:24 + r // 2, 32 - r // 2:32 + r // 2] = 20
    np.save(data / "video.npy", frames)
    (data / "labels.csv").write_text(LABELS + "video,collision,6,11\n")
    out = tmp_path / "out"
    assert _dataset(data, out) == 0
    rows = _rows(out)
    assert int(rows[("video", "cdnf")]["frames"]) == 12
    assert int(rows[("loom", "cdnf")]["frames"]) == _n_bins(data / "loom.npy")
    assert not any(r["error"] for r in rows.values())


def test_rain_on_a_mixed_folder_is_an_error_naming_the_recordings(recordings, tmp_path, capsys):
    data = _copy(recordings, tmp_path)
    np.save(data / "video.npy", np.full((8, 48, 64), 100, np.uint8))
    (data / "labels.csv").write_text(LABELS + "video,non-collision,,\n")
    assert _dataset(data, tmp_path / "out", "--rain", "both") == 2
    err = capsys.readouterr().err
    assert "2 of the 3 labelled clips" in err and "loom" in err and "translate" in err


def test_a_corrupt_recording_is_an_error_line_and_the_batch_goes_on(recordings, tmp_path, capsys):
    data = _copy(recordings, tmp_path)
    ev = random_events(300, (64, 48), seed=0)
    good = raw_header({"evt": "3.0", "geometry": "64x48"}) + encode_evt3(ev)
    (data / "cut.raw").write_bytes(good[:-1])  # the last word is cut in half
    (data / "labels.csv").write_text(LABELS + "cut,non-collision,,\n")
    out = tmp_path / "out"
    assert _dataset(data, out) == 1
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and str(data / "cut.raw") in lines[0] and "byte offset" in lines[0]
    rows = _rows(out)
    assert rows[("cut", "cdnf")]["error"] and not rows[("loom", "cdnf")]["error"]
    assert not rows[("translate", "cdnf")]["error"]


def test_unlabelled_recordings_are_named_in_the_note(recordings, tmp_path, capsys):
    data = _copy(recordings, tmp_path)
    ev = random_events(200, (64, 48), seed=3)
    (data / "extra.raw").write_bytes(raw_header({"evt": "3.0", "geometry": "64x48"}) + encode_evt3(ev))
    assert _dataset(data, tmp_path / "out") == 0
    err = capsys.readouterr().err
    assert "1 video(s)" in err and "extra.raw" in err


def test_event_options_on_a_folder_of_videos_give_a_note(tmp_path, capsys):
    data = tmp_path / "videos"
    data.mkdir()
    np.save(data / "v.npy", np.full((8, 48, 64), 100, np.uint8))
    (data / "labels.csv").write_text("clip,label,window_start,window_end\nv,non-collision,,\n")
    assert main(["dataset", str(data), "--out", str(tmp_path / "out"), "--bin-ms", "10", *QUIET]) == 0
    assert "note: --bin-ms change(s) nothing: no labelled clip" in capsys.readouterr().err


def test_table2_takes_a_folder_of_recordings(recordings, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["experiment", "table2", str(recordings), "--out", str(out), "--model", "cdnf",
                 "--sensor-size", SIZE, *QUIET]) == 0
    assert "note: --rain applies to frames only" in capsys.readouterr().err  # table2 runs rain both by default
    assert set(_rows(out)) == {("loom", "cdnf"), ("translate", "cdnf")}


def test_sweep_takes_a_folder_of_recordings_and_keys_on_the_event_options(recordings, tmp_path, capsys):
    out = tmp_path / "out"
    args = ["experiment", "sweep", str(recordings), "--out", str(out), "--model", "cdnf", "--param",
            "epsilon=0.006,0.02", "--sensor-size", SIZE, "--no-html", *QUIET]
    assert main(args) == 0
    rec = json.loads(next(out.glob("settings/*/traces/clean/loom.cdnf.json")).read_text())
    assert rec["frames"] == _n_bins(recordings / "loom.npy")
    assert rec["fingerprint"]["bin_ms"] == pytest.approx(1000 / 30)
    capsys.readouterr()
    assert main(args + ["--bin-ms", "50"]) == 0
    assert "4 tasks run now, 0 reused" in capsys.readouterr().err


# --- render ----------------------------------------------------------------------------------------

def _events_at(path: Path, on: list[tuple[int, int]], off: list[tuple[int, int]], n_bins: int = 4) -> None:
    """A recording: in every bin, one ON event at each ``on`` pixel and one OFF event at each ``off`` pixel."""
    rows = []
    for k in range(n_bins):
        t = int(k * 1e6 / 30) + 1000
        rows += [(t, x, y, 1) for x, y in on] + [(t, x, y, 0) for x, y in off]
    ev = np.array(rows, dtype=EVENT_DTYPE)
    np.save(path, ev)


ON_PX = [(x, y) for x in range(10, 14) for y in range(30, 34)]
OFF_PX = [(x, y) for x in range(40, 44) for y in range(30, 34)]


def test_event_panel_is_grey_without_net_contrast_green_for_on_and_red_for_off():
    p_on = np.zeros((4, 4))
    p_off = np.zeros((4, 4))
    p_on[0, 0] = 1.0
    p_off[1, 1] = 1.0
    p_on[2, 2] = p_off[2, 2] = 0.6
    img = event_panel(p_on, p_off)
    assert img[0, 0].tolist() == EVENT_ON.tolist() and img[1, 1].tolist() == EVENT_OFF.tolist()
    assert img[2, 2].tolist() == EVENT_GREY.tolist() and img[3, 3].tolist() == EVENT_GREY.tolist()


def test_render_frames_of_a_recording_show_on_and_off_events_at_their_pixels(tmp_path):
    rec = tmp_path / "rec.npy"
    _events_at(rec, ON_PX, OFF_PX)
    src = open_event_source(rec, (64, 48))
    model = create_model("cdnf")
    frames = list(render_frames(model, src.contrast(0.15), src.fps, 4))
    assert len(frames) == 4
    panel = frames[1][:48, :64].astype(int)  # the input panel, top left
    for x, y in ON_PX:
        assert panel[y, x, 1] > 100 and panel[y, x, 2] < 100  # green
    for x, y in OFF_PX:
        assert panel[y, x, 2] > 100 and panel[y, x, 1] < 100  # red
    assert panel[40, 30].tolist() == EVENT_GREY.tolist()  # no event there


def test_render_command_writes_one_movie_frame_per_bin_of_a_recording(tmp_path, capsys):
    rec = tmp_path / "rec.npy"
    _events_at(rec, ON_PX, OFF_PX, n_bins=6)
    movie = tmp_path / "rec.avi"
    assert main(["render", str(rec), "--model", "cdnf", "--sensor-size", SIZE, "--out", str(movie),
                 "--no-progress"]) == 0
    assert f"{movie}: 6 frames" in capsys.readouterr().out  # "wrote" lines go to stdout, as run's do
    cap = cv2.VideoCapture(str(movie))
    ok, frame = cap.read()
    n = 1
    while cap.read()[0]:
        n += 1
    assert ok and n == 6
    x, y = ON_PX[5]
    assert frame[y, x, 1] > frame[y, x, 2] + 60  # green survives the codec
    x, y = OFF_PX[5]
    assert frame[y, x, 2] > frame[y, x, 1] + 60


def test_render_with_rain_on_a_recording_is_an_error(tmp_path, capsys):
    rec = tmp_path / "rec.npy"
    _events_at(rec, ON_PX, OFF_PX)
    assert main(["render", str(rec), "--rain", "--out", str(tmp_path / "m.avi"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {rec}: is an event recording; --rain applies to frames only")


def test_a_clip_name_matching_a_video_and_a_recording_is_ambiguous(recordings, tmp_path, capsys):
    data = _copy(recordings, tmp_path)
    ev = random_events(200, (64, 48), seed=4)
    (data / "loom.raw").write_bytes(raw_header({"evt": "3.0", "geometry": "64x48"}) + encode_evt3(ev))
    assert _dataset(data, tmp_path / "out") == 2
    err = capsys.readouterr().err
    assert "matches several videos" in err and "loom.npy" in err and "loom.raw" in err


def test_dataset_render_makes_a_movie_of_each_recording(recordings, tmp_path):
    out = tmp_path / "out"
    assert _dataset(recordings, out, "--render") == 0
    movies = sorted(p.name for p in (out / "movies").iterdir())
    assert movies == ["loom.cdnf.mp4", "translate.cdnf.mp4"]
    cap = cv2.VideoCapture(str(out / "movies" / "loom.cdnf.mp4"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == _n_bins(recordings / "loom.npy")


# --- windows in seconds --------------------------------------------------------------------------

SECONDS_LABELS = ("clip,label,window_start_s,window_end_s,contact_s\n"
                  "loom,collision,0.4,0.7,0.75\ntranslate,non-collision,,,\n")


@pytest.mark.parametrize("bin_ms, window, contact", [(1000 / 30, (12, 20), 22), (50.0, (8, 13), 15)])
def test_a_window_in_seconds_is_scored_in_the_bins_of_bin_ms(recordings, tmp_path, bin_ms, window, contact):
    data = _copy(recordings, tmp_path)
    (data / "labels.csv").write_text(SECONDS_LABELS)
    out = tmp_path / "out"
    assert _dataset(data, out, "--bin-ms", f"{bin_ms!r}") == 0
    row = _rows(out)[("loom", "cdnf")]
    assert (int(row["window_start"]), int(row["window_end"]), int(row["contact_frame"])) == (*window, contact)


def test_a_row_with_both_frames_and_seconds_is_rejected_before_any_work(recordings, tmp_path, capsys):
    data = _copy(recordings, tmp_path)
    (data / "labels.csv").write_text("clip,label,window_start,window_end,window_start_s,window_end_s\n"
                                     "loom,collision,10,20,0.4,0.7\ntranslate,non-collision,,,,\n")
    assert _dataset(data, tmp_path / "out") == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {data / 'labels.csv'}: row 2 (loom): the row gives both frames and seconds")


def test_a_window_in_seconds_past_a_videos_end_is_rejected(recordings, tmp_path, capsys):
    data = _copy(recordings, tmp_path)
    np.save(data / "video.npy", np.full((12, 48, 64), 100, np.uint8))  # 12 frames at 30 fps: 0.4 s
    (data / "labels.csv").write_text(SECONDS_LABELS + "video,collision,0.2,1.0,\n")
    assert _dataset(data, tmp_path / "out") == 2
    err = capsys.readouterr().err
    assert "row 4 (video): window_end (from seconds) 29 is outside the video (frames 0..11)" in err


def test_a_window_in_seconds_covers_the_frames_that_overlap_it():
    # frame k spans [k / fps, (k + 1) / fps): 1.0 s starts frame 30 at 30 fps, 1.5 s starts frame 45
    assert frame_at(1.0, 30.0) == 30 and last_frame_before(1.5, 30.0) == 44
    assert frame_at(1.01, 30.0) == 30 and last_frame_before(1.51, 30.0) == 45
    assert frame_at(0.7, 20.0) == 14 and last_frame_before(0.7, 20.0) == 13  # on a boundary


def test_a_downscaled_bin_carries_the_area_average_of_its_net_contrast():
    from cdnf_ti.experiments.clip_tasks import _resized_bins

    rng = np.random.default_rng(0)
    p_on, p_off = rng.random((48, 64)), rng.random((48, 64))
    (small_on, small_off), = list(_resized_bins([(p_on, p_off)], 0.5))
    assert small_on.shape == (24, 32)
    expected = (p_on - p_off).reshape(24, 2, 32, 2).mean(axis=(1, 3))
    np.testing.assert_allclose(small_on - small_off, expected, atol=1e-12)
