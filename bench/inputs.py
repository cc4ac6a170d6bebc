"""Benchmark inputs: basic stimuli, the development dashcam clips, or a generated stand-in video."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

#: The development dashcam clips (426/432 x 240), beside the repository when present
#: (``$CDNF_TI_SHARED/data/real``).
SHARED_REAL = (Path(os.environ.get("CDNF_TI_SHARED", Path(__file__).resolve().parents[1].parent / "shared"))
               / "data" / "real")


def shared_clip(name: str = "serial_vehicle_collision") -> Path | None:
    """Path of a development dashcam clip, or ``None`` when the clips are absent."""
    p = SHARED_REAL / f"{name}.mp4"
    return p if p.exists() else None


#: The development clip that is exactly 426x240.
DEFAULT_CLIP = "serial_vehicle_collision"


def standin_video(n_frames: int, height: int = 240, width: int = 426, seed: int = 0) -> list[np.ndarray]:
    """A dashcam-like stand-in: a textured scene drifting and zooming, plus a looming dark object.

    Deterministic for a given ``seed``. Every pixel changes from frame to frame
    (camera ego-motion), as in real footage.

    Returns
    -------
    list of ndarray, each (height, width) uint8
    """
    import cv2

    rng = np.random.default_rng(seed)
    big = rng.random((height // 4 + 8, width // 4 + 8)).astype(np.float32)
    tex = cv2.resize(big, (2 * width, 2 * height), interpolation=cv2.INTER_CUBIC)
    tex = cv2.GaussianBlur(tex, (0, 0), 2.0)
    tex = (tex - tex.min()) / (np.ptp(tex) + 1e-9)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    cy, cx = height / 2, width / 2
    frames = []
    for t in range(n_frames):
        zoom = 1.0 + 0.004 * t
        mx = ((xx - cx) / zoom + cx + width / 2 + 1.5 * t).astype(np.float32)
        my = ((yy - cy) / zoom + cy + height / 2).astype(np.float32)
        f = cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        r = 6.0 * 1.06**t
        obj = (np.abs(xx - cx) < r) & (np.abs(yy - cy - 10) < 0.7 * r)
        f = np.where(obj, 0.1, 0.25 + 0.6 * f)
        frames.append(np.clip(f * 255.0, 0, 255).astype(np.uint8))
    return frames


def real_or_standin(n_frames: int, clip: str | Path | None = None, start: int = 0) -> tuple[str, list[np.ndarray]]:
    """``n_frames`` grey frames of a shared clip (decoded up front), else of :func:`standin_video`.

    Returns
    -------
    label : str
        ``"real:<clip>"`` or ``"standin"``.
    frames : list of ndarray (H, W) uint8
    """
    from ..frames import iter_grey, open_source

    path = Path(clip) if clip is not None else shared_clip()
    if path is None or not path.exists():
        return "standin", standin_video(n_frames)
    src = open_source(path)
    frames = []
    for t, f in enumerate(iter_grey(src)):
        if t >= start:
            frames.append(f)
        if len(frames) >= n_frames:
            break
    return f"real:{src.name}", frames


def basic_frames(name: str, n_frames: int, height: int = 600, width: int = 600,
                 start: int | None = None) -> list[np.ndarray]:
    """``n_frames`` consecutive frames of a basic stimulus (float32, (height, width)).

    ``start`` defaults to the middle of the sequence (a mid-size object).
    """
    from ..stimuli.basic import basic_stimulus

    st = basic_stimulus(name, height=height, width=width)
    k0 = max(0, st.n_frames // 2 - n_frames // 2) if start is None else start
    return [st.frame(k) for k in range(k0, min(st.n_frames, k0 + n_frames))]
