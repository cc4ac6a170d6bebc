"""Live frame sources for ``python -m cdnf_ti.run live``: cameras, device paths, stream URLs, replayed files.

A :class:`Capture` reads one source on its own thread and hands its frames to a
:class:`LatestFrames` queue, which holds at most a few frames and drops the
oldest when the consumer (the models) falls behind, counting each drop.
:class:`ProcessCapture` runs a :class:`Capture` in a child process (the command line's
choice), so that frames are timed on arrival even while kernels hold this process's
interpreter lock.

Sources (:func:`parse_source`):

* ``0``, ``1``, ... a camera index (OpenCV's default camera API);
* ``/dev/video0`` (any path under ``/dev/``): a capture device;
* ``http://...``, ``https://...``, ``rtsp://...`` (any ``SCHEME://``): a stream URL opened by
  OpenCV's FFmpeg backend, with open and read timeouts;
* anything else: a file input of :func:`cdnf_ti.inputs.resolve_input` (video file, image
  folder, ``.npy`` array, generated ``stim:NAME``), replayed at its own frame rate in real time.

A camera, device or URL that stops delivering frames (dropped connection, stalled
stream, unplugged camera) is reopened with exponential backoff; each attempt is
reported through the capture's ``report`` callback. A source that gives no frame
after ``retry_for`` seconds of reconnecting has ended. A file ends at its last frame.
"""
from __future__ import annotations

import collections
import math
import multiprocessing
import os
import signal
import threading
import time
from dataclasses import dataclass, replace
from typing import Any, Callable, Iterator

import cv2
import numpy as np

from .errors import InputError, UserError
from .frames import DEFAULT_FPS, ColourFrame, to_grey
from .inputs import resolve_input

#: Kinds of source (:attr:`SourceSpec.kind`).
KINDS = ("camera", "device", "url", "file")

#: First and largest wait between two reconnect attempts (s); the wait doubles after each failed attempt.
BACKOFF_FIRST_S, BACKOFF_MAX_S = 0.25, 5.0


@dataclass(frozen=True)
class SourceSpec:
    """A parsed ``SOURCE`` argument.

    Attributes
    ----------
    text : str
        The argument as given (names the source in messages).
    kind : {"camera", "device", "url", "file"}
    target : int or str
        Camera index, device path, URL, or file input spec.
    """

    text: str
    kind: str
    target: Any

    @property
    def live(self) -> bool:
        """True for cameras, devices and URLs (frames arrive on their own clock; reconnect on loss)."""
        return self.kind != "file"


def parse_source(text: str) -> SourceSpec:
    """Classify a ``SOURCE`` argument (see the module docstring).

    Raises
    ------
    InputError
        Empty text, or a device path that does not exist.
    """
    s = str(text).strip()
    if not s:
        raise InputError(repr(text), "empty source; give a camera index, a device path, a URL or a video file")
    if s.isdigit():
        return SourceSpec(s, "camera", int(s))
    if "://" in s:
        return SourceSpec(s, "url", s)
    if s.startswith("/dev/"):
        if not os.path.exists(s):
            raise InputError(s, "no such device")
        return SourceSpec(s, "device", s)
    return SourceSpec(s, "file", s)


@dataclass
class Frame:
    """One captured frame.

    Attributes
    ----------
    index : int
        Index of the frame at the source: frames read since the start, 0-based, counted
        across reconnects.
    image : ndarray or ColourFrame
        (H, W, 3) BGR uint8 from cameras, URLs and video files; whatever the file input
        yields otherwise ((H, W) float32 grey in [0, 1] for generated stimuli). From a
        :class:`ProcessCapture`: grey, or a :class:`~cdnf_ti.frames.ColourFrame` (``colour``).
    captured : float
        ``time.perf_counter()`` when the frame was received (s): a camera or URL frame
        once grabbed, before its conversion to BGR; a file's frame once decoded.
    t : float
        Seconds since the stream started: a live source's time of capture after its first
        frame; a file's position, ``index / fps``.
    session : int
        Connection number: 0 for the first opening, +1 after each reconnect (the frame
        before it is not this frame's predecessor).
    """

    index: int
    image: np.ndarray
    captured: float
    t: float
    session: int = 0


class StreamEnded(Exception):
    """End of the frame stream (carries the reason as its message)."""


