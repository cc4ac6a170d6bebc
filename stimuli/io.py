"""Lossless stimulus files: FFV1 AVI or a PNG folder, plus a JSON sidecar.

Frames (float in [0, 1] or uint8, grey) are stored as 8-bit grey:
``uint8 = round(255 x)``. FFV1 and PNG are lossless, so reading a file back
gives exactly those 8-bit frames (binary stimuli come back exactly).

The sidecar (:func:`sidecar_path`) records every parameter and the seed; it is
written after the frames, both atomically.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterable, Iterator

import cv2
import numpy as np
from tqdm import tqdm

from ..atomic import atomic_write, atomic_write_json
from ..errors import InputError, OutputError, UserError, output_error
from ..frames import iter_grey, open_source
from ..video import open_writer

FORMATS = ("avi", "png")


def output_format(path: str | os.PathLike) -> str:
    """``"avi"`` for a ``.avi`` path, ``"png"`` (a folder of PNG frames) for a path with no suffix."""
    suffix = Path(path).suffix.lower()
    if suffix == ".avi":
        return "avi"
    if suffix == "":
        return "png"
    raise UserError(f"{path}: output must be a .avi file (FFV1, lossless) or a folder name without a suffix "
                    f"(PNG frames)")


def sidecar_path(path: str | os.PathLike) -> Path:
    """``clip.avi`` -> ``clip.json``; PNG folder ``clip`` -> ``clip/sidecar.json``."""
    p = Path(path)
    return p.with_suffix(".json") if output_format(p) == "avi" else p / "sidecar.json"


def to_uint8(frame: np.ndarray) -> np.ndarray:
    """Grey frame (float in [0, 1] or uint8) -> uint8 ``round(255 x)``."""
    a = np.asarray(frame)
    if a.dtype == np.uint8:
        return np.ascontiguousarray(a)
    return np.clip(np.rint(a.astype(np.float64) * 255.0), 0, 255).astype(np.uint8)


def _write_failure(path: Path) -> str:
    """Why writing next to ``path`` probably failed: the free space on its file system."""
    try:
        free = shutil.disk_usage(path.parent).free
    except OSError:
        return "write error"
    if free < 16 * 2**20:
        return f"No space left on device: {free / 2**20:.1f} MB free"
    return "write error or file size limit"


def write_frames(frames: Iterable[np.ndarray], path: str | os.PathLike, fps: float = 30.0,
                 progress: bool | str = False, total: int | None = None) -> int:
    """Stream grey frames to a lossless file and return the frame count.

    Parameters
    ----------
    frames : iterable of ndarray, each (H, W)
        float in [0, 1] or uint8; consumed one at a time.
    path : path
        ``*.avi`` (FFV1) or a folder name (PNG frames ``000000.png`` ...). An
        existing output is replaced only once the new one is complete.
    fps : float
        Frame rate stored in the AVI.
    progress : bool or str
        tqdm progress bar (label when a string); silent when not a TTY.
    """
    fmt = output_format(path)
    path = Path(path)
    bar = None
    if progress:
        bar = tqdm(total=total, desc=progress if isinstance(progress, str) else path.name, unit="frame",
                   leave=False, disable=None)
    count = 0
    try:
        if fmt == "avi":
            def write(tmp: str) -> None:
                nonlocal count
                writer = None
                try:
                    for f in frames:
                        g = to_uint8(f)
                        if writer is None:
                            try:
                                writer = open_writer(tmp, fps, (g.shape[1], g.shape[0]), "FFV1", is_color=False,
                                                     name=path)
                            except InputError:
                                raise InputError(path, "cannot open an FFV1 AVI writer (OpenCV without FFV1?); "
                                                       "give a folder name for PNG frames instead") from None
                            shape = g.shape
                        if g.shape != shape:
                            raise ValueError(f"{path}: frame {count} has shape {g.shape}, expected {shape}")
                        writer.write(g)
                        count += 1
                        if bar is not None:
                            bar.update(1)
                finally:
                    if writer is not None:
                        writer.release()
                if count == 0:
                    raise ValueError(f"{path}: no frames to write")
                check = cv2.VideoCapture(tmp)  # the container must hold every frame at this fps
                stored = int(check.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
                stored_fps = float(check.get(cv2.CAP_PROP_FPS) or 0.0)
                last_ok = False
                if stored > 0:  # a file cut short (full disk) still states the full count in its header
                    check.set(cv2.CAP_PROP_POS_FRAMES, stored - 1)
                    last_ok = bool(check.read()[0])
                check.release()
                fps_ok = abs(stored_fps - float(fps)) <= 1e-3 * float(fps)
                if not last_ok or (stored != count and fps_ok):  # not the frame rate: the write failed
                    raise OutputError(path, f"the file was cut short: not all {count} frames could be "
                                            f"written ({_write_failure(path)})")
                if stored != count or not fps_ok:
                    raise InputError(path, f"the AVI holds {stored} frames at {stored_fps:g} fps instead of "
                                           f"{count} at {float(fps):g} fps (frame rate not representable); "
                                           "write PNG frames (a folder name) instead")

            atomic_write(path, write)
        else:
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
            except OSError as e:
                raise output_error(path, e) from None
            try:
                for f in frames:
                    g = to_uint8(f)
                    if not cv2.imwrite(str(tmp / f"{count:06d}.png"), g):
                        raise OutputError(path, f"cannot write PNG frame {count} ({_write_failure(path)})")
                    count += 1
                    if bar is not None:
                        bar.update(1)
                if count == 0:
                    raise ValueError(f"{path}: no frames to write")
                if path.exists():
                    if not path.is_dir():
                        raise InputError(path, "exists and is not a folder")
                    shutil.rmtree(path)
                os.replace(tmp, path)
            except OSError as e:
                shutil.rmtree(tmp, ignore_errors=True)
                raise output_error(path, e) from None
            except BaseException:
                shutil.rmtree(tmp, ignore_errors=True)
                raise
    finally:
        if bar is not None:
            bar.close()
    return count


def write_sidecar(path: str | os.PathLike, meta: dict[str, Any]) -> Path:
    """Write ``meta`` as the JSON sidecar of output ``path`` (atomically); return its path."""
    sp = sidecar_path(path)
    atomic_write_json(sp, meta)
    return sp


def read_sidecar(path: str | os.PathLike) -> dict[str, Any]:
    """Read the JSON sidecar of output ``path``."""
    sp = sidecar_path(path)
    try:
        return json.loads(Path(sp).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(sp, "no such sidecar file") from None
    except json.JSONDecodeError as e:
        raise InputError(sp, f"not valid JSON ({e.msg} at line {e.lineno})") from None


def read_frames(path: str | os.PathLike) -> Iterator[np.ndarray]:
    """Yield the frames of a written file as float32 (H, W) in [0, 1] (``uint8 / 255``)."""
    for g in iter_grey(open_source(path)):
        yield g.astype(np.float32) / np.float32(255.0) if g.dtype == np.uint8 else g


def read_frames_uint8(path: str | os.PathLike) -> Iterator[np.ndarray]:
    """Yield the frames of a written file as stored: uint8 (H, W)."""
    for g in iter_grey(open_source(path)):
        yield to_uint8(g)
