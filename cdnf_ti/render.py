"""Field movies: ``python -m cdnf_ti.run render VIDEO --model cdnf --out movie.mp4``.

Each output frame shows, side by side, the input and three of the model's
inner fields, colour-mapped (C-DNF: the ON, OFF and Summation fields
``u_on``, ``u_off``, ``v``; the LGMD family: ON, OFF and S; SDNF: P, E and u),
above the model's output trace so far with its threshold (or, for the LGMD
family, the spike count and ``n_ts``) and the alert. It shows why a model fires.

Frames are drawn with OpenCV (no matplotlib per frame) and written by
:func:`cdnf_ti.video.write_video`.
"""
from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import Any, Iterator, Sequence

import cv2
import numpy as np
from tqdm import tqdm

from .cli_common import EXIT_OK, ArgumentParser, add_model_options, parse_models
from .errors import UserError
from .experiments.labels import find_clip
from .experiments.layout import trace_path
from .frames import iter_grey, to_grey
from .inputs import resolve_input
from .models import create_model
from .models.base import NotConvergedWarning
from .video import codec_for, write_video

#: Fields shown per model (first three found), and their colour scale: "signed" (symmetric about 0) or "pos".
FIELD_CHOICES = {
    "cdnf": [("u_on", "ON field u_on"), ("u_off", "OFF field u_off"), ("v", "Summation field v")],
    "lgmd2": [("ON", "ON"), ("OFF", "OFF"), ("S", "Summation S")],
    "lgmd1": [("ON", "ON"), ("OFF", "OFF"), ("S", "Summation S")],
    "flgmd_onn": [("ON", "ON"), ("OFF", "OFF"), ("S", "Summation S")],
}
PANEL_FONT = cv2.FONT_HERSHEY_SIMPLEX
TRACE_H = 170


def _pick_fields(model_name: str, fields: dict[str, np.ndarray]) -> list[tuple[str, str]]:
    pref = [(k, t) for k, t in FIELD_CHOICES.get(model_name, []) if k in fields]
    rest = [(k, k) for k in fields if k not in dict(pref) and k != "P"]
    return (pref + rest)[:3]


class _Scale:
    """Colour scale of one field: symmetric about 0 for signed fields, fixed after the
    first frames so colours mean the same value all through the movie (running max)."""

    def __init__(self) -> None:
        self.lo, self.hi = 0.0, 1e-6

    def __call__(self, a: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=np.float32)
        lo, hi = float(np.percentile(a, 0.5)), float(np.percentile(a, 99.5))
        self.lo, self.hi = min(self.lo, lo), max(self.hi, hi)
        m = max(abs(self.lo), abs(self.hi), 1e-6)
        if self.lo < 0:
            x = (a / m + 1.0) * 0.5
        else:
            x = a / m
        u8 = np.clip(np.rint(x * 255.0), 0, 255).astype(np.uint8)
        return cv2.applyColorMap(u8, cv2.COLORMAP_TURBO if self.lo >= 0 else cv2.COLORMAP_TWILIGHT_SHIFTED)


def _label(img: np.ndarray, text: str) -> None:
    cv2.rectangle(img, (0, 0), (min(img.shape[1], 9 * len(text) + 8), 18), (0, 0, 0), -1)
    cv2.putText(img, text, (4, 13), PANEL_FONT, 0.42, (255, 255, 255), 1, cv2.LINE_AA)


