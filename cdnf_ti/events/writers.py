"""Write events: ``.npy`` (structured array) and ``.h5`` (DSEC layout), both read back by :mod:`.readers`.

Both writers take an iterable of chunks and stream them (memory bounded by one chunk), and
write atomically: the file appears complete or not at all.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterable

import numpy as np

from ..atomic import atomic_write
from ..errors import InputError, UserError
from .readers import _INSTALL
from .types import EVENT_DTYPE

#: Output extensions of :func:`write_events`.
WRITE_EXTENSIONS = (".npy", ".h5", ".hdf5")


def _as_chunks(events: np.ndarray | Iterable[np.ndarray]) -> Iterable[np.ndarray]:
    return [events] if isinstance(events, np.ndarray) else events


def write_npy(path: str | os.PathLike, events: np.ndarray | Iterable[np.ndarray]) -> int:
    """Save events as a structured ``.npy`` array (fields ``t`` µs int64, ``x``, ``y`` uint16, ``p`` uint8).

    Chunks are spooled to a temporary file (the header needs the count), then
    copied behind the header. Returns the number of events written.
    """
    n = 0
    with tempfile.TemporaryFile() as spool:
        for c in _as_chunks(events):
            c = np.ascontiguousarray(c, dtype=EVENT_DTYPE)
            spool.write(c.tobytes())
            n += c.shape[0]

        def write(tmp: str) -> None:
            with open(tmp, "wb") as f:
                np.lib.format.write_array_header_2_0(
                    f, {"descr": np.lib.format.dtype_to_descr(EVENT_DTYPE), "fortran_order": False, "shape": (n,)})
                spool.seek(0)
                shutil.copyfileobj(spool, f, 1 << 22)

        atomic_write(path, write)
    return n


def write_h5(path: str | os.PathLike, events: np.ndarray | Iterable[np.ndarray], sensor_size: tuple[int, int],
             t_offset: int = 0) -> int:
    """Save events in the DSEC layout; returns the number of events written.

    ``events/t`` (µs since ``t_offset``, int64), ``events/x``, ``events/y``
    (uint16), ``events/p`` (uint8, 1 = ON), ``t_offset`` (µs, the recording's
    start; 0: the emulator's clock starts at the video's first frame),
    ``ms_to_idx`` (``ms_to_idx[m]`` is the first event at or after ``m`` ms past
    ``t_offset``), and root attributes ``width``, ``height`` (DSEC's own files
    have none; cdnf_ti reads them when present). Gzip-compressed, so no plugin is
    needed to read it back. Events must come in time order (``ms_to_idx``).
    """
    try:
        import h5py
    except ImportError:
        raise UserError(f"{path}: writing HDF5 needs the h5py package ({_INSTALL})") from None
    count = [0]

    def write(tmp: str) -> None:
        with h5py.File(tmp, "w") as f:
            g = f.create_group("events")
            dtypes = {"t": np.int64, "x": np.uint16, "y": np.uint16, "p": np.uint8}
            sets = {k: g.create_dataset(k, shape=(0,), maxshape=(None,), dtype=d, chunks=(1 << 16,),
                                        compression="gzip", compression_opts=4) for k, d in dtypes.items()}
            ms_to_idx = [0]
            n = 0
            for c in _as_chunks(events):
                if not c.shape[0]:
                    continue
                t = c["t"] - t_offset
                for k, ds in sets.items():
                    ds.resize((n + c.shape[0],))
                    ds[n:] = t if k == "t" else c[k]
                # ms_to_idx entries for every ms boundary up to this chunk's last event
                top = max(int(t[-1]), 0) // 1000
                ms = np.arange(len(ms_to_idx), top + 1) * 1000
                ms_to_idx.extend((n + np.searchsorted(t, ms, side="left")).tolist())
                n += c.shape[0]
            ms_to_idx.append(n)  # the ms after the last event
            f.create_dataset("t_offset", data=np.int64(t_offset))
            f.create_dataset("ms_to_idx", data=np.asarray(ms_to_idx, dtype=np.uint64))
            f.attrs["width"], f.attrs["height"] = int(sensor_size[0]), int(sensor_size[1])
            count[0] = n

    atomic_write(path, write)
    return count[0]


def write_events(path: str | os.PathLike, events: np.ndarray | Iterable[np.ndarray],
                 sensor_size: tuple[int, int]) -> int:
    """Write events (an array or an iterable of chunks) to ``path``; the extension picks the format
    (:data:`WRITE_EXTENSIONS`). Returns the number of events written.

    A ``.npy`` carries no sensor size (read it back with ``--sensor-size``, or let it be inferred).
    """
    ext = Path(path).suffix.lower()
    if ext == ".npy":
        return write_npy(path, events)
    if ext in (".h5", ".hdf5"):
        return write_h5(path, events, sensor_size)
    raise InputError(path, f"unknown event output format {ext or '(no extension)'!r}; "
                           f"choose {', '.join(WRITE_EXTENSIONS)}")
