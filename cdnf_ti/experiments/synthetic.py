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

from ..atomic import atomic_write_text
from ..stimuli.basic import basic_stimulus
from ..video import write_video as _write

DEFAULT_CLIPS = ("dark_looming", "light_translating", "light_looming", "dark_receding")


def write_video(path: str | os.PathLike, frames: Iterable[np.ndarray], fps: float = 30.0) -> Path:
    """Write grey frames (float in [0, 1] or uint8) to a lossless FFV1 AVI file, atomically
    (:func:`cdnf_ti.video.write_video`)."""
    path = Path(path)
    if path.suffix.lower() != ".avi":
        raise ValueError(f"{path}: write_video writes .avi (FFV1) files")
    _write(path, frames, fps)
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
