"""Binning throughput: events per second of :func:`cdnf_ti.events.bin_events` (with the sensor checks) on one core.

Usage::

    python -m cdnf_ti.bench.events_binning [--events 20000000] [--sensor 640x480] [--rate 50] [--repeats 5]

Generates a time-sorted recording (``--rate`` million events per second of
recording, uniform over a ``--sensor`` sensor, half ON), then times
``checked`` + ``bin_events`` in 33.333 ms bins, streamed in chunks of
:data:`cdnf_ti.events.readers.CHUNK_EVENTS` as the readers give them, and prints
the median and best over the repeats, of wall time and of the process's CPU time
(on a shared machine the wall time counts other work too). The target (issue 31) is at least 20
million events/s on one core. Generation is not timed; NumPy runs these
operations on one thread.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from cdnf_ti.events import EventReport, bin_events, checked, parse_sensor_size
from cdnf_ti.events.readers import CHUNK_EVENTS
from cdnf_ti.events.types import EVENT_DTYPE


def make_events(n: int, sensor: tuple[int, int], rate_meps: float, seed: int = 0) -> np.ndarray:
    """``n`` events, uniform over the sensor, ``rate_meps`` million per second of recording, time-sorted."""
    rng = np.random.default_rng(seed)
    ev = np.empty(n, dtype=EVENT_DTYPE)
    ev["t"] = np.sort(rng.integers(0, max(1, int(n / rate_meps)), n))
    ev["x"] = rng.integers(0, sensor[0], n)
    ev["y"] = rng.integers(0, sensor[1], n)
    ev["p"] = rng.integers(0, 2, n)
    return ev


def time_binning(ev: np.ndarray, sensor: tuple[int, int], bin_ms: float = 33.333) -> tuple[float, float, int]:
    """Wall and CPU seconds to bin ``ev`` (streamed in reader-sized chunks), and the number of bins."""
    chunks = [ev[i:i + CHUNK_EVENTS] for i in range(0, ev.size, CHUNK_EVENTS)]
    t, c = time.perf_counter(), time.process_time()
    n_bins = sum(1 for _ in bin_events(checked(chunks, sensor, EventReport()), sensor, bin_ms))
    return time.perf_counter() - t, time.process_time() - c, n_bins


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--events", type=int, default=20_000_000)
    ap.add_argument("--sensor", type=parse_sensor_size, default=(640, 480))
    ap.add_argument("--rate", type=float, default=50.0, help="million events per second of recording")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    ev = make_events(args.events, args.sensor, args.rate)
    times, cpu = [], []
    for _ in range(args.repeats):
        s, c, n_bins = time_binning(ev, args.sensor)
        times.append(s)
        cpu.append(c)
    w, h = args.sensor
    print(f"binning {args.events:,} events, {w}x{h}, {args.rate:g} Mev/s of recording, {n_bins} bins of 33.333 ms: "
          f"median {args.events / statistics.median(times) / 1e6:.1f} M events/s, "
          f"best {args.events / min(times) / 1e6:.1f} M events/s; per CPU second (what a shared machine's load "
          f"does not count): median {args.events / statistics.median(cpu) / 1e6:.1f} M events/s "
          f"({args.repeats} repeats)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