def _trace_panel(width: int, t: int, n_total: int | None, out: list[float], thr: list[float | None],
                 spikes: list[bool], name: str, fps: float, window: tuple[int, int] | None) -> np.ndarray:
    """The output so far (white), its threshold (dashed yellow), alerts (red) over frames 0..n_total."""
    h = TRACE_H
    img = np.full((h, width, 3), 24, np.uint8)
    n = max(n_total or 0, t + 1, 2)
    x0, x1, y0, y1 = 46, width - 8, 24, h - 24
    vals = [v for v in out if np.isfinite(v)] + [v for v in thr if v is not None and np.isfinite(v)]
    lo, hi = (min(vals), max(vals)) if vals else (0.0, 1.0)
    if hi - lo < 1e-6:
        hi = lo + 1e-3
    pad = 0.08 * (hi - lo)
    lo, hi = lo - pad, hi + pad

    def X(i: float) -> int:
        return int(round(x0 + (x1 - x0) * i / (n - 1)))

    def Y(v: float) -> int:
        return int(round(y1 - (y1 - y0) * (v - lo) / (hi - lo)))

    if window is not None:
        cv2.rectangle(img, (X(window[0] - 0.5), y0), (X(window[1] + 0.5), y1), (120, 80, 160), -1)
    cv2.rectangle(img, (x0, y0), (x1, y1), (90, 90, 90), 1)
    for i in range(0, n, max(1, int(round(fps)))):  # a tick per second
        cv2.line(img, (X(i), y1), (X(i), y1 + 4), (160, 160, 160), 1)
        cv2.putText(img, f"{i}", (X(i) - 8, h - 6), PANEL_FONT, 0.35, (180, 180, 180), 1, cv2.LINE_AA)
    for v, txt in ((hi - pad, f"{hi - pad:.4g}"), (lo + pad, f"{lo + pad:.4g}")):
        cv2.putText(img, txt, (2, Y(v) + 4), PANEL_FONT, 0.3, (180, 180, 180), 1, cv2.LINE_AA)
    th = [(X(i), Y(v)) for i, v in enumerate(thr) if v is not None and np.isfinite(v)]
    for k in range(0, len(th) - 1, 2):  # dashed
        cv2.line(img, th[k], th[k + 1], (0, 220, 255), 1, cv2.LINE_AA)
    pts = np.array([(X(i), Y(v)) for i, v in enumerate(out) if np.isfinite(v)], np.int32)
    if len(pts) > 1:
        cv2.polylines(img, [pts.reshape(-1, 1, 2)], False, (255, 255, 255), 1, cv2.LINE_AA)
    for i, s in enumerate(spikes):
        if s:
            cv2.line(img, (X(i), y1 - 10), (X(i), y1), (0, 0, 255), 2)
    cv2.line(img, (X(t), y0), (X(t), y1), (0, 255, 0), 1)
    alert = bool(spikes and spikes[-1])
    cv2.putText(img, f"{name}  frame {t}  t={t / fps:.2f}s  (x axis: frames; purple: labelled window)", (x0, 16),
                PANEL_FONT, 0.42, (255, 255, 255), 1, cv2.LINE_AA)
    cv2.putText(img, "threshold --", (x1 - 200, 16), PANEL_FONT, 0.38, (0, 220, 255), 1, cv2.LINE_AA)
    if alert:
        cv2.putText(img, "ALERT", (x1 - 70, 17), PANEL_FONT, 0.55, (0, 0, 255), 2, cv2.LINE_AA)
    return img


