"""Event recordings: recognise a file's format and stream its events in chunks.

Formats (recognised by content first, then by extension):

=================  ===========================================================================
``.aedat4``        AEDAT 4 (iniVation DV): the first event stream, read with the ``aedat``
                   package (MIT; ``pip install 'cdnf_ti[events]'``); sensor size from the header
``.raw``           Prophesee RAW, EVT 2.0 or EVT 3.0 (:mod:`cdnf_ti.events.prophesee`); sensor
                   size from the header (``geometry``, ``format``, or a known ``plugin_name``)
``.dat``           Prophesee DAT (CD events); sensor size from the header's ``width``/``height``
``.h5``, ``.hdf5`` the DSEC layout: ``events/{x,y,t,p}``, ``t_offset`` (µs, added to ``t``),
                   ``ms_to_idx`` (not needed to read); ``h5py`` and, for DSEC's Blosc-compressed
                   files, ``hdf5plugin``; sensor size from root attributes ``width``/``height``
                   when present
``.npy``           a structured array with fields ``t`` (µs), ``x``, ``y``, ``p`` (read memory-mapped);
                   ``t`` is in ms when a ``sim_data.npz`` with ``t_end`` and ``dt`` sits beside it
                   (the layout of Schubert et al.'s looming data sets, ``p`` 0 or 1)
``.npz``           the same fields as four arrays ``t``, ``x``, ``y``, ``p``, or one structured
                   array (an ``.npz`` is read whole: zip members cannot be memory-mapped)
=================  ===========================================================================

Polarity: ``p > 0`` (1, True) is ON, anything else (0, False, -1) is OFF.
When neither the file nor ``sensor_size`` gives the sensor size, it is the
smallest that holds every event (one extra pass over the file; a note says so).
"""
from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from ..errors import InputError
from . import prophesee
from .types import EVENT_DTYPE

#: Extensions read as event recordings.
EVENT_EXTENSIONS = (".aedat4", ".raw", ".dat", ".h5", ".hdf5", ".npy", ".npz")
#: Events per chunk for the formats that can choose (memory-mapped arrays, HDF5).
CHUNK_EVENTS = 1 << 20
_FIELDS = ("t", "x", "y", "p")
_INSTALL = "pip install 'cdnf_ti[events]'"


@dataclass
class EventFile:
    """An opened event recording.

    Attributes
    ----------
    path : str
    format : str
        ``aedat4``, ``evt2``, ``evt3``, ``dat``, ``hdf5``, ``npy`` or ``npz``.
    sensor_size : (width, height) or None
        From the file's header; ``None`` when it states none.
    n_events : int or None
        When known without reading the events.
    t_start : int or None
        The recording's start on its clock, µs, where the layout defines one: 0 for
        ``.npy``/``.npz`` (timestamps count from the recording's start, as the emulator
        writes them), ``t_offset`` for DSEC HDF5; ``None`` for camera clocks (AEDAT4, RAW, DAT).
    """

    path: str
    format: str
    sensor_size: tuple[int, int] | None
    n_events: int | None
    _chunks: Callable[[], Iterator[np.ndarray]]
    t_start: int | None = None

    def chunks(self) -> Iterator[np.ndarray]:
        """The events in file order, as structured chunks of :data:`~cdnf_ti.events.types.EVENT_DTYPE`."""
        return self._chunks()


def parse_sensor_size(text: str) -> tuple[int, int]:
    """``"640x480"`` -> ``(640, 480)`` (width, height in pixels; each 2..65536).

    Raises
    ------
    ValueError
        Not ``WxH`` with two whole numbers in range.
    """
    w, sep, h = str(text).lower().partition("x")
    try:
        size = (int(w), int(h)) if sep else None
    except ValueError:
        size = None
    if size is None or not all(2 <= v <= 65536 for v in size):
        raise ValueError(f"sensor size must be WIDTHxHEIGHT with whole numbers from 2 to 65536, got {text!r}")
    return size


def is_event_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is an event recording: a ``.npy`` only when it is a structured array with
    fields ``t``, ``x``, ``y``, ``p`` (a frame array is not), a ``.raw``/``.dat`` only with a
    Prophesee ``% `` header (a VCD ``.dat`` is a video)."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in EVENT_EXTENSIONS or not p.is_file():
        return False
    if ext in (".raw", ".dat"):
        with open(p, "rb") as f:
            return f.read(2) == b"% "
    if ext == ".npy":
        try:
            dtype = np.load(p, mmap_mode="r", allow_pickle=False).dtype
        except Exception:  # noqa: BLE001 - not a readable .npy array: not an event file
            return False
        return dtype.names is not None and all(k in dtype.names for k in _FIELDS)
    return True


