"""A small HTTP MJPEG server: streams frames at a fixed frame rate, for trying and testing ``live``.

``MJPEGServer`` serves ``multipart/x-mixed-replace`` JPEG frames (the format of IP cameras
and of ``mjpg-streamer``) from a thread of the calling process. It streams one shared
sequence: a connection that opens continues the sequence where the previous one left it,
as a camera's stream goes on while nobody watches. Faults can be injected: a connection
dropped after some frames, or a stall (the connection stays open and sends nothing).

From the command line, it streams a file input or a generated stimulus::

    python -m cdnf_ti.mjpeg_server stim:dark_looming --port 8080 --lead 5
    python -m cdnf_ti.run live http://127.0.0.1:8080/stream.mjpg --model cdnf
"""
from __future__ import annotations

import argparse
import http.server
import socketserver
import sys
import threading
import time
from typing import Iterable, Sequence

import cv2
import numpy as np

from .cli_common import ArgumentParser, positive_float
from .errors import UserError
from .inputs import resolve_input
from .video import to_uint8


def encode_jpeg(frame: np.ndarray, quality: int = 90) -> bytes:
    """A frame ((H, W) grey or (H, W, 3) BGR; uint8 or float in [0, 1]) as JPEG bytes."""
    ok, buf = cv2.imencode(".jpg", to_uint8(frame), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("OpenCV cannot encode this frame as JPEG")
    return buf.tobytes()


class _Server(socketserver.ThreadingMixIn, http.server.HTTPServer):
    daemon_threads = True
    allow_reuse_address = True


class MJPEGServer:
    """Serve ``frames`` as an MJPEG stream on ``http://HOST:PORT/stream.mjpg``.

    Parameters
    ----------
    frames : iterable of ndarray
        The stream's frames, encoded once up front (keep them few and small).
    fps : float
        Frames per second sent (frames/s).
    lead : ndarray, optional
        A frame repeated before ``frames`` until :attr:`go` is set (e.g. once the
        client says it is ready); without it ``frames`` start at once.
    drop_after : int, optional
        Close the connection once this many frames of the sequence have been sent (once).
    stall_after : int, optional
        Once this many frames of the sequence have been sent, the connection stops
        sending but stays open for ``stall_s`` seconds (once).
    stall_s : float
        How long a stalled connection stays open (s).
    host : str
        Interface to listen on (default: this machine only).
    port : int
        0: an ephemeral port (see :attr:`url`).
    quality : int
        JPEG quality (0..100).
    loop : bool
        Play ``frames`` again and again (the connection never ends).

    Attributes
    ----------
    go : threading.Event
        Set it to end the lead-in.
    sent : int
        Frames sent so far (lead-in included), over every connection.
    connections : int
        Connections served so far.
    finished : threading.Event
        Set when the last frame of the sequence has been sent.
    """

    def __init__(self, frames: Iterable[np.ndarray], fps: float = 30.0, lead: np.ndarray | None = None,
                 drop_after: int | None = None, stall_after: int | None = None, stall_s: float = 10.0,
                 host: str = "127.0.0.1", port: int = 0, quality: int = 90, loop: bool = False):
        self._jpegs: list[bytes] = [encode_jpeg(f, quality) for f in frames]
        self._lead = encode_jpeg(lead, quality) if lead is not None else None
        self.fps = float(fps)
        self.loop = bool(loop)
        self.drop_after = drop_after
        self.stall_after = stall_after
        self.stall_s = float(stall_s)
        self.go = threading.Event()
        if lead is None:
            self.go.set()
        self.finished = threading.Event()
        self.sent = 0
        self.connections = 0
        self._pos = 0
        self._faults: set[str] = set()
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._server = _Server((host, port), self._handler())
        self._thread = threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.05},
                                        name="cdnf_ti-mjpeg", daemon=True)

    @property
    def url(self) -> str:
        host, port = self._server.server_address[:2]
        return f"http://{host}:{port}/stream.mjpg"

    @property
    def n_frames(self) -> int:
        """Frames in the sequence (lead-in excluded)."""
        return len(self._jpegs)

    def start(self) -> "MJPEGServer":
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop serving and close every connection."""
        self._closing.set()
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(5)

    def __enter__(self) -> "MJPEGServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    def _next(self) -> tuple[bytes | None, int]:
        """The next frame to send and its position in the sequence (-1: lead-in); None at the end."""
        with self._lock:
            if not self.go.is_set():
                return self._lead, -1
            if self._pos >= len(self._jpegs):
                self.finished.set()
                if not self.loop:
                    return None, len(self._jpegs)
                self._pos = 0
            k = self._pos
            self._pos += 1
            return self._jpegs[k], k

    def _fault(self, name: str) -> bool:
        """True the first time a fault is asked for (each fault happens once)."""
        with self._lock:
            if name in self._faults:
                return False
            self._faults.add(name)
            return True

    def _handler(self):
        server = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def log_message(self, format, *args):  # noqa: A002 - silence the access log
                pass

            def do_GET(self):  # noqa: N802 - http.server's name
                with server._lock:
                    server.connections += 1
                self.send_response(200)
                self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=frame")
                self.send_header("Cache-Control", "no-cache")
                self.end_headers()
                start = time.perf_counter()
                n = 0
                while not server._closing.is_set():
                    jpeg, k = server._next()
                    if jpeg is None:
                        return
                    if k >= 0 and k == server.stall_after and server._fault("stall"):
                        with server._lock:
                            server._pos -= 1  # this frame was not sent: the next connection sends it
                        server._closing.wait(server.stall_s)
                        return
                    due = start + n / server.fps
                    wait = due - time.perf_counter()
                    if wait > 0:
                        time.sleep(wait)
                    try:
                        self.wfile.write(b"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n"
                                         % len(jpeg) + jpeg + b"\r\n")
                        self.wfile.flush()
                    except OSError:  # the client went away
                        return
                    with server._lock:
                        server.sent += 1
                    n += 1
                    if k >= 0 and k + 1 == server.drop_after and server._fault("drop"):
                        return  # the connection drops (the handler closes it)

        return Handler


def _parser() -> argparse.ArgumentParser:
    ap = ArgumentParser(prog="python -m cdnf_ti.mjpeg_server",
                        description="Stream a video file or a generated stimulus as HTTP MJPEG "
                                    "(http://HOST:PORT/stream.mjpg), e.g. to try 'python -m cdnf_ti.run live'.")
    ap.add_argument("input", metavar="INPUT", help="video file, image folder, .npy array or stim:NAME[?...]")
    ap.add_argument("--port", type=int, default=8080, help="TCP port (default: %(default)s; 0: any free one)")
    ap.add_argument("--host", default="127.0.0.1", help="interface to listen on (default: %(default)s)")
    ap.add_argument("--fps", type=positive_float, default=None, help="frames/s sent (default: the input's rate)")
    ap.add_argument("--lead", type=float, default=0.0,
                    help="seconds of the first frame, repeated, before the input plays (default: %(default)s)")
    ap.add_argument("--loop", action="store_true", help="play the input again and again (Ctrl-C ends)")
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: serve one input until it has been sent (or forever with ``--loop``)."""
    args = _parser().parse_args(argv)
    try:
        src = resolve_input(args.input, fps=args.fps)
        frames = list(src)
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    fps = args.fps or src.fps
    lead = [frames[0]] * int(round(args.lead * fps))
    try:
        with MJPEGServer(lead + frames, fps=fps, host=args.host, port=args.port, loop=args.loop) as server:
            print(f"serving {args.input} ({len(frames)} frames at {fps:g} fps) on {server.url}", file=sys.stderr)
            while args.loop or not server.finished.is_set():
                time.sleep(0.2)
            time.sleep(0.5)
        return 0
    except KeyboardInterrupt:
        return 130
    except OSError as e:
        print(f"error: {args.host}:{args.port}: {e.strerror or e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