class LatestFrames:
    """A bounded frame queue that drops the OLDEST frame when full, and counts the drops.

    The capture thread ``put``s; the consumer ``get``s. The queue never holds more than
    ``maxsize`` frames, so a slow consumer always gets one of the newest frames.

    Parameters
    ----------
    maxsize : int
        Frames held at most (>= 1).
    """

    def __init__(self, maxsize: int = 2):
        if maxsize < 1:
            raise ValueError(f"queue size must be >= 1, got {maxsize}")
        self.maxsize = int(maxsize)
        self._items: collections.deque = collections.deque()
        self._cv = threading.Condition()
        self._end: BaseException | None = None
        #: Frames dropped so far (cumulative).
        self.dropped = 0
        #: Frames put so far (cumulative).
        self.received = 0

    def put(self, frame: Frame) -> None:
        """Add a frame, dropping (and counting) the oldest one when the queue is full."""
        with self._cv:
            if len(self._items) >= self.maxsize:
                self._items.popleft()
                self.dropped += 1
            self._items.append(frame)
            self.received += 1
            self._cv.notify()

    def close(self, reason: BaseException) -> None:
        """No more frames: ``get`` raises ``reason`` once the queue is empty."""
        with self._cv:
            if self._end is None:
                self._end = reason
            self._cv.notify_all()

    def get(self, timeout: float | None = None) -> Frame | None:
        """The oldest frame held; None after ``timeout`` seconds with none.

        Raises
        ------
        BaseException
            The reason given to :meth:`close` (e.g. :class:`StreamEnded`), once every
            frame put before it has been taken.
        """
        with self._cv:
            if not self._items and self._end is None:
                self._cv.wait(timeout)
            if self._items:
                return self._items.popleft()
            if self._end is not None:
                raise self._end
            return None

    def count_upstream_drops(self, n: int) -> None:
        """Count ``n`` frames read at the source but dropped before they reached this queue."""
        if n > 0:
            with self._cv:
                self.dropped += n
                self.received += n

    def drop_all(self) -> int:
        """Drop (and count) every frame held; returns how many."""
        with self._cv:
            n = len(self._items)
            self._items.clear()
            self.dropped += n
            return n


def _open_cv(spec: SourceSpec, timeout_s: float) -> cv2.VideoCapture:
    """An OpenCV capture of a camera, device or URL (maybe not opened: check ``isOpened``)."""
    ms = int(max(1.0, timeout_s * 1000.0))
    if spec.kind == "url":
        return cv2.VideoCapture(spec.target, cv2.CAP_FFMPEG,
                                [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, ms, cv2.CAP_PROP_READ_TIMEOUT_MSEC, ms])
    return cv2.VideoCapture(spec.target)


def _cannot_open(spec: SourceSpec) -> InputError:
    if spec.kind == "camera":
        return InputError(f"camera {spec.target}", "cannot open (no such camera, or it is in use)")
    if spec.kind == "device":
        return InputError(spec.text, "cannot open as a capture device (not a camera, or it is in use)")
    return InputError(spec.text, "cannot open the stream (unreachable, not a video stream, or timed out)")


def _read(cap: cv2.VideoCapture) -> tuple[bool, np.ndarray | None, float]:
    """The next frame of ``cap``: ``(ok, BGR image, time it arrived)``.

    The time is taken when the frame has been received (``grab``), before its conversion
    to BGR (``retrieve``), so the latency counted from it includes that conversion.
    """
    if not cap.grab():
        return False, None, 0.0
    arrived = time.perf_counter()
    ok, image = cap.retrieve()
    return ok, image, arrived


def _sane_fps(value: float) -> float | None:
    return float(value) if math.isfinite(value) and 0 < value < 1000 else None


