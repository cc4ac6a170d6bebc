"""Readers of the public collision-anticipation benchmarks, in the layouts they are distributed in.

``python -m cdnf_ti.run dataset DIR --format nexar|ccd|dad|dota|labels`` reads ``DIR`` with
:func:`read_benchmark`; every reader returns :class:`~.annotations.Annotation` objects (docs/EVALUATION.md,
"Benchmarks", gives each format, its fields and their sources). Nothing is downloaded: the user supplies
the data. Annotation files are untrusted: each is size-capped before it is read, every name read from
one stays inside ``DIR`` (:func:`~.annotations.inside`), and any problem is one
:class:`~cdnf_ti.errors.InputError` naming the file (and line).
"""
from __future__ import annotations

import csv
import io
import json
import os
import re
from pathlib import Path
from typing import Callable

from ..errors import InputError
from .annotations import Annotation, check_unique, finite_seconds, inside

FORMATS = ("labels", "nexar", "ccd", "dad", "dota")
#: Largest annotation file read (bytes): far above any published one, so memory stays bounded.
MAX_ANNOTATION_BYTES = 64 * 1024 * 1024
#: Frame rates the benchmarks state (frames/s).
CCD_FPS, DAD_FPS, DOTA_FPS = 10.0, 20.0, 10.0
#: DAD: 100 frames per clip, the accident at frame 90 of every positive clip (Chan et al., ACCV 2016).
DAD_FRAMES, DAD_ACCIDENT_FRAME = 100, 90
#: Characters allowed in a clip name taken from an annotation (it becomes part of output file names).
_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,199}$")


def read_benchmark(fmt: str, folder: str | os.PathLike, annotation: str | os.PathLike | None = None,
                   split: str | None = None) -> list[Annotation]:
    """The annotations of a benchmark folder in its published layout.

    Parameters
    ----------
    fmt : {"nexar", "ccd", "dad", "dota"}
    folder : path-like
        The dataset folder as distributed (see each reader).
    annotation : path-like, optional
        The annotation file, where the format has one and it is not at its published place
        (``--labels``): Nexar's ``train.csv``, CCD's ``Crash-1500.txt``, DoTA's ``metadata_<split>.json``.
    split : str, optional
        DAD: ``training`` or ``testing``; DoTA: ``train`` or ``val`` (its metadata file); default: all clips.

    Returns
    -------
    list of Annotation
        In a stable order; an annotation whose video is absent has ``path=None``.

    Raises
    ------
    InputError
        A missing or bad annotation file, or a name that leaves the folder.
    """
    readers: dict[str, Callable[..., list[Annotation]]] = {
        "nexar": read_nexar, "ccd": read_ccd, "dad": read_dad, "dota": read_dota}
    if fmt not in readers:
        raise InputError(fmt, f"unknown dataset format; choose from {', '.join(FORMATS)}")
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(folder, "dataset folder not found")
    anns = readers[fmt](folder, None if annotation is None else Path(annotation), split)
    if not anns:
        raise InputError(folder, f"holds no {fmt} clip (see docs/EVALUATION.md for the {fmt} layout)")
    check_unique(anns, str(folder))
    return anns


def _read_text(path: Path) -> str:
    """An annotation file's text, at most :data:`MAX_ANNOTATION_BYTES`."""
    if not path.is_file():
        raise InputError(path, "annotation file not found")
    try:
        if path.stat().st_size > MAX_ANNOTATION_BYTES:
            raise InputError(path, f"annotation file is larger than {MAX_ANNOTATION_BYTES // 2**20} MiB")
        return path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(path, f"cannot read annotation file ({type(e).__name__})") from None


def _clip_name(name: str, where: str) -> str:
    name = name.strip()
    if not _SAFE_NAME.match(name):
        raise InputError(where, f"name {name!r} is not a plain file name (letters, digits, '.', '_', '-')")
    return name


def _first_existing(folder: Path, names: list[str], where: str) -> Path | None:
    for n in names:
        p = inside(folder, n, where)
        if p.exists():
            return p
    return None


def _flag(text: str, where: str, what: str) -> str:
    t = str(text).strip().lower()
    if t in ("1", "true", "yes", "y"):
        return "yes"
    if t in ("0", "false", "no", "n"):
        return "no"
    raise InputError(where, f"{what} {text!r} is not yes/no, true/false or 1/0")


# --- Nexar --------------------------------------------------------------------------------------------


