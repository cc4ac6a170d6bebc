"""A minimal motion-JPEG AVI writer for tests: every frame is encoded at its own size, which
cv2.VideoWriter cannot do (it drops or rescales frames of another size)."""
from __future__ import annotations

import struct

import cv2
import numpy as np


def _chunk(fourcc: bytes, data: bytes) -> bytes:
    return fourcc + struct.pack("<I", len(data)) + data + (b"\0" if len(data) % 2 else b"")


def _list(kind: bytes, body: bytes) -> bytes:
    return _chunk(b"LIST", kind + body)


def mjpeg_avi(frames: list[np.ndarray], fps: int = 30, size: tuple[int, int] | None = None) -> bytes:
    """An AVI file (bytes) holding ``frames`` (BGR or grey uint8, any sizes) as JPEG images.

    Parameters
    ----------
    frames : list of ndarray
        Each (H, W) or (H, W, 3) uint8, encoded at its own size.
    fps : int
        Frame rate the headers state, frames/s.
    size : (int, int), optional
        (width, height) the headers state (default: the first frame's).
    """
    jpegs = [cv2.imencode(".jpg", f)[1].tobytes() for f in frames]
    w, h = size if size is not None else (frames[0].shape[1], frames[0].shape[0])
    n = len(jpegs)
    avih = struct.pack("<14I", 1_000_000 // fps, 0, 0, 0x10, n, 0, 1, 0, w, h, 0, 0, 0, 0)
    strh = b"vidsMJPG" + struct.pack("<IHHIIIIIIII4h", 0, 0, 0, 0, 1, fps, 0, n, 0, 0xFFFFFFFF, 0, 0, 0, w, h)
    strf = struct.pack("<IiiHHIIiiII", 40, w, h, 1, 24, int.from_bytes(b"MJPG", "little"), w * h * 3, 0, 0, 0, 0)
    hdrl = _list(b"hdrl", _chunk(b"avih", avih) + _list(b"strl", _chunk(b"strh", strh) + _chunk(b"strf", strf)))
    movi, index, offset = b"", b"", 4
    for j in jpegs:
        c = _chunk(b"00dc", j)
        index += b"00dc" + struct.pack("<III", 0x10, offset, len(j))
        movi += c
        offset += len(c)
    return _chunk(b"RIFF", b"AVI " + hdrl + _list(b"movi", movi) + _chunk(b"idx1", index))


def ramp_frames(n: int, height: int, width: int, start: int = 0) -> list[np.ndarray]:
    """``n`` flat grey frames of ``height x width`` px, levels ``start, start + 20, ...`` (mod 256)."""
    return [np.full((height, width, 3), (start + 20 * t) % 256, np.uint8) for t in range(n)]
