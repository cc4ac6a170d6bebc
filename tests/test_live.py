"""Live mode (``python -m cdnf_ti.run live``): a real local HTTP MJPEG stream of generated stimuli at 30 fps.

The server (:class:`cdnf_ti.mjpeg_server.MJPEGServer`) listens on 127.0.0.1 at an ephemeral
port. It repeats a lead-in frame until the loop has compiled its models (the ``start`` line),
then plays the stimulus once, so a slow compile never hides the approach.
"""
from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import cv2
import numpy as np
import pytest
from conftest import REPO

from cdnf_ti.errors import InputError
from cdnf_ti.live import LatencyStats, LiveLoop, Recorder, Sinks, Status, StreamSink, annotate, json_line, main
from cdnf_ti.live_sources import Frame, LatestFrames, ProcessCapture, parse_source
from cdnf_ti.mjpeg_server import MJPEGServer
from cdnf_ti.models import create_model
from cdnf_ti.run import main as run_main
from cdnf_ti.stimuli.basic import basic_stimulus

SIZE = 128  # px: small, and the translating bar stays below C-DNF's threshold at this size, as at 600
FPS = 30.0
FRAME_KEYS = {"frame", "t", "model", "output", "alert", "latency_ms", "dropped"}


@pytest.fixture(scope="module", autouse=True)
def compiled_cdnf():
    """Compile C-DNF for SIZE frames once, before any server thread runs (compiling holds the interpreter,
    which would stall a server thread of this process)."""
    m = create_model("cdnf", fps=FPS)
    m.step(np.zeros((SIZE, SIZE), np.float32))
    m.step(np.full((SIZE, SIZE), 0.5, np.float32))
    return m


def stimulus(name: str, hold: int = 6, **params) -> tuple[np.ndarray, list[np.ndarray]]:
    """(lead-in frame, the stimulus' frames + its last frame held ``hold`` more times)."""
    frames = list(basic_stimulus(name, height=SIZE, width=SIZE, fps=FPS, **params).frames())
    return frames[0], frames + [frames[-1]] * hold


class ListSink:
    """Collects the JSON lines of a loop as dicts."""

    name = "list"

    def __init__(self):
        self.records: list[dict] = []

    def write(self, line: str) -> None:
        self.records.append(json.loads(line))

    def flush(self) -> None:
        pass

    def close(self) -> None:
        pass

    def frames(self, model: str | None = None) -> list[dict]:
        return [r for r in self.records if r["event"] == "frame" and (model is None or r["model"] == model)]

    def events(self, kind: str) -> list[dict]:
        return [r for r in self.records if r["event"] == kind]


class SlowModel:
    """A real model that takes ``delay_s`` longer per frame (an artificially slow model)."""

    def __init__(self, model, delay_s: float):
        self.model, self.delay_s = model, delay_s
        self.name, self.output_name, self.threshold = model.name, model.output_name, model.threshold

    def step(self, frame):
        time.sleep(self.delay_s)
        return self.model.step(frame)

    def reset(self):
        self.model.reset()


def run_loop(server: MJPEGServer, models=("cdnf",), queue: int = 2, timeout_s: float = 5.0,
             retry_for_s: float = 1.0, wrap=None, status_stream=None) -> tuple[ListSink, LiveLoop]:
    """Run the live loop on ``server``'s stream until it ends; the lead-in ends when the loop is ready."""
    sink = ListSink()
    capture = ProcessCapture(parse_source(server.url), LatestFrames(queue), fps=FPS, timeout_s=timeout_s,
                             retry_for_s=retry_for_s)

    def make(fps):
        ms = [create_model(n, fps=fps) for n in models]
        return [wrap(m) for m in ms] if wrap else ms

    status = Status(status_stream, enabled=False) if status_stream is not None else None
    loop = LiveLoop(capture, make, Sinks([sink]), status=status, on_start=lambda rec: server.go.set())
    loop.run()
    return sink, loop


# -- the frame queue ----------------------------------------------------------------------------------
def test_queue_drops_the_oldest_frames_and_counts_them():
    q = LatestFrames(2)
    for k in range(5):
        q.put(Frame(k, np.zeros((2, 2), np.uint8), 0.0, 0.0))
    assert [q.get(0).index, q.get(0).index] == [3, 4]
    assert q.dropped == 3 and q.received == 5
    assert q.get(0.01) is None


