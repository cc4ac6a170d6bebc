"""The one video writer of cdnf_ti: streams frames to a file atomically and checks what was stored.

* ``.avi``: FFV1, lossless (stimuli, synthetic datasets);
* ``.mp4``: MPEG-4 Part 2 (``mp4v``), which every OpenCV build writes and common
  players read (field movies from ``python -m cdnf_ti.run render``).

Frames may be grey (H, W) or BGR (H, W, 3), uint8 or float in [0, 1]. The file
appears only when complete (written to a temporary name, then renamed), and its
frame count and frame rate are read back and checked.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

import cv2
import numpy as np

from .atomic import atomic_write
from .errors import InputError

#: File suffix -> (FOURCC, description).
CODECS = {".avi": ("FFV1", "FFV1 lossless AVI"), ".mp4": ("mp4v", "MPEG-4 (mp4v) MP4")}


def to_uint8(frame: np.ndarray) -> np.ndarray:
    """Frame (float in [0, 1] or uint8) -> uint8 ``round(255 x)``."""
    a = np.asarray(frame)
    if a.dtype == np.uint8:
        return np.ascontiguousarray(a)
    return np.clip(np.rint(a.astype(np.float64) * 255.0), 0, 255).astype(np.uint8)


def codec_for(path: str | os.PathLike, fourcc: str | None = None) -> str:
    """The FOURCC used for ``path`` (from its suffix unless given)."""
    if fourcc:
        return fourcc
    suffix = Path(path).suffix.lower()
    if suffix not in CODECS:
        raise InputError(path, f"cannot write a {suffix or 'suffix-less'} video; use one of "
                               f"{', '.join(CODECS)}")
    return CODECS[suffix][0]


def open_writer(path: str | os.PathLike, fps: float, size: tuple[int, int], fourcc: str = "FFV1",
                is_color: bool = True, name: str | os.PathLike | None = None) -> "cv2.VideoWriter":
    """An opened ``cv2.VideoWriter`` for ``size = (width, height)``.

    Raises
    ------
    InputError
        The OpenCV build cannot write this codec (message names ``name`` or ``path``).
    """
    wr = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), float(fps), (int(size[0]), int(size[1])),
                         isColor=is_color)
    if not wr.isOpened():
        raise InputError(name or path, f"OpenCV cannot open a {fourcc} video writer")
    return wr


def write_video(path: str | os.PathLike, frames: Iterable[np.ndarray], fps: float = 30.0,
                fourcc: str | None = None, check: bool = True) -> int:
    """Stream ``frames`` to ``path`` atomically; returns the frame count.

    Parameters
    ----------
    path : path-like
        ``.avi`` (FFV1, lossless) or ``.mp4`` (mp4v); another suffix needs ``fourcc``.
    frames : iterable of ndarray
        (H, W) grey or (H, W, 3) BGR, uint8 or float in [0, 1]; all the same shape.
    fps : float
        Frame rate stored in the file (frames/s).
    fourcc : str, optional
        Codec override (e.g. ``"MJPG"``).
    check : bool
        Read the file back and check its frame count and frame rate.

    Raises
    ------
    ValueError
        No frames, or a frame of another shape.
    InputError
        The codec cannot be written, or the stored file does not hold the frames.
    """
    path = Path(path)
    code = codec_for(path, fourcc)
    count = 0

    def write(tmp: str) -> None:
        nonlocal count
        writer = None
        shape = None
        try:
            for f in frames:
                a = to_uint8(f)
                if writer is None:
                    shape = a.shape
                    writer = open_writer(tmp, fps, (a.shape[1], a.shape[0]), code, is_color=a.ndim == 3, name=path)
                if a.shape != shape:
                    raise ValueError(f"{path}: frame {count} has shape {a.shape}, expected {shape}")
                writer.write(a)
                count += 1
        finally:
            if writer is not None:
                writer.release()
        if count == 0:
            raise ValueError(f"{path}: no frames to write")
        if check:
            cap = cv2.VideoCapture(tmp)
            stored = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
            stored_fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
            cap.release()
            if stored != count or abs(stored_fps - float(fps)) > 1e-3 * float(fps):
                raise InputError(path, f"the file holds {stored} frames at {stored_fps:g} fps instead of "
                                       f"{count} at {float(fps):g} fps")

    atomic_write(path, write)
    return count
