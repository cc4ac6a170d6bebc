"""Labels of a dataset: reading and validating the labels CSV (docs/EVALUATION.md).

A labels file has one row per clip; columns are found by their header names
(``clip,label,window_start,window_end[,contact_frame]``) and any other column
is ignored. A window may instead be given in seconds from the clip's start
(``window_start_s,window_end_s[,contact_s]``), row by row; :func:`labels_in_frames`
turns it into frames at the clip's rate (an event recording's: ``1000 / bin_ms``
bins per second), so the same labels hold for any ``--bin-ms``. Every problem is an
:class:`~cdnf_ti.errors.InputError` naming the file and the row (1-based line number in
the file, the header being line 1), raised before any model work starts.
"""
from __future__ import annotations

import csv
import dataclasses
import glob
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Iterable

from ..errors import InputError
from ..events.readers import is_event_file
from ..frames import open_source
from ..paths import inside, name_problem

#: Label values and the class each maps to (``near-miss`` counts as non-collision).
LABEL_VALUES = {"collision": True, "non-collision": False, "noncollision": False, "non_collision": False,
                "near-miss": False, "near_miss": False, "nearmiss": False}
REQUIRED_COLUMNS = ("clip", "label", "window_start", "window_end")
#: The window in seconds from the clip's start (instead of ``window_start``, ``window_end``, ``contact_frame``).
SECONDS_COLUMNS = ("window_start_s", "window_end_s", "contact_s")
#: Longest clip name (bytes, UTF-8): the longest file name (255) less room for what output names add
#: (``traces_<clip>.png``, ``<clip>.<model>.<condition>.mp4``).
CLIP_NAME_MAX = 200
#: File name endings tried, in order, when looking a clip up in the dataset folder.
VIDEO_EXTENSIONS = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg", ".wmv", ".npy")


@dataclass(frozen=True)
class ClipLabel:
    """The label of one clip.

    Attributes
    ----------
    clip : str
        Clip name (the video's file name without extension).
    label : str
        The label as written in the file (``collision``, ``non-collision``, ``near-miss``).
    collision : bool
        True for a collision clip.
    window_start, window_end : int or None
        The potential-collision window, frames, 0-based, inclusive (collision clips only).
    contact_frame : int or None
        Frame of contact, when known (used for the lead time).
    row : int
        Line number of the row in the labels file (header = 1).
    window_s : (float, float) or None
        The window as written in seconds (``window_start_s``, ``window_end_s``), when the row gives it
        so; ``window_start``/``window_end`` are then ``None`` until :func:`labels_in_frames` sets them.
    contact_s : float or None
        The contact time as written in seconds (``contact_s``).
    """

    clip: str
    label: str
    collision: bool
    window_start: int | None
    window_end: int | None
    contact_frame: int | None
    row: int
    window_s: tuple[float, float] | None = None
    contact_s: float | None = None

    @property
    def in_seconds(self) -> bool:
        """Whether the row gives its window or contact time in seconds."""
        return self.window_s is not None or self.contact_s is not None

    def to_dict(self) -> dict:
        return asdict(self)


class _RowError(Exception):
    """One bad row (collected; all of them are reported together)."""


#: How to fix each kind of problem (appended to the message).
HINTS = {
    "frame": "frames are 0-based whole numbers as read by cv2.VideoCapture",
    "label": "write collision, non-collision or near-miss",
    "window": "a collision clip needs window_start <= window_end (frames, inclusive)",
    "empty-window": "leave window_start and window_end empty for a non-collision clip, or label it collision",
    "clip": "give the video's file name without its extension",
    "plain": "a clip is a file in the dataset folder: give its name without any folder part, "
             f"at most {CLIP_NAME_MAX} bytes",
    "duplicate": "keep one row per clip (delete or merge the other)",
    "missing": "put the video in the dataset folder or fix the clip name",
    "outside": "frames are 0-based: the last frame of an N-frame video is N-1",
    "ambiguous": "write the file name with its extension in the clip column",
    "seconds": "times are seconds from the clip's start, numbers >= 0",
    "both": "give the window and contact in frames or in seconds, not both",
    "quote": "close the quote, or remove it: a field needs quotes only when it holds a comma",
}