def test_queue_hands_out_every_held_frame_before_the_end():
    q = LatestFrames(3)
    q.put(Frame(0, np.zeros((2, 2), np.uint8), 0.0, 0.0))
    q.close(EOFError("done"))
    assert q.get(0).index == 0
    with pytest.raises(EOFError):
        q.get(0)


# -- sources ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("text, kind", [("0", "camera"), ("http://127.0.0.1:8080/stream.mjpg", "url"),
                                        ("rtsp://cam/live", "url"), ("clip.mp4", "file"),
                                        ("stim:dark_looming", "file")])
def test_source_kinds(text, kind):
    assert parse_source(text).kind == kind


def test_missing_device_path_is_an_input_error():
    with pytest.raises(InputError, match="no such device"):
        parse_source("/dev/video-cdnf-ti-missing")


# -- the loop on a real MJPEG stream -------------------------------------------------------------------
def test_looming_stream_alerts():
    lead, frames = stimulus("dark_looming")
    with MJPEGServer(frames, fps=FPS, lead=lead) as server:
        sink, loop = run_loop(server, queue=len(frames))  # a queue that never drops: the model sees every frame
    lines = sink.frames("cdnf")
    assert lines and all(FRAME_KEYS <= set(r) for r in lines)
    assert all(set(r["output"]) == {"I_v"} for r in lines)
    alerts = sink.events("alert")
    assert alerts, f"no alert; max I_v {max(r['output']['I_v'] for r in lines):.4f}"
    assert any(r["alert"] for r in lines)
    assert alerts[0]["model"] == "cdnf"


def test_translating_stream_does_not_alert():
    # a bar crossing in 3 s: C-DNF stays below its threshold even where the stream loses a frame (the
    # bar then moves twice as far in one step; at the default 1.5 s, I_v reaches 0.5075 > 0.506 there)
    lead, frames = stimulus("dark_translating", duration=3.0)
    with MJPEGServer(frames, fps=FPS, lead=lead) as server:
        sink, loop = run_loop(server, queue=len(frames))  # a queue that never drops: the model sees every frame
    lines = sink.frames("cdnf")
    assert loop.summary.dropped == 0 and len(lines) >= len(frames) - 2
    assert not sink.events("alert")
    assert not any(r["alert"] for r in lines), f"max I_v {max(r['output']['I_v'] for r in lines):.4f}"


