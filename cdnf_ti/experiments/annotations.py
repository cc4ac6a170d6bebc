"""One label form for every dataset: an event time, an alert time, per-frame labels, conditions.

cdnf_ti reads its own ``labels.csv`` (:mod:`.labels`) and the published layouts of the public
collision-anticipation benchmarks (:mod:`.benchmark_formats`). Both become a list of
:class:`Annotation`: per clip, the time of the event in seconds from the clip's start (``None`` for
a negative clip), an optional alert time (when the coming event first becomes predictable), optional
per-frame labels and optional conditions (weather, day/night, ego-involved). The benchmark scorers
(:mod:`.benchmark_scores`) work on this form only.

A ``labels.csv`` row maps onto it with the clip's frame rate ``fps`` (:func:`from_clip_label`): the
event is the contact frame's start ``contact_frame / fps`` (else the window's end), the alert the
window's start ``window_start / fps``, and the per-frame labels mark the window. An annotation maps
back onto a :class:`~.labels.ClipLabel` (:meth:`Annotation.to_clip_label`) so that a benchmark runs
through the same dataset engine and accuracy scoring as ``labels.csv``.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from .. import paths
from ..errors import InputError
from .labels import ClipLabel, frame_at

#: The window used for the accuracy table when an annotation gives no alert time: this many seconds
#: before the event up to the event (the longest Nexar horizon).
DEFAULT_WINDOW_S = 1.5


@dataclass(frozen=True)
class Annotation:
    """The label of one clip, in seconds.

    Attributes
    ----------
    clip : str
        The clip's name (unique within a dataset; safe as a file name).
    path : Path or None
        The clip's video file or image folder (``None``: the annotation names a video that is absent).
    event_s : float or None
        Time of the event (collision, accident, anomaly start) in s from the clip's first frame;
        ``None`` for a negative clip. May be negative or past the clip's end (kept as given; the
        scorers say how they treat it).
    alert_s : float or None
        Time from which the event is predictable (Nexar's ``time_of_alert``), s.
    frame_labels : tuple of int or None
        Per-frame labels (1 = event frame), frame ``k`` starting at ``k / fps`` s.
    fps : float or None
        The rate the annotation counts frames at (CCD 10, DAD 20, DoTA 10); ``None``: the video's own.
    conditions : dict of str to str
        Conditions of the clip (``weather``, ``timing`` day/night, ``ego_involved``, ...).
    source : str
        Where the annotation was read: ``file`` or ``file:line``.
    """

    clip: str
    path: Path | None
    event_s: float | None
    alert_s: float | None = None
    frame_labels: tuple[int, ...] | None = None
    fps: float | None = None
    conditions: dict = field(default_factory=dict, hash=False, compare=False)
    source: str = ""

    @property
    def positive(self) -> bool:
        """Whether the clip holds an event."""
        return self.event_s is not None or bool(self.frame_labels and any(self.frame_labels))

    def frame_label_array(self, n_frames: int, fps: float) -> np.ndarray:
        """Per-frame labels over the ``n_frames`` frames the model saw, shape ``(n_frames,)``, int 0/1.

        The annotation's own ``frame_labels`` when given (frames past their end are 0); otherwise every
        frame from the one holding the event on (``frame_at(event_s, fps)``); all 0 for a negative clip.
        """
        out = np.zeros(int(n_frames), dtype=np.int64)
        if self.frame_labels is not None:
            k = min(len(self.frame_labels), out.size)
            out[:k] = np.asarray(self.frame_labels[:k], dtype=np.int64) > 0
        elif self.event_s is not None:
            out[max(0, frame_at(max(self.event_s, 0.0), fps)):] = 1
        return out

    def to_clip_label(self, row: int) -> ClipLabel:
        """The :class:`~.labels.ClipLabel` that the dataset engine scores for accuracy.

        A positive clip is a ``collision`` with the window from the alert time (else
        :data:`DEFAULT_WINDOW_S` before the event) to the event, both in seconds and clipped at 0, and
        the event as the contact time; a negative clip is a ``non-collision``.
        """
        if not self.positive:
            return ClipLabel(self.clip, "non-collision", False, None, None, None, row)
        event = self.event_s if self.event_s is not None else 0.0
        start = self.alert_s if self.alert_s is not None and self.alert_s <= event else event - DEFAULT_WINDOW_S
        start, end = max(0.0, start), max(0.0, event)
        return ClipLabel(self.clip, "collision", True, None, None, None, row, window_s=(start, end), contact_s=end)


def from_clip_label(label: ClipLabel, fps: float, path: Path | None = None) -> Annotation:
    """A ``labels.csv`` row as an :class:`Annotation`, at the clip's rate ``fps`` (frames/s).

    The event is the start of the contact frame, ``contact_frame / fps`` (the window's end when no contact
    frame is given), the alert the start of the window, ``window_start / fps``; the per-frame labels mark
    the window's frames. The row's frames must already be set (:func:`~.labels.labels_in_frames`).
    """
    if not label.collision:
        return Annotation(label.clip, path, None, fps=fps, source=f"labels row {label.row}")
    contact = label.contact_frame if label.contact_frame is not None else label.window_end
    n = int(label.window_end) + 1
    frames = tuple(1 if k >= label.window_start else 0 for k in range(n))
    return Annotation(label.clip, path, contact / fps, label.window_start / fps, frames, fps,
                      source=f"labels row {label.row}")


def inside(folder: str | os.PathLike, name: str, annotation_file: str | os.PathLike) -> Path:
    """``folder / name`` (:func:`cdnf_ti.paths.inside`), also refused where a link leads out of ``folder``.

    Names read from an annotation file are untrusted: an absolute name, ``..`` or a link out of the
    dataset folder is an :class:`~cdnf_ti.errors.InputError` naming the annotation file.
    """
    try:
        path = paths.inside(folder, name)
    except paths.PathEscapeError as e:
        raise InputError(annotation_file, f"name {name!r} is not a file name inside {folder} ({e})") from None
    base, cand = Path(folder).resolve(), path.resolve()
    if cand != base and base not in cand.parents:
        raise InputError(annotation_file, f"name {name!r} points outside the dataset folder {folder}")
    return cand


def finite_seconds(text: object, what: str, where: str) -> float | None:
    """A time in seconds read from an annotation (``None`` for an empty field).

    Raises
    ------
    InputError
        Not a finite number.
    """
    if text is None or (isinstance(text, str) and not text.strip()):
        return None
    try:
        v = float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(where, f"{what} {text!r} is not a time in seconds") from None
    if not math.isfinite(v):
        raise InputError(where, f"{what} {text!r} is not a finite time")
    return v


def check_unique(annotations: Sequence[Annotation], where: str) -> None:
    """Refuse two annotations of the same clip (:class:`~cdnf_ti.errors.InputError`)."""
    seen: dict[str, str] = {}
    for a in annotations:
        if a.clip in seen:
            raise InputError(where, f"clip {a.clip!r} is annotated twice ({seen[a.clip]} and {a.source})")
        seen[a.clip] = a.source
