"""Hostile event recordings (issue 37): corrupt timestamps, decoder panics, empty recordings, impossible
header sizes and malformed columns each end in one ``error: <file>: ...`` line, within bounded memory.

The command-line cases run in a child process under an address-space cap (``RLIMIT_AS``), so a
recording that made the reader allocate for its whole time span fails the test instead of the machine.
"""
from __future__ import annotations

import csv
import itertools
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from event_encoders import encode_aedat4, encode_dat, encode_evt2, encode_evt3, random_events, raw_header
from test_events_binning import chunked, histogram
from test_faults import _cli, linux_only

from cdnf_ti.errors import InputError
from cdnf_ti.events import EVENT_DTYPE, bin_events, open_event_source
from cdnf_ti.run import main

SIZE = (64, 48)
FUZZ = Path(__file__).resolve().parent / "data" / "fuzz"
#: Address-space cap of the child processes: the Taichi runtime alone reserves 1 GiB of it.
CAP_BYTES = 4 << 30


def memory_cap(limit: int = CAP_BYTES):
    """``preexec_fn`` capping the child's address space at ``limit`` bytes."""
    def apply() -> None:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    return apply


def error_lines(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln.startswith("error:")]


def write_recording(path: Path, ev: np.ndarray) -> Path:
    """``ev`` written in the format of ``path``'s suffix (``.raw`` EVT 2.0 unless the stem says evt3)."""
    fmt = path.suffix
    if fmt == ".npy":
        np.save(path, ev)
    elif fmt == ".npz":
        np.savez(path, t=ev["t"], x=ev["x"], y=ev["y"], p=ev["p"])
    elif fmt == ".dat":
        path.write_bytes(encode_dat(ev, SIZE))
    elif fmt == ".raw" and "evt3" in path.stem:
        path.write_bytes(raw_header({"evt": "3.0", "geometry": "64x48"}) + encode_evt3(ev))
    elif fmt == ".raw":
        path.write_bytes(raw_header({"evt": "2.0", "geometry": "64x48"}) + encode_evt2(ev))
    elif fmt == ".aedat4":
        pytest.importorskip("aedat")
        path.write_bytes(encode_aedat4(ev, SIZE, packet_events=100))
    elif fmt == ".h5":
        h5py = pytest.importorskip("h5py")
        with h5py.File(path, "w") as f:
            for k in "txyp":
                f.create_dataset(f"events/{k}", data=ev[k])
            f.create_dataset("t_offset", data=np.int64(0))
    return path


FORMATS = ["rec.npy", "rec.npz", "rec.dat", "rec_evt2.raw", "rec_evt3.raw", "rec.aedat4", "rec.h5"]


def jumped(gap_us: int, at: int = 200, n: int = 400) -> np.ndarray:
    """A recording whose events from ``at`` on are ``gap_us`` later than they should be."""
    ev = random_events(n, SIZE, duration_us=500_000, seed=0)
    ev["t"][at:] += gap_us
    return ev


# -- 1. corrupt timestamps ----------------------------------------------------------------------------------
def test_bins_are_made_one_at_a_time_whatever_the_gap_between_events():
    ev = np.zeros(2, dtype=EVENT_DTYPE)
    ev["t"] = [0, 10**13]  # 10^13 us: 3 * 10^11 bins of 33 ms between the two events
    tracemalloc.start()
    try:
        first = list(itertools.islice(bin_events([ev], SIZE), 3))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert [int(b.sum()) for b in first] == [1, 0, 0]
    assert peak < 50 * 2 * SIZE[0] * SIZE[1] * 8  # a few count images, nothing per bin of the span