def test_latency_is_reported_from_capture_to_result():
    lead, frames = stimulus("dark_looming", hold=0)
    with MJPEGServer(frames, fps=FPS, lead=lead) as server:
        t0 = time.perf_counter()
        sink, loop = run_loop(server)
        wall_ms = (time.perf_counter() - t0) * 1e3
    lat = [r["latency_ms"] for r in sink.frames()]
    assert lat and all(0 < x < wall_ms for x in lat)
    end = loop.summary.record()
    lower_median = sorted(lat)[(len(lat) - 1) // 2]
    assert end["latency_ms_median"] == pytest.approx(lower_median, abs=0.011)


def test_slow_model_drops_frames_and_counts_them():
    lead, frames = stimulus("dark_looming", hold=0)
    with MJPEGServer(frames, fps=FPS, lead=lead) as server:
        sink, loop = run_loop(server, queue=2, wrap=lambda m: SlowModel(m, 3.0 / FPS))
    s = loop.summary
    lines = sink.frames()
    assert s.dropped > 0
    assert s.processed + s.dropped == s.read  # every frame read was either processed or dropped
    assert s.processed == len(lines)
    dropped = [r["dropped"] for r in lines]
    assert dropped == sorted(dropped) and dropped[-1] <= s.dropped  # cumulative
    gaps = np.diff([r["frame"] for r in lines])
    assert gaps.max() > 1  # frames were skipped ...
    assert gaps.min() >= 1  # ... and never processed twice or out of order


def test_dropped_connection_is_reopened():
    lead, frames = stimulus("dark_looming", hold=0)
    status = _Text()
    with MJPEGServer(frames, fps=FPS, lead=lead, drop_after=10) as server:
        sink, loop = run_loop(server, retry_for_s=3.0, status_stream=status)
        connections = server.connections
    assert connections >= 2
    assert sink.events("reconnect") and sink.events("reconnected")
    assert "reconnecting" in status.text and "reconnected" in status.text
    assert loop.summary.reconnects >= 1
    indices = [r["frame"] for r in sink.frames()]
    assert max(indices) > 10  # frames of the new connection were processed, counted on from the old ones


def test_stalled_stream_is_reopened():
    lead, frames = stimulus("dark_looming", hold=0)
    with MJPEGServer(frames, fps=FPS, lead=lead, stall_after=8, stall_s=5.0) as server:
        sink, loop = run_loop(server, timeout_s=1.0, retry_for_s=3.0)
    assert sink.events("reconnect")
    assert max(r["frame"] for r in sink.frames()) > 8


class _Text:
    """A stderr stand-in that keeps what is written."""

    def __init__(self):
        self.text = ""

    def write(self, s: str) -> None:
        self.text += s

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return False


# -- files, faults, bad input (command line) ------------------------------------------------------------
def test_file_is_replayed_at_its_frame_rate_and_ends_with_exit_0(tmp_path, capsys):
    out = tmp_path / "live.mp4"
    spec = f"stim:dark_looming?size={SIZE}&duration=0.5"
    code = main([spec, "--model", "cdnf", "--record", str(out), "--no-progress"])
    assert code == 0
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    frames = [r for r in records if r["event"] == "frame"]
    assert [r["frame"] for r in frames] == list(range(16))  # a file: nothing dropped
    assert all(r["t"] == pytest.approx(r["frame"] / FPS, abs=1e-3) for r in frames)
    end = records[-1]
    assert end["event"] == "end" and end["reason"] == "end of file"
    assert end["seconds"] >= 15 / FPS  # real time: the last frame is due 15 frame intervals after the first
    cap = cv2.VideoCapture(str(out))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 16
    cap.release()


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (a file that is always full)")
def test_sink_that_cannot_be_written_is_one_error_line_and_the_loop_goes_on(capsys):
    code = main([f"stim:dark_looming?size={SIZE}&duration=0.3", "--model", "cdnf", "--jsonl", "/dev/full",
                 "--no-progress"])
    out, err = capsys.readouterr()
    records = [json.loads(line) for line in out.splitlines()]
    assert code == 1
    assert [e for e in err.splitlines() if e.startswith("error:")] == ["error: /dev/full: No space left on device"]
    assert records[-1]["event"] == "end" and records[-1]["processed"] == 10


def test_reader_of_stdout_going_away_ends_the_loop():
    class Gone:
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self):
            raise BrokenPipeError(32, "Broken pipe")

    capture = ProcessCapture(parse_source(f"stim:dark_looming?size={SIZE}&duration=5"), LatestFrames(2))
    loop = LiveLoop(capture, lambda fps: [create_model("cdnf", fps=fps)], Sinks([StreamSink(Gone(), "stdout")]))
    summary = loop.run()
    assert summary.reason == "stdout closed" and summary.processed == 0


def test_duration_stops_the_loop_with_exit_0(capsys):
    code = main([f"stim:dark_translating?size={SIZE}&duration=60", "--model", "cdnf", "--duration", "0.5",
                 "--no-progress"])
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert code == 0
    assert records[-1]["event"] == "end" and "--duration" in records[-1]["reason"]
    assert 0 < records[-1]["processed"] < 60 * FPS