def _sniff(path: str) -> str:
    with open(path, "rb") as f:
        head = f.read(16)
    ext = Path(path).suffix.lower()
    if head.startswith(b"#!AER-DAT4"):
        return "aedat4"
    if head.startswith(b"#!AER-DAT"):
        raise InputError(path, f"AEDAT version {head[9:12].decode('latin-1')!r} is not supported (AEDAT 4 is)")
    if head.startswith(b"\x89HDF\r\n\x1a\n"):
        return "hdf5"
    if head.startswith(b"\x93NUMPY"):
        return "npy"
    if head.startswith(b"PK") and ext == ".npz":
        return "npz"
    if head.startswith(b"% ") or ext in (".raw", ".dat"):
        return "dat" if ext == ".dat" else "raw"
    return {".aedat4": "aedat4", ".h5": "hdf5", ".hdf5": "hdf5", ".npy": "npy", ".npz": "npz"}.get(ext, "unknown")


def open_events(path: str | os.PathLike) -> EventFile:
    """Open an event recording (see the module docstring for the formats).

    Raises
    ------
    InputError
        Missing, empty, unrecognised or malformed file, or a missing optional
        package; one line naming the file.
    """
    path = str(path)
    p = Path(path)
    if not p.exists():
        raise InputError(path, "no such file")
    if p.is_dir():
        raise InputError(path, "is a folder, not an event recording")
    if p.stat().st_size == 0:
        raise InputError(path, "file is empty")
    kind = _sniff(path)
    opener = {"aedat4": _open_aedat4, "raw": _open_raw, "dat": _open_dat, "hdf5": _open_hdf5,
              "npy": _open_npy, "npz": _open_npz}.get(kind)
    if opener is None:
        raise InputError(path, f"not a recognised event recording ({', '.join(EVENT_EXTENSIONS)})")
    return opener(path)


def to_events(t, x, y, p, path: str = "", start: int = 0) -> np.ndarray:
    """Columns -> a structured chunk (``t`` rounded to whole µs, ``p > 0`` -> 1).

    Parameters
    ----------
    t, x, y, p : array-like, shape (n,)
        Timestamps (µs, integer or float), pixel column and row, polarity.
    path : str
        The recording, for messages.
    start : int
        Index of the chunk's first event in the file (from 0), for messages.

    Raises
    ------
    InputError
        A timestamp that is not a finite number of µs within int64, or a pixel coordinate outside
        0..65535 (naming the first such event).
    """
    t = np.asarray(t)
    out = np.empty(len(t), dtype=EVENT_DTYPE)
    if t.dtype.kind == "f":
        bad = ~np.isfinite(t) | (np.abs(t) >= 2.0 ** 63)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(path, f"event {start + i} has timestamp {float(t[i])}, not a whole number of µs")
        out["t"] = np.rint(t)
    elif t.dtype.kind in "iub":
        if t.dtype.kind == "u" and t.dtype.itemsize == 8 and t.size and int(t.max()) >= 2 ** 63:
            i = int(np.argmax(t >= 2 ** 63))
            raise InputError(path, f"event {start + i} has timestamp {int(t[i])} us, past the largest int64")
        out["t"] = t
    else:
        raise InputError(path, f"timestamps must be numbers (µs), got {t.dtype}")
    for name, v in (("x", x), ("y", y)):
        v = np.asarray(v)
        if v.dtype.kind not in "iub":
            if v.dtype.kind != "f" or not (np.isfinite(v) & (v == np.floor(v))).all():
                raise InputError(path, f"column {name} must hold whole pixel numbers, got {v.dtype} values")
        if v.size and (v.min() < 0 or v.max() > 65535):
            i = int(np.argmax((v < 0) | (v > 65535)))
            raise InputError(path, f"event {start + i} has {name}={v[i].item()}, outside 0..65535 (a pixel coordinate "
                                   "cannot be negative)")
        out[name] = v
    out["p"] = np.asarray(p) > 0
    return out


def _check_columns(path: str, names, where: str) -> None:
    missing = [k for k in _FIELDS if k not in names]
    if missing:
        raise InputError(path, f"{where} lacks field(s) {', '.join(missing)} (need t in µs, x, y, p)")


# -- NumPy ---------------------------------------------------------------------------------------
#: The metadata file beside an ``.npy`` whose ``t`` is in ms (Schubert et al.'s sequences:
#: ``events.npy`` and ``sim_data.npz`` with ``t_end`` and ``dt`` in ms, among others).
MS_SIDECAR = "sim_data.npz"


def times_in_ms(path: str | os.PathLike) -> bool:
    """Whether the ``.npy`` at ``path`` has ``t`` in ms: a :data:`MS_SIDECAR` with ``t_end`` and ``dt`` beside it."""
    sidecar = Path(path).with_name(MS_SIDECAR)
    if not sidecar.is_file():
        return False
    try:
        with np.load(sidecar, allow_pickle=False) as z:
            return {"t_end", "dt"} <= set(z.files)
    except Exception:  # noqa: BLE001 - an unreadable sidecar is no sidecar: t stays in µs
        return False


