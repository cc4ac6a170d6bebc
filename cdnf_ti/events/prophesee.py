"""Prophesee recordings: ``.raw`` (EVT 2.0 and EVT 3.0 encodings) and ``.dat``, decoded in NumPy.

Written from Prophesee's published format descriptions (the "RAW File Format",
"EVT 2.0 Format", "EVT 3.0 Format" and "DAT File Format" pages of the Metavision
documentation); no other decoder's code was used.

``.raw`` file: an ASCII header of lines ``"% key value\\n"`` (optionally closed by
``"% end"``; the data starts at the first line that does not begin with ``"% "``),
then little-endian words:

* **EVT 2.0**, 32-bit words, type in bits 31..28: ``CD_OFF`` (0x0) and ``CD_ON``
  (0x1) carry ``t[5:0]`` in bits 27..22, ``x`` in 21..11, ``y`` in 10..0;
  ``EVT_TIME_HIGH`` (0x8) carries ``t[33:6]`` in bits 27..0; ``EXT_TRIGGER``
  (0xA), ``OTHERS`` (0xE) and ``CONTINUED`` (0xF) carry no CD event.
* **EVT 3.0**, 16-bit words, type in bits 15..12, a stateful encoding:
  ``EVT_ADDR_Y`` (0x0, ``y`` in bits 10..0), ``EVT_ADDR_X`` (0x2, polarity in bit
  11, ``x`` in 10..0: one event), ``VECT_BASE_X`` (0x3, polarity and base ``x``),
  ``VECT_12`` (0x4) and ``VECT_8`` (0x5): a validity mask, one event at
  ``base + i`` for each set bit ``i``, then ``base += 12`` (or 8);
  ``EVT_TIME_LOW`` (0x6) and ``EVT_TIME_HIGH`` (0x8): the low and high 12 bits of
  a 24-bit microsecond time base, which wraps every 16.8 s (a drop of the high
  part by more than half its range counts as a wrap); ``CONTINUED_4`` (0x7),
  ``EXT_TRIGGER`` (0xA), ``OTHERS`` (0xE), ``CONTINUED_12`` (0xF) carry no CD event.

Word types the descriptions mark as reserved are a corrupt file: the error names
the byte offset of the first one.

``.dat`` file: the same kind of header, then two bytes (event type, event size:
8), then 8-byte records: ``uint32 t`` (µs) and ``uint32`` with ``x`` in bits
13..0, ``y`` in 27..14, polarity in bit 28.

Each decoder is a generator of structured chunks (:data:`~cdnf_ti.events.readers.EVENT_DTYPE`)
that reads the file a block at a time and carries the decoding state across
blocks, so recordings larger than memory stream.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import BinaryIO, Iterator

import numpy as np

from ..errors import InputError
from .types import EVENT_DTYPE

#: Bytes read per block (a multiple of 4 and of 8).
BLOCK_BYTES = 1 << 22

#: Sensor sizes (width, height) of Prophesee sensors, by a fragment of the header's ``plugin_name``,
#: for recordings whose header states no geometry (older Metavision versions).
KNOWN_SENSORS = (("imx636", (1280, 720)), ("gen41", (1280, 720)), ("genx320", (320, 320)),
                 ("gen31", (640, 480)), ("gen3", (640, 480)), ("imx8", (640, 480)))

_EVT2_KNOWN = np.zeros(16, dtype=bool)
_EVT2_KNOWN[[0x0, 0x1, 0x8, 0xA, 0xE, 0xF]] = True
_EVT3_KNOWN = np.zeros(16, dtype=bool)
_EVT3_KNOWN[[0x0, 0x2, 0x3, 0x4, 0x5, 0x6, 0x7, 0x8, 0xA, 0xE, 0xF]] = True
#: Set bits of every 12-bit validity mask.
_POPCOUNT12 = np.array([bin(m).count("1") for m in range(1 << 12)], dtype=np.int64)


@dataclass
class PropheseeHeader:
    """A ``.raw``/``.dat`` header.

    Attributes
    ----------
    fields : dict
        ``key -> value`` of every ``% key value`` line (keys lower-cased).
    size : int
        Header length in bytes (where the data starts).
    """

    fields: dict = field(default_factory=dict)
    size: int = 0

    @property
    def encoding(self) -> str | None:
        """``"evt2"``, ``"evt3"``, or another encoding's name (``None`` when the header states none)."""
        fmt = self.fields.get("format", "")
        evt = self.fields.get("evt", "")
        name = fmt.split(";")[0].strip().lower() if fmt else ""
        if not name and evt:
            name = "evt" + evt.strip().replace(".0", "")
        return {"evt2": "evt2", "evt3": "evt3", "evt20": "evt2", "evt30": "evt3"}.get(name, name or None)

    @property
    def sensor_size(self) -> tuple[int, int] | None:
        """``(width, height)`` from ``geometry WxH``, ``format ...;width=..;height=..``, ``width``/``height``
        lines, or a known sensor's ``plugin_name``; ``None`` when the header gives none."""
        geo = self.fields.get("geometry", "")
        m = re.fullmatch(r"\s*(\d+)\s*x\s*(\d+)\s*", geo)
        if m:
            return int(m.group(1)), int(m.group(2))
        fmt = dict(kv.split("=", 1) for kv in self.fields.get("format", "").split(";") if "=" in kv)
        for src in (fmt, self.fields):
            w, h = src.get("width"), src.get("height")
            if w and h and w.strip().isdigit() and h.strip().isdigit():
                return int(w), int(h)
        plugin = self.fields.get("plugin_name", "").lower()
        for key, size in KNOWN_SENSORS:
            if key in plugin:
                return size
        return None