def _bad(line: int, clip: str, problem: str, hint: str) -> _RowError:
    where = f"row {line}" + (f" ({clip})" if clip else "")
    return _RowError(f"{where}: {problem} (hint: {HINTS[hint]})")


def _int_field(path: str, line: int, name: str, text: str, clip: str = "") -> int | None:
    text = text.strip()
    if text == "":
        return None
    try:
        val = float(text)
    except ValueError:
        raise _bad(line, clip, f"{name} {text!r} is not a frame number", "frame") from None
    if not val.is_integer():
        raise _bad(line, clip, f"{name} {text!r} is not a whole frame number", "frame")
    if val < 0:
        raise _bad(line, clip, f"{name} {text!r} is negative", "frame")
    return int(val)


def _seconds_field(line: int, name: str, text: str, clip: str) -> float | None:
    text = text.strip()
    if text == "":
        return None
    try:
        val = float(text)
    except ValueError:
        raise _bad(line, clip, f"{name} {text!r} is not a time in seconds", "seconds") from None
    if not math.isfinite(val) or val < 0:
        raise _bad(line, clip, f"{name} {text!r} is not a time >= 0 s", "seconds")
    return val


def _reject(path: str, problems: list[str]) -> InputError:
    """One InputError listing every bad row (one line; rows separated by ' | ')."""
    head = f"{len(problems)} bad row{'s' if len(problems) > 1 else ''}: " if len(problems) > 1 else ""
    return InputError(path, head + " | ".join(problems))


def read_labels(path: str | os.PathLike) -> list[ClipLabel]:
    """Read and check a labels CSV (without looking at the videos).

    :func:`load_labels` also checks the videos, and reports every problem of both in one message.

    Parameters
    ----------
    path : path-like
        The labels file.

    Returns
    -------
    list of ClipLabel
        In file order.

    Raises
    ------
    InputError
        Missing file, missing columns, an unknown label value, a bad or missing
        window, ``window_start > window_end``, a duplicate clip, or an empty file;
        the message names the row.
    """
    labels, problems = _parse_labels(path)
    if problems:
        raise _reject(str(path), problems)
    if not labels:
        raise InputError(str(path), "labels file has a header but no rows")
    return labels


