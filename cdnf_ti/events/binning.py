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

A corrupt timestamp is refused, not binned (:func:`checked`): an event more than
``max_gap_s`` (:data:`DEFAULT_MAX_GAP_S`, ``--max-gap-s``) after every event before
it (or after the start of bin 0, when given), or more than ``max_span_s``
(:data:`DEFAULT_MAX_SPAN_S`, ``--max-span-s``) after the recording's start, is an
:class:`~cdnf_ti.errors.InputError` naming the event, raised before its chunk is
binned. Bins are produced one at a time (empty ones too), so reading and binning
hold one chunk and a few count images, whatever the timestamps say.

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

from ..errors import InputError

#: Default bin: one frame interval at 30 frames/s, ms (exactly 1000 / 30, so bins stay on a 30 fps video's
#: frame times; ``--bin-ms 33.333`` drifts from them by 0.33 µs per bin).
DEFAULT_BIN_MS = 1000.0 / 30.0
#: Default contrast threshold C of a DVS pixel (log-intensity units; DVS346 and Prophesee sensors: 0.1-0.3).
DEFAULT_EVENT_THRESHOLD = 0.15
#: Default largest gap between an event and every event before it, s (``--max-gap-s``). A camera
#: that sees nothing still sends noise events every few ms; a recording paused for more than a
#: minute is far rarer than a corrupt timestamp (a flipped high bit is a jump of hours to millennia).
DEFAULT_MAX_GAP_S = 60.0
#: Default longest recording, s (``--max-span-s``): 24 h, about 2.6 million bins of 33 ms.
DEFAULT_MAX_SPAN_S = 86400.0


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