def test_sparse_events_bin_as_a_per_event_histogram_whatever_the_chunking():
    ev = random_events(300, SIZE, duration_us=1_000_000, seed=8)  # 1 ms bins: most chunks span more bins
    want = histogram(ev, SIZE, 1.0, int(ev["t"][-1] // 1000) + 1, 0.0)  # than they have events
    for chunk in (7, 50, ev.size):
        np.testing.assert_array_equal(np.stack(list(bin_events(chunked(ev, chunk), SIZE, bin_ms=1.0, t0=0.0))), want)


@pytest.mark.parametrize("name", FORMATS)
def test_a_timestamp_jump_past_max_gap_is_an_error_naming_the_event(name, tmp_path):
    ev = jumped(5_000_000)  # 5 s, past a limit of 1 s (EVT 3.0's clock cannot jump more than 16.7 s)
    f = write_recording(tmp_path / name, ev)
    src = open_event_source(f, SIZE, max_gap_s=1.0)
    with pytest.raises(InputError, match=f"timestamp jumps from {ev['t'][199]} to {ev['t'][200]} us at event 200"):
        list(src.counts())


def test_a_first_event_far_after_the_recordings_start_is_a_jump(tmp_path):
    ev = jumped(10**13, at=0)
    f = write_recording(tmp_path / "late.npy", ev)  # .npy: bin 0 starts at t = 0
    with pytest.raises(InputError, match=f"timestamp jumps from 0 to {ev['t'][0]} us at event 0"):
        list(open_event_source(f, SIZE).counts())


def test_timestamps_past_max_span_are_an_error_naming_the_event(tmp_path):
    ev = random_events(100, SIZE, duration_us=1000, seed=1)
    ev["t"] += np.arange(ev.size) * 2_000_000  # 2 s between events: no gap past 60 s, a span of 200 s
    f = write_recording(tmp_path / "long.npy", ev)
    i = int(np.argmax(ev["t"] > 100_000_000))  # the first event more than 100 s after t = 0
    with pytest.raises(InputError, match=f"timestamp {ev['t'][i]} us at event {i} is .* s after the recording's "
                                         r"start at 0 us \(at most --max-span-s 100 s\)"):
        list(open_event_source(f, SIZE, max_span_s=100.0).counts())


def test_max_gap_s_admits_a_recording_with_a_long_pause(tmp_path, capsys):
    ev = jumped(90_000_000)  # a 90 s pause
    f = write_recording(tmp_path / "pause.npy", ev)
    assert main(["events", "--info", str(f), "--sensor-size", "64x48"]) == 2
    assert "at most --max-gap-s 60 s" in capsys.readouterr().err
    assert main(["events", "--info", str(f), "--sensor-size", "64x48", "--max-gap-s", "120"]) == 0
    n_bins = int(ev["t"][-1] // (100_000 / 3)) + 1
    assert f"{ev.size} events" in capsys.readouterr().out and n_bins > 2700
    assert sum(1 for _ in open_event_source(f, SIZE, max_gap_s=120).counts()) == n_bins



def test_render_takes_the_time_limits_of_its_options(tmp_path):
    from cdnf_ti.render import open_render_input

    f = write_recording(tmp_path / "pause.npy", jumped(5_000_000))
    assert sum(1 for _ in open_render_input(f, events={"sensor_size": SIZE}).counts()) > 150
    with pytest.raises(InputError, match="at most --max-gap-s 1 s"):
        list(open_render_input(f, events={"sensor_size": SIZE, "max_gap_s": 1.0}).counts())


@linux_only
@pytest.mark.parametrize("command", [["run", "--no-progress", "--out", "{tmp}/out"], ["events", "--info"]])
def test_a_huge_timestamp_jump_is_one_error_line_within_the_memory_cap(command, tmp_path):
    f = write_recording(tmp_path / "jump.npy", jumped(10**13))
    argv = [a.format(tmp=tmp_path) for a in command] + [str(f), "--sensor-size", "64x48"]
    proc = _cli(*argv, timeout=300, preexec_fn=memory_cap())
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "MemoryError" not in proc.stderr
    assert error_lines(proc.stderr) == [f"error: {f}: timestamp jumps from {jumped(0)['t'][199]} to "
                                        f"{jumped(10**13)['t'][200]} us at event 200 (1e+07 s; at most "
                                        "--max-gap-s 60 s)"]


# -- 2. decoder panics ----------------------------------------------------------------------------------------
PANIC = FUZZ / "events_aedat4_header_panic.aedat4"  # a generated AEDAT4 file with one byte of its header changed


@linux_only
def test_an_aedat4_decoder_panic_is_one_error_line_in_run(tmp_path):
    pytest.importorskip("aedat")
    proc = _cli("run", str(PANIC), "--out", str(tmp_path / "out"), "--no-progress", timeout=300,
                preexec_fn=memory_cap())
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "panicked" not in proc.stderr
    assert [ln for ln in proc.stderr.splitlines() if ln.strip()] == [
        f"error: {PANIC}: bad AEDAT4 header (the decoder failed: start byte index 11 is not a char boundary; "
        "it is inside 'n' (bytes 10..12 of string))"]


def test_probing_the_sensor_size_of_a_batch_skips_a_panicking_recording(tmp_path, capsys):
    from cdnf_ti.experiments.clip_tasks import note_inferred_sensor_size

    pytest.importorskip("aedat")
    good = write_recording(tmp_path / "good.npy", random_events(100, SIZE, seed=2))
    note_inferred_sensor_size({"bad": PANIC, "good": good}, None)
    assert "1 event recording(s) state no sensor size (good)" in capsys.readouterr().err


# -- 3. empty recordings --------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["rec_evt3.raw", "rec.npy", "rec.dat", "rec.h5"])
def test_a_recording_without_events_holds_no_events(name, tmp_path):
    f = write_recording(tmp_path / name, np.zeros(0, dtype=EVENT_DTYPE))
    with pytest.raises(InputError, match=f"^{f}: holds no events$"):
        list(open_event_source(f, SIZE).counts())


def test_run_on_a_recording_without_events_is_one_error_line_and_exit_2(tmp_path, capsys):
    f = write_recording(tmp_path / "empty_evt3.raw", np.zeros(0, dtype=EVENT_DTYPE))
    assert main(["run", str(f), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    assert error_lines(capsys.readouterr().err) == [f"error: {f}: holds no events"]
    assert not list((tmp_path / "out").glob("*.cdnf.csv"))  # no trace of 0 bins



def test_a_record_of_no_frames_is_an_error_row_never_a_true_negative():
    from cdnf_ti.experiments.dataset import build_row
    from cdnf_ti.experiments.labels import ClipLabel
    from cdnf_ti.experiments.scoring import Padding

    label = ClipLabel("quiet", "non-collision", False, None, None, None, 2)
    row = build_row(label, "cdnf", "clean", {"frames": 0, "fps": 30.0, "first_alert": None, "source": "quiet.raw",
                                             "error": ""}, Padding())
    assert row["error"] == "quiet.raw: holds no frames" and not row["outcome"]


def test_a_clip_figure_draws_an_empty_trace_as_no_trace(tmp_path):
    from cdnf_ti.experiments.figures import plot_clip
    from cdnf_ti.experiments.labels import ClipLabel
    from cdnf_ti.models.base import Trace

    empty = Trace("cdnf", "I_v", 0.5, np.zeros(0), np.zeros(0, bool), np.zeros(0, bool), {})
    label = ClipLabel("quiet", "non-collision", False, None, None, None, 2)
    png = plot_clip(tmp_path / "quiet.png", label, {("cdnf", "clean"): empty}, ["cdnf"], ["clean"])
    assert png.is_file() and png.stat().st_size > 0


# -- 5. one size budget ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("command", [["events", "--info"], ["run", "--no-progress", "--out", "{tmp}/out"],
                                     ["render", "--no-progress", "--out", "{tmp}/m.avi"]])
def test_binning_counts_in_the_one_memory_budget_of_info_run_and_render(command, tmp_path, monkeypatch, capsys):
    from cdnf_ti import limits

    monkeypatch.setattr(limits, "physical_memory", lambda: 1 << 30)  # half of it, 512 MiB, may be planned
    side = 1700  # frames of one model fit (1700^2 x 160 B = 0.43 GiB); with the binning's 64 B/px they do not
    limits.check_frame_size(side, side, n_models=1)
    f = write_recording(tmp_path / "rec.npy", random_events(100, SIZE, seed=3))
    argv = [a.format(tmp=tmp_path) for a in command] + [str(f), "--sensor-size", f"{side}x{side}"]
    assert main(argv) == 2
    assert error_lines(capsys.readouterr().err) == [
        f"error: {f}: frames of {side}x{side} px need about 0.6 GB for binning events and 1 model(s), more than "
        "half of this machine's 1.0 GB of memory; largest square frame here: about 1548x1548 px"]


def test_the_emulator_counts_its_state_in_the_memory_budget(tmp_path, monkeypatch, capsys):
    from cdnf_ti import limits

    monkeypatch.setattr(limits, "physical_memory", lambda: 1 << 30)
    frames = tmp_path / "big.npy"
    np.save(frames, np.zeros((2, 1500, 1500), dtype=np.uint8))  # 1500^2 x (160 + 96) B = 0.54 GiB
    assert main(["events", str(frames), "--out", str(tmp_path / "ev.npy"), "--no-progress"]) == 2
    assert error_lines(capsys.readouterr().err) == [
        f"error: {frames}: frames of 1500x1500 px need about 0.5 GB for emulating events, more than half of this "
        "machine's 1.0 GB of memory; largest square frame here: about 1448x1448 px"]


# -- 12. impossible header sizes -------------------------------------------------------------------------------
@pytest.mark.parametrize("size", [(0, 0), (100_000, 100_000)])
def test_an_impossible_sensor_size_in_a_header_is_named_as_the_headers_fault(size, tmp_path, capsys):
    f = tmp_path / "rec.dat"
    f.write_bytes(encode_dat(random_events(50, SIZE, seed=4), size))
    assert main(["events", "--info", str(f)]) == 2
    assert error_lines(capsys.readouterr().err) == [
        f"error: {f}: the header states a sensor size of {size[0]}x{size[1]}, which no sensor has (each side 1 to "
        "16384 px): a corrupt header? give --sensor-size WxH to override it"]
    assert main(["events", "--info", str(f), "--sensor-size", "64x48"]) == 0


# -- 13. NumPy's wording -----------------------------------------------------------------------------------------
def test_random_bytes_in_an_npz_are_not_an_archive(tmp_path):
    f = tmp_path / "rec.npz"
    f.write_bytes(np.random.default_rng(5).bytes(2000))
    with pytest.raises(InputError, match=r"not a NumPy \.npz archive") as e:
        list(open_event_source(f, SIZE).counts())
    assert "pickle" not in str(e.value)


@pytest.mark.filterwarnings("error::RuntimeWarning")  # NumPy's "invalid value encountered in cast" fails the test
def test_a_nan_timestamp_names_the_event(tmp_path):
    ev = random_events(100, SIZE, seed=6)
    a = np.zeros(ev.size, dtype=[("t", "<f8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
    for k in "txyp":
        a[k] = ev[k]
    a["t"][37] = np.nan
    np.save(tmp_path / "rec.npy", a)
    with pytest.raises(InputError, match="event 37 has timestamp nan, not a whole number of µs"):
        list(open_event_source(tmp_path / "rec.npy", SIZE).counts())


def test_a_negative_x_names_the_event_instead_of_wrapping(tmp_path):
    ev = random_events(100, SIZE, seed=7)
    a = np.zeros(ev.size, dtype=[("t", "<i8"), ("x", "<i2"), ("y", "<i2"), ("p", "i1")])
    for k in "txyp":
        a[k] = ev[k]
    a["x"][12] = -3  # as uint16: 65533
    np.save(tmp_path / "rec.npy", a)
    with pytest.raises(InputError, match="event 12 has x=-3, outside 0..65535"):
        list(open_event_source(tmp_path / "rec.npy", SIZE).counts())


# -- the acceptance test -------------------------------------------------------------------------------
@linux_only
def test_a_dataset_of_one_good_and_three_hostile_recordings_scores_the_good_one_and_reports(tmp_path):
    pytest.importorskip("aedat")
    data = tmp_path / "data"
    data.mkdir()
    assert main(["events", "stim:dark_looming?width=64&height=48&duration=0.8", "--out", str(data / "loom.npy"),
                 "--no-progress"]) == 0  # the good clip: no sensor size in the file, so every file is probed
    (data / "panic.aedat4").write_bytes(PANIC.read_bytes())
    write_recording(data / "empty_evt3.raw", np.zeros(0, dtype=EVENT_DTYPE))
    write_recording(data / "span.npy", jumped(10**13))
    (data / "labels.csv").write_text("clip,label,window_start,window_end\nloom,collision,10,23\n"
                                     "panic,non-collision,,\nempty_evt3,non-collision,,\nspan,non-collision,,\n")
    out = tmp_path / "out"
    proc = _cli("dataset", str(data), "--out", str(out), "--workers", "0", "--no-progress", timeout=600,
                preexec_fn=memory_cap())
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr and "panicked" not in proc.stderr
    with open(out / "results.csv", newline="") as f:
        rows = {r["clip"]: r for r in csv.DictReader(f)}
    assert not rows["loom"]["error"] and rows["loom"]["outcome"]
    assert rows["panic"]["error"].startswith(f"{data / 'panic.aedat4'}: bad AEDAT4 header (the decoder failed")
    assert rows["empty_evt3"]["error"] == f"{data / 'empty_evt3.raw'}: holds no events"
    assert rows["span"]["error"].startswith(f"{data / 'span.npy'}: timestamp jumps from")
    assert all(not rows[c]["outcome"] for c in ("panic", "empty_evt3", "span"))  # never scored (a TN)
    assert (out / "report.html").is_file() and (out / "summary.md").is_file()