def read_nexar(folder: Path, annotation: Path | None = None, split: str | None = None) -> list[Annotation]:
    """Nexar Dashcam Collision Prediction (Kaggle ``nexar-collision-prediction``).

    ``train.csv`` with columns ``id, time_of_event, time_of_alert, target`` (optional ``light_conditions``,
    ``weather``, ``scene``); the videos ``<id>.mp4`` in ``train/`` (the Kaggle archive), ``videos/`` or the
    folder itself, the id as written or zero-padded to 5 digits. ``target`` 1 is a collision or near-miss
    at ``time_of_event`` s, predictable from ``time_of_alert`` s; 0 is normal driving.
    """
    path = annotation or folder / "train.csv"
    rows = list(csv.reader(io.StringIO(_read_text(path))))
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise InputError(path, "annotation file is empty")
    header = [h.strip().lower() for h in rows[0]]
    missing = [c for c in ("id", "time_of_event", "time_of_alert", "target") if c not in header]
    if missing:
        raise InputError(path, f"header lacks column(s) {', '.join(missing)} (Nexar train.csv: "
                               "id,time_of_event,time_of_alert,target)")
    col = {h: i for i, h in enumerate(header)}
    out = []
    for line, r in enumerate(rows[1:], start=2):
        where = f"{path}:{line}"

        def get(name: str) -> str:
            i = col.get(name)
            return r[i].strip() if i is not None and i < len(r) else ""  # noqa: B023 - this row only

        clip = _clip_name(get("id"), where)
        target = get("target")
        if target not in ("0", "1", "0.0", "1.0"):
            raise InputError(where, f"target {target!r} is not 0 or 1")
        event = finite_seconds(get("time_of_event"), "time_of_event", where)
        alert = finite_seconds(get("time_of_alert"), "time_of_alert", where)
        if float(target) == 1:
            if event is None:
                raise InputError(where, "a target-1 row needs time_of_event")
            if alert is not None and alert > event:
                raise InputError(where, f"time_of_alert {alert:g} is after time_of_event {event:g}")
        else:
            event = alert = None
        names = [f"{d}{n}.mp4" for d in ("train/", "videos/", "") for n in dict.fromkeys((clip, clip.zfill(5)))]
        cond = {k: get(k) for k in ("light_conditions", "weather", "scene") if get(k)}
        out.append(Annotation(clip, _first_existing(folder, names, where), event, alert, None, None, cond, where))
    return out


# --- CCD ----------------------------------------------------------------------------------------------


def read_ccd(folder: Path, annotation: Path | None = None, split: str | None = None) -> list[Annotation]:
    """CCD, the Car Crash Dataset (Cogito2012/CarCrashDataset).

    ``Crash-1500.txt`` (in the folder or its ``videos/``), one line per accident video:
    ``vidname,[binlabels of the 50 frames],startframe,youtubeID,timing,weather,egoinvolve``; the accident
    videos ``Crash-1500/<vidname>.mp4`` and the normal videos ``Normal/*.mp4`` beside it. 50 frames at
    10 fps; a binlabel 1 marks an accident frame. Clips are named ``crash_<vidname>`` and ``normal_<name>``.
    """
    path = annotation or next((p for p in (folder / "Crash-1500.txt", folder / "videos" / "Crash-1500.txt")
                               if p.is_file()), folder / "Crash-1500.txt")
    base = path.parent
    out = []
    for line_no, line in enumerate(_read_text(path).splitlines(), start=1):
        if not line.strip():
            continue
        where = f"{path}:{line_no}"
        head, sep, rest = line.partition(",[")
        labels_text, sep2, tail = rest.partition("],")
        fields = [f.strip() for f in tail.split(",")]
        if not sep or not sep2 or len(fields) != 5:
            raise InputError(where, "expected vidname,[binlabels],startframe,youtubeID,timing,weather,egoinvolve")
        name = _clip_name(head, where)
        try:
            labels = tuple(int(v) for v in labels_text.split(",") if v.strip())
        except ValueError:
            raise InputError(where, "binlabels are not whole numbers") from None
        if not labels or any(v not in (0, 1) for v in labels):
            raise InputError(where, "binlabels must be a non-empty list of 0 and 1")
        first = labels.index(1) if 1 in labels else None
        cond = {"timing": fields[2], "weather": fields[3], "ego_involved": _flag(fields[4], where, "egoinvolve")}
        video = _first_existing(base, [f"Crash-1500/{name}.mp4"], where)
        out.append(Annotation(f"crash_{name}", video, None if first is None else first / CCD_FPS, None, labels,
                              CCD_FPS, cond, where))
    normal = base / "Normal"
    if normal.is_dir():
        for p in sorted(normal.glob("*.mp4")):
            name = _clip_name(p.stem, str(p))
            out.append(Annotation(f"normal_{name}", inside(base, f"Normal/{p.name}", str(path)), None, None,
                                  None, CCD_FPS, {}, str(p)))
    return out


# --- DAD ----------------------------------------------------------------------------------------------