def _open_npy(path: str) -> EventFile:
    try:
        arr = np.load(path, mmap_mode="r", allow_pickle=False)
    except Exception as e:  # noqa: BLE001 - any failure here is a bad file
        raise InputError(path, f"cannot read as a NumPy array ({type(e).__name__}: {e})".splitlines()[0]) from None
    if arr.dtype.names is None:
        raise InputError(path, f"not an event array: a structured array with fields t, x, y, p is needed "
                               f"(got a plain {arr.dtype} array of shape {arr.shape})")
    _check_columns(path, arr.dtype.names, "structured array")
    if arr.ndim != 1:
        raise InputError(path, f"event array must be one-dimensional, got shape {arr.shape}")

    us_per_tick = 1000 if times_in_ms(path) else 1

    def gen() -> Iterator[np.ndarray]:
        for i in range(0, arr.shape[0], CHUNK_EVENTS):
            c = arr[i:i + CHUNK_EVENTS]
            t = c["t"] if us_per_tick == 1 else np.asarray(c["t"], dtype=np.float64) * us_per_tick
            yield to_events(t, c["x"], c["y"], c["p"], path, i)

    return EventFile(path, "npy", None, int(arr.shape[0]), gen, t_start=0)


def _open_npz(path: str) -> EventFile:
    if not zipfile.is_zipfile(path):
        raise InputError(path, "not a NumPy .npz archive (no zip directory found: corrupt, truncated or another "
                               "kind of file)")
    try:
        z = np.load(path, allow_pickle=False)
        names = list(z.files)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
        raise InputError(path, f"cannot read as a NumPy .npz archive ({type(e).__name__}: {e})".splitlines()[0]) \
            from None
    if all(k in names for k in _FIELDS):
        def load():
            return [z[k] for k in _FIELDS]
    else:
        structured = [k for k in names if z[k].dtype.names is not None]
        if not structured:
            _check_columns(path, names, "archive")
        def load():  # noqa: E306
            a = z[structured[0]]
            _check_columns(path, a.dtype.names, f"array {structured[0]!r}")
            return [a[k] for k in _FIELDS]

    def gen() -> Iterator[np.ndarray]:
        try:
            cols = load()
        except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
            raise InputError(path, f"corrupt .npz archive ({type(e).__name__}: {e})".splitlines()[0]) from None
        n = len(cols[0])
        if any(len(c) != n for c in cols):
            raise InputError(path, f"columns t, x, y, p differ in length ({', '.join(str(len(c)) for c in cols)})")
        for i in range(0, n, CHUNK_EVENTS):
            yield to_events(*(c[i:i + CHUNK_EVENTS] for c in cols), path, i)

    return EventFile(path, "npz", None, None, gen, t_start=0)


# -- HDF5 (DSEC) -----------------------------------------------------------------------------------
def _h5py(path: str):
    try:
        import h5py
    except ImportError:
        raise InputError(path, f"reading HDF5 event files needs the h5py package ({_INSTALL})") from None
    try:
        import hdf5plugin  # noqa: F401 - registers the Blosc filter DSEC's files use
    except ImportError:
        pass
    return h5py


def _open_hdf5(path: str) -> EventFile:
    h5py = _h5py(path)
    try:
        with h5py.File(path, "r") as f:
            if "events" not in f:
                raise InputError(path, "HDF5 file has no 'events' group (DSEC layout: events/x, events/y, "
                                       "events/t, events/p, t_offset)")
            g = f["events"]
            _check_columns(path, list(g.keys()), "HDF5 group 'events'")
            n = int(g["t"].shape[0])
            lengths = {k: int(g[k].shape[0]) for k in _FIELDS}
            size = None
            t_start = int(np.asarray(f["t_offset"][()]).item()) if "t_offset" in f else 0
            if "width" in f.attrs and "height" in f.attrs:
                size = (int(f.attrs["width"]), int(f.attrs["height"]))
    except InputError:
        raise
    except BaseException as e:  # noqa: BLE001 - HDF5's errors on a corrupt file come as many types
        if not decoder_failure(e):
            raise
        raise InputError(path, f"cannot read as HDF5 ({type(e).__name__}: {e})".splitlines()[0]) from None
    if len(set(lengths.values())) > 1:
        raise InputError(path, "events/t, x, y, p differ in length (" +
                         ", ".join(f"{k} {v}" for k, v in lengths.items()) + ")")

    def gen() -> Iterator[np.ndarray]:
        with h5py.File(path, "r") as f:
            g = f["events"]
            t_offset = t_start
            for i in range(0, n, CHUNK_EVENTS):
                try:
                    cols = [g[k][i:i + CHUNK_EVENTS] for k in _FIELDS]
                except BaseException as e:  # noqa: BLE001 - as on opening
                    if not decoder_failure(e):
                        raise
                    raise InputError(path, f"cannot read events {i} to {min(n, i + CHUNK_EVENTS) - 1} "
                                           f"(corrupt or truncated HDF5: {e})".splitlines()[0]) from None
                if cols[0].dtype.kind in "iu":
                    cols[0] = cols[0].astype(np.int64) + t_offset
                else:
                    cols[0] = cols[0] + t_offset
                yield to_events(*cols, path, i)

    return EventFile(path, "hdf5", size, n, gen, t_start=t_start)