def read_header(f: BinaryIO) -> PropheseeHeader:
    """Read the ``% key value`` lines at the start of ``f``; leaves ``f`` at the first data byte."""
    head = PropheseeHeader()
    pos = 0
    while True:
        f.seek(pos)
        start = f.read(2)
        if start != b"% ":
            break
        f.seek(pos)
        line = f.readline(1 << 16)
        pos += len(line)
        text = line.decode("latin-1").rstrip("\r\n")[2:]
        key, _, value = text.partition(" ")
        if key.lower() == "end":
            break
        head.fields[key.lower()] = value
    f.seek(pos)
    head.size = pos
    return head


def _ffill(values: np.ndarray, mask: np.ndarray, init) -> np.ndarray:
    """``out[i] = values[j]`` for the last ``j <= i`` with ``mask[j]``; ``init`` where there is none."""
    rank = np.cumsum(mask, dtype=np.int64) - 1
    return np.concatenate(([init], values[mask]))[rank + 1]


def _first_unknown(path: str, types: np.ndarray, known: np.ndarray, offset: int, word_bytes: int, name: str) -> None:
    bad = ~known[types]
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(path, f"corrupt {name} data: reserved word type 0x{int(types[i]):X} at byte offset "
                               f"{offset + i * word_bytes}")


@dataclass
class _Evt2State:
    time_high: int = 0


def decode_evt2(words: np.ndarray, state: _Evt2State, path: str = "", offset: int = 0) -> np.ndarray:
    """Decode EVT 2.0 words (uint32) into events, carrying ``state`` (the last time high) across calls.

    ``offset`` is the byte offset of ``words[0]`` in the file (for error messages).
    """
    types = (words >> 28).astype(np.uint8)
    _first_unknown(path, types, _EVT2_KNOWN, offset, 4, "EVT 2.0")
    is_high = types == 0x8
    high = _ffill((words & 0x0FFFFFFF).astype(np.int64), is_high, state.time_high)
    if is_high.any():
        state.time_high = int(high[-1])
    cd = types <= 0x1
    w = words[cd]
    out = np.empty(w.size, dtype=EVENT_DTYPE)
    out["t"] = (high[cd] << 6) | ((w >> 22) & 0x3F).astype(np.int64)
    out["x"] = (w >> 11) & 0x7FF
    out["y"] = w & 0x7FF
    out["p"] = types[cd]
    return out