def _parse_labels(path: str | os.PathLike) -> tuple[list[ClipLabel], list[str]]:
    """The good rows of a labels CSV and the problems of the bad ones (:func:`read_labels`).

    Raises
    ------
    InputError
        The file cannot be read at all: missing, a folder, empty, not UTF-8, or its header lacks columns.
    """
    path = str(path)
    p = Path(path)
    if p.is_dir():
        raise InputError(path, "is a folder, not a labels CSV file")
    if not p.is_file():
        raise InputError(path, "labels file not found")
    try:
        with open(p, newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise InputError(path, f"cannot read labels file ({type(e).__name__}: {e})".splitlines()[0]) from None
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise InputError(path, "labels file is empty")
    header = [h.strip().lower() for h in rows[0]]
    seconds = all(c in header for c in SECONDS_COLUMNS[:2])
    missing = [c for c in REQUIRED_COLUMNS if c not in header and not (seconds and c.startswith("window_"))]
    if missing:
        raise InputError(path, f"header lacks column(s) {', '.join(missing)} "
                               f"(need {','.join(REQUIRED_COLUMNS)}[,contact_frame], or the window in seconds: "
                               f"{','.join(SECONDS_COLUMNS[:2])}[,contact_s])")
    col = {name: header.index(name) for name in header if name}
    labels: list[ClipLabel] = []
    seen: dict[str, int] = {}
    problems: list[str] = []
    for line, r in enumerate(rows[1:], start=2):
        if any("\n" in c or "\r" in c for c in r):  # the rest of the file was read into one quoted field
            problems.append(str(_bad(line, "", "a quote (\") opened in this row is never closed, so the rest of "
                                               "the file is read as one field", "quote")))
            break

        def get(name: str) -> str:
            i = col.get(name)
            return r[i] if i is not None and i < len(r) else ""  # noqa: B023 - called in this iteration only

        clip = get("clip").strip()
        try:
            if not clip:
                raise _bad(line, "", "empty clip name", "clip")
            if name_problem(clip, CLIP_NAME_MAX) is not None:
                shown = clip if len(clip) <= 120 else clip[:60] + "..."
                raise _bad(line, shown, f"clip name {name_problem(clip, CLIP_NAME_MAX)}", "plain")
            if clip in seen:
                raise _bad(line, "", f"clip {clip!r} is already labelled in row {seen[clip]}", "duplicate")
            seen[clip] = line
            lab = get("label").strip()
            errs = []  # every problem of the row, not only its first
            collision = LABEL_VALUES.get(lab.lower())
            if collision is None:
                errs.append(str(_bad(line, clip, f"label {lab!r} is not collision, non-collision or near-miss",
                                     "label")))
            vals = {}
            for name in ("window_start", "window_end", "contact_frame"):
                try:
                    vals[name] = _int_field(path, line, name, get(name), clip)
                except _RowError as e:
                    errs.append(str(e))
            for name in SECONDS_COLUMNS:
                try:
                    vals[name] = _seconds_field(line, name, get(name), clip)
                except _RowError as e:
                    errs.append(str(e))
            if errs:
                raise _RowError("; ".join(errs))
            ws, we, cf = vals["window_start"], vals["window_end"], vals["contact_frame"]
            ss, se, cs = vals["window_start_s"], vals["window_end_s"], vals["contact_s"]
            in_s = ss is not None or se is not None or cs is not None
            if in_s and (ws is not None or we is not None or cf is not None):
                raise _bad(line, clip, "the row gives both frames and seconds", "both")
            if collision and in_s:
                if ss is None or se is None:
                    raise _bad(line, clip, "a collision clip needs window_start_s and window_end_s", "window")
                if ss > se:
                    raise _bad(line, clip, f"window_start_s {ss:g} > window_end_s {se:g}", "window")
            elif collision:
                if ws is None or we is None:
                    raise _bad(line, clip, "a collision clip needs window_start and window_end", "window")
                if ws > we:
                    raise _bad(line, clip, f"window_start {ws} > window_end {we}", "window")
            elif ws is not None or we is not None or ss is not None or se is not None:
                raise _bad(line, clip, f"a {lab} clip must have an empty window", "empty-window")
        except _RowError as e:
            problems.append(str(e))
            continue
        labels.append(ClipLabel(clip, lab, collision, ws, we, cf, line,
                                window_s=(ss, se) if ss is not None and se is not None else None, contact_s=cs))
    return labels, problems


def drop_missing(labels: list[ClipLabel], folder: str | os.PathLike) -> tuple[list[ClipLabel], list[str]]:
    """The labels whose clip has a video in ``folder``, and the names of those that have none
    (``--skip-missing``: run the clips that exist)."""
    kept = [lab for lab in labels if find_clip(folder, lab.clip) is not None]
    return kept, [lab.clip for lab in labels if find_clip(folder, lab.clip) is None]


def find_clip(folder: str | os.PathLike, clip: str) -> Path | None:
    """The file (or image folder) of ``clip`` in ``folder``, or ``None``.

    ``clip`` must be a plain name (:func:`cdnf_ti.paths.inside` raises
    :class:`~cdnf_ti.paths.PathEscapeError` for one that leaves ``folder``).

    An exact file name wins; otherwise the first of :data:`VIDEO_EXTENSIONS`
    that exists; otherwise any file whose stem is ``clip``; otherwise a folder
    named ``clip`` (a folder of images).
    """
    folder = Path(folder)
    exact = inside(folder, clip)
    if exact.is_file():
        return exact
    for ext in VIDEO_EXTENSIONS:
        cand = inside(folder, f"{clip}{ext}")
        if cand.exists():
            return cand
    for cand in sorted(folder.glob(f"{glob_escape(clip)}.*")):
        if cand.is_file() and cand.stem == clip and not cand.name.endswith((".csv", ".md", ".json", ".txt")):
            return cand
    if exact.is_dir():
        return exact
    return None


def glob_escape(name: str) -> str:
    """Escape glob metacharacters in a file name."""
    return glob.escape(name)


def frame_count(path: Path) -> int | None:
    """The clip's frame count as the container reports it, or ``None`` if unknown/unreadable."""
    try:
        return open_source(path).n_frames
    except InputError:
        return None


def validate_dataset(labels: Iterable[ClipLabel], folder: str | os.PathLike,
                     labels_path: str | os.PathLike = "labels") -> dict[str, Path]:
    """Check every labelled clip exists in ``folder`` and its window lies inside the video.

    Parameters
    ----------
    labels : iterable of ClipLabel
    folder : path-like
        The dataset folder.
    labels_path : path-like
        The labels file, for messages.

    Returns
    -------
    dict of str to Path
        Clip name -> its file.

    Raises
    ------
    InputError
        The folder does not exist, a row names a clip with no file in the folder,
        or a window / contact frame lies past the video's last frame. Clips whose
        frame count cannot be read (corrupt) are not rejected here: they become
        error rows when the run reaches them.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(folder, "dataset folder not found")
    files, problems = _check_files(labels, folder)
    if problems:
        raise _reject(str(labels_path), problems)
    return files


def _check_files(labels: Iterable[ClipLabel], folder: Path) -> tuple[dict[str, Path], list[str]]:
    """Clip -> its file for the labels whose video is found, and the problems (:func:`validate_dataset`)."""
    files: dict[str, Path] = {}
    problems: list[str] = []
    for lab in labels:
        f = find_clip(folder, lab.clip)
        if f is None:
            problems.append(str(_bad(lab.row, "", f"clip {lab.clip!r} has no video in {folder}", "missing")))
            continue
        same_stem = _videos_named(folder, lab.clip) if f.name != lab.clip else []
        if len(same_stem) > 1:
            problems.append(str(_bad(lab.row, lab.clip, f"clip {lab.clip!r} matches several videos in {folder}: "
                                                        f"{', '.join(p.name for p in same_stem)}", "ambiguous")))
            continue
        files[lab.clip] = f
        if lab.window_start is not None or lab.contact_frame is not None:
            problems += _outside(lab, frame_count(f))
    return files, problems


def _outside(lab: ClipLabel, n: int | None) -> list[str]:
    """The problems of a label whose window or contact frame lies past the clip's last frame ``n - 1``."""
    if n is None:
        return []
    unit = " (from seconds)" if lab.in_seconds else ""
    return [str(_bad(lab.row, lab.clip, f"{name}{unit} {val} is outside the video (frames 0..{n - 1})", "outside"))
            for name, val in (("window_start", lab.window_start), ("window_end", lab.window_end),
                              ("contact_frame", lab.contact_frame)) if val is not None and val >= n]


#: Tolerance (frames) of a time that falls on a frame boundary.
_BOUNDARY = 1e-6


def frame_at(seconds: float, fps: float) -> int:
    """The frame (from 0) that holds time ``seconds``: frame ``k`` spans ``[k / fps, (k + 1) / fps)``."""
    return int(math.floor(seconds * fps + _BOUNDARY))


def last_frame_before(seconds: float, fps: float) -> int:
    """The last frame that starts before ``seconds`` (an inclusive window's end at ``seconds``)."""
    return int(math.ceil(seconds * fps - _BOUNDARY)) - 1


def labels_in_frames(labels: Iterable[ClipLabel], files: dict[str, Path], fps: float | None = None,
                     bin_ms: float | None = None, labels_path: str | os.PathLike = "labels") -> list[ClipLabel]:
    """The labels with every window given in seconds turned into frames at its clip's rate.

    A window ``[s, e]`` s covers the frames that start at or before ``e`` and end after ``s``:
    ``floor(s fps)`` to ``ceil(e fps) - 1`` (at least the first); the contact frame is the frame
    holding the contact time.

    Parameters
    ----------
    labels : iterable of ClipLabel
    files : dict
        Clip -> its file (:func:`validate_dataset`).
    fps : float, optional
        ``--fps``: the rate of every video (default: each video's own; 30 for image folders and
        ``.npy`` arrays).
    bin_ms : float, optional
        ``--bin-ms``: an event recording's rate is ``1000 / bin_ms`` bins per second (default 1000/30).
    labels_path : path-like
        The labels file, for messages.

    Raises
    ------
    InputError
        A window or contact time past a video's end.
    """
    out, problems = _in_frames(labels, files, fps, bin_ms)
    if problems:
        raise _reject(str(labels_path), problems)
    return out


def _in_frames(labels: Iterable[ClipLabel], files: dict[str, Path], fps: float | None,
               bin_ms: float | None) -> tuple[list[ClipLabel], list[str]]:
    """The labels in frames and the problems (:func:`labels_in_frames`)."""
    out, problems = [], []
    for lab in labels:
        f = files.get(lab.clip)
        if not lab.in_seconds or f is None:
            out.append(lab)
            continue
        if is_event_file(f):
            rate, n = 1000.0 / (bin_ms or 1000.0 / 30.0), None
        else:
            try:
                src = open_source(f, fps=fps)
                rate, n = src.fps, src.n_frames
            except InputError:  # a bad clip: its error row when the run reaches it
                rate, n = fps or 30.0, None
        ws = we = None
        if lab.window_s is not None:
            ws = frame_at(lab.window_s[0], rate)
            we = max(ws, last_frame_before(lab.window_s[1], rate))
        cf = None if lab.contact_s is None else frame_at(lab.contact_s, rate)
        lab = dataclasses.replace(lab, window_start=ws, window_end=we, contact_frame=cf)
        problems += _outside(lab, n)
        out.append(lab)
    return out, problems


def load_labels(labels_path: str | os.PathLike, folder: str | os.PathLike, fps: float | None = None,
                bin_ms: float | None = None, skip_missing: bool = False) -> tuple[list[ClipLabel], dict[str, Path]]:
    """Read a labels file and check it against the dataset folder, reporting every bad row in one pass.

    :func:`read_labels`, then (``skip_missing``) :func:`drop_missing`, :func:`validate_dataset` and
    :func:`labels_in_frames`, except that the problems of all three (a bad value, a clip with no video,
    a window past a video's end) are collected and raised together, in row order.

    Returns
    -------
    (list of ClipLabel, dict of str to Path)
        The labels with every window in frames, and clip -> its file.

    Raises
    ------
    InputError
        The folder or the file cannot be read, or any row is bad (one message naming every bad row).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(folder, "dataset folder not found")
    labels, problems = _parse_labels(labels_path)
    if skip_missing:
        labels, _ = drop_missing(labels, folder)
    files, missing = _check_files(labels, folder)
    labels, outside = _in_frames(labels, files, fps, bin_ms)
    problems = sorted(problems + missing + outside, key=_row_of)
    if problems:
        raise _reject(str(labels_path), problems)
    if not labels:
        raise InputError(str(labels_path), "labels file has a header but no rows")
    return labels, files


def _row_of(problem: str) -> int:
    """The row number a problem message starts with (``"row 5 (c06): ..."``)."""
    head = problem.split(" ", 2)
    return int(head[1].rstrip(":")) if len(head) > 1 and head[0] == "row" and head[1].rstrip(":").isdigit() else 0


def is_clip_file(path: Path) -> bool:
    """Whether ``path`` is a clip a dataset runs: a video file, an ``.npy`` array, or an event recording."""
    return path.is_file() and (path.suffix.lower() in VIDEO_EXTENSIONS or is_event_file(path))


def _videos_named(folder: Path, clip: str) -> list[Path]:
    """The clip files (:func:`is_clip_file`) in ``folder`` whose name is ``clip`` plus an extension."""
    return sorted(p for p in folder.glob(f"{glob_escape(clip)}.*") if p.stem == clip and is_clip_file(p))


def unlabelled_videos(folder: str | os.PathLike, labels: Iterable[ClipLabel]) -> list[str]:
    """File names of the videos, ``.npy`` arrays and event recordings in ``folder`` that no labels row names.

    Such videos are not run; the command line prints a note listing them.
    """
    folder = Path(folder)
    named = set()
    for lab in labels:
        f = find_clip(folder, lab.clip)
        if f is not None:
            named.add(f.name)
    try:
        entries = sorted(folder.iterdir())
    except OSError:
        return []
    return [p.name for p in entries if p.name not in named and is_clip_file(p)]