class Capture:
    """Reads a source on a background thread into a :class:`LatestFrames` queue.

    :meth:`open` opens the source and reads its first frame on the caller's thread
    (so a source that cannot be opened is one :class:`~cdnf_ti.errors.InputError`
    before any work); :meth:`start` begins the reading thread.

    A live source (camera, device, URL) is only probed by :meth:`open` (frame size and
    rate) and closed again: the models compile for that size next, and compiling holds
    the interpreter, so no thread could read the source meanwhile and its frames would
    pile up and be processed late. :meth:`start` opens it again and reads it as fast as
    it delivers. A file is replayed from its first frame at ``fps`` in real time from the
    moment :meth:`start` is called.

    Parameters
    ----------
    spec : SourceSpec
    frames : LatestFrames
        Where the frames go.
    fps : float, optional
        Frame rate (frames/s): a file's replay rate (default: its own), a live source's
        nominal rate (default: what the camera states, 30 for URLs, whose stated rate
        is unreliable).
    color_order : {"bgr", "rgb"}
        Channel order of colour ``.npy`` inputs.
    timeout_s : float
        A live source that gives no frame for this long is reopened (also the open timeout
        of URLs), s.
    retry_for_s : float
        Stop reconnecting (the stream has ended) after trying this long without getting a
        frame, s; 0: never reconnect; ``inf``: forever.
    report : callable, optional
        ``report(kind, info)`` for events of the capture thread: ``"reconnect"`` (info:
        ``attempt``, ``reason``, ``wait_s``) and ``"reconnected"`` (``attempt``, ``width``,
        ``height``).
    """

    def __init__(self, spec: SourceSpec, frames: LatestFrames, fps: float | None = None, color_order: str = "bgr",
                 timeout_s: float = 5.0, retry_for_s: float = 30.0,
                 report: Callable[[str, dict], None] | None = None):
        self.spec = spec
        self.frames = frames
        self._fps_override = fps
        self.color_order = color_order
        self.timeout_s = float(timeout_s)
        self.retry_for_s = float(retry_for_s)
        self.report = report or (lambda kind, info: None)
        self.fps = float(fps) if fps else DEFAULT_FPS
        self.shape: tuple[int, int] | None = None
        self.first: Frame | None = None
        self.reconnects = 0
        self._cap: cv2.VideoCapture | None = None
        self._file_frames: Iterator[np.ndarray] | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._t0 = 0.0

    # -- opening --------------------------------------------------------------
    def open(self) -> Frame:
        """Open the source and read its first frame (not yet queued).

        Raises
        ------
        InputError
            The source cannot be opened or gives no frame (one line naming it).
        """
        if self.spec.live:
            cap = _open_cv(self.spec, self.timeout_s)
            if not cap.isOpened():
                cap.release()
                raise _cannot_open(self.spec)
            ok, image = cap.read()
            if not ok or image is None:
                cap.release()
                raise InputError(self.spec.text, "opened, but gave no frame")
            if self._fps_override is None and self.spec.kind != "url":
                self.fps = _sane_fps(cap.get(cv2.CAP_PROP_FPS) or 0.0) or DEFAULT_FPS
            cap.release()  # reopened by start()
        else:
            source = resolve_input(self.spec.target, fps=self._fps_override, color_order=self.color_order)
            self.fps = float(source.fps)
            self._file_frames = iter(source)
            try:
                image = next(self._file_frames)
            except StopIteration:
                raise InputError(self.spec.text, "holds no frames") from None
        now = time.perf_counter()
        self._t0 = now
        self.shape = tuple(image.shape[:2])  # type: ignore[assignment]
        self.first = Frame(0, image, now, 0.0, 0)
        return self.first

    # -- the reading thread -------------------------------------------------------
    def start(self) -> None:
        """Start reading on a background thread (a file: from its first frame; a live source: reopened)."""
        if self.first is None:
            raise RuntimeError("open() the capture first")
        target = self._read_live if self.spec.live else self._replay_file
        self._thread = threading.Thread(target=self._run, args=(target,), name="cdnf_ti-capture", daemon=True)
        self._thread.start()

    def stop(self, wait_s: float = 2.0) -> None:
        """Ask the reading thread to end and wait for it (at most ``wait_s`` seconds)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(wait_s)

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _run(self, target: Callable[[], str]) -> None:
        try:
            reason = target()
            self.frames.close(StreamEnded(reason))
        except BaseException as e:  # noqa: BLE001 - handed to the consumer
            self.frames.close(e)
        finally:
            if self._cap is not None:
                self._cap.release()
            close = getattr(self._file_frames, "close", None)
            if close is not None:
                try:
                    close()
                except Exception:  # noqa: BLE001 - a generator's clean-up cannot fail the stream
                    pass

    def _replay_file(self) -> str:
        """Queue the file's frames at ``fps`` in real time (frame k at start + k / fps)."""
        start = time.perf_counter()
        first = self.first
        assert first is not None
        self.frames.put(Frame(0, first.image, start, 0.0, 0))
        index = 0
        for image in self._file_frames or ():
            index += 1
            due = start + index / self.fps
            while not self._stop.is_set():
                wait = due - time.perf_counter()
                if wait <= 0:
                    break
                self._stop.wait(min(wait, 0.05))
            if self._stop.is_set():
                return "stopped"
            self.frames.put(Frame(index, image, time.perf_counter(), index / self.fps, 0))
        return "end of file"

    def _read_live(self) -> str:
        """Queue frames as the source delivers them; reopen it with backoff when it fails."""
        cap = self._cap = _open_cv(self.spec, self.timeout_s)
        if not cap.isOpened():
            cap.release()
            cap = self._cap = None
        index, session = -1, 0
        while not self._stop.is_set():
            ok, image, now = _read(cap) if cap is not None else (False, None, 0.0)
            if self._stop.is_set():
                return "stopped"
            if not (ok and image is not None):  # the stream dropped, or stalled (a read timed out): reopen it
                if cap is not None:
                    cap.release()
                    cap = self._cap = None
                if self.retry_for_s <= 0:
                    return "the stream stalled or dropped (reconnecting is off)"
                cap, image = self._reconnect()
                if cap is None:
                    if self._stop.is_set():
                        return "stopped"
                    return f"lost: no frame in {self.retry_for_s:g} s of reconnecting ({self.reconnects} attempts)"
                self._cap = cap
                session += index >= 0  # the first frame of a new connection starts a new session
                now = time.perf_counter()
            index += 1
            if index == 0:
                self._t0 = now
            self.shape = tuple(image.shape[:2])  # type: ignore[assignment]
            self.frames.put(Frame(index, image, now, now - self._t0, session))
        return "stopped"

    def _reconnect(self) -> tuple[cv2.VideoCapture | None, np.ndarray | None]:
        """Reopen the source with exponential backoff until it gives a frame, or ``retry_for_s`` passes.

        Returns the new capture and its first frame, or ``(None, None)``.
        """
        wait = BACKOFF_FIRST_S
        attempt = 0
        reason = "the stream stalled or dropped"
        give_up = time.perf_counter() + self.retry_for_s
        while not self._stop.is_set():
            if time.perf_counter() + wait > give_up:
                return None, None
            attempt += 1
            self.reconnects += 1
            self.report("reconnect", {"attempt": attempt, "reason": reason, "wait_s": round(wait, 3)})
            if self._stop.wait(wait):
                break
            cap = _open_cv(self.spec, self.timeout_s)
            if cap.isOpened():
                ok, image = cap.read()
                if ok and image is not None:
                    self.report("reconnected", {"attempt": attempt, "width": int(image.shape[1]),
                                                "height": int(image.shape[0])})
                    return cap, image
                reason = "reopened, but it gave no frame"
            else:
                reason = "cannot reopen"
            cap.release()
            wait = min(wait * 2.0, BACKOFF_MAX_S)
        return None, None