@dataclass
class _Evt3State:
    y: int = 0
    base_x: int = 0  # where the next vector word starts
    polarity: int = 0  # of vector words (from the last VECT_BASE_X)
    time_high: int = 0  # 12 bits
    time_low: int = 0  # 12 bits
    epoch: int = 0  # wraps of the 24-bit time base
    seen_high: bool = False


def decode_evt3(words: np.ndarray, state: _Evt3State, path: str = "", offset: int = 0) -> np.ndarray:
    """Decode EVT 3.0 words (uint16) into events, carrying ``state`` across calls.

    Vectorised: the state an event word sees (``y``, base ``x``, polarity, time)
    is the value set by the last word of that kind before it, found by a running
    count of those words (``np.cumsum`` of their mask: the rank of the last one);
    every event word becomes a 12-bit validity mask at a base ``x``
    (``EVT_ADDR_X`` is the mask 1 at its own ``x``), expanded in one step.
    """
    types = (words >> 12).astype(np.uint8)
    _first_unknown(path, types, _EVT3_KNOWN, offset, 2, "EVT 3.0")
    payload = (words & 0x0FFF).astype(np.int64)
    is_x, is_v12, is_v8 = types == 0x2, types == 0x4, types == 0x5
    pos = np.flatnonzero(is_x | is_v12 | is_v8)  # the event words

    def last(mask: np.ndarray, values: np.ndarray, init) -> np.ndarray:
        """At each event word: ``values`` (one per word of ``mask``) of the last such word before it, or ``init``."""
        rank = np.cumsum(mask, dtype=np.int64)[pos] - 1
        vals = np.concatenate(([init], values)) if values.size else np.array([init], dtype=np.int64)
        return vals[rank + 1]

    # --- time: 24-bit base (high 12 | low 12), wraps counted on the high part
    is_high, is_low = types == 0x8, types == 0x6
    highs = payload[is_high]
    init_high = (state.epoch << 12) | state.time_high  # before the block's first EVT_TIME_HIGH
    high_full = highs
    if highs.size:
        first_prev = state.time_high if state.seen_high else highs[0]
        prev = np.concatenate(([first_prev], highs[:-1]))
        epochs = state.epoch + np.cumsum(highs - prev < -2048)
        high_full = (epochs << 12) | highs
        state.epoch, state.time_high, state.seen_high = int(epochs[-1]), int(highs[-1]), True
    lows = payload[is_low]
    t = last(is_high, high_full, init_high) << 12
    t |= last(is_low, lows, state.time_low)
    # --- y, polarity of vectors, base x
    is_y, is_base = types == 0x0, types == 0x3
    y = last(is_y, payload[is_y] & 0x7FF, state.y)
    base_words = payload[is_base]
    vec_pol = last(is_base, base_words >> 11, state.polarity)
    step = np.where(is_v12, 12, 0) + np.where(is_v8, 8, 0)
    cum = np.cumsum(step)
    base = last(is_base, (base_words & 0x7FF) - cum[is_base], state.base_x) + cum[pos] - step[pos]
    # --- carry the state to the next block
    if lows.size:
        state.time_low = int(lows[-1])
    if np.any(is_y):
        state.y = int(payload[is_y][-1] & 0x7FF)
    if base_words.size:
        state.polarity = int(base_words[-1] >> 11)
        state.base_x = int((base_words[-1] & 0x7FF) - cum[is_base][-1] + cum[-1])
    elif cum.size:
        state.base_x += int(cum[-1])
    # --- event words -> (mask, x0, polarity) -> events
    pw, tw = payload[pos], types[pos]
    single = tw == 0x2
    mask = np.where(single, 1, np.where(tw == 0x4, pw, pw & 0xFF))
    x0 = np.where(single, pw & 0x7FF, base)
    pol = np.where(single, (pw >> 11) & 1, vec_pol)
    rows = np.repeat(np.arange(mask.size), _POPCOUNT12[mask])  # the event word of each event, in order
    cols = np.zeros(rows.size, dtype=np.int64)  # bit of the event in its word's mask (0 for EVT_ADDR_X)
    vec = ~single
    if vec.any():
        cols[vec[rows]] = np.nonzero((mask[vec][:, None] >> np.arange(12)) & 1)[1]
    out = np.empty(rows.size, dtype=EVENT_DTYPE)
    out["t"] = t[rows]
    out["x"] = x0[rows] + cols
    out["y"] = y[rows]
    out["p"] = pol[rows]
    return out


