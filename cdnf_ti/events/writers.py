"""Write events: ``.npy`` (structured array) and ``.h5`` (DSEC layout), both read back by :mod:`.readers`."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..atomic import atomic_write
from ..errors import InputError, UserError
from .readers import _INSTALL
from .types import EVENT_DTYPE

#: Output extensions of :func:`write_events`.
WRITE_EXTENSIONS = (".npy", ".h5", ".hdf5")


def write_npy(path: str | os.PathLike, events: np.ndarray) -> None:
    """Save ``events`` as a structured ``.npy`` array (fields ``t`` µs int64, ``x``, ``y`` uint16, ``p`` uint8)."""
    ev = np.asarray(events, dtype=EVENT_DTYPE)

    def write(tmp: str) -> None:
        with open(tmp, "wb") as f:
            np.save(f, ev, allow_pickle=False)

    atomic_write(path, write)


def write_h5(path: str | os.PathLike, events: np.ndarray, sensor_size: tuple[int, int], t_offset: int = 0) -> None:
    """Save ``events`` in the DSEC layout.

    ``events/t`` (µs since ``t_offset``, int64), ``events/x``, ``events/y``
    (uint16), ``events/p`` (uint8, 1 = ON), ``t_offset`` (µs, the recording's
    start; 0: the emulator's clock starts at the video's first frame),
    ``ms_to_idx`` (``ms_to_idx[m]`` is the first event at or after ``m`` ms past
    ``t_offset``), and root attributes ``width``, ``height`` (DSEC's
    own files have none; cdnf_ti reads them when present). Gzip-compressed, so
    no plugin is needed to read it back.
    """
    try:
        import h5py
    except ImportError:
        raise UserError(f"{path}: writing HDF5 needs the h5py package ({_INSTALL})") from None
    ev = np.asarray(events, dtype=EVENT_DTYPE)
    t = ev["t"] - t_offset
    ms = np.arange(0, (max(int(t.max()), 0) // 1000 + 2) if t.size else 1) * 1000

    def write(tmp: str) -> None:
        with h5py.File(tmp, "w") as f:
            g = f.create_group("events")
            opts = {"compression": "gzip", "compression_opts": 4} if ev.size else {}
            g.create_dataset("t", data=t.astype(np.int64), **opts)
            g.create_dataset("x", data=ev["x"], **opts)
            g.create_dataset("y", data=ev["y"], **opts)
            g.create_dataset("p", data=ev["p"], **opts)
            f.create_dataset("t_offset", data=np.int64(t_offset))
            f.create_dataset("ms_to_idx", data=np.searchsorted(t, ms, side="left").astype(np.uint64))
            f.attrs["width"], f.attrs["height"] = int(sensor_size[0]), int(sensor_size[1])

    atomic_write(path, write)


def write_events(path: str | os.PathLike, events: np.ndarray, sensor_size: tuple[int, int]) -> None:
    """Write ``events`` to ``path``; the extension picks the format (:data:`WRITE_EXTENSIONS`).

    A ``.npy`` carries no sensor size (read it back with ``--sensor-size``, or let it be inferred).
    """
    ext = Path(path).suffix.lower()
    if ext == ".npy":
        write_npy(path, events)
    elif ext in (".h5", ".hdf5"):
        write_h5(path, events, sensor_size)
    else:
        raise InputError(path, f"unknown event output format {ext or '(no extension)'!r}; "
                               f"choose {', '.join(WRITE_EXTENSIONS)}")
