"""Tiny encoders of the event formats, for the reader tests (written from the published layouts).

Each takes events of :data:`cdnf_ti.events.types.EVENT_DTYPE`, in the order the
decoder gives them back, and returns the file's bytes.
"""
from __future__ import annotations

import struct

import numpy as np

from cdnf_ti.events.types import EVENT_DTYPE


def random_events(n: int, size: tuple[int, int] = (64, 48), duration_us: int = 2_000_000, seed: int = 0,
                  per_timestamp: int = 5) -> np.ndarray:
    """Events sorted by ``(t, y, p, x)``, unique, several per timestamp and row (so EVT3 makes vectors)."""
    rng = np.random.default_rng(seed)
    w, h = size
    n_t = max(1, n // per_timestamp)
    ts = np.sort(rng.choice(duration_us, size=n_t, replace=False))
    t = np.repeat(ts, per_timestamp)
    y = np.repeat(rng.integers(0, h, n_t), per_timestamp)
    p = np.repeat(rng.integers(0, 2, n_t), per_timestamp)
    x = rng.integers(0, w, t.size)
    ev = np.empty(t.size, dtype=EVENT_DTYPE)
    ev["t"], ev["x"], ev["y"], ev["p"] = t, x, y, p
    ev = np.unique(ev)  # sorts by (t, x, y, p) and drops duplicates
    return ev[np.lexsort((ev["x"], ev["p"], ev["y"], ev["t"]))]


def raw_header(lines: dict) -> bytes:
    return b"".join(f"% {k} {v}\n".encode() for k, v in lines.items()) + b"% end\n"


def encode_evt2(ev: np.ndarray) -> bytes:
    """EVT 2.0 words: a TIME_HIGH word whenever ``t >> 6`` changes, then one CD word per event."""
    words = []
    high = None
    for t, x, y, p in ev.tolist():
        if t >> 6 != high:
            high = t >> 6
            words.append((0x8 << 28) | (high & 0x0FFFFFFF))
        words.append(((0x1 if p else 0x0) << 28) | ((t & 0x3F) << 22) | (x << 11) | y)
    return np.array(words, dtype="<u4").tobytes()


def encode_evt3(ev: np.ndarray) -> bytes:
    """EVT 3.0 words: TIME_HIGH / TIME_LOW / ADDR_Y when they change; a lone event as EVT_ADDR_X, a run of
    events sharing ``(t, y, p)`` as VECT_BASE_X and VECT_12 (or VECT_8 for the last 8 or fewer)."""
    words: list[int] = []
    high = low = yy = None
    i, n = 0, ev.size
    rows = ev.tolist()
    while i < n:
        t, _, y, p = rows[i]
        j = i
        while j < n and rows[j][0] == t and rows[j][2] == y and rows[j][3] == p:
            j += 1
        th, tl = (t >> 12) & 0xFFF, t & 0xFFF
        if th != high:
            words.append((0x8 << 12) | th)
            high = th
        if tl != low:
            words.append((0x6 << 12) | tl)
            low = tl
        if y != yy:
            words.append((0x0 << 12) | y)
            yy = y
        xs = [r[1] for r in rows[i:j]]
        if len(xs) == 1:
            words.append((0x2 << 12) | (p << 11) | xs[0])
        else:
            base = xs[0]
            words.append((0x3 << 12) | (p << 11) | base)
            end = xs[-1]
            while base <= end:
                width = 8 if end - base < 8 else 12
                mask = sum(1 << (x - base) for x in xs if base <= x < base + width)
                words.append(((0x5 if width == 8 else 0x4) << 12) | mask)
                base += width
        i = j
    return np.array(words, dtype="<u2").tobytes()


def encode_dat(ev: np.ndarray, size: tuple[int, int]) -> bytes:
    head = raw_header({"Date": "2026-11-25", "Version": "2", "Width": size[0], "Height": size[1]})[:-6]
    rec = np.empty((ev.size, 2), dtype="<u4")
    rec[:, 0] = ev["t"]
    rec[:, 1] = ev["x"].astype(np.uint32) | (ev["y"].astype(np.uint32) << 14) | (ev["p"].astype(np.uint32) << 28)
    return head + bytes([0x0C, 8]) + rec.tobytes()


def _aedat4_header(size: tuple[int, int]) -> bytes:
    """IOHeader flatbuffer (compression None, data position -1, the XML description)."""
    desc = ('<dv version="2.0"><node name="outInfo" path="/mainModule/output/"><node name="0" '
            'path="/mainModule/output/0/"><attr key="compression" type="string">NONE</attr>'
            '<attr key="originalModuleName" type="string">capture</attr>'
            '<attr key="originalOutputName" type="string">events</attr>'
            '<attr key="typeDescription" type="string">Array of events.</attr>'
            '<attr key="typeIdentifier" type="string">EVTS</attr>'
            '<node name="info" path="/mainModule/output/0/info/">'
            f'<attr key="sizeX" type="int">{size[0]}</attr><attr key="sizeY" type="int">{size[1]}</attr>'
            '<attr key="source" type="string">cdnf_ti test</attr></node></node></node></dv>').encode()
    b = bytearray()
    b += struct.pack("<I", 24) + b"IOHE"  # root table at 24
    b += struct.pack("<HHHHH", 10, 20, 4, 8, 16) + b"\0" * 6  # vtable at 8 (10 bytes) + pad to 24
    b += struct.pack("<i", 24 - 8)  # table at 24: soffset to the vtable
    b += struct.pack("<i", 0)  # compression None (at table + 4)
    b += struct.pack("<q", -1)  # file_data_position (at table + 8 = 32)
    b += struct.pack("<I", 44 - 40)  # description offset (at table + 16 = 40) -> string at 44
    b += struct.pack("<I", len(desc)) + desc + b"\0"
    return bytes(b)


def _aedat4_packet(ev: np.ndarray) -> bytes:
    """A size-prefixed EventPacket flatbuffer ("EVTS") holding ``ev``."""
    el = np.zeros(ev.size, dtype=[("t", "<i8"), ("x", "<i2"), ("y", "<i2"), ("on", "u1"), ("pad", "V3")])
    el["t"], el["x"], el["y"], el["on"] = ev["t"], ev["x"], ev["y"], ev["p"]
    body = bytearray()
    body += struct.pack("<I", 20 - 4) + b"EVTS"  # (after the size prefix) root table at 20
    body += struct.pack("<HHH", 6, 8, 4) + b"\0\0"  # vtable at 12
    body += struct.pack("<i", 20 - 12)  # table at 20
    body += struct.pack("<I", 28 - 24)  # elements vector at 28
    body += struct.pack("<I", ev.size) + el.tobytes()
    return struct.pack("<I", len(body)) + bytes(body)


def encode_aedat4(ev: np.ndarray, size: tuple[int, int], packet_events: int = 1000) -> bytes:
    """AEDAT 4.0: magic, IOHeader, then uncompressed event packets of stream 0."""
    head = _aedat4_header(size)
    out = bytearray(b"#!AER-DAT4.0\r\n" + struct.pack("<I", len(head)) + head)
    for i in range(0, ev.size, packet_events):
        pkt = _aedat4_packet(ev[i:i + packet_events])
        out += struct.pack("<iI", 0, len(pkt)) + pkt
    return bytes(out)
