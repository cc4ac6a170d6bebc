"""Small benchmark folders in each published layout, made from the basic stimuli (for the tests).

Each ``make_<format>(folder)`` writes a handful of short synthetic clips (64 x 64 px, a few KB each) and the
annotation files in the exact format the benchmark distributes (docs/EVALUATION.md, "Benchmarks"), and
returns what it wrote: ``{clip name as the reader names it: (event frame or None, fps, per-frame labels)}``
(the labels as the benchmark defines them; all 0 for a negative clip). Positive clips
loom up to their event frame; negative clips translate or recede.
"""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from cdnf_ti.stimuli.basic import basic_stimulus
from cdnf_ti.video import write_video

SIZE = 64


def clip_frames(n: int, event: int | None, stimulus: str | None = None) -> list[np.ndarray]:
    """``n`` grey frames (uint8): a looming stimulus that fills the view at frame ``event`` and holds, or
    ``stimulus`` (default a translating bar) for a negative clip, held at its ends to make ``n`` frames."""
    name = stimulus or ("dark_looming" if event is not None else "dark_translating")
    frames = [np.asarray(f) for f in basic_stimulus(name, height=SIZE, width=SIZE).frames()]
    if event is not None:
        frames = frames[-(event + 1):]
        frames = [frames[0]] * (event + 1 - len(frames)) + frames
    frames = (frames + [frames[-1]] * n)[:n]
    return [np.clip(np.asarray(f, dtype=np.float64) * (255 if f.dtype != np.uint8 else 1), 0, 255).astype(np.uint8)
            for f in frames]


def make_nexar(folder: Path) -> dict:
    """Kaggle ``nexar-collision-prediction``: ``train.csv`` and ``train/<id>.mp4`` (30 fps, 2 s clips)."""
    fps, n = 30.0, 60
    rows = [("00001", 1.8, 1.0, 1), ("00002", None, None, 0), ("00003", 1.6, 0.9, 1), ("00004", None, None, 0)]
    (folder / "train").mkdir(parents=True, exist_ok=True)
    lines = ["id,time_of_event,time_of_alert,target"]
    out = {}
    for vid, ev, al, target in rows:
        event = None if ev is None else round(ev * fps)
        write_video(folder / "train" / f"{vid}.mp4", clip_frames(n, event, None if target else "light_receding"), fps)
        lines.append(f"{vid},{'' if ev is None else ev},{'' if al is None else al},{target}")
        out[vid] = (event, fps, [int(event is not None and k >= event) for k in range(n)])
    (folder / "train.csv").write_text("\n".join(lines) + "\n")
    return out


def make_ccd(folder: Path) -> dict:
    """CarCrashDataset: ``Crash-1500.txt``, ``Crash-1500/<vidname>.mp4``, ``Normal/<name>.mp4`` (50 frames, 10 fps)."""
    fps, n = 10.0, 50
    crashes = [("000001", 40, "Day", "Normal", "Yes"), ("000002", 35, "Night", "Rainy", "No"),
               ("000003", 42, "Day", "Rainy", "Yes")]
    (folder / "Crash-1500").mkdir(parents=True, exist_ok=True)
    (folder / "Normal").mkdir(parents=True, exist_ok=True)
    lines, out = [], {}
    for i, (vid, event, timing, weather, ego) in enumerate(crashes):
        write_video(folder / "Crash-1500" / f"{vid}.mp4", clip_frames(n, event), fps)
        bins = ", ".join(str(int(k >= event)) for k in range(n))
        lines.append(f"{vid},[{bins}],{1000 + 37 * i:06d},{5000 + i},{timing},{weather},{ego}")
        out[f"crash_{vid}"] = (event, fps, [int(k >= event) for k in range(n)])
    for vid in ("000001", "000002"):
        write_video(folder / "Normal" / f"{vid}.mp4", clip_frames(n, None), fps)
        out[f"normal_{vid}"] = (None, fps, [0] * n)
    (folder / "Crash-1500.txt").write_text("\n".join(lines) + "\n")
    return out


def make_dad(folder: Path) -> dict:
    """DAD: ``videos/{training,testing}/{positive,negative}/<name>.mp4``, 100 frames at 20 fps, accident at
    frame 90 of every positive clip."""
    fps, n, out = 20.0, 100, {}
    for split, cls, name in (("testing", "positive", "000001"), ("testing", "positive", "000002"),
                             ("testing", "negative", "000001"), ("training", "positive", "000003"),
                             ("training", "negative", "000004")):
        d = folder / "videos" / split / cls
        d.mkdir(parents=True, exist_ok=True)
        event = 90 if cls == "positive" else None
        write_video(d / f"{name}.mp4", clip_frames(n, event), fps)
        out[f"{split}_{cls}_{name}"] = (event, fps, [int(event is not None and k >= event) for k in range(n)])
    return out


def make_dota(folder: Path) -> dict:
    """DoTA: ``annotations/<video_name>.json``, ``frames/<video_name>/images/000000.jpg ...`` (10 fps) and
    ``metadata_train.json`` / ``metadata_val.json``."""
    fps, out = 10.0, {}
    clips = [("aaaaaaaaaaa_000100", 40, 30, 36, True, False, "train"),
             ("bbbbbbbbbbb_000200", 45, 25, 41, False, True, "val"),
             ("ccccccccccc_000300", 40, 32, 40, True, True, "val")]
    (folder / "annotations").mkdir(parents=True, exist_ok=True)
    meta: dict = {"train": {}, "val": {}}
    for name, n, start, end, ego, night, subset in clips:
        img = folder / "frames" / name / "images"
        img.mkdir(parents=True, exist_ok=True)
        for k, f in enumerate(clip_frames(n, start)):
            cv2.imwrite(str(img / f"{k:06d}.jpg"), f)
        per_frame = [{"frame_id": k, "image_path": f"{name}/images/{k:06d}.jpg",
                      "accident_id": 3 if start <= k < end else 0,
                      "accident_name": "lateral" if start <= k < end else "normal", "objects": []} for k in range(n)]
        (folder / "annotations" / f"{name}.json").write_text(json.dumps({
            "video_name": name, "num_frames": n, "video_start": 100, "video_end": 100 + n - 1,
            "anomaly_start": start, "anomaly_end": end, "accident_id": 3, "accident_name": "lateral",
            "ego_involve": ego, "night": night, "labels": per_frame}))
        meta[subset][name] = {"video_start": 100, "video_end": 100 + n - 1, "anomaly_start": start,
                              "anomaly_end": end, "anomaly_class": "ego: lateral", "num_frames": n, "subset": subset}
        out[name] = (start, fps, [int(start <= k < end) for k in range(n)])
    for subset, d in meta.items():
        (folder / f"metadata_{subset}.json").write_text(json.dumps(d, indent=2))
    return out


MAKERS = {"nexar": make_nexar, "ccd": make_ccd, "dad": make_dad, "dota": make_dota}