# -- AEDAT 4 -------------------------------------------------------------------------------------
def decoder_failure(e: BaseException) -> bool:
    """Whether ``e``, raised by a decoder of a recording, means a bad file: anything but an interrupt or an exit.

    A compiled decoder signals a corrupt file in ways ``except Exception`` misses: the ``aedat``
    package raises ``pyo3_runtime.PanicException`` (a ``BaseException``) when its Rust code panics.
    """
    return not isinstance(e, (KeyboardInterrupt, SystemExit, GeneratorExit))


@contextlib.contextmanager
def _panic_text_hidden():
    """Send file descriptor 2 to a scratch file while a compiled decoder runs, so that a Rust panic's own
    lines (``thread ... panicked at ...``) do not reach stderr: the error line says what happened."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no stderr, or not a file descriptor
        yield
        return
    try:
        with tempfile.TemporaryFile() as scratch:
            os.dup2(scratch.fileno(), 2)
            try:
                yield
            finally:
                os.dup2(saved, 2)
    finally:
        os.close(saved)


def _aedat_error(path: str, e: BaseException, where: str) -> InputError:
    text = (str(e).splitlines() or [""])[0] or type(e).__name__
    if type(e).__name__ == "PanicException":
        text = f"the decoder failed: {text}"
    return InputError(path, f"{where} ({text})")


def _open_aedat4(path: str) -> EventFile:
    try:
        import aedat
    except ImportError:
        raise InputError(path, f"reading AEDAT4 needs the aedat package ({_INSTALL})") from None
    try:
        with _panic_text_hidden():
            streams = aedat.Decoder(path).id_to_stream()
    except BaseException as e:  # noqa: BLE001 - the decoder's errors (panics too) are all about the file
        if not decoder_failure(e):
            raise
        raise _aedat_error(path, e, "bad AEDAT4 header") from None
    ids = sorted(i for i, s in streams.items() if s.get("type") == "events")
    if not ids:
        raise InputError(path, "AEDAT4 file has no event stream")
    sid = ids[0]
    size = (int(streams[sid]["width"]), int(streams[sid]["height"]))

    def gen() -> Iterator[np.ndarray]:
        n = 0
        try:
            with _panic_text_hidden():
                decoder = aedat.Decoder(path)
        except BaseException as e:  # noqa: BLE001 - as above
            if not decoder_failure(e):
                raise
            raise _aedat_error(path, e, "bad AEDAT4 header") from None
        while True:
            try:
                with _panic_text_hidden():
                    packet = next(decoder)
            except StopIteration:
                return
            except BaseException as e:  # noqa: BLE001 - a truncated or corrupt packet, or a panic on one
                if not decoder_failure(e):
                    raise
                raise _aedat_error(path, e, f"truncated or corrupt AEDAT4 data after event {n}") from None
            if packet.get("stream_id") != sid or "events" not in packet:
                continue
            e = packet["events"]
            yield to_events(e["t"], e["x"], e["y"], e["on"], path, n)
            n += e.shape[0]

    return EventFile(path, "aedat4", size, None, gen)


# -- Prophesee -----------------------------------------------------------------------------------
def _open_raw(path: str) -> EventFile:
    with open(path, "rb") as f:
        header = prophesee.read_header(f)
    enc = header.encoding
    if enc not in ("evt2", "evt3"):
        raise InputError(path, f"unsupported RAW encoding {enc!r} (supported: EVT 2.0, EVT 3.0)" if enc else
                         "RAW header names no encoding (expected '% evt 2.0', '% evt 3.0' or '% format EVT3')")
    return EventFile(path, enc, header.sensor_size, None, lambda: prophesee.iter_raw(path, header))


def _open_dat(path: str) -> EventFile:
    with open(path, "rb") as f:
        header = prophesee.read_header(f)
        start = prophesee.dat_layout(path, f, header)
    n = (os.path.getsize(path) - start) // 8
    return EventFile(path, "dat", header.sensor_size, n, lambda: prophesee.iter_dat(path, header))