def _blocks(f: BinaryIO, path: str, start: int, word_bytes: int, name: str) -> Iterator[tuple[int, bytes]]:
    """``(byte offset, bytes)`` blocks of whole words; a partial last word is a truncation error."""
    offset = start
    while True:
        data = f.read(BLOCK_BYTES)
        if not data:
            return
        whole = len(data) - len(data) % word_bytes
        if whole < len(data):
            rest = f.read(1)
            if not rest:
                if whole:
                    yield offset, data[:whole]
                raise InputError(path, f"truncated {name} data: the last {word_bytes}-byte word is incomplete "
                                       f"at byte offset {offset + whole} ({len(data) - whole} of {word_bytes} "
                                       f"bytes)")
            f.seek(-1 - (len(data) - whole), 1)
            data = data[:whole]
        yield offset, data
        offset += len(data)


def iter_raw(path: str, header: PropheseeHeader) -> Iterator[np.ndarray]:
    """Decoded event chunks of a ``.raw`` file (EVT 2.0 or EVT 3.0)."""
    enc = header.encoding
    if enc not in ("evt2", "evt3"):
        raise InputError(path, f"unsupported RAW encoding {enc!r} (supported: EVT 2.0, EVT 3.0)"
                         if enc else "RAW header names no encoding ('% evt 2.0' / '% evt 3.0' / '% format EVT3')")
    with open(path, "rb") as f:
        f.seek(header.size)
        if enc == "evt2":
            s2 = _Evt2State()
            for off, data in _blocks(f, path, header.size, 4, "EVT 2.0"):
                yield decode_evt2(np.frombuffer(data, dtype="<u4"), s2, path, off)
        else:
            s3 = _Evt3State()
            for off, data in _blocks(f, path, header.size, 2, "EVT 3.0"):
                yield decode_evt3(np.frombuffer(data, dtype="<u2"), s3, path, off)


def dat_layout(path: str, f: BinaryIO, header: PropheseeHeader) -> int:
    """Check a ``.dat`` file's event type/size bytes; returns the offset of the first record."""
    f.seek(header.size)
    ts = f.read(2)
    if len(ts) < 2:
        raise InputError(path, f"truncated DAT file: no event type/size bytes at byte offset {header.size}")
    if ts[1] != 8:
        raise InputError(path, f"unsupported DAT event size {ts[1]} bytes at byte offset {header.size + 1} "
                               "(CD events are 8 bytes)")
    return header.size + 2


def iter_dat(path: str, header: PropheseeHeader) -> Iterator[np.ndarray]:
    """Decoded event chunks of a ``.dat`` file (CD events, 8-byte records)."""
    with open(path, "rb") as f:
        start = dat_layout(path, f, header)
        f.seek(start)
        for _, data in _blocks(f, path, start, 8, "DAT"):
            rec = np.frombuffer(data, dtype="<u4").reshape(-1, 2)
            out = np.empty(rec.shape[0], dtype=EVENT_DTYPE)
            out["t"] = rec[:, 0]
            out["x"] = rec[:, 1] & 0x3FFF
            out["y"] = (rec[:, 1] >> 14) & 0x3FFF
            out["p"] = (rec[:, 1] >> 28) & 1
            yield out
