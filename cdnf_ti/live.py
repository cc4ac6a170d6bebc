"""Live mode: ``python -m cdnf_ti.run live SOURCE [--model M,...]``: a collision cue from a running camera.

The source (camera index, device path, stream URL, or a file replayed in real time;
:mod:`cdnf_ti.live_sources`) is read by a thread of a child process (where each frame's
arrival is timed: here, running kernels hold the interpreter lock) into a small queue
that drops the oldest frame when the models fall behind. Every selected model steps on each frame
taken from the queue, and each result is written at once as one JSON line (stdout, and
the ``--jsonl`` / ``--udp`` sinks)::

    {"event": "frame", "frame": 57, "t": 1.9, "model": "cdnf", "output": {"I_v": 0.5123},
     "alert": false, "latency_ms": 4.21, "dropped": 0, "converged": true}

``latency_ms`` runs from the moment the frame was received from the source to the moment
this model's result was ready (the models are compiled before the stream starts; the
compile time is reported apart, ``compile_s``).
Other lines are events (``"event"``: ``start``, ``alert`` at each alert onset,
``reconnect``, ``reconnected``, ``end``). A one-line status goes to stderr.

Exit codes: 0 when the stream ends (a file's last frame; a live source that stays away
for ``--retry-for`` seconds), after ``--duration``, on SIGTERM, or when the reader of
stdout goes away; 130 on Ctrl-C (SIGINT); 2 when the source cannot be opened or an
option is wrong (one ``error:`` line); 1 when the stream failed after it started
(e.g. a corrupt file), or a ``--jsonl`` file or the recording could not be written.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import queue
import signal
import socket
import statistics
import sys
import threading
import time
import warnings
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence, TextIO

import cv2
import numpy as np

from .cli_common import (
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    ArgumentParser,
    add_input_options,
    add_model_options,
    add_param_options,
    check_model_options,
    params_from_args,
    parse_models,
    positive_float,
)
from .errors import InputError, UserError, output_error
from .experiments.parallel import acknowledge_signal
from .frames import ColourFrame
from .limits import check_frame_size
from .live_sources import Capture, Frame, LatestFrames, ProcessCapture, SourceSpec, StreamEnded, parse_source
from .models import create_model, get_model_class
from .video import codec_for, to_uint8, write_video

#: Seconds between two status lines when stderr is a log (not a terminal), by default.
STATUS_EVERY_S = 5.0
#: Seconds between two refreshes of the status line in a terminal.
STATUS_REFRESH_S = 0.25


# -- argparse types ---------------------------------------------------------------------------------
def seconds_or_inf(text: str) -> float:
    """argparse type: seconds >= 0, or ``inf`` (forever)."""
    if text.strip().lower() in ("inf", "forever"):
        return math.inf
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds (or 'inf')") from None
    if not (value >= 0) or math.isnan(value):
        raise argparse.ArgumentTypeError(f"must be >= 0 seconds (or 'inf'), got {text!r}")
    return value


def queue_size(text: str) -> int:
    """argparse type: frames the queue holds (1 .. 1000)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if not 1 <= value <= 1000:
        raise argparse.ArgumentTypeError(f"must be between 1 and 1000 frames, got {text!r}")
    return value


def udp_address(text: str) -> tuple[str, int]:
    """argparse type: ``HOST:PORT`` (``[IPv6]:PORT`` too) -> ``(host, port)``."""
    host, sep, port = text.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT (e.g. 127.0.0.1:9000), got {text!r}")
    return host, int(port)


