"""Event cameras (DVS) as input: readers, binning into ON/OFF count images, the counts-to-contrast
mapping, and a video-to-events emulator.

* :mod:`.readers` - ``open_events(path)``: AEDAT4, Prophesee RAW (EVT 2.0/3.0) and DAT, DSEC HDF5,
  ``.npy``/``.npz`` structured arrays; streamed in chunks of :data:`.types.EVENT_DTYPE`.
* :mod:`.binning` - ``bin_events`` (per-bin OFF/ON counts), ``checked`` (events outside the sensor and
  timestamps going backwards, reported), ``contrast_input`` (counts -> ``P_on``, ``P_off``).
* :mod:`.source` - ``open_event_source(path, sensor_size, bin_ms)``: one recording as binned input.
* :mod:`.emulator` - ``emulate(frames, fps, EmulatorParams(...), seed)``.
* :mod:`.writers` - ``.npy`` and DSEC ``.h5``.
* :mod:`.cli` - ``python -m cdnf_ti.run events``.
"""
from __future__ import annotations

from .binning import DEFAULT_BIN_MS, DEFAULT_EVENT_THRESHOLD, EventReport, bin_events, checked, contrast_input
from .emulator import EmulatorParams, emulate
from .readers import EVENT_EXTENSIONS, EventFile, is_event_file, open_events, parse_sensor_size
from .source import EventSource, open_event_source
from .types import EVENT_DTYPE
from .writers import write_events

__all__ = ["DEFAULT_BIN_MS", "DEFAULT_EVENT_THRESHOLD", "EVENT_DTYPE", "EVENT_EXTENSIONS", "EmulatorParams",
           "EventFile", "EventReport", "EventSource", "bin_events", "checked", "contrast_input", "emulate",
           "is_event_file", "open_event_source", "open_events", "parse_sensor_size", "write_events"]