def checked(chunks: Iterable[np.ndarray], sensor_size: tuple[int, int], report: EventReport, path: str = "",
            t0: float | None = None, max_gap_s: float = DEFAULT_MAX_GAP_S,
            max_span_s: float = DEFAULT_MAX_SPAN_S) -> Iterator[np.ndarray]:
    """Pass ``chunks`` on without the events outside the sensor, recording every problem in ``report``
    and refusing corrupt timestamps (:func:`check_time_jumps`) before their chunk is passed on.

    Parameters
    ----------
    chunks : iterable of structured arrays (:data:`~cdnf_ti.events.types.EVENT_DTYPE`)
    sensor_size : (width, height)
    report : EventReport
        Updated in place.
    path : str
        The recording, for messages.
    t0 : float, optional
        Start of bin 0, µs (the first event may not be more than ``max_gap_s`` after it).
    max_gap_s, max_span_s : float
        The largest jump forward of the timestamps and the longest span from the start, s.

    Raises
    ------
    InputError
        A timestamp jumps forward more than ``max_gap_s``, or lies more than ``max_span_s`` after
        the start.
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
        origin = report.t_first if t0 is None else t0
        check_time_jumps(t, origin if latest is None else latest, origin, start, path, max_gap_s, max_span_s)
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


def check_time_jumps(t: np.ndarray, before: float, origin: float, start: int, path: str,
                     max_gap_s: float = DEFAULT_MAX_GAP_S, max_span_s: float = DEFAULT_MAX_SPAN_S) -> None:
    """Refuse a chunk's timestamps that jump forward too far (a corrupt timestamp).

    Parameters
    ----------
    t : ndarray, shape (n,), int64
        The chunk's timestamps, µs, in file order.
    before : float
        The latest timestamp before the chunk (or the start of bin 0), µs.
    origin : float
        The recording's start (the start of bin 0, else the first timestamp), µs.
    start : int
        Index of ``t[0]`` in the file (from 0), for the message.
    path : str
        The recording, for the message.
    max_gap_s, max_span_s : float
        The largest step of the running maximum of ``t`` and the longest ``max(t) - origin``, s.

    Raises
    ------
    InputError
        ``timestamp jumps from t1 to t2 us at event i`` (``t1`` the latest before event ``i``),
        or ``timestamp t2 us at event i is ... s after the start``.

    Notes
    -----
    Works on the running maximum of ``t`` (a timestamp going backwards is no jump), in float64
    so that the differences of any int64 timestamps are exact enough and never overflow. A chunk
    whose largest timestamp is within both limits of ``before`` and ``origin`` is passed at once.
    """
    top = float(t.max())
    if top - float(before) <= max_gap_s * 1e6 and top - float(origin) <= max_span_s * 1e6:
        return  # no step of the running maximum can be larger than its whole rise (the usual case: O(1) more)
    peak = np.maximum(np.maximum.accumulate(t).astype(np.float64), float(before))
    steps = np.diff(peak, prepend=float(before))
    i = int(np.argmax(steps))
    if steps[i] > max_gap_s * 1e6:
        was = peak[i - 1] if i else before
        raise InputError(path, f"timestamp jumps from {int(was)} to {int(t[i])} us at event {start + i} "
                               f"({steps[i] / 1e6:.6g} s; at most --max-gap-s {max_gap_s:g} s)")
    if peak[-1] - origin > max_span_s * 1e6:
        i = int(np.argmax(peak - origin > max_span_s * 1e6))
        raise InputError(path, f"timestamp {int(t[i])} us at event {start + i} is {(peak[i] - origin) / 1e6:.6g} s "
                               f"after the recording's start at {int(origin)} us (at most --max-span-s "
                               f"{max_span_s:g} s)")


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
    """Per-bin event counts, streamed, one bin at a time.

    Parameters
    ----------
    chunks : iterable of structured arrays
        Events inside the sensor (pass them through :func:`checked` first, which also refuses
        corrupt timestamps); an event earlier than an event before it is counted in the bin being
        filled.
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
    Per chunk: the running maximum of ``t`` (the timestamps themselves when in order) is cut
    into bins (:func:`_bin_parts`), and each bin's part counted by one ``np.bincount`` over
    ``p H W + y W + x``.
    Memory: a few int64 arrays of the chunk's length and three count images (``2 H W`` int64
    each: the bin being filled, one part's counts, the bin handed on); the empty bins between
    two events are made one at a time as they are taken, so a gap of any length allocates
    nothing more (it takes time: :func:`checked` bounds it).
    """
    if not bin_ms > 0:
        raise ValueError(f"bin length must be > 0 ms, got {bin_ms}")
    w, h = sensor_size
    plane = w * h
    bin_us = float(bin_ms) * 1000.0
    current, acc = -1, None  # the bin being filled (-1: none yet) and its counts
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
        flat = ev["y"].astype(np.int64)
        flat *= w
        flat += ev["x"]
        flat += ev["p"].astype(np.int64) * plane
        for kk, s, e in _bin_parts(t, t0, bin_us, max(current, 0)):
            if kk != current:
                if acc is not None:
                    yield acc.reshape(2, h, w)
                yield from _empty_bins(kk - current - 1, (2, h, w))
                current, acc = kk, None
            if e > s or acc is None:
                counts = np.bincount(flat[s:e], minlength=2 * plane)
                if acc is None:
                    acc = counts
                else:
                    acc += counts
    if acc is not None:
        yield acc.reshape(2, h, w)


def _bin_parts(t: np.ndarray, t0: float, bin_us: float, k_open: int) -> Iterator[tuple[int, int, int]]:
    """``(k, start, end)``: the events ``t[start:end]`` that fall in bin ``k``, bins in order.

    ``t`` (µs, non-decreasing) is cut at the bin edges with ``searchsorted`` when the chunk spans
    fewer bins than it has events (each bin is a part, empty ones too), else where its events' bin
    index changes (only bins with events; the caller makes the empty ones between). Events before
    bin ``k_open`` count in it. Memory: O(len(t)) whatever the span.
    """
    n = t.shape[0]
    k_first = max(int(np.floor((int(t[0]) - t0) / bin_us)), k_open)
    k_last = max(int(np.floor((int(t[-1]) - t0) / bin_us)), k_first)
    if k_last - k_first < n:
        cuts = np.searchsorted(t, t0 + np.arange(k_first + 1, k_last + 1) * bin_us, side="left").tolist()
        yield from zip(range(k_first, k_last + 1), [0] + cuts, cuts + [n])
        return
    k = np.floor((t - t0) / bin_us).astype(np.int64)
    np.maximum(k, k_open, out=k)
    starts = (np.flatnonzero(k[1:] != k[:-1]) + 1).tolist()
    yield from ((int(k[s]), s, e) for s, e in zip([0] + starts, starts + [n]))


def _empty_bins(n: int, shape: tuple[int, int, int]) -> Iterator[np.ndarray]:
    """``n`` zero count images, made one at a time as they are taken."""
    for _ in range(n):
        yield np.zeros(shape, dtype=np.int64)


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