# -- sinks ---------------------------------------------------------------------------------------------
def json_line(record: dict) -> str:
    """One compact JSON line (no newline) for ``record``; non-finite numbers become null."""
    def clean(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        if isinstance(v, (bool, np.bool_)):
            return bool(v)
        if isinstance(v, (int, np.integer)):
            return int(v)
        if isinstance(v, (float, np.floating)):
            return float(v) if math.isfinite(v) else None
        return v

    return json.dumps(clean(record), allow_nan=False)


class UdpSink:
    """Sends each line as one UDP datagram (UTF-8, newline-terminated) to ``(host, port)``.

    A datagram that cannot be sent is counted in :attr:`errors` (the loop goes on).
    """

    def __init__(self, address: tuple[str, int]):
        host, port = address
        try:
            info = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
        except OSError as e:
            raise UserError(f"--udp {host}:{port}: {e.strerror or e}") from None
        family, kind, proto, _, self.address = info[0]
        self.sock = socket.socket(family, kind, proto)
        self.errors = 0

    def write(self, line: str) -> None:
        try:
            self.sock.sendto(line.encode("utf-8") + b"\n", self.address)
        except OSError:
            self.errors += 1

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self.sock.close()


class StreamSink:
    """Writes lines to a text stream (stdout, a ``--jsonl`` file); flushed after each frame.

    A stream that cannot be written any more (a full disk) prints one ``error:`` line and is
    left out from then on (:attr:`failed`); the loop goes on with the other sinks. A closed
    pipe on stdout marks it :attr:`broken` (the loop then stops: nobody reads).

    Parameters
    ----------
    stream : text stream
    name : str
        Names the stream in messages.
    own : bool
        Close the stream at the end.
    """

    def __init__(self, stream: TextIO, name: str, own: bool = False):
        self.stream, self.name, self.own = stream, name, own
        self.broken = False
        self.failed: UserError | None = None

    def _guard(self, action: Callable[[], Any]) -> None:
        if self.broken or self.failed is not None:
            return
        try:
            action()
        except (BrokenPipeError, ValueError):
            self.broken = True
        except OSError as e:
            self.failed = output_error(self.name, e)
            print(f"error: {self.failed}", file=sys.stderr)

    def write(self, line: str) -> None:
        self._guard(lambda: self.stream.write(line + "\n"))

    def flush(self) -> None:
        self._guard(self.stream.flush)

    def close(self) -> None:
        self.flush()
        if self.own:
            try:
                self.stream.close()
            except OSError:
                pass


class Sinks:
    """Every destination of the JSON lines: :meth:`emit` writes one record to each."""

    def __init__(self, sinks: Sequence[Any]):
        self.sinks = list(sinks)
        self.lines = 0

    def emit(self, record: dict) -> None:
        line = json_line(record)
        for s in self.sinks:
            s.write(line)
        self.lines += 1

    def flush(self) -> None:
        for s in self.sinks:
            s.flush()

    def close(self) -> None:
        for s in self.sinks:
            try:
                s.close()
            except (OSError, UserError):
                pass

    @property
    def failed(self) -> list:
        """The errors of sinks that could not be written (each reported once)."""
        return [s.failed for s in self.sinks if getattr(s, "failed", None) is not None]

    @property
    def stdout_gone(self) -> bool:
        """The reader of stdout went away (broken pipe)."""
        return any(getattr(s, "broken", False) and getattr(s, "name", "") == "stdout" for s in self.sinks)


# -- status line ---------------------------------------------------------------------------------------
class Status:
    """The one-line human status on stderr: refreshed in place in a terminal, a line every
    ``every_s`` seconds in a log; messages (reconnects) as lines of their own."""

    def __init__(self, stream: TextIO, enabled: bool = True, every_s: float = STATUS_EVERY_S):
        self.stream = stream
        self.enabled = enabled
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.every_s = STATUS_REFRESH_S if self.tty else every_s
        self._last = -math.inf
        self._shown = False
        self._lock = threading.Lock()

    def update(self, text: str, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if not force and now - self._last < self.every_s:
            return
        self._last = now
        with self._lock:
            if self.tty:
                self.stream.write("\r\x1b[K" + text)
                self._shown = True
            else:
                self.stream.write(text + "\n")
            self.stream.flush()

    def message(self, text: str) -> None:
        """A line of its own (always shown, also with the status off)."""
        with self._lock:
            if self.tty and self._shown:
                self.stream.write("\r\x1b[K")
                self._shown = False
            self.stream.write(text + "\n")
            self.stream.flush()
        self._last = -math.inf  # the status follows at once

    def close(self) -> None:
        with self._lock:
            if self.tty and self._shown:
                self.stream.write("\n")
                self.stream.flush()
                self._shown = False


# -- recording -----------------------------------------------------------------------------------------
def annotate(image: np.ndarray, results: Sequence[dict], frame: Frame) -> np.ndarray:
    """The input frame as BGR uint8 with each model's output and alert drawn over it.

    Parameters
    ----------
    image : ndarray or ColourFrame
        (H, W) grey or (H, W, 3) BGR; uint8 or float in [0, 1] (a ColourFrame: its colour form).
    results : list of dict
        One per model: ``model``, ``output_name``, ``value``, ``alert``, ``latency_ms``.
    frame : Frame
        For the frame index and time written at the bottom.
    """
    a = to_uint8(image.bgr if isinstance(image, ColourFrame) else image)
    out = cv2.cvtColor(a, cv2.COLOR_GRAY2BGR) if a.ndim == 2 else a.copy()
    h, w = out.shape[:2]
    scale = max(0.35, min(h, w) / 700.0)
    thick = max(1, int(round(scale * 2)))
    step = int(round(26 * scale)) + 4
    any_alert = False
    for k, r in enumerate(results):
        alert = bool(r["alert"])
        any_alert |= alert
        text = f"{r['model']} {r['output_name']} {r['value']:.4f}" + ("  ALERT" if alert else "")
        colour = (0, 0, 255) if alert else (0, 200, 0)
        y = step * (k + 1)
        cv2.putText(out, text, (8, y), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), thick + 2, cv2.LINE_AA)
        cv2.putText(out, text, (8, y), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thick, cv2.LINE_AA)
    lat = max((r["latency_ms"] for r in results), default=float("nan"))
    foot = f"frame {frame.index}  t {frame.t:.2f} s  latency {lat:.1f} ms"
    cv2.putText(out, foot, (8, h - 8), cv2.FONT_HERSHEY_SIMPLEX, scale * 0.8, (0, 0, 0), thick + 2, cv2.LINE_AA)
    cv2.putText(out, foot, (8, h - 8), cv2.FONT_HERSHEY_SIMPLEX, scale * 0.8, (255, 255, 255), thick, cv2.LINE_AA)
    if any_alert:
        cv2.rectangle(out, (0, 0), (w - 1, h - 1), (0, 0, 255), max(2, int(round(6 * scale))))
    return out


class Recorder:
    """``--record FILE``: writes the processed frames, annotated (:func:`annotate`), on its own thread.

    Frames dropped between two processed ones are filled by repeating the earlier
    annotated frame, so the movie keeps the source's timing at ``fps``. The file
    appears when complete (:func:`cdnf_ti.video.write_video`). If the writer falls
    more than ``backlog`` frames behind, frames are left out of the movie
    (:attr:`lost`).
    """

    def __init__(self, path: str | os.PathLike, fps: float, backlog: int = 64):
        self.path = Path(path)
        codec_for(self.path)  # .mp4 / .avi, or one error line now
        parent = self.path.expanduser().resolve().parent
        if not parent.is_dir():
            raise InputError(self.path, "its folder does not exist")
        if not os.access(parent, os.W_OK):
            raise InputError(self.path, "its folder cannot be written (permission denied)")
        self.fps = float(fps)
        self._queue: queue.Queue = queue.Queue(maxsize=backlog)
        self._thread: threading.Thread | None = None
        self._cut = threading.Event()  # finish_now(): end the movie at the frame being written
        self.error: BaseException | None = None
        self.written = 0
        self.lost = 0

    def put(self, frame: Frame, results: list[dict]) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="cdnf_ti-record", daemon=True)
            self._thread.start()
        try:
            self._queue.put_nowait((frame, results))
        except queue.Full:
            self.lost += 1

    def _frames(self):
        size = None
        last_index, last_session, last_image = None, None, None
        max_fill = int(self.fps * 10)
        while not self._cut.is_set():
            item = self._queue.get()
            if item is None or self._cut.is_set():
                return
            frame, results = item
            image = annotate(frame.image, results, frame)
            if size is None:
                size = image.shape[1], image.shape[0]
            elif (image.shape[1], image.shape[0]) != size:
                image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
            if last_image is not None and frame.session == last_session:
                for _ in range(min(frame.index - last_index - 1, max_fill)):
                    if self._cut.is_set():
                        return
                    yield last_image
            last_index, last_session, last_image = frame.index, frame.session, image
            yield image

    def _run(self) -> None:
        try:
            self.written = write_video(self.path, self._frames(), fps=self.fps)
        except BaseException as e:  # noqa: BLE001 - reported by close()
            self.error = e
            while True:  # let put() go on without blocking
                try:
                    if self._queue.get(timeout=0.5) is None:
                        return
                except queue.Empty:
                    continue

    def close(self) -> None:
        """Finish the file (waits for the frames still queued)."""
        if self._thread is None:
            return
        self._queue.put(None)
        self._thread.join()

    def finish_now(self, timeout_s: float = 10.0) -> None:
        """Finish the file with the frames written so far, leaving the queued ones out (a second Ctrl-C
        during the clean stop): the movie is closed and renamed into place, playable. Waits at most
        ``timeout_s`` seconds for the writer."""
        if self._thread is None:
            return
        self._cut.set()
        with contextlib.suppress(queue.Full):
            self._queue.put_nowait(None)  # wakes a writer waiting for a frame
        self._thread.join(timeout_s)


