"""Events -> per-bin ON and OFF count images, and counts -> the models' ON/OFF contrast input.

Binning. Bins are ``b = bin_ms`` long on the recording's clock: bin ``k`` holds
the events with ``t0 + k b <= t < t0 + (k + 1) b``, where ``t0`` (unless given)
is the start of the bin that holds the first event, ``floor(t_first / b) b``, so
the bins of an emulated video start at its frame times. Every bin up to the last
event's is produced, empty ones as zeros. Counting is one
``np.bincount`` per bin over ``p H W + y W + x``, streamed chunk by chunk.

Problems are reported, not silently dropped (:class:`EventReport`):

* an event outside the sensor (``x >= W`` or ``y >= H``) cannot be placed in a
  count image: it is left out and counted;
* an event whose timestamp is earlier than an earlier event's is counted and
  placed in the bin being filled (never in a bin already handed on).

Mapping (see :func:`contrast_input` and docs/MODELS.md, "Event cameras"):
``n`` ON events in a bin at a pixel mean its log intensity rose by about ``n C``
(``C`` the sensor's contrast threshold); the models' ON input there is
``P_on = min(1, C n_on)``, their OFF input ``P_off = min(1, C n_off)``, on the
[0, 1] scale of the luminance differences ``P = L(t) - L(t-1)`` they take from
frames.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Iterator

import numpy as np

#: Default bin: one frame interval at 30 frames/s, ms (exactly 1000 / 30, so bins stay on a 30 fps video's
#: frame times; ``--bin-ms 33.333`` drifts from them by 0.33 µs per bin).
DEFAULT_BIN_MS = 1000.0 / 30.0
#: Default contrast threshold C of a DVS pixel (log-intensity units; DVS346 and Prophesee sensors: 0.1-0.3).
DEFAULT_EVENT_THRESHOLD = 0.15


@dataclass
class EventReport:
    """What a pass over a recording found: counts, time span, and problems.

    Attributes
    ----------
    n_events : int
        Events read.
    n_on : int
        ON events among them.
    n_outside : int
        Events outside the sensor (left out of the count images).
    first_outside : (index, x, y) or None
        The first such event (index in file order, from 0).
    n_backwards : int
        Events whose timestamp is earlier than the latest before them.
    first_backwards : (index, t, latest t) or None
    t_first, t_last : int or None
        First timestamp, and the latest timestamp seen (µs).
    """

    n_events: int = 0
    n_on: int = 0
    n_outside: int = 0
    first_outside: tuple[int, int, int] | None = None
    n_backwards: int = 0
    first_backwards: tuple[int, int, int] | None = None
    t_first: int | None = None
    t_last: int | None = None
    sensor_size: tuple[int, int] | None = field(default=None)

    def problems(self) -> list[str]:
        """One sentence per kind of problem (empty when the recording is clean)."""
        out = []
        if self.n_outside:
            i, x, y = self.first_outside
            w, h = self.sensor_size or (0, 0)
            out.append(f"{self.n_outside} event(s) outside the {w}x{h} sensor were left out (first: event {i} "
                       f"at x={x}, y={y}; give --sensor-size if the header is wrong)")
        if self.n_backwards:
            i, t, latest = self.first_backwards
            out.append(f"{self.n_backwards} event(s) have a timestamp earlier than an event before them, binned "
                       f"with the bin being filled (first: event {i} at t={t} us after t={latest} us)")
        return out


def checked(chunks: Iterable[np.ndarray], sensor_size: tuple[int, int], report: EventReport) -> Iterator[np.ndarray]:
    """Pass ``chunks`` on without the events outside the sensor, recording every problem in ``report``.

    Parameters
    ----------
    chunks : iterable of structured arrays (:data:`~cdnf_ti.events.types.EVENT_DTYPE`)
    sensor_size : (width, height)
    report : EventReport
        Updated in place.
    """
    w, h = sensor_size
    report.sensor_size = (w, h)
    latest = None
    for ev in chunks:
        n = ev.shape[0]
        if n == 0:
            continue
        start = report.n_events
        t = np.ascontiguousarray(ev["t"])
        if report.t_first is None:
            report.t_first = int(t[0])
        if (latest is not None and t[0] < latest) or not (t[1:] >= t[:-1]).all():
            _backwards(t, latest, start, report)
        latest = int(t[-1]) if latest is None else max(latest, int(t.max()))
        report.t_last = latest
        report.n_events += n
        report.n_on += int(np.count_nonzero(ev["p"]))
        x, y = ev["x"], ev["y"]
        if int(x.max()) >= w or int(y.max()) >= h:
            inside = (x < w) & (y < h)
            i = int(np.argmin(inside))
            if report.first_outside is None:
                report.first_outside = (start + i, int(x[i]), int(y[i]))
            report.n_outside += int(n - np.count_nonzero(inside))
            ev = ev[inside]
        yield ev


def _backwards(t: np.ndarray, latest: int | None, start: int, report: EventReport) -> None:
    """Count the events of ``t`` earlier than an event before them (``latest``: the chunks before)."""
    prev = np.empty_like(t)
    prev[0] = t[0] if latest is None else latest
    np.maximum.accumulate(t[:-1], out=prev[1:])
    if latest is not None:
        np.maximum(prev, latest, out=prev)
    back = t < prev
    if back.any():
        i = int(np.argmax(back))
        if report.first_backwards is None:
            report.first_backwards = (start + i, int(t[i]), int(prev[i]))
        report.n_backwards += int(back.sum())


def bin_events(chunks: Iterable[np.ndarray], sensor_size: tuple[int, int], bin_ms: float = DEFAULT_BIN_MS,
               t0: float | None = None) -> Iterator[np.ndarray]:
    """Per-bin event counts, streamed.

    Parameters
    ----------
    chunks : iterable of structured arrays
        Events inside the sensor (pass them through :func:`checked` first); an
        event earlier than an event before it is counted in the bin being filled.
    sensor_size : (width, height)
    bin_ms : float
        Bin length, ms (> 0).
    t0 : float, optional
        Start of bin 0, µs; the bins from there to the first event are produced
        (empty). Default: ``floor(t_first / b) b``.

    Yields
    ------
    ndarray, shape (2, H, W), int64
        ``[0]`` the OFF counts, ``[1]`` the ON counts of one bin, bins in order.

    Notes
    -----
    Per chunk: the running maximum of ``t`` (the timestamps themselves when in
    order) is cut at the bin edges with ``searchsorted``, and each bin's part is
    counted by one ``np.bincount`` over ``p H W + y W + x``.
    """
    if not bin_ms > 0:
        raise ValueError(f"bin length must be > 0 ms, got {bin_ms}")
    w, h = sensor_size
    plane = w * h
    bin_us = float(bin_ms) * 1000.0
    # the bin being filled and its counts: from bin 0 when t0 is given, else from the first event's bin
    current, acc = (0, np.zeros(2 * plane, dtype=np.int64)) if t0 is not None else (-1, None)
    latest = None
    for ev in chunks:
        n = ev.shape[0]
        if n == 0:
            continue
        t = np.ascontiguousarray(ev["t"])
        if t0 is None:
            t0 = np.floor(int(t[0]) / bin_us) * bin_us
        if (latest is not None and t[0] < latest) or not (t[1:] >= t[:-1]).all():
            t = np.maximum.accumulate(t)
            if latest is not None:
                np.maximum(t, latest, out=t)
        latest = int(t[-1])
        k_first = max(int(np.floor((int(t[0]) - t0) / bin_us)), current, 0)
        k_last = max(int(np.floor((latest - t0) / bin_us)), k_first)
        cuts = np.searchsorted(t, t0 + np.arange(k_first + 1, k_last + 1) * bin_us, side="left").tolist()
        flat = ev["y"].astype(np.int64)
        flat *= w
        flat += ev["x"]
        flat += ev["p"].astype(np.int64) * plane
        for k, s, e in zip(range(k_first, k_last + 1), [0] + cuts, cuts + [n]):
            if k != current:
                if acc is not None:
                    yield acc.reshape(2, h, w)
                    for _ in range(current + 1, k):
                        yield np.zeros((2, h, w), dtype=np.int64)
                current, acc = k, None
            if e > s or acc is None:
                counts = np.bincount(flat[s:e], minlength=2 * plane)
                acc = counts if acc is None else acc + counts
    if acc is not None:
        yield acc.reshape(2, h, w)


def contrast_input(counts: np.ndarray, event_threshold: float = DEFAULT_EVENT_THRESHOLD) -> tuple[np.ndarray,
                                                                                                   np.ndarray]:
    """One bin's counts -> the models' ON and OFF contrast input.

    Parameters
    ----------
    counts : ndarray, shape (2, H, W)
        OFF and ON event counts (:func:`bin_events`).
    event_threshold : float
        ``C``, the sensor's log-contrast threshold (> 0).

    Returns
    -------
    p_on, p_off : ndarray, shape (H, W), float64 in [0, 1]
        ``min(1, C n_on)`` and ``min(1, C n_off)``: the estimated log-intensity
        rise and fall in the bin, on the scale of the frame-based luminance
        difference (docs/MODELS.md, "Event cameras"). The LGMD family takes grey
        levels: ``255 p_on`` and ``255 p_off``.
    """
    if not event_threshold > 0:
        raise ValueError(f"event threshold must be > 0, got {event_threshold}")
    c = float(event_threshold)
    return np.minimum(counts[1] * c, 1.0), np.minimum(counts[0] * c, 1.0)
