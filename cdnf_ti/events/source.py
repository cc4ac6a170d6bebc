"""An event recording as a stream of binned ON/OFF inputs: what a model run reads from an event file."""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from ..errors import InputError
from ..limits import MAX_SIDE
from .binning import (
    DEFAULT_BIN_MS,
    DEFAULT_EVENT_THRESHOLD,
    DEFAULT_MAX_GAP_S,
    DEFAULT_MAX_SPAN_S,
    EventReport,
    bin_events,
    checked,
    contrast_input,
)
from .readers import EventFile, open_events


@dataclass
class EventSource:
    """Binned events of one recording.

    Attributes
    ----------
    events : EventFile
    sensor_size : (width, height)
        From ``--sensor-size``, else the header, else inferred (``inferred``).
    bin_ms : float
        Bin length, ms; ``fps = 1000 / bin_ms`` bins per second.
    t0 : float or None
        Start of bin 0, µs: the recording's start where its layout defines one
        (:attr:`~cdnf_ti.events.readers.EventFile.t_start`), else ``None``: the start of
        the bin holding the first event.
    report : EventReport
        Filled while :meth:`counts` runs.
    max_gap_s, max_span_s : float
        Corrupt-timestamp limits (:func:`~cdnf_ti.events.binning.checked`; ``--max-gap-s``,
        ``--max-span-s``).
    """

    events: EventFile
    sensor_size: tuple[int, int]
    bin_ms: float = DEFAULT_BIN_MS
    t0: float | None = None
    inferred: bool = False
    report: EventReport = field(default_factory=EventReport)
    max_gap_s: float = DEFAULT_MAX_GAP_S
    max_span_s: float = DEFAULT_MAX_SPAN_S

    @property
    def path(self) -> str:
        return self.events.path

    @property
    def name(self) -> str:
        """The recording's name (file stem), as a video's."""
        return Path(self.path).stem

    @property
    def n_frames(self) -> None:
        """Unknown until the recording is read (the bins stream); ``None``, as for a live source."""
        return None

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the count images."""
        return self.sensor_size[1], self.sensor_size[0]

    @property
    def fps(self) -> float:
        return 1000.0 / self.bin_ms

    def counts(self) -> Iterator[np.ndarray]:
        """(2, H, W) OFF/ON counts per bin (:func:`~cdnf_ti.events.binning.bin_events`); refills :attr:`report`.

        Raises
        ------
        InputError
            A corrupt timestamp (:func:`~cdnf_ti.events.binning.checked`), or, once the file is
            read, a recording that holds no events.
        """
        self.report = EventReport()
        events = checked(self.events.chunks(), self.sensor_size, self.report, self.path, self.t0, self.max_gap_s,
                         self.max_span_s)
        yield from bin_events(events, self.sensor_size, self.bin_ms, self.t0)
        if self.report.n_events == 0:
            raise InputError(self.path, "holds no events")

    def contrast(self, event_threshold: float = DEFAULT_EVENT_THRESHOLD) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """``(p_on, p_off)`` per bin (:func:`~cdnf_ti.events.binning.contrast_input`)."""
        for c in self.counts():
            yield contrast_input(c, event_threshold)


def infer_sensor_size(events: EventFile) -> tuple[int, int]:
    """The smallest sensor holding every event: ``(max x + 1, max y + 1)`` (one pass over the file)."""
    mx = my = -1
    for ev in events.chunks():
        if ev.shape[0]:
            mx, my = max(mx, int(ev["x"].max())), max(my, int(ev["y"].max()))
    if mx < 0:
        raise InputError(events.path, "holds no events")
    return max(mx + 1, 2), max(my + 1, 2)


def check_header_size(path: str, size: tuple[int, int]) -> None:
    """Refuse a sensor size stated by a file's header that no sensor has (each side 1..MAX_SIDE px).

    Raises
    ------
    InputError
        Naming the header as the fault, and how to override it.
    """
    w, h = size
    if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE):
        raise InputError(path, f"the header states a sensor size of {w}x{h}, which no sensor has (each side "
                               f"1 to {MAX_SIDE} px): a corrupt header? give --sensor-size WxH to override it")


def open_event_source(path: str | os.PathLike, sensor_size: tuple[int, int] | None = None,
                      bin_ms: float = DEFAULT_BIN_MS, t0: float | None = None, quiet: bool = False,
                      max_gap_s: float = DEFAULT_MAX_GAP_S, max_span_s: float = DEFAULT_MAX_SPAN_S) -> EventSource:
    """Open an event recording for binning.

    Parameters
    ----------
    sensor_size : (width, height), optional
        Overrides the file's header. When neither gives one it is inferred from
        the events and a ``note:`` line says so (unless ``quiet``).
    bin_ms : float
        Bin length, ms.
    t0 : float, optional
        Start of bin 0, µs (default: the file's :attr:`~cdnf_ti.events.readers.EventFile.t_start`).
    max_gap_s, max_span_s : float
        Corrupt-timestamp limits, s (:func:`~cdnf_ti.events.binning.checked`).

    Raises
    ------
    InputError
        Bad file (:func:`~cdnf_ti.events.readers.open_events`), a header's impossible sensor size
        (:func:`check_header_size`), a bad bin length.
    """
    if not (np.isfinite(bin_ms) and bin_ms > 0):
        raise InputError(path, f"bin length must be a finite number of ms > 0, got {bin_ms}")
    ef = open_events(path)
    inferred = False
    if sensor_size is None and ef.sensor_size is not None:
        check_header_size(ef.path, ef.sensor_size)
    size = sensor_size or ef.sensor_size
    if size is None:
        size = infer_sensor_size(ef)
        inferred = True
        if not quiet:
            print(f"note: {path}: the file states no sensor size; using {size[0]}x{size[1]}, the smallest that "
                  "holds every event (give --sensor-size WxH to set it)", file=sys.stderr)
    return EventSource(ef, (int(size[0]), int(size[1])), float(bin_ms), ef.t_start if t0 is None else t0, inferred,
                       max_gap_s=float(max_gap_s), max_span_s=float(max_span_s))