# -- the loop ------------------------------------------------------------------------------------------
def _inverted_patch(image: np.ndarray) -> np.ndarray:
    """A copy of ``image`` (uint8, or float in [0, 1]) whose patch from a quarter to half of each side is inverted."""
    b = np.array(image)
    h, w = b.shape[:2]
    region = b[h // 4: h // 2 + 1, w // 4: w // 2 + 1]
    region[...] = 255 - region if b.dtype == np.uint8 else 1.0 - region
    return b


def warm_up(models: Sequence[Any], image: np.ndarray | ColourFrame) -> float:
    """Compile every model for frames like ``image`` (three steps, then reset); returns the seconds taken."""
    t0 = time.perf_counter()
    a = image if isinstance(image, ColourFrame) else np.asarray(image)
    b = (ColourFrame(_inverted_patch(a.grey), _inverted_patch(a.bgr)) if isinstance(a, ColourFrame)
         else _inverted_patch(a))
    for m in models:
        m.reset()
        for f in (a, b, a):
            m.step(f)
        m.reset()
    return time.perf_counter() - t0


class LatencyStats:
    """Latencies in constant memory (a live run may last days): a histogram of 0.01 ms bins.

    Quantiles are exact to the bin width (0.01 ms) up to :attr:`MAX_MS`; longer latencies
    count as :attr:`MAX_MS`.
    """

    BIN_MS = 0.01
    MAX_MS = 5_000.0

    def __init__(self):
        self.counts = np.zeros(int(self.MAX_MS / self.BIN_MS) + 1, dtype=np.int64)
        self.count = 0

    def add(self, ms: float) -> None:
        k = int(min(max(ms, 0.0), self.MAX_MS) / self.BIN_MS + 0.5)
        self.counts[k] += 1
        self.count += 1

    def quantile(self, q: float) -> float | None:
        """The ``q`` quantile (0..1) in ms (the lower median for q = 0.5), or None before any latency."""
        if self.count == 0:
            return None
        rank = min(self.count - 1, int(q * (self.count - 1)))
        k = int(np.searchsorted(np.cumsum(self.counts), rank + 1))
        return k * self.BIN_MS


@dataclass
class LiveSummary:
    """What a live run did (also the ``end`` event).

    Attributes
    ----------
    reason : str
        Why it stopped.
    read, processed, dropped : int
        Frames read from the source, processed by the models, dropped from the queue.
    latency : LatencyStats
        Every result's latency (ms), all models.
    alerts : dict
        Alert onsets per model.
    compile_s : float
        Seconds spent compiling the models before the first counted frame.
    seconds : float
        Seconds from the first counted frame to the end.
    reconnects : int
    """

    reason: str = ""
    read: int = 0
    processed: int = 0
    dropped: int = 0
    latency: LatencyStats = field(default_factory=LatencyStats)
    alerts: dict = field(default_factory=dict)
    compile_s: float = 0.0
    seconds: float = 0.0
    reconnects: int = 0

    def record(self) -> dict:
        return {"event": "end", "reason": self.reason, "frames_read": self.read, "processed": self.processed,
                "dropped": self.dropped, "reconnects": self.reconnects,
                "latency_ms_median": _round(self.latency.quantile(0.5), 2),
                "latency_ms_p95": _round(self.latency.quantile(0.95), 2), "alerts": self.alerts,
                "compile_s": round(self.compile_s, 3), "seconds": round(self.seconds, 3)}


def _round(x: float | None, n: int) -> float | None:
    return None if x is None else round(float(x), n)


def model_start_record(model) -> dict:
    """A model in the ``start`` event: its name, output and alert rule (:meth:`~cdnf_ti.models.base.Model.alert_rule`).

    ``threshold`` is the rule's level (for the LGMD family the spike count ``n_ts``), ``rule`` the rule in
    words, ``compares`` the per-frame value it compares (a frame line's output or diagnostic).
    A model-like object without ``alert_rule`` gives its ``threshold`` and no rule.
    """
    rule = model.alert_rule() if hasattr(model, "alert_rule") else None
    if rule is None:
        return {"model": model.name, "output": model.output_name, "threshold": model.threshold}
    return {"model": model.name, "output": model.output_name, "threshold": rule.level, "rule": rule.rule,
            "compares": rule.column}


class LiveLoop:
    """Runs models on a capture and writes their results.

    Parameters
    ----------
    capture : ProcessCapture or Capture
        :class:`~cdnf_ti.live_sources.ProcessCapture` (the command line's) or
        :class:`~cdnf_ti.live_sources.Capture` (a thread of this process). Not yet opened
        (:meth:`open` or :meth:`run` opens it: a source that cannot be opened raises a
        :class:`~cdnf_ti.errors.UserError` before any work).
    make_models : callable
        ``make_models(fps)`` -> list of models (:class:`~cdnf_ti.models.base.Model` or any
        object with ``name``, ``output_name``, ``threshold``, ``step(frame)`` and ``reset()``).
    sinks : Sinks
    status : Status, optional
    recorder : Recorder, optional
    duration_s : float
        Stop after this many seconds of counted frames (inf: until the stream ends).
    diagnostics : bool
        Add each model's per-frame diagnostics to the frame lines.
    on_start : callable, optional
        Called with the ``start`` record once the models are compiled.
    """

    def __init__(self, capture: ProcessCapture | Capture, make_models: Callable[[float], list], sinks: Sinks,
                 status: Status | None = None, recorder: Recorder | None = None, duration_s: float = math.inf,
                 diagnostics: bool = False, on_start: Callable[[dict], None] | None = None):
        self.capture = capture
        self.frames = capture.frames
        self.make_models = make_models
        self.sinks = sinks
        self.status = status or Status(sys.stderr, enabled=False)
        self.recorder = recorder
        self.duration_s = duration_s
        self.diagnostics = diagnostics
        self.on_start = on_start
        self.stop = threading.Event()
        self.summary = LiveSummary()
        self._events: queue.SimpleQueue = queue.SimpleQueue()
        self._recent: deque = deque(maxlen=120)
        capture.report = self._report

    def _report(self, kind: str, info: dict) -> None:
        """Capture-thread events: a stderr line now, a JSON event from the loop's thread."""
        if kind == "reconnect":
            self.status.message(f"live: {self.capture.spec.text}: {info['reason']}; reconnecting "
                                f"(attempt {info['attempt']}, in {info['wait_s']:g} s)")
        else:
            self.status.message(f"live: {self.capture.spec.text}: reconnected ({info['width']}x{info['height']})")
        self._events.put({"event": kind, **info})

    def _drain_events(self, t: float) -> None:
        while True:
            try:
                ev = self._events.get_nowait()
            except queue.Empty:
                return
            self.sinks.emit({**ev, "t": round(t, 3), "dropped": self.frames.dropped})

    def _prepare(self, image: np.ndarray) -> list:
        """New models for frames like ``image``, compiled; counts the compile time."""
        models = self.make_models(self.capture.fps)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # NotConvergedWarning: each line says "converged"
            self.summary.compile_s += warm_up(models, image)
        return models

    def open(self, n_models: int = 1) -> Frame:
        """Open the source and check its frame size (for ``n_models`` models) against this machine.

        Raises
        ------
        InputError
            The source cannot be opened, or its frames are too large (one line).
        """
        first = self.capture.open()
        check_frame_size(*first.image.shape[:2], n_models=n_models, what=self.capture.spec.text)
        if self.recorder is not None:
            self.recorder.fps = self.capture.fps
        return first

    def run(self) -> LiveSummary:
        """Compile the models and process frames until the stream ends or :attr:`stop` is set.

        Opens the source first unless :meth:`open` was called.
        """
        capture, summary = self.capture, self.summary
        first = capture.first if capture.first is not None else self.open()
        h, w = first.image.shape[:2]
        models = self._prepare(first.image)  # before reading on: compiling holds the interpreter
        if self.stop.is_set():
            capture.stop()
            self.summary.reason = "stopped before the stream started"
            return self.summary
        capture.start()
        start = {"event": "start", "source": capture.spec.text, "kind": capture.spec.kind, "width": w, "height": h,
                 "fps": round(capture.fps, 3), "queue": self.frames.maxsize,
                 "models": [model_start_record(m) for m in models],
                 "compile_s": round(summary.compile_s, 3)}
        self.sinks.emit(start)
        self.sinks.flush()
        self.status.message(f"live: {capture.spec.text} ({capture.spec.kind}, {w}x{h}, {capture.fps:g} fps): "
                            f"{', '.join(m.name for m in models)} compiled in {summary.compile_s:.1f} s; running "
                            "(Ctrl-C stops)")
        if self.on_start is not None:
            self.on_start(start)
        t_start = time.perf_counter()
        session, shape = 0, (h, w)
        alerting = [False] * len(models)
        summary.alerts = {m.name: 0 for m in models}
        last_t = 0.0
        try:
            while not self.stop.is_set():
                if self.sinks.stdout_gone:
                    summary.reason = "stdout closed"
                    break
                if time.perf_counter() - t_start >= self.duration_s:
                    summary.reason = f"--duration {self.duration_s:g} s reached"
                    break
                self._drain_events(last_t)
                try:
                    frame = self.frames.get(timeout=0.1)
                except StreamEnded as e:
                    summary.reason = str(e)
                    break
                if frame is None:
                    self._show(models, None)
                    continue
                if frame.image.shape[:2] != shape:  # a reconnected source with another frame size
                    shape = frame.image.shape[:2]
                    check_frame_size(*shape, n_models=len(models), what=capture.spec.text)
                    models = self._prepare(frame.image)
                    self.frames.drop_all()  # read while compiling: their latency would be the compile time
                    session, alerting = frame.session, [False] * len(models)
                    continue
                if frame.session != session:  # after a reconnect: the previous frame is not this one's predecessor
                    session = frame.session
                    for m in models:
                        m.reset()
                    alerting = [False] * len(models)
                last_t = frame.t
                results = self._step(models, frame, alerting)
                summary.processed += 1
                if self.recorder is not None:
                    self.recorder.put(frame, results)
                self._show(models, results)
        finally:
            summary.seconds = time.perf_counter() - t_start
            capture.stop()
            self.frames.drop_all()  # read but never processed (the loop stopped first)
            self._drain_events(last_t)
            summary.read = self.frames.received
            summary.dropped = self.frames.dropped
            summary.reconnects = capture.reconnects
        return summary

    def _step(self, models: list, frame: Frame, alerting: list[bool]) -> list[dict]:
        """Step every model on ``frame`` and write a line each (and an alert event at an onset)."""
        results = []
        for k, m in enumerate(models):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = m.step(frame.image)
            latency = (time.perf_counter() - frame.captured) * 1e3
            self.summary.latency.add(latency)
            self._recent.append(latency)
            output = {m.output_name: float(r.output)}
            rec = {"event": "frame", "frame": frame.index, "t": round(frame.t, 4), "model": m.name,
                   "output": output, "alert": bool(r.spike), "latency_ms": round(latency, 3),
                   "dropped": self.frames.dropped, "converged": bool(r.converged)}
            if self.diagnostics:
                rec["diagnostics"] = dict(r.diagnostics)
            self.sinks.emit(rec)
            if r.spike and not alerting[k]:
                self.summary.alerts[m.name] = self.summary.alerts.get(m.name, 0) + 1
                self.sinks.emit({"event": "alert", "frame": frame.index, "t": round(frame.t, 4), "model": m.name,
                                 "output": output, "latency_ms": round(latency, 3)})
                if self.status.enabled:
                    self.status.message(f"live: ALERT {m.name} at frame {frame.index} (t {frame.t:.2f} s, "
                                        f"{m.output_name} {float(r.output):.4f})")
            alerting[k] = bool(r.spike)
            results.append({"model": m.name, "output_name": m.output_name, "value": float(r.output),
                            "alert": bool(r.spike), "latency_ms": latency})
        self.sinks.flush()
        return results

    def _show(self, models: list, results: list[dict] | None) -> None:
        s = self.summary
        lat = statistics.median(self._recent) if self._recent else float("nan")
        text = (f"live {self.capture.spec.text}: read {self.frames.received}, processed {s.processed}, "
                f"dropped {self.frames.dropped}, latency {lat:.1f} ms")
        if results:
            text += " | " + "  ".join(f"{r['model']} {r['output_name']} {r['value']:.4f}"
                                      + (" ALERT" if r["alert"] else "") for r in results)
        self.status.update(text)


# -- command line --------------------------------------------------------------------------------------
def _parser() -> argparse.ArgumentParser:
    ap = ArgumentParser(
        prog="python -m cdnf_ti.run live",
        description="Run looming models on a live source, frame by frame, and write one JSON line per frame "
                    "and model (stdout, --jsonl, --udp). Frames that arrive while the models are busy are dropped "
                    "(oldest first) and counted.")
    ap.add_argument("source", metavar="SOURCE",
                    help="camera index (0), device path (/dev/video0), stream URL (http://.../stream.mjpg, "
                         "rtsp://...), or a video file / image folder / .npy array / stim:NAME replayed at its "
                         "own frame rate in real time")
    add_model_options(ap)
    add_param_options(ap)
    add_input_options(ap)
    for action in ap._actions:  # the scheme's --fps, and what it means for a live source
        if action.dest == "fps":
            action.help += ("; for a file also its replay rate. A camera's or URL's rate as the models take it "
                            "(default: what a camera states; 30 for a URL)")
    ap.add_argument("--jsonl", metavar="FILE", default=None, help="also write the JSON lines to FILE")
    ap.add_argument("--udp", metavar="HOST:PORT", type=udp_address, default=None,
                    help="also send each JSON line as one UDP datagram to HOST:PORT")
    ap.add_argument("--record", metavar="FILE.mp4", default=None,
                    help="write the input with each model's output and alert drawn over it (.mp4 or .avi)")
    ap.add_argument("--queue", metavar="N", type=queue_size, default=2,
                    help="frames waiting for the models at most; the oldest is dropped beyond (default: %(default)s)")
    ap.add_argument("--timeout", metavar="S", type=positive_float, default=5.0,
                    help="seconds without a frame before a camera or URL is reopened; also a URL's open timeout "
                         "(default: %(default)s)")
    ap.add_argument("--retry-for", metavar="S", type=seconds_or_inf, default=30.0,
                    help="seconds to keep reconnecting a lost camera or URL before the stream counts as ended "
                         "(default: %(default)s; 0: never reconnect; inf: forever)")
    ap.add_argument("--duration", metavar="S", type=positive_float, default=None,
                    help="stop after this many seconds (default: when the stream ends)")
    ap.add_argument("--diagnostics", action="store_true",
                    help="add each model's per-frame diagnostics (iterations, ...) to the frame lines")
    ap.add_argument("--status-every", metavar="S", type=positive_float, default=STATUS_EVERY_S,
                    help="seconds between status lines when stderr is not a terminal (default: %(default)s)")
    ap.add_argument("--no-progress", action="store_true", help="hide the status line on stderr")
    return ap


class _Signals:
    """SIGINT and SIGTERM set :attr:`stop` (the loop ends cleanly); a second one ends the process at once,
    after ``before_exit`` (the recording is finished with what was written: :meth:`Recorder.finish_now`)."""

    def __init__(self, stop: threading.Event, before_exit: Callable[[], None] | None = None):
        self.stop = stop
        self.before_exit = before_exit
        self.received: int | None = None
        self._old: dict = {}

    def __enter__(self) -> "_Signals":
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        acknowledge_signal()
        if self.received is not None:
            try:
                if self.before_exit is not None:
                    self.before_exit()
            finally:
                os._exit(EXIT_INTERRUPTED if signum == signal.SIGINT else 128 + signum)
        self.received = signum
        self.stop.set()

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


def main(argv: Sequence[str]) -> int:
    """``python -m cdnf_ti.run live``; returns the exit code (see the module docstring)."""
    args = _parser().parse_args(argv)
    names = parse_models(args.models)
    check_model_options(args)
    params = params_from_args(args, names)
    spec: SourceSpec = parse_source(args.source)
    status = Status(sys.stderr, enabled=not args.no_progress, every_s=args.status_every)

    sinks = Sinks([StreamSink(sys.stdout, "stdout")])
    if args.udp is not None:
        sinks.sinks.append(UdpSink(args.udp))

    def make_models(fps: float) -> list:
        return [create_model(n, params[n], backend=args.backend, arch=args.arch, fps=fps) for n in names]

    frames = LatestFrames(args.queue)
    colour = any(get_model_class(n).frame_colour(params[n]) == "bgr" for n in names)  # frames in both forms
    capture = ProcessCapture(spec, frames, fps=args.fps, color_order=args.color_order, timeout_s=args.timeout,
                             retry_for_s=args.retry_for, colour=colour)
    recorder = Recorder(args.record, fps=30.0) if args.record is not None else None  # checked before any work
    loop = LiveLoop(capture, make_models, sinks, status=status, recorder=recorder,
                    duration_s=args.duration or math.inf, diagnostics=args.diagnostics)
    code = EXIT_OK
    with _Signals(loop.stop, recorder.finish_now if recorder is not None else None) as signals:
        loop.open(len(names))  # a source that cannot be opened: one error line, exit 2
        if args.jsonl is not None:
            try:
                sinks.sinks.append(StreamSink(open(args.jsonl, "w", encoding="utf-8"), args.jsonl, own=True))
            except OSError as e:
                raise output_error(args.jsonl, e) from None
        try:
            try:
                summary = loop.run()
            except UserError as e:  # the stream failed after it started (a corrupt file, ...)
                print(f"error: {e}", file=sys.stderr)
                summary, code = loop.summary, EXIT_FAILED
                summary.reason = f"error: {e}"
            if signals.received is not None:
                summary.reason = signal.Signals(signals.received).name
                if signals.received == signal.SIGINT:
                    code = EXIT_INTERRUPTED
            if recorder is not None:
                recorder.close()
                if recorder.error is not None:
                    e = recorder.error
                    msg = str(e) if isinstance(e, UserError) else f"{args.record}: {type(e).__name__}: {e}"
                    print(f"error: {msg}".splitlines()[0], file=sys.stderr)
                    code = EXIT_FAILED if code == EXIT_OK else code
            sinks.emit(summary.record())
            sinks.flush()
        finally:
            status.close()
            sinks.close()
    if sinks.failed and code == EXIT_OK:
        code = EXIT_FAILED
    _report_end(status, summary, recorder, args)
    if sinks.stdout_gone:
        _quiet_stdout()
    return code


def _report_end(status: Status, s: LiveSummary, recorder: Recorder | None, args) -> None:
    med, p95 = s.latency.quantile(0.5), s.latency.quantile(0.95)
    alerts = ", ".join(f"{k} {v}" for k, v in s.alerts.items()) or "none"
    status.message(f"live: stopped ({s.reason}) after {s.seconds:.1f} s: {s.read} frames read, {s.processed} "
                   f"processed, {s.dropped} dropped, {s.reconnects} reconnect attempts; latency median {_ms(med)}, "
                   f"p95 {_ms(p95)}; alert onsets: {alerts}; "
                   f"compile {s.compile_s:.1f} s")
    if recorder is not None and recorder.error is None and recorder.written:
        lost = f" ({recorder.lost} frames left out: the writer fell behind)" if recorder.lost else ""
        status.message(f"live: recorded {recorder.written} frames to {args.record}{lost}")


def _ms(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.1f} ms"


def _quiet_stdout() -> None:
    """After the reader of stdout went away: send what is left to /dev/null (no error at exit)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