# -- capture in a child process ---------------------------------------------------------------------------
def _child_main(conn, spec: SourceSpec, queue_size: int, fps: float | None, color_order: str, timeout_s: float,
                retry_for_s: float, colour: bool = False) -> None:
    """The capture process: a :class:`Capture` whose frames are sent to the parent over ``conn``.

    Frames are sent grey (:func:`cdnf_ti.frames.to_grey`, what the models take), or with ``colour`` (a model
    takes colour frames) as :class:`~cdnf_ti.frames.ColourFrame` (made grey once, here).
    Messages to the parent: ``("opened", fps, first_frame)`` or ``("error", message)``; then
    ``("frame", frame, dropped_here, reconnects)``, ``("event", kind, info)``, and at last
    ``("end", reason, reconnects)`` or ``("error", message)``. From the parent: ``"start"``,
    then ``"stop"`` (or the pipe closing).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole process group: the parent stops us
    send_lock = threading.Lock()

    def send(message: tuple) -> None:
        with send_lock:
            conn.send(message)

    convert = ColourFrame.of if colour else to_grey
    frames = LatestFrames(queue_size)
    capture = Capture(spec, frames, fps=fps, color_order=color_order, timeout_s=timeout_s, retry_for_s=retry_for_s,
                      report=lambda kind, info: send(("event", kind, info)))
    try:
        try:
            opened = capture.open()  # queued again by the capture at start: converted there, as every frame
            first = replace(opened, image=convert(opened.image))
        except Exception as e:  # noqa: BLE001 - one line for the parent
            send(("error", str(e) if isinstance(e, UserError) else f"{spec.text}: {type(e).__name__}: {e}"))
            return
        send(("opened", capture.fps, first))
        if conn.recv() != "start":
            return
        capture.start()

        def listen() -> None:  # "stop", or the parent gone
            try:
                conn.recv()
            except (EOFError, OSError):
                pass
            capture.stop(0)
            frames.close(StreamEnded("stopped"))

        threading.Thread(target=listen, name="cdnf_ti-capture-listen", daemon=True).start()
        while True:
            try:
                frame = frames.get(timeout=0.5)
                if frame is not None:
                    frame.image = convert(frame.image)  # what the models take (grey: a third of the bytes to send)
            except StreamEnded as e:
                send(("end", str(e), capture.reconnects))
                return
            except Exception as e:  # noqa: BLE001 - a corrupt file: one line for the parent
                send(("error", str(e) if isinstance(e, UserError) else f"{spec.text}: {type(e).__name__}: {e}"))
                return
            if frame is not None:
                send(("frame", frame, frames.dropped, capture.reconnects))
    except (BrokenPipeError, EOFError, OSError):
        pass  # the parent went away
    finally:
        capture.stop(1.0)


class ProcessCapture:
    """A :class:`Capture` run in a child process; same interface.

    Frames are timestamped in the child, whose interpreter does nothing else: in the
    parent, compiled kernels hold the interpreter lock while they run, so a capture
    thread there could only note a frame's arrival once the running kernel returned, and
    the latencies would come out too short. Frames are converted to grey in the child
    (:func:`cdnf_ti.frames.to_grey`), or with ``colour`` kept in both forms
    (:class:`~cdnf_ti.frames.ColourFrame`, for a model that takes colour frames), and reach the parent
    through a pipe (counted in the latency); they go to ``frames``, where the frames the child had to
    drop while the pipe was busy are counted too.

    Parameters are those of :class:`Capture`, and ``colour``.
    """

    def __init__(self, spec: SourceSpec, frames: LatestFrames, fps: float | None = None, color_order: str = "bgr",
                 timeout_s: float = 5.0, retry_for_s: float = 30.0,
                 report: Callable[[str, dict], None] | None = None, colour: bool = False):
        self.spec, self.frames = spec, frames
        self._args = (spec, frames.maxsize, fps, color_order, float(timeout_s), float(retry_for_s), bool(colour))
        self.timeout_s = float(timeout_s)
        self.report = report or (lambda kind, info: None)
        self.fps = float(fps) if fps else DEFAULT_FPS
        self.first: Frame | None = None
        self.shape: tuple[int, int] | None = None
        self.reconnects = 0
        self._proc = None
        self._conn = None
        self._thread: threading.Thread | None = None
        self._child_dropped = 0

    def open(self) -> Frame:
        """Start the child, which opens the source and sends its first frame.

        Raises
        ------
        UserError
            The source cannot be opened (the child's one-line message).
        """
        ctx = multiprocessing.get_context("spawn")  # this process runs threads and a compiler: no fork
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_child_main, args=(child, *self._args), name="cdnf_ti-capture", daemon=True)
        self._proc.start()
        child.close()
        try:
            message = self._conn.recv()
        except (EOFError, OSError):
            self._shutdown()
            raise UserError(f"{self.spec.text}: the capture process ended before opening the source") from None
        if message[0] == "error":
            self._shutdown()
            raise UserError(message[1])
        _, self.fps, self.first = message
        self.shape = tuple(self.first.image.shape[:2])  # type: ignore[assignment]
        return self.first

    def start(self) -> None:
        """Let the child read on; a thread here hands its frames to ``frames``."""
        if self.first is None:
            raise RuntimeError("open() the capture first")
        self._conn.send("start")
        self._thread = threading.Thread(target=self._receive, name="cdnf_ti-capture-receive", daemon=True)
        self._thread.start()

    def _receive(self) -> None:
        try:
            while True:
                try:
                    message = self._conn.recv()
                except (EOFError, OSError):
                    self.frames.close(StreamEnded("the capture process ended"))
                    return
                kind = message[0]
                if kind == "frame":
                    _, frame, dropped, self.reconnects = message
                    self.frames.count_upstream_drops(dropped - self._child_dropped)
                    self._child_dropped = dropped
                    self.shape = tuple(frame.image.shape[:2])  # type: ignore[assignment]
                    self.frames.put(frame)
                elif kind == "event":
                    self.report(message[1], message[2])
                elif kind == "end":
                    self.reconnects = message[2]
                    self.frames.close(StreamEnded(message[1]))
                    return
                else:
                    self.frames.close(UserError(message[1]))
                    return
        except BaseException as e:  # noqa: BLE001 - handed to the consumer
            self.frames.close(e)

    def stop(self, wait_s: float = 2.0) -> None:
        """Ask the child to stop, and wait for it (at most ``wait_s`` seconds, then end it)."""
        try:
            if self._conn is not None:
                self._conn.send("stop")
        except (OSError, ValueError):
            pass
        if self._thread is not None:
            self._thread.join(wait_s)
        self._shutdown(wait_s)

    def _shutdown(self, wait_s: float = 2.0) -> None:
        if self._proc is not None:
            self._proc.join(wait_s)
            if self._proc.is_alive():
                self._proc.terminate()
                self._proc.join(1.0)
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    @property
    def alive(self) -> bool:
        return self._proc is not None and self._proc.is_alive()