@pytest.mark.parametrize("source, message", [
    ("97", "error: camera 97: cannot open"),
    ("/dev/video-cdnf-ti-missing", "no such device"),
    ("http://127.0.0.1:9/stream.mjpg", "cannot open the stream"),
    ("no_such_clip.mp4", "no such file"),
])
def test_source_that_cannot_be_opened_is_one_error_line_and_exit_2(source, message, capsys):
    code = run_main(["live", source, "--timeout", "1", "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0]


@pytest.mark.parametrize("args, message", [
    (["--udp", "localhost"], "HOST:PORT"),
    (["--record", "out.txt"], "out.txt"),
    (["--queue", "0"], "--queue"),
])
def test_bad_option_is_one_error_line(args, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    try:
        code = run_main(["live", "stim:dark_looming?size=32", *args])
    except SystemExit as e:  # argparse's way out
        code = e.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0]


def _result(alert: bool) -> dict:
    return {"model": "cdnf", "output_name": "I_v", "value": 0.51, "alert": alert, "latency_ms": 3.0}


def test_recording_draws_the_alert_over_the_input():
    grey = np.full((96, 96), 0.5, np.float32)
    frame = Frame(7, grey, 0.0, 0.25)
    calm, alert = annotate(grey, [_result(False)], frame), annotate(grey, [_result(True)], frame)
    assert calm.shape == alert.shape == (96, 96, 3)
    assert tuple(alert[48, 0]) == (0, 0, 255) and tuple(calm[48, 0]) == (128, 128, 128)  # a red border
    assert (calm[:30] != 128).any()  # the output is written over the frame


def test_recording_repeats_a_frame_for_each_dropped_one(tmp_path):
    rec = Recorder(tmp_path / "rec.avi", fps=FPS)
    image = np.zeros((32, 32), np.uint8)
    for index in (0, 1, 4, 5):  # frames 2 and 3 were dropped
        rec.put(Frame(index, image, 0.0, index / FPS), [_result(False)])
    rec.close()
    assert rec.error is None and rec.written == 6
    cap = cv2.VideoCapture(str(tmp_path / "rec.avi"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 6
    cap.release()


def test_latency_quantiles_are_exact_to_a_hundredth_of_a_millisecond():
    xs = np.random.default_rng(0).gamma(2.0, 4.0, size=1001)
    stats = LatencyStats()
    for x in xs:
        stats.add(float(x))
    assert stats.quantile(0.5) == pytest.approx(float(np.median(xs)), abs=0.0051)
    assert stats.quantile(0.95) == pytest.approx(float(np.sort(xs)[950]), abs=0.0051)
    assert LatencyStats().quantile(0.5) is None


def test_json_lines_hold_no_non_finite_numbers():
    assert json.loads(json_line({"output": {"I_v": math.nan}, "x": np.float32(0.5)})) == \
        {"output": {"I_v": None}, "x": 0.5}


@pytest.mark.parametrize("sig, exit_code", [(signal.SIGTERM, 0), (signal.SIGINT, 130)], ids=["SIGTERM", "SIGINT"])
def test_signal_stops_cleanly_and_flushes_every_sink(tmp_path, sig, exit_code):
    lead, frames = stimulus("dark_translating", hold=0)
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(0.2)
    datagrams: list[bytes] = []
    done = threading.Event()

    def receive():
        while not done.is_set():
            try:
                datagrams.append(receiver.recv(65536))
            except socket.timeout:
                continue

    listener = threading.Thread(target=receive, daemon=True)
    listener.start()
    jsonl = tmp_path / "live.jsonl"
    with MJPEGServer(frames, fps=FPS, lead=lead, loop=True) as server:
        proc = subprocess.Popen(
            [sys.executable, "-m", "cdnf_ti.run", "live", server.url, "--model", "cdnf", "--jsonl", str(jsonl),
             "--udp", f"127.0.0.1:{receiver.getsockname()[1]}", "--status-every", "0.5"],
            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"})
        stdout_lines = []
        try:
            frames_seen = 0
            while frames_seen < 10:  # however long the start takes (kernels compile first)
                line = proc.stdout.readline()
                if not line:
                    break
                stdout_lines.append(line)
                record = json.loads(line)
                if record["event"] == "start":
                    server.go.set()
                frames_seen += record["event"] == "frame"
            assert frames_seen == 10, proc.stderr.read()
            proc.send_signal(sig)
            rest, err = proc.communicate(timeout=600)  # a hang guard: it stops within a frame or two
        finally:
            if proc.poll() is None:
                proc.kill()
    done.set()
    listener.join()
    receiver.setblocking(False)
    while True:  # the child has exited: what it sent is in the socket's buffer, however slow the listener was
        try:
            datagrams.append(receiver.recv(65536))
        except BlockingIOError:
            break
    receiver.close()
    stdout_lines += rest.splitlines(keepends=True)
    assert proc.returncode == exit_code, err
    assert json.loads(stdout_lines[-1]) == json.loads(jsonl.read_text().splitlines()[-1])
    assert jsonl.read_text() == "".join(stdout_lines)  # every line reached the file, the last one too
    end = json.loads(stdout_lines[-1])
    assert end["event"] == "end" and end["reason"] == sig.name
    assert json.loads(datagrams[-1]) == end and len(datagrams) == len(stdout_lines)
    assert f"live: stopped ({sig.name})" in err and "error" not in err
