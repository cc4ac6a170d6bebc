"""Field movies: ``python -m cdnf_ti.run render VIDEO --model cdnf --out movie.mp4``.

Each output frame shows, side by side, the input and three of the model's
inner fields, colour-mapped (C-DNF: the ON, OFF and Summation fields
``u_on``, ``u_off``, ``v``; the LGMD family: ON, OFF and S; SDNF: P, E and u),
above the model's output trace so far with its threshold (or, for the LGMD
family, the spike count and ``n_ts``) and the alert. It shows why a model fires.

Every panel has a colour bar with a **fixed** scale: a first pass over the input
finds each field's range over the whole clip (0.5 and 99.5 percentiles of each
frame, then the extremes of those), so a colour means the same value in every
frame. Signed fields use a diverging map symmetric about 0.

An event recording (docs/EVENTS.md) is rendered bin by bin: the model takes each
bin through its ON/OFF input stage, and the input panel shows the bin's net contrast
``P_on - P_off`` on grey, ON events green and OFF events red (:func:`event_panel`).

Several models (``--model cdnf,lgmd2``) or ``--rain both`` make one movie each,
``<clip>.<model>[.rain].mp4`` in the ``--out`` folder; ``--out`` names the movie
file itself (``.mp4`` or ``.avi``) when one movie is made.

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

from .atomic import prepare_output
from .cli_common import (
    EXIT_OK,
    ArgumentParser,
    add_event_options,
    add_input_options,
    add_model_options,
    add_output_option,
    add_param_options,
    add_rain_options,
    add_seed_options,
    check_model_options,
    event_options_of,
    note_unused_rain_options,
    params_from_args,
    parse_models,
    rain_conditions,
    rain_seed_of,
)
from .errors import InputError, UserError
from .events.binning import DEFAULT_BIN_MS, DEFAULT_EVENT_THRESHOLD
from .events.readers import is_event_file
from .events.source import EventSource, open_event_source
from .experiments.labels import find_clip
from .experiments.layout import trace_path
from .frames import ColourFrame, iter_frames, to_grey
from .inputs import resolve_input
from .limits import check_frame_size
from .models import create_model, get_model_class
from .models.base import NotConvergedWarning, bin_ms_for, takes_colour
from .paths import inside
from .stimuli.rain import RainParams, RainyFrames
from .video import codec_for, to_uint8, write_video

PANEL_FONT = cv2.FONT_HERSHEY_SIMPLEX
TRACE_H = 170


def _pick_fields(model_name: str, fields: dict[str, np.ndarray]) -> list[tuple[str, str]]:
    pref = [(k, t) for k, t in get_model_class(model_name).panels if k in fields]  # the model's declared panels
    rest = [(k, k) for k in fields if k not in dict(pref) and k != "P"]
    return (pref + rest)[:3]


#: Width (px) of the colour bar strip right of every panel: the bar and its value labels.
CBAR_W = 56


def _diverging_lut() -> np.ndarray:
    """A diverging colour map for :func:`cv2.applyColorMap`, (256, 1, 3) uint8 BGR: blue (most negative),
    white (0, the middle), red (most positive); ColorBrewer's RdBu stops, interpolated."""
    rgb = np.array([(33, 102, 172), (67, 147, 195), (146, 197, 222), (209, 229, 240), (247, 247, 247),
                    (253, 219, 199), (244, 165, 130), (214, 96, 77), (178, 24, 43)], float)
    x = np.linspace(0.0, 255.0, len(rgb))
    lut = np.stack([np.interp(np.arange(256), x, rgb[:, c]) for c in (2, 1, 0)], axis=1)  # BGR
    return np.rint(lut).astype(np.uint8)[:, None, :]


#: The colour map of a signed field (symmetric about 0): diverging, white at 0.
DIVERGING = _diverging_lut()
#: The colour map of a non-negative field (from 0): sequential, dark at 0 and light at the top.
SEQUENTIAL = cv2.COLORMAP_VIRIDIS