def render_frames(model: Any, frames: Iterator[np.ndarray], fps: float, n_total: int | None = None,
                  window: tuple[int, int] | None = None, progress: bool | str = False) -> Iterator[np.ndarray]:
    """Step ``model`` through ``frames`` and yield one BGR movie frame per input frame.

    Parameters
    ----------
    model : Model
        A cdnf_ti model (reset here).
    frames : iterator of ndarray
        Grey frames (uint8 or float in [0, 1]).
    fps : float
        Input frame rate (frames/s), for the time labels.
    n_total : int, optional
        Number of frames (fixes the trace's x axis).
    window : (int, int), optional
        The labelled collision window (frames), shaded in the trace.
    """
    model.reset()
    out: list[float] = []
    thr: list[float | None] = []
    spikes: list[bool] = []
    scales = [_Scale(), _Scale(), _Scale()]
    uses_count = False
    n_ts = getattr(model.params, "n_ts", None)
    bar = None
    if progress:
        bar = tqdm(total=n_total, desc=progress if isinstance(progress, str) else "render", unit="frame",
                   disable=None)
    try:
        for t, frame in enumerate(frames):
            grey = to_grey(frame)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", NotConvergedWarning)  # recorded per frame in "converged"
                res = model.step(grey)
            if "count" in res.diagnostics and n_ts is not None:
                uses_count = True
                out.append(float(res.diagnostics["count"]))
                thr.append(float(n_ts))
            else:
                out.append(float(res.output))
                dyn = res.diagnostics.get("dyn_threshold")
                thr.append(float(dyn) if dyn is not None else model.threshold)
            spikes.append(bool(res.spike))
            g8 = grey if grey.dtype == np.uint8 else np.clip(np.rint(grey * 255), 0, 255).astype(np.uint8)
            panels = [cv2.cvtColor(g8, cv2.COLOR_GRAY2BGR)]
            _label(panels[0], "input")
            fields = model.fields()
            for (key, title), sc in zip(_pick_fields(model.name, fields), scales):
                img = sc(fields[key])
                if img.shape[:2] != g8.shape:
                    img = cv2.resize(img, (g8.shape[1], g8.shape[0]), interpolation=cv2.INTER_NEAREST)
                _label(img, title)
                panels.append(img)
            while len(panels) < 4:
                panels.append(np.zeros_like(panels[0]))
            top = np.concatenate([np.concatenate(panels[:2], 1), np.concatenate(panels[2:4], 1)], 0)
            name = f"{model.name} spike count (n_ts {n_ts})" if uses_count else f"{model.name} {model.output_name}"
            trace = _trace_panel(top.shape[1], t, n_total, out, thr, spikes, name, fps, window)
            movie = np.concatenate([top, trace], 0)
            if movie.shape[0] % 2 or movie.shape[1] % 2:  # even sizes for MPEG-4
                movie = movie[: movie.shape[0] // 2 * 2, : movie.shape[1] // 2 * 2]
            if bar is not None:
                bar.update(1)
            yield movie
    finally:
        if bar is not None:
            bar.close()


def render_video(source: str | Path, model_name: str, out: str | Path, params: Any = None, backend: str = "taichi",
                 arch: str = "cpu", window: tuple[int, int] | None = None, progress: bool | str = False) -> int:
    """Render the field movie of ``model_name`` on ``source`` to ``out`` (.mp4 or .avi); returns the frame count.

    Raises
    ------
    InputError
        Unreadable input, or a video the codec cannot write.
    UserError
        ``window`` is not ``0 <= start <= end <=`` the input's last frame.
    """
    codec_for(out)  # a bad suffix fails before any work
    src = resolve_input(source)
    if window is not None:
        last = src.n_frames - 1 if src.n_frames else None
        if not 0 <= window[0] <= window[1] or (last is not None and window[1] > last):
            raise UserError(f"{source}: window {window[0]}:{window[1]} must satisfy 0 <= START <= END <= "
                            f"{'the last frame' if last is None else last} (frames, inclusive)")
    model = create_model(model_name, params, backend=backend, arch=arch, fps=src.fps)
    frames = render_frames(model, iter_grey(src), src.fps, src.n_frames, window, progress)
    return write_video(out, frames, src.fps)


def render_main(argv: Sequence[str]) -> int:
    """``python -m cdnf_ti.run render VIDEO --model cdnf --out movie.mp4``."""
    ap = ArgumentParser(
        prog="python -m cdnf_ti.run render",
        description="Write a field movie: the input, the model's ON, OFF and Summation fields (colour-mapped) "
                    "and its output trace with threshold and alert, side by side.")
    ap.add_argument("input", metavar="VIDEO", help="video file, image folder, .npy or stim:NAME")
    ap.add_argument("--out", default=None, help="movie file, .mp4 or .avi (default: <input name>.<model>.mp4)")
    add_model_options(ap)
    ap.add_argument("--window", default=None, metavar="START:END",
                    help="labelled collision window in frames, shaded in the trace")
    ap.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    args = ap.parse_args(list(argv))
    models = parse_models(args.models)
    if len(models) != 1:
        raise UserError("render takes one --model")
    window = None
    if args.window:
        try:
            a, b = (int(x) for x in args.window.split(":"))
        except ValueError:
            raise UserError(f"--window must be START:END in frames, got {args.window!r}") from None
        window = (a, b)
    out = Path(args.out) if args.out else Path(f"{Path(str(args.input)).stem}.{models[0]}.mp4")
    n = render_video(args.input, models[0], out, backend=args.backend, arch=args.arch, window=window,
                     progress=False if args.no_progress else f"render {Path(str(args.input)).name}")
    print(f"{out}: {n} frames", file=sys.stderr)
    return EXIT_OK


def render_dataset(run: Any, folder: str | Path, progress: bool = False) -> list[Path]:
    """Field movies of every scored clip of a dataset run: ``OUT/movies/<clip>.<model>.mp4`` (clean input).

    A movie newer than its trace is kept (a rerun does not redraw it).
    """
    made = []
    for lab in run.labels:
        for m in run.models:
            row = next((r for r in run.rows if r["clip"] == lab.clip and r["model"] == m and not r.get("error")), None)
            if row is None:
                continue
            src = trace_path(run.out, row["condition"], lab.clip, m, "json")
            movie = Path(run.out) / "movies" / f"{lab.clip}.{m}.mp4"
            if movie.is_file() and src.is_file() and movie.stat().st_mtime >= src.stat().st_mtime:
                made.append(movie)
                continue
            video = find_clip(folder, lab.clip)
            if video is None:
                continue
            window = (lab.window_start, lab.window_end) if lab.collision else None
            render_video(video, m, movie, window=window,
                         progress=f"movie {lab.clip} [{m}]" if progress else False)
            made.append(movie)
    return made
