"""A small labelled dataset generated from the basic stimuli (for tests, docs and trying the tool).

Looming clips are labelled ``collision`` (window: the last ``window`` frames,
contact at the last frame); receding and translating clips are labelled
``non-collision``. Videos are lossless FFV1 AVI files.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..atomic import atomic_write, atomic_write_text

DEFAULT_CLIPS = ("dark_looming", "light_translating", "light_looming", "dark_receding")


def write_video(path: str | os.PathLike, frames: Iterable[np.ndarray], fps: float = 30.0) -> Path:
    """Write grey frames (float in [0, 1] or uint8) to a lossless FFV1 AVI file, atomically."""
    import cv2

    frames = list(frames)
    if not frames:
        raise ValueError(f"{path}: no frames to write")
    h, w = frames[0].shape[:2]

    def _w(tmp: str) -> None:
        wr = cv2.VideoWriter(tmp, cv2.VideoWriter_fourcc(*"FFV1"), float(fps), (w, h), True)
        if not wr.isOpened():  # pragma: no cover - depends on the OpenCV build
            raise RuntimeError(f"{path}: OpenCV cannot write FFV1 video")
        try:
            for f in frames:
                a = np.asarray(f)
                if a.dtype != np.uint8:
                    a = np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8)
                wr.write(cv2.cvtColor(a, cv2.COLOR_GRAY2BGR) if a.ndim == 2 else a)
        finally:
            wr.release()

    path = Path(path)
    if path.suffix.lower() != ".avi":
        raise ValueError(f"{path}: write_video writes .avi (FFV1) files")
    atomic_write(path, _w)
    return path


def make_synthetic_dataset(folder: str | os.PathLike, size: int = 96, clips: Sequence[str] = DEFAULT_CLIPS,
                           window: int = 14, extra_columns: bool = True) -> Path:
    """Write basic-stimulus clips and their ``labels.csv`` into ``folder``.

    Parameters
    ----------
    folder : path-like
    size : int
        Frame side in px.
    clips : sequence of str
        Basic stimulus names (each becomes ``<name>.avi``).
    window : int
        Frames in a looming clip's collision window (ending at its last frame).
    extra_columns : bool
        Add ``frames`` and ``description`` columns (ignored by the reader).

    Returns
    -------
    Path
        The labels file.
    """
    from ..stimuli.basic import basic_stimulus

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    head = "clip,label,window_start,window_end,contact_frame" + (",frames,description" if extra_columns else "")
    lines = [head]
    for name in clips:
        s = basic_stimulus(name, height=size, width=size)
        write_video(folder / f"{name}.avi", s.frames(), s.fps)
        n = s.n_frames
        if s.motion == "looming":
            row = f"{name},collision,{n - window},{n - 1},{n - 1}"
        else:
            row = f"{name},non-collision,,,"
        if extra_columns:
            row += f",{n},\"{name.replace('_', ' ')}, {size}x{size}\""
        lines.append(row)
    labels = folder / "labels.csv"
    atomic_write_text(labels, "\n".join(lines) + "\n")
    return labels