class FieldScale:
    """A fixed colour scale of one field: ``lo .. hi``; a field with negative values is shown
    symmetric about 0 with a diverging map (:data:`DIVERGING`, white at 0), a non-negative one
    from 0 with a sequential map (:data:`SEQUENTIAL`).

    Without a range (``FieldScale()``) the scale grows with the values it has seen (a running
    range; :func:`render_frames` called without ``ranges``).
    """

    def __init__(self, lo: float | None = None, hi: float | None = None, grey: bool = False) -> None:
        self.grey = grey  # a grey ramp (the input panel)
        self.fixed = lo is not None and hi is not None
        self.lo, self.hi = (float(lo), float(hi)) if self.fixed else (0.0, 1e-6)

    @property
    def signed(self) -> bool:
        return self.lo < 0

    @property
    def limits(self) -> tuple[float, float]:
        """The values at the two ends of the colour bar."""
        if self.signed:
            m = max(abs(self.lo), abs(self.hi), 1e-6)
            return -m, m
        return min(self.lo, 0.0), max(self.hi, min(self.lo, 0.0) + 1e-6)

    def _cmap(self) -> int | np.ndarray:
        """:data:`DIVERGING` for a signed field, :data:`SEQUENTIAL` for a non-negative one."""
        return DIVERGING if self.signed else SEQUENTIAL

    def __call__(self, a: np.ndarray) -> np.ndarray:
        """The field as a BGR image (uint8, (H, W, 3))."""
        a = np.asarray(a, dtype=np.float32)
        if not self.fixed:
            lo, hi = robust_range(a)
            self.lo, self.hi = min(self.lo, lo), max(self.hi, hi)
        lo, hi = self.limits
        u8 = np.clip(np.rint((a - lo) / (hi - lo) * 255.0), 0, 255).astype(np.uint8)
        return cv2.applyColorMap(u8, self._cmap())

    def bar(self, height: int) -> np.ndarray:
        """The colour bar strip (``height`` x :data:`CBAR_W`): the map from ``hi`` (top) to ``lo``, labelled."""
        img = np.full((height, CBAR_W, 3), 24, np.uint8)
        ramp = np.linspace(255, 0, height).astype(np.uint8)[:, None]
        ramp = np.repeat(ramp, 8, axis=1)
        img[:, 2:10] = cv2.cvtColor(ramp, cv2.COLOR_GRAY2BGR) if self.grey else cv2.applyColorMap(ramp, self._cmap())
        lo, hi = self.limits
        marks = [(hi, 8), (lo, height - 2)] + ([(0.0, height // 2 + 3)] if self.signed and height >= 40 else [])
        for v, y in marks:
            cv2.putText(img, f"{v:.3g}", (12, y), PANEL_FONT, 0.3, (230, 230, 230), 1, cv2.LINE_AA)
        return img


def robust_range(a: np.ndarray) -> tuple[float, float]:
    """The 0.5 and 99.5 percentiles of ``a`` (finite values; (0, 0) when none)."""
    a = np.asarray(a, dtype=np.float32)
    a = a[np.isfinite(a)]
    if not a.size:
        return 0.0, 0.0
    lo, hi = np.percentile(a, (0.5, 99.5))
    return float(lo), float(hi)


#: The key of the event panel's scale in :func:`field_ranges`.
EVENTS_KEY = "events"
#: The key of the trace panel's y range in :func:`field_ranges`.
TRACE_KEY = "trace"


def _rule_column(model: Any, res: Any) -> Any:
    """The model's alert rule when it compares a diagnostic of ``res`` rather than the output (EMD-LPLC2: ``V``
    before a spike's reset; oLGMD: the spike sum), else None."""
    rule = model.alert_rule() if hasattr(model, "alert_rule") else None
    if rule is None or rule.column == model.output_name or rule.column not in res.diagnostics:
        return None
    return rule


def _trace_values(model: Any, res: Any, n_ts: int | None) -> tuple[float, float | None]:
    """What the trace panel draws for one step: the spike count and ``n_ts`` (the LGMD family); the diagnostic
    the alert rule compares and its level (:func:`_rule_column`); else the output and its threshold (SDNF: the
    dynamic one; None: none)."""
    if "count" in res.diagnostics and n_ts is not None:
        return float(res.diagnostics["count"]), float(n_ts)
    rule = _rule_column(model, res)
    if rule is not None:
        return float(res.diagnostics[rule.column]), float(rule.level)
    dyn = res.diagnostics.get("dyn_threshold")
    return float(res.output), (float(dyn) if dyn is not None else model.threshold)


def _step(model: Any, item: Any) -> Any:
    """Step ``model`` on one input: a frame (an array, or a :class:`~cdnf_ti.frames.ColourFrame`: the form the model
    takes), or an event bin ``(p_on, p_off)`` (its ON/OFF input stage)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotConvergedWarning)  # recorded per frame in "converged"
        return model.step_on_off(*item) if isinstance(item, tuple) else model.step(item)


def field_ranges(model: Any, frames: Iterator[np.ndarray], progress: bool | str = False,
                 n_total: int | None = None) -> dict[str, tuple[float, float]]:
    """First pass of a movie: each shown field's range over all ``frames`` (the colour bars' fixed scales).

    Returns ``{field: (lo, hi)}``: the smallest 0.5 and the largest 99.5 percentile over the frames;
    for event bins also ``{"events": (-m, m)}``, ``m`` the largest net contrast (:func:`event_scale`);
    and ``{"trace": (lo, hi)}``, the range of the trace panel's values and threshold (its fixed y axis).
    """
    model.reset()
    ranges: dict[str, tuple[float, float]] = {}
    n_ts = getattr(getattr(model, "params", None), "n_ts", None)
    bar = tqdm(total=n_total, desc=progress, unit="frame", disable=None) if isinstance(progress, str) else None
    try:
        for frame in frames:
            res = _step(model, frame)
            vals = [v for v in _trace_values(model, res, n_ts) if v is not None and np.isfinite(v)]
            if vals:
                old = ranges.get(TRACE_KEY, (min(vals), max(vals)))
                ranges[TRACE_KEY] = (min(old[0], *vals), max(old[1], *vals))
            if isinstance(frame, tuple):  # the event panel's scale: the largest net contrast of the recording
                m = max(event_scale(*frame), ranges.get(EVENTS_KEY, (0.0, 0.0))[1])
                ranges[EVENTS_KEY] = (-m, m)
            fields = model.fields()
            for key, _ in _pick_fields(model.name, fields):
                lo, hi = robust_range(fields[key])
                old = ranges.get(key, (lo, hi))
                ranges[key] = (min(old[0], lo), max(old[1], hi))
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return ranges


#: The input panel's scale: grey levels 0..1.
_GREY_SCALE = FieldScale(0.0, 1.0, grey=True)

#: Colours of the event panel (BGR): the background (no net contrast), full ON (+1) and full OFF (-1).
EVENT_GREY = np.array([128.0, 128.0, 128.0])
EVENT_ON = np.array([0.0, 255.0, 0.0])
EVENT_OFF = np.array([0.0, 0.0, 255.0])


def event_panel(p_on: np.ndarray, p_off: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """An event bin as the models take it: its net contrast ``P = P_on - P_off``, drawn on grey.

    A pixel with net ON contrast ``a`` is grey blended towards green by ``a / scale`` (green at
    ``a >= scale``); net OFF, towards red; no events (or as much ON as OFF), grey.

    Parameters
    ----------
    p_on, p_off : ndarray, (H, W)
        The bin's ON and OFF contrast, in [0, 1].
    scale : float
        The net contrast shown at full colour (a movie's largest, so that one event of
        contrast ``C`` is not a faint tint; 1: the models' whole range).

    Returns
    -------
    ndarray, (H, W, 3) uint8
        BGR image.
    """
    net = np.asarray(p_on, np.float64) - np.asarray(p_off, np.float64)
    net = np.clip(net / max(float(scale), 1e-9), -1.0, 1.0)[..., None]
    on, off = np.maximum(net, 0.0), np.maximum(-net, 0.0)
    img = EVENT_GREY * (1.0 - on - off) + EVENT_ON * on + EVENT_OFF * off
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def event_bar(height: int, scale: float = 1.0) -> np.ndarray:
    """The event panel's colour bar (``height`` x :data:`CBAR_W`): ``+scale`` (ON, green) at the top to
    ``-scale`` (OFF, red) at the bottom."""
    img = np.full((height, CBAR_W, 3), 24, np.uint8)
    ramp = np.linspace(1.0, -1.0, height)[:, None].repeat(8, axis=1)
    img[:, 2:10] = event_panel(np.maximum(ramp, 0.0), np.maximum(-ramp, 0.0))
    marks = [(f"+{scale:.3g} ON", 8), (f"-{scale:.3g} OFF", height - 2)] + ([("0", height // 2 + 3)]
                                                                          if height >= 40 else [])
    for txt, y in marks:
        cv2.putText(img, txt, (12, y), PANEL_FONT, 0.3, (230, 230, 230), 1, cv2.LINE_AA)
    return img


def event_scale(p_on: np.ndarray, p_off: np.ndarray) -> float:
    """The largest net contrast ``|P_on - P_off|`` of a bin (the event panel's scale is the movie's largest)."""
    return float(np.max(np.abs(np.asarray(p_on, np.float64) - np.asarray(p_off, np.float64)), initial=0.0))


def input_panel(item: Any, scale: float = 1.0) -> np.ndarray:
    """The input panel of one step, with its colour bar: the grey frame; the colour frame of a
    :class:`~cdnf_ti.frames.ColourFrame` (a model that takes colour), beside the grey scale of its luma;
    or an event bin (:func:`event_panel`, full colour at net contrast ``scale``)."""
    if isinstance(item, tuple):
        img = event_panel(*item, scale=scale)
        _label(img, "events")
        return np.concatenate([img, event_bar(img.shape[0], scale)], 1)
    if isinstance(item, ColourFrame) and item.bgr.ndim == 3:
        img = to_uint8(item.bgr).copy()  # drawn on: not the frame itself
        _label(img, "input (colour)")
        return np.concatenate([img, _GREY_SCALE.bar(img.shape[0])], 1)
    grey = to_grey(getattr(item, "grey", item))
    g8 = grey if grey.dtype == np.uint8 else np.clip(np.rint(grey * 255), 0, 255).astype(np.uint8)
    img = cv2.cvtColor(g8, cv2.COLOR_GRAY2BGR)
    _label(img, "input")
    return np.concatenate([img, _GREY_SCALE.bar(g8.shape[0])], 1)


def _label(img: np.ndarray, text: str) -> None:
    cv2.rectangle(img, (0, 0), (min(img.shape[1], 9 * len(text) + 8), 18), (0, 0, 0), -1)
    cv2.putText(img, text, (4, 13), PANEL_FONT, 0.42, (255, 255, 255), 1, cv2.LINE_AA)


#: The labelled window's band in the trace panel (BGR), and the colour's name in the panel's title.
WINDOW_BGR = (160, 80, 220)
WINDOW_COLOUR = "pink"


def window_legend(window: tuple[int, int] | None) -> str | None:
    """The trace panel's legend of the labelled window's band, naming its colour; None without a window."""
    return None if window is None else f"{WINDOW_COLOUR}: labelled window, {window[0]}-{window[1]}"


def _trace_panel(width: int, t: int, n_total: int | None, out: list[float], thr: list[float | None],
                 spikes: list[bool], name: str, fps: float, window: tuple[int, int] | None,
                 unit: str = "frame", ylim: tuple[float, float] | None = None) -> np.ndarray:
    """The output so far (white), its threshold (dashed yellow), alerts (red) over frames 0..n_total
    (``unit``: what a step is called, ``"frame"``, or ``"bin"`` for an event recording). ``ylim``: the
    y axis's range over the whole movie (fixed while it plays); without it, the range of the values so far."""
    h = TRACE_H
    img = np.full((h, width, 3), 24, np.uint8)
    n = max(n_total or 0, t + 1, 2)
    x0, x1, y0, y1 = 46, width - 8, 24, h - 24
    vals = [v for v in out if np.isfinite(v)] + [v for v in thr if v is not None and np.isfinite(v)]
    lo, hi = ylim if ylim is not None else ((min(vals), max(vals)) if vals else (0.0, 1.0))
    if hi - lo < 1e-6:
        hi = lo + 1e-3
    pad = 0.08 * (hi - lo)
    lo, hi = lo - pad, hi + pad

    def X(i: float) -> int:
        return int(round(x0 + (x1 - x0) * i / (n - 1)))

    def Y(v: float) -> int:
        return int(round(y1 - (y1 - y0) * (v - lo) / (hi - lo)))

    if window is not None:
        cv2.rectangle(img, (X(window[0] - 0.5), y0), (X(window[1] + 0.5), y1), WINDOW_BGR, -1)
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
    cv2.putText(img, f"{name}  {unit} {t}  t={t / fps:.2f}s  (x axis: {unit}s)", (x0, 16), PANEL_FONT, 0.42,
                (255, 255, 255), 1, cv2.LINE_AA)
    cv2.putText(img, "-- threshold", (x0 + 4, y0 + 12), PANEL_FONT, 0.35, (0, 220, 255), 1, cv2.LINE_AA)
    legend = window_legend(window)
    if legend is not None:  # a swatch of the band's colour, then its name
        cv2.rectangle(img, (x0 + 4, y0 + 18), (x0 + 14, y0 + 26), WINDOW_BGR, -1)
        cv2.putText(img, legend, (x0 + 18, y0 + 26), PANEL_FONT, 0.35, (255, 255, 255), 1, cv2.LINE_AA)
    if alert:
        cv2.putText(img, "ALERT", (x1 - 60, y0 + 16), PANEL_FONT, 0.55, (0, 0, 255), 2, cv2.LINE_AA)
    return img


def render_frames(model: Any, frames: Iterator[np.ndarray], fps: float, n_total: int | None = None,
                  window: tuple[int, int] | None = None, progress: bool | str = False,
                  ranges: dict[str, tuple[float, float]] | None = None) -> Iterator[np.ndarray]:
    """Step ``model`` through ``frames`` and yield one BGR movie frame per input frame.

    Parameters
    ----------
    model : Model
        A cdnf_ti model (reset here).
    frames : iterator of ndarray or of (p_on, p_off)
        Grey frames (uint8 or float in [0, 1]), or event bins (:meth:`~cdnf_ti.models.base.Model.step_on_off`).
    fps : float
        Input frame rate (frames/s; bins/s for events), for the time labels.
    n_total : int, optional
        Number of frames (fixes the trace's x axis).
    window : (int, int), optional
        The labelled collision window (frames), shaded in the trace.
    ranges : dict, optional
        ``{field: (lo, hi)}``, the fixed colour scales (:func:`field_ranges`; ``"events"``: the
        event panel's); without it each scale grows with the values seen so far.
    """
    model.reset()
    out: list[float] = []
    thr: list[float | None] = []
    spikes: list[bool] = []
    scales: dict[str, FieldScale] = {}
    uses_count = False
    ev_scale = 0.0
    n_ts = getattr(model.params, "n_ts", None)
    bar = None
    if progress:
        bar = tqdm(total=n_total, desc=progress if isinstance(progress, str) else "render", unit="frame",
                   disable=None)
    try:
        for t, frame in enumerate(frames):
            res = _step(model, frame)
            uses_count = uses_count or ("count" in res.diagnostics and n_ts is not None)
            value, level = _trace_values(model, res, n_ts)
            out.append(value)
            thr.append(level)
            spikes.append(bool(res.spike))
            if isinstance(frame, tuple):
                ev = (ranges or {}).get(EVENTS_KEY)
                ev_scale = max(ev_scale, ev[1] if ev else event_scale(*frame))  # fixed, or the largest so far
            first = input_panel(frame, ev_scale or 1.0)
            hw = (first.shape[0], first.shape[1] - CBAR_W)  # the input's (H, W)
            panels = [first]
            fields = model.fields()
            for key, title in _pick_fields(model.name, fields):
                if key not in scales:
                    scales[key] = FieldScale(*ranges[key]) if ranges and key in ranges else FieldScale()
                sc = scales[key]
                img = sc(fields[key])
                if img.shape[:2] != hw:
                    img = cv2.resize(img, (hw[1], hw[0]), interpolation=cv2.INTER_NEAREST)
                _label(img, title)
                panels.append(np.concatenate([img, sc.bar(hw[0])], 1))
            while len(panels) < 4:
                panels.append(np.zeros_like(panels[0]))
            top = np.concatenate([np.concatenate(panels[:2], 1), np.concatenate(panels[2:4], 1)], 0)
            rule = None if uses_count else _rule_column(model, res)
            name = (f"{model.name} spike count (n_ts {n_ts})" if uses_count
                    else f"{model.name} {rule.quantity if rule is not None else model.output_name}")
            trace = _trace_panel(top.shape[1], t, n_total, out, thr, spikes, name, fps, window,
                                 "bin" if isinstance(frame, tuple) else "frame", (ranges or {}).get(TRACE_KEY))
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
                 arch: str = "cpu", window: tuple[int, int] | None = None, progress: bool | str = False,
                 fps: float | None = None, color_order: str = "bgr", rain: Any = None, rain_seed: int = 0,
                 events: dict | None = None) -> int:
    """Render the field movie of ``model_name`` on ``source`` to ``out`` (.mp4 or .avi); returns the frame count.

    Two passes over the input: the first fixes the colour scales (:func:`field_ranges`), the
    second draws. ``fps``/``color_order`` are how a file is read; ``rain`` (a
    :class:`~cdnf_ti.stimuli.rain.RainParams`) adds the same synthetic rain (seed ``rain_seed``)
    in both passes. An event recording is binned as ``events`` says (``sensor_size``, ``bin_ms``,
    ``event_threshold``: :func:`cdnf_ti.cli_common.event_options_of`), one movie frame per bin; without
    a ``bin_ms`` at the model's own width (:func:`~cdnf_ti.models.base.bin_ms_for`).

    Raises
    ------
    InputError
        Unreadable input, a video the codec cannot write, or rain asked on an event recording.
    UserError
        ``window`` is not ``0 <= start <= end <=`` the input's last frame, or the frames are
        smaller than the widest kernel.
    """
    codec_for(out)  # a bad suffix fails before any work
    if is_event_file(source):  # binned at the model's width (--bin-ms when given), as `run` bins it for the model
        events = dict(events or {})
        events["bin_ms"] = bin_ms_for(get_model_class(model_name), params, events.get("bin_ms"))
    src = open_render_input(source, fps, color_order, events)
    is_events = isinstance(src, EventSource)
    if is_events and rain is not None:
        raise InputError(source, "is an event recording; --rain applies to frames only")
    check_frame_size(*src.shape, n_models=1, what=str(source), binning=is_events)
    if window is not None:
        last = src.n_frames - 1 if src.n_frames else None
        if not 0 <= window[0] <= window[1] or (last is not None and window[1] > last):
            raise UserError(f"{source}: window {window[0]}:{window[1]} must satisfy 0 <= START <= END <= "
                            f"{'the last frame' if last is None else last} (frames, inclusive)")
    model = create_model(model_name, params, backend=backend, arch=arch, fps=src.fps)
    threshold = float((events or {}).get("event_threshold", DEFAULT_EVENT_THRESHOLD))

    def frames():
        if is_events:
            return src.contrast(threshold)
        if rain is not None:  # rainy frames are grey
            return iter(RainyFrames(iter_frames(src, False), rain, seed=rain_seed))
        return iter_frames(src, takes_colour([model]))

    seen = [0]

    def counted(items):
        for item in items:
            seen[0] += 1
            yield item

    ranges = field_ranges(model, counted(frames()),
                          f"{progress} (colour scales)" if isinstance(progress, str) else False, src.n_frames)
    n_total = src.n_frames if src.n_frames is not None else seen[0]  # a recording's bins: counted in pass 1
    movie = render_frames(model, frames(), src.fps, n_total, window, progress, ranges)
    n = write_video(out, movie, src.fps)
    if is_events:
        for line in src.report.problems():
            print(f"warning: {source}: {line}", file=sys.stderr)
    return n


def open_render_input(source: str | Path, fps: float | None = None, color_order: str = "bgr",
                      events: dict | None = None, quiet: bool = False) -> Any:
    """The input of a movie: an :class:`~cdnf_ti.events.source.EventSource` for an event recording
    (binned as ``events`` says; no ``bin_ms``: the default width), else a frame source
    (:func:`~cdnf_ti.inputs.resolve_input`)."""
    if is_event_file(source):
        ev = events or {}
        limits = {k: ev[k] for k in ("max_gap_s", "max_span_s") if k in ev}  # --max-gap-s, --max-span-s
        width = DEFAULT_BIN_MS if ev.get("bin_ms") is None else ev["bin_ms"]
        return open_event_source(source, ev.get("sensor_size"), width, quiet=quiet, **limits)
    return resolve_input(source, fps=fps, color_order=color_order)


def movie_name(clip: str, model: str, condition: str = "clean", suffix: str = ".mp4") -> str:
    """``<clip>.<model>.mp4``, or ``<clip>.<model>.<condition>.mp4`` for rain (as ``run``'s trace names)."""
    return f"{clip}.{model}{suffix}" if condition == "clean" else f"{clip}.{model}.{condition}{suffix}"


def render_main(argv: Sequence[str]) -> int:
    """``python -m cdnf_ti.run render VIDEO [--model M[,M..]] [--rain [on|both]] [--out DIR|FILE.mp4]``."""
    ap = ArgumentParser(
        prog="python -m cdnf_ti.run render",
        description="Write field movies: the input, the model's ON, OFF and Summation fields (colour-mapped, with "
                    "colour bars of fixed scale) and its output trace with threshold and alert, side by side. "
                    "One movie per model and condition (--model cdnf,lgmd2; --rain both): "
                    "OUT/<clip>.<model>[.rain].mp4.")
    ap.add_argument("input", metavar="VIDEO",
                    help="video file, image folder, .npy, stim:NAME, or an event recording (one movie frame per bin; "
                         "the input panel shows the bin's ON events green and OFF events red)")
    add_output_option(ap, movie=True)
    add_model_options(ap)
    add_param_options(ap)
    add_input_options(ap)
    add_event_options(ap)
    add_rain_options(ap, default="off", what="the input (frames only)")
    add_seed_options(ap, rain=True)
    ap.add_argument("--window", default=None, metavar="START:END",
                    help="labelled collision window in frames (bins for an event recording), shaded in the trace")
    ap.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    args = ap.parse_args(list(argv))
    models = parse_models(args.models)
    note_unused_rain_options(args)
    check_model_options(args)
    params = params_from_args(args, models)
    conditions = rain_conditions(args)
    window = None
    if args.window:
        try:
            a, b = (int(x) for x in args.window.split(":"))
        except ValueError:
            raise UserError(f"--window must be START:END in frames, got {args.window!r}") from None
        window = (a, b)
    events = event_options_of(args)
    src = open_render_input(args.input, args.fps, args.color_order, events, quiet=True)
    if isinstance(src, EventSource) and "rain" in conditions:
        raise InputError(args.input, "is an event recording; --rain applies to frames only (give --rain off)")
    clip = src.name
    jobs = [(m, c) for m in models for c in conditions]
    out = Path(args.out)
    if out.suffix:  # a movie file
        codec_for(out)
        if len(jobs) > 1:
            raise UserError(f"--out {out}: one movie file, but {len(jobs)} movies are made "
                            f"({len(models)} model(s) x {len(conditions)} condition(s)); give a folder")
        prepare_output(out.parent)
        targets = [out]
    else:
        folder = prepare_output(out)
        targets = [inside(folder, movie_name(clip, m, c)) for m, c in jobs]
    rain = RainParams(drops=args.rain_drops) if "rain" in conditions else None
    for (m, c), target in zip(jobs, targets):
        label = f"render {Path(str(args.input)).name} [{m}{'' if c == 'clean' else ', ' + c}]"
        n = render_video(args.input, m, target, params=params[m], backend=args.backend, arch=args.arch, window=window,
                         progress=False if args.no_progress else label, fps=args.fps, color_order=args.color_order,
                         rain=rain if c == "rain" else None, rain_seed=rain_seed_of(args), events=events)
        print(f"{target}: {n} frames")  # results on stdout, as run's lines
    return EXIT_OK


def render_dataset(run: Any, folder: str | Path, progress: bool = False, params: dict | None = None,
                   fps: float | None = None, color_order: str = "bgr", backend: str = "taichi",
                   arch: str = "cpu", events: dict | None = None) -> list[Path]:
    """Field movies of every scored clip of a dataset run: ``OUT/movies/<clip>.<model>.mp4`` (clean input).

    ``params`` (``{model: parameter object or None}``), ``fps`` and ``color_order`` are the run's
    own (``--param``, ``--fps``, ``--color-order``; ``events``: how event recordings are binned,
    :func:`cdnf_ti.cli_common.event_options_of`), so a movie shows the model that was scored.
    A movie newer than its trace is kept (a rerun does not redraw it).
    """
    made = []
    for lab in run.labels:
        for m in run.models:
            row = next((r for r in run.rows if r["clip"] == lab.clip and r["model"] == m and not r.get("error")), None)
            if row is None:
                continue
            src = trace_path(run.out, row["condition"], lab.clip, m, "json")
            movie = inside(Path(run.out) / "movies", movie_name(lab.clip, m))
            if movie.is_file() and src.is_file() and movie.stat().st_mtime >= src.stat().st_mtime:
                made.append(movie)
                continue
            video = find_clip(folder, lab.clip)
            if video is None:
                continue
            window = (lab.window_start, lab.window_end) if lab.collision else None
            render_video(video, m, movie, params=(params or {}).get(m), backend=backend, arch=arch, window=window,
                         progress=f"movie {lab.clip} [{m}]" if progress else False, fps=fps,
                         color_order=color_order, events=events)
            made.append(movie)
    return made