def read_dad(folder: Path, annotation: Path | None = None, split: str | None = None) -> list[Annotation]:
    """DAD, the Dashcam Accident Dataset (smallcorgi/Anticipating-Accidents).

    ``videos/{training,testing}/{positive,negative}/*.mp4`` (or those folders in ``DIR`` itself): clips of
    100 frames at 20 fps; every positive clip has its accident at frame 90 (4.5 s), the convention of the
    authors' ``accident.py`` (``evaluation(..., total_time=90)``, fps 20). Clips are named
    ``<split>_<positive|negative>_<name>``.
    """
    root = folder / "videos" if (folder / "videos").is_dir() else folder
    splits = ("training", "testing") if split is None else (split,)
    if split is not None and split not in ("training", "testing"):
        raise InputError(folder, f"--split {split!r}: DAD has training and testing")
    out = []
    for sp in splits:
        for cls in ("positive", "negative"):
            d = root / sp / cls
            if not d.is_dir():
                continue
            for p in sorted(d.glob("*.mp4")):
                name = _clip_name(p.stem, str(p))
                frames = tuple(int(k >= DAD_ACCIDENT_FRAME) for k in range(DAD_FRAMES)) if cls == "positive" else None
                event = DAD_ACCIDENT_FRAME / DAD_FPS if cls == "positive" else None
                out.append(Annotation(f"{sp}_{cls}_{name}", inside(root, f"{sp}/{cls}/{p.name}", str(d)), event,
                                      None, frames, DAD_FPS, {"split": sp}, str(p)))
    return out


# --- DoTA ---------------------------------------------------------------------------------------------


def read_dota(folder: Path, annotation: Path | None = None, split: str | None = None) -> list[Annotation]:
    """DoTA, Detection of Traffic Anomaly (MoonBlvd/Detection-of-Traffic-Anomaly).

    ``annotations/<video_name>.json`` per clip (``num_frames``, ``anomaly_start``, ``anomaly_end``,
    ``ego_involve``, ``night``, ``accident_name``, ``labels[].accident_id`` per frame), the extracted frames
    ``frames/<video_name>/images/*.jpg`` at 10 fps (the repository's ``video2frames.py -f 10``), and
    ``metadata_train.json`` / ``metadata_val.json`` listing each split's clips. The anomaly covers frames
    ``anomaly_start`` to ``anomaly_end - 1`` (the repository's ``labels[anomaly_start:anomaly_end] = 1``)
    unless the per-frame ``accident_id`` (0 = normal) is given.
    """
    root = folder / "dataset" if not (folder / "annotations").is_dir() and (folder / "dataset").is_dir() else folder
    ann_dir = root / "annotations"
    if split is not None or annotation is not None:
        meta_path = annotation or root / f"metadata_{split}.json"
        meta = _json(meta_path)
        if not isinstance(meta, dict):
            raise InputError(meta_path, "expected an object mapping video names to their metadata")
        names = [_clip_name(str(k), str(meta_path)) for k in meta]
    else:
        if not ann_dir.is_dir():
            raise InputError(ann_dir, "DoTA annotations folder not found")
        names = [p.stem for p in sorted(ann_dir.glob("*.json"))]
    out = []
    for name in names:
        jp = inside(root, f"annotations/{_clip_name(name, str(ann_dir))}.json", str(ann_dir))
        out.append(_dota_clip(root, name, jp))
    return out


def _json(path: Path):
    try:
        return json.loads(_read_text(path))
    except json.JSONDecodeError as e:
        raise InputError(path, f"not valid JSON (line {e.lineno}: {e.msg})") from None


def _dota_clip(root: Path, name: str, jp: Path) -> Annotation:
    d = _json(jp)
    if not isinstance(d, dict):
        raise InputError(jp, "expected a JSON object")
    try:
        n = int(d["num_frames"])
        start, end = int(d["anomaly_start"]), int(d["anomaly_end"])
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(jp, f"num_frames, anomaly_start and anomaly_end must be whole numbers ({e})") from None
    if not (0 < n <= 1_000_000) or not (0 <= start <= end <= n):
        raise InputError(jp, f"needs 0 <= anomaly_start <= anomaly_end <= num_frames, got {start}, {end}, {n}")
    if "video_name" in d and str(d["video_name"]) != name:
        raise InputError(jp, f"video_name {d['video_name']!r} differs from the file name {name!r}")
    per_frame = d.get("labels")
    if isinstance(per_frame, list) and per_frame:
        try:
            labels = tuple(int(int(f.get("accident_id", 0)) > 0) for f in per_frame[:n])
        except (AttributeError, TypeError, ValueError):
            raise InputError(jp, "labels[].accident_id must be whole numbers") from None
    else:
        labels = tuple(int(start <= k < end) for k in range(n))
    first = labels.index(1) if 1 in labels else None
    cond = {"ego_involved": _flag(d.get("ego_involve", "false"), str(jp), "ego_involve"),
            "timing": "night" if _flag(d.get("night", "false"), str(jp), "night") == "yes" else "day"}
    if d.get("accident_name"):
        cond["anomaly"] = str(d["accident_name"])[:80]
    frames = _first_existing(root, [f"frames/{name}/images", f"frames/{name}"], str(jp))
    return Annotation(name, frames, None if first is None else first / DOTA_FPS, None, labels, DOTA_FPS, cond,
                      str(jp))
