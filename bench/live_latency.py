"""Live-mode benchmark: ``python -m cdnf_ti.run live`` on a 30 fps MJPEG stream of a 600x600 stimulus.

Streams a basic stimulus over HTTP MJPEG from this process (127.0.0.1, an ephemeral port),
runs the live command on it in a child process, and reports what it printed: frames
sent, processed and dropped, the latency from capture to result (median, 95th
percentile), and the alert onsets. The stimulus starts once the command says it is
ready (its ``start`` line): until then the server repeats the stimulus' first frame.
The command is stopped with SIGTERM once the stream is over.

Usage::

    python -m cdnf_ti.bench.live_latency                       # dark_looming and dark_translating
    python -m cdnf_ti.bench.live_latency --stimulus dark_looming --size 600 --model cdnf --repeats 3
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from typing import Sequence

from cdnf_ti.mjpeg_server import MJPEGServer
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus


def load_average() -> str:
    """The machine's 1/5/15-minute load averages (``uptime``'s numbers)."""
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def measure(stimulus: str, size: int, model: str, fps: float = 30.0, hold_s: float = 0.5,
            extra: Sequence[str] = ()) -> dict:
    """One run of the live command on a stream of ``stimulus``; returns its numbers."""
    frames = list(basic_stimulus(stimulus, height=size, width=size, fps=fps).frames())
    frames += [frames[-1]] * int(round(hold_s * fps))
    with MJPEGServer(frames, fps=fps, lead=frames[0]) as server:
        cmd = [sys.executable, "-m", "cdnf_ti.run", "live", server.url, "--model", model, *extra]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        records = []
        load_at_start = None
        try:
            for line in proc.stdout:
                rec = json.loads(line)
                records.append(rec)
                if rec["event"] == "start":
                    load_at_start = load_average()
                    server.go.set()
                if server.finished.is_set() and rec["event"] == "frame" and proc.poll() is None:
                    time.sleep(1.0)  # the last frames in flight
                    proc.send_signal(signal.SIGTERM)
                    rest, err = proc.communicate(timeout=60)
                    records += [json.loads(x) for x in rest.splitlines()]
                    break
            else:
                err = proc.stderr.read()
        finally:
            if proc.poll() is None:
                proc.kill()
        sent = server.sent
    end = records[-1] if records and records[-1]["event"] == "end" else {}
    lines = [r for r in records if r["event"] == "frame"]
    lat = [r["latency_ms"] for r in lines]
    keys = {"frame", "t", "model", "output", "alert", "latency_ms", "dropped"}
    return {
        "stimulus": stimulus, "size": size, "model": model, "exit": proc.returncode,
        "sent": sent, "read": end.get("frames_read"), "processed": end.get("processed"),
        "dropped": end.get("dropped"),
        "coverage": (end.get("processed", 0) + end.get("dropped", 0)) / sent if sent else float("nan"),
        "latency_ms_median": statistics.median(lat) if lat else float("nan"),
        "latency_ms_p95": sorted(lat)[int(0.95 * (len(lat) - 1))] if lat else float("nan"),
        "alert_onsets": [r["frame"] for r in records if r["event"] == "alert"],
        "all_keys": all(keys <= set(r) for r in lines), "compile_s": end.get("compile_s"),
        "load_at_start": load_at_start, "load_at_end": load_average(),
        "stderr_tail": err.strip().splitlines()[-1:] if err else [],
    }


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m cdnf_ti.bench.live_latency", description=__doc__.split("\n\n")[0])
    ap.add_argument("--stimulus", action="append", choices=BASIC_STIMULI, default=None,
                    help="stimulus streamed (repeatable; default: dark_looming and dark_translating)")
    ap.add_argument("--size", type=int, default=600, help="frame side in px (default: %(default)s)")
    ap.add_argument("--model", default="cdnf", help="--model of the live command (default: %(default)s)")
    ap.add_argument("--repeats", type=int, default=1, help="runs per stimulus (default: %(default)s)")
    args = ap.parse_args(argv)
    for name in args.stimulus or ["dark_looming", "dark_translating"]:
        for _ in range(args.repeats):
            r = measure(name, args.size, args.model)
            print(json.dumps(r), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
