"""Figures (matplotlib, Agg backend; written atomically as PNG).

* :func:`plot_clip` - a clip's output traces with threshold, alerts and the
  labelled window shaded (paper Fig. 5 style), a row per model, clean and rain;
* :func:`plot_threshold_sweep` - accuracy, hits and false alarms vs alert level;
* :func:`plot_accuracy` - accuracy per model and condition beside the paper's Table II;
* :func:`plot_selectivity` - the six basic stimuli: snapshots, outputs, alerts (Fig. 2 style);
* :func:`plot_coherence` - which models alert at each coherence, per stimulus (Fig. 4 style).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
from tqdm import tqdm

from ..atomic import atomic_write, atomic_write_text
from ..models import get_model_class
from ..paper import TABLE2
from ..paths import inside
from .clipscores import roc_envelope
from .layout import trace_path

if TYPE_CHECKING:  # pragma: no cover
    from ..models.base import Trace
    from .clip_tasks import DatasetRun
    from .labels import ClipLabel
    from .scoring import Padding

COND_STYLE = {"clean": dict(color="tab:blue", label="clean"), "rain": dict(color="tab:orange", label="rain")}
MODEL_COLOURS = ["tab:red", "tab:blue", "tab:green", "tab:purple", "tab:brown", "tab:olive", "tab:cyan"]
WINDOW_COLOUR = "#f4a6c0"  # the paper shades the collision period pink


def _plt():
    # lazy: optional heavy dependency, needed only when a figure is drawn
    import matplotlib

    if "matplotlib.pyplot" not in sys.modules and not os.environ.get("MPLBACKEND"):
        matplotlib.use("Agg")  # files only; a host program's (notebook's) own backend is never switched
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: str | os.PathLike, dpi: int = 110) -> Path:
    """Save ``fig`` to ``path`` (PNG) atomically and close it."""
    plt = _plt()
    path = Path(path)
    try:
        atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format="png", bbox_inches="tight"))
    finally:
        plt.close(fig)
    return path


def _alert_rug(ax, trace: "Trace", t: np.ndarray, y: float, **style) -> None:
    idx = np.flatnonzero(trace.spike)
    if idx.size:
        ax.plot(t[idx], np.full(idx.size, y), "|", markersize=7, mew=1.2, color=style.get("color", "k"))
        fa = idx[0]
        ax.plot(t[fa], trace.output[fa], "v", markersize=8, color=style.get("color", "k"),
                markeredgecolor="k", zorder=5)


def _count_threshold(model: str) -> float | None:
    """The spike-count threshold ``n_ts`` of an LGMD-family model (None for others)."""
    try:
        cls = get_model_class(model)
        return float(cls.params_type().n_ts) if hasattr(cls.params_type(), "n_ts") else None
    except Exception:  # noqa: BLE001 - a model we do not know: no count panel
        return None


def plot_clip(path: str | os.PathLike, label: "ClipLabel", traces: Mapping[tuple[str, str], "Trace"],
              models: Sequence[str], conditions: Sequence[str], fps: float = 30.0,
              padding: "Padding | None" = None) -> Path:
    """Fig. 5 style: each model's output over frames for one clip, clean and rainy.

    The x axis is frames (seconds on the top axis). The pink window is the
    labelled collision window of ``label`` (the labels file in use). Models
    with a spike count (LGMD family) get a second panel with the count and its
    threshold ``n_ts``; SDNF's moving threshold (``dyn_threshold``) is drawn as
    a line over frames.

    Parameters
    ----------
    path : path-like
        PNG to write.
    label : ClipLabel
    traces : mapping of (model, condition) -> Trace
    models, conditions : sequence of str
    fps : float
        Frame rate (frames/s), for the seconds axis.
    padding : Padding, optional
        Shows the padded window (lighter) around the labelled one.
    """
    plt = _plt()
    traces = {k: tr for k, tr in traces.items() if tr is not None and tr.n_frames}  # an empty trace: no trace
    panels: list[tuple[str, str]] = []
    for m in models:
        panels.append((m, "output"))
        if any("count" in tr.diagnostics for (mm, _c), tr in traces.items() if mm == m):
            panels.append((m, "count"))
    ratios = [1.0 if kind == "output" else 0.7 for _m, kind in panels]
    fig, axes = plt.subplots(len(panels), 1, figsize=(8, 1.7 * sum(ratios) + 0.9), sharex=True, squeeze=False,
                             height_ratios=ratios)
    for k_ax, (ax, (m, kind)) in enumerate(zip(axes[:, 0], panels)):
        first = k_ax == 0  # the window / contact legend only once
        if label.collision:
            if padding is not None and (padding.before or padding.after):
                lo = max(0, label.window_start - padding.before)
                ax.axvspan(lo - 0.5, label.window_end + padding.after + 0.5, color=WINDOW_COLOUR, alpha=0.3,
                           lw=0, label="padded window" if first else None)
            ax.axvspan(label.window_start - 0.5, label.window_end + 0.5, color=WINDOW_COLOUR, alpha=0.7, lw=0,
                       label=f"collision window {label.window_start}-{label.window_end}" if first else None)
        if label.contact_frame is not None:
            ax.axvline(label.contact_frame, color="k", lw=0.8, ls=":",
                       label=f"contact {label.contact_frame}" if first else None)
        if kind == "count":
            n_ts = _count_threshold(m)
            hi = 1.0
            for c in conditions:
                tr = traces.get((m, c))
                if tr is None or "count" not in tr.diagnostics:
                    continue
                cnt = tr.diagnostics["count"]
                st = dict(COND_STYLE.get(c, dict(label=c)))
                st.pop("label", None)
                ax.step(np.arange(tr.n_frames), cnt, where="mid", lw=1.1, **st)
                hi = max(hi, float(np.nanmax(cnt)))
            if n_ts is not None:
                ax.axhline(n_ts, color="k", ls="--", lw=0.9, label=f"n_ts = {n_ts:g} (alert)")
                hi = max(hi, n_ts)
            for c in conditions:  # frames held at rest by feed-forward inhibition (LGMD1, F-LGMD ONn)
                tr = traces.get((m, c))
                held = None if tr is None else tr.diagnostics.get("held")
                if held is not None and np.nansum(held) > 0:
                    ax.fill_between(np.arange(tr.n_frames), -0.5, hi * 1.15 + 0.5, where=held > 0, step="mid",
                                    color=COND_STYLE.get(c, {}).get("color", "0.5"), alpha=0.15, lw=0,
                                    label=f"held at rest ({c}): {100 * np.nanmean(held > 0):.0f}% of frames")
            ax.set_ylim(-0.5, hi * 1.15 + 0.5)
            ax.set_ylabel(f"{m}\nspike count")
            ax.legend(loc="upper left", fontsize=6, framealpha=0.8)
            ax.grid(alpha=0.3)
            continue
        thr = None
        lo_y, hi_y = np.inf, -np.inf
        name = "output"
        for c in conditions:
            tr = traces.get((m, c))
            if tr is None:
                continue
            t = np.arange(tr.n_frames)
            st = dict(COND_STYLE.get(c, dict(label=c)))
            if not first:
                st.pop("label", None)
            ax.plot(t, tr.output, lw=1.2, **st)
            lo_y, hi_y = min(lo_y, float(np.nanmin(tr.output))), max(hi_y, float(np.nanmax(tr.output)))
            dyn = tr.diagnostics.get("dyn_threshold")
            if dyn is not None:
                ax.plot(t, dyn, ls="--", lw=0.8, color=st.get("color", "k"), alpha=0.8,
                        label=f"moving threshold ({c})")
                lo_y, hi_y = min(lo_y, float(np.nanmin(dyn))), max(hi_y, float(np.nanmax(dyn)))
            elif tr.threshold is not None:
                thr = tr.threshold
            name = tr.output_name
        if thr is not None:
            ax.axhline(thr, color="k", ls="--", lw=0.9, label=f"threshold {thr:.4g}")
            lo_y, hi_y = min(lo_y, thr), max(hi_y, thr)
        if np.isfinite(lo_y):
            span = max(hi_y - lo_y, 1e-6)
            rug_y = lo_y - 0.08 * span
            for c in conditions:
                tr = traces.get((m, c))
                if tr is not None:
                    _alert_rug(ax, tr, np.arange(tr.n_frames), rug_y, **COND_STYLE.get(c, {}))
                    rug_y -= 0.08 * span
            ax.set_ylim(rug_y - 0.04 * span, hi_y + 0.1 * span)
        else:
            ax.text(0.5, 0.5, "no trace (error)", transform=ax.transAxes, ha="center", va="center")
        ax.set_ylabel(f"{m}\n{name}")
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper left", fontsize=6, ncol=3, framealpha=0.8)
    top = axes[0, 0].secondary_xaxis("top", functions=(lambda f: f / fps, lambda s: s * fps))
    top.set_xlabel("time (s)", fontsize=8)
    top.tick_params(labelsize=7)
    axes[-1, 0].set_xlabel("frame   [ticks: alert frames; triangle: first alert]")
    kind = "collision" if label.collision else label.label
    fig.suptitle(f"{label.clip} ({kind}, {fps:g} fps)", fontsize=11)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_roc(path: str | os.PathLike, scores: Mapping[str, Mapping[str, Mapping]]) -> Path:
    """Clip-level ROC per model and condition (hit rate vs false-alarm rate over the alert level)."""
    plt = _plt()
    conds = list(dict.fromkeys(c for m in scores.values() for c in m))
    fig, axes = plt.subplots(1, max(1, len(conds)), figsize=(4.3 * max(1, len(conds)), 4.0), squeeze=False)
    for ax, c in zip(axes[0], conds):
        for k, (m, per) in enumerate(scores.items()):
            d = per.get(c)
            if not d:
                continue
            r = d["roc"]
            xs, ys = roc_envelope(r["hit_rate"], r["false_alarm_rate"])
            auc = d.get("auc")
            colour = MODEL_COLOURS[k % len(MODEL_COLOURS)]
            jitter = (k - len(scores) / 2) * 0.008  # keep overlapping curves apart
            ax.plot(np.array(xs) + jitter, np.array(ys) + jitter, "-", lw=1.4, color=colour,
                    label=f"{m} (AUC {'n/a' if auc is None else f'{auc:.2f}'})")
            ax.plot(np.array(r["false_alarm_rate"]) + jitter, np.array(r["hit_rate"]) + jitter, "o", ms=3,
                    color=colour, alpha=0.6)
        ax.plot([0, 1], [0, 1], color="0.6", ls=":", lw=0.8)
        n_c = next((per[c]["roc"]["n_collision"] for per in scores.values() if c in per), 0)
        n_n = next((per[c]["roc"]["n_non_collision"] for per in scores.values() if c in per), 0)
        ax.set_xlabel(f"false-alarm rate ({n_n} non-collision clips)")
        ax.set_ylabel(f"hit rate ({n_c} collision clips; first alert in window)")
        ax.set_xlim(-0.05, 1.05)
        ax.set_ylim(-0.05, 1.05)
        ax.set_title(f"clip-level ROC, {c}", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return save_figure(fig, path)


def plot_threshold_sweep(path: str | os.PathLike, rows: Sequence[Mapping], specs: Mapping) -> Path:
    """Accuracy (top) and hits / false alarms (bottom) against each model's alert level."""
    plt = _plt()
    models = [m for m in specs if any(r["model"] == m for r in rows)]
    n = max(1, len(models))
    fig, axes = plt.subplots(2, n, figsize=(4.2 * n, 5.6), squeeze=False)
    for j, m in enumerate(models):
        spec = specs[m]
        ax_a, ax_c = axes[0, j], axes[1, j]
        for c in ("clean", "rain"):
            rr = [r for r in rows if r["model"] == m and r["condition"] == c]
            if not rr:
                continue
            v = np.array([r["value"] for r in rr])
            st = COND_STYLE[c]
            ax_a.plot(v, [100 * r["accuracy"] for r in rr], "o-", ms=3, color=st["color"], label=c)
            ax_c.plot(v, [r["hits"] for r in rr], "o-", ms=3, color=st["color"], label=f"hits ({c})")
            ax_c.plot(v, [r["false_alarms"] for r in rr], "s--", ms=3, color=st["color"], alpha=0.7,
                      label=f"false alarms ({c})")
        for ax in (ax_a, ax_c):
            if spec.default is not None:
                ax.axvline(spec.default, color="k", ls=":", lw=0.9, label="default")
            ax.grid(alpha=0.3)
        ax_a.set_ylim(-3, 103)
        ax_a.set_title(f"{m} ({'fallback: ' if spec.method == 'fallback' else ''}{spec.parameter})", fontsize=10)
        ax_a.set_ylabel("accuracy (%)")
        ax_c.set_ylabel("clips")
        ax_c.set_xlabel(spec.parameter)
        ax_a.legend(fontsize=7)
        ax_c.legend(fontsize=7)
    fig.suptitle("Threshold sweep, IN-SAMPLE: scored on the same clips (false alarm = alert on a non-collision clip "
                 "or before the window); see the CV accuracy for an out-of-sample figure", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_lead_times(path: str | os.PathLike, scores: Mapping[str, Mapping[str, Mapping]]) -> Path:
    """First alert time relative to contact on every collision clip, one row per model and condition.

    Filled dots: hits (first alert inside the window); open: misses (early or
    late). Dotted lines at 0.5 s and 1 s before contact; the right margin
    counts the clips that never alerted and the shares warned >= 0.5 s / >= 1 s.
    """
    plt = _plt()
    rows = [(m, c, d["warning"]) for m, per in scores.items() for c, d in per.items()
            if d.get("warning") and d["warning"]["collision_clips"]]
    fig, ax = plt.subplots(figsize=(8.2, 0.9 + 0.45 * max(1, len(rows))))
    for k, (_m, c, w) in enumerate(rows):
        y = len(rows) - 1 - k
        rel, hit = w["alert_minus_contact_s"], w["hit"]
        colour = COND_STYLE.get(c, {}).get("color", "C0")
        for i, (clip, t) in enumerate(sorted(rel.items())):
            dy = 0.3 * (i / max(1, len(rel) - 1) - 0.5) if len(rel) > 1 else 0.0  # clips side by side
            ax.plot(t, y + dy, "o", ms=6, color=colour, mfc=colour if hit.get(clip) else "none", alpha=0.8)
        n = w["collision_clips"]
        ax.text(1.02, y, f"{w['0.5']['warned']}/{n} >= 0.5 s, {w['1']['warned']}/{n} >= 1 s, "
                         f"{w['never_alerted']} never", transform=ax.get_yaxis_transform(), va="center", fontsize=7)
    for x, ls, name in ((0.0, "-", "contact"), (-0.5, ":", "0.5 s"), (-1.0, ":", "1 s")):
        ax.axvline(x, color="k", ls=ls, lw=0.9)
        ax.text(x, 1.01, name, transform=ax.get_xaxis_transform(), ha="center", va="bottom", fontsize=7,
                rotation=90)
    ax.set_yticks(range(len(rows)), [f"{m} {c}" for m, c, _ in reversed(rows)])
    ax.set_ylim(-0.6, len(rows) - 0.4)
    ax.set_xlabel("first alert time - contact time (s); negative = before contact")
    ax.grid(axis="x", alpha=0.3)
    ax.set_title("First alert vs contact, collision clips (filled: hit in window; open: miss)", fontsize=10,
                 pad=34)
    fig.tight_layout()
    return save_figure(fig, path)


#: Gap (accuracy points) between a bar's value label and what is under it: the bar's top or the paper's
#: diamond, whichever is higher (a diamond is about 1.5 points tall from its centre in accuracy.png).
LABEL_GAP = 3.0


def value_label_y(value: float, paper: float | None) -> float:
    """Where a bar's value label starts (its bottom, accuracy %): above the bar and above the paper's
    diamond of that bar, so the diamond never hides the label."""
    return max(value, paper if paper is not None else value) + LABEL_GAP


def plot_accuracy(path: str | os.PathLike, results: Mapping[str, Mapping[str, Mapping | None]],
                  models: Sequence[str], conditions: Sequence[str]) -> Path:
    """Bars: accuracy per model and condition; diamonds: the paper's Table II."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(1.6 + 1.5 * len(models), 3.4))
    w = 0.8 / max(1, len(conditions))
    x = np.arange(len(models))
    for k, c in enumerate(conditions):
        vals = [100 * ((results[m].get(c) or {}).get("accuracy") or 0.0) for m in models]
        xs = x - 0.4 + w * (k + 0.5)
        ax.bar(xs, vals, w * 0.9, color=COND_STYLE.get(c, {}).get("color"), label=f"this run: {c}")
        paper = [TABLE2.get(m, {}).get(c) for m in models]
        for xi, v, p in zip(xs, vals, paper):
            ax.text(xi, value_label_y(v, p), f"{v:.0f}", ha="center", va="bottom", fontsize=7)
        px = [xi for xi, p in zip(xs, paper) if p is not None]
        if px:
            ax.plot(px, [p for p in paper if p is not None], "D", color="k", mfc="none", ms=6,
                    label="paper" if k == 0 else None)
    ax.set_xticks(x, models)
    ax.set_ylabel("accuracy (%)")
    ax.set_ylim(0, 100 + 2 * LABEL_GAP + 6)
    ax.legend(fontsize=7, loc="upper right")
    ax.grid(axis="y", alpha=0.3)
    ax.set_title("Accuracy (paper Table II: diamonds)", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def _up_to_date(png: Path, inputs: Sequence[Path]) -> bool:
    if not png.is_file():
        return False
    t = png.stat().st_mtime
    return all(p.is_file() and p.stat().st_mtime <= t for p in inputs)


def dataset_figures(run: "DatasetRun", traces: Mapping, specs: Mapping, progress: bool = False) -> list[Path]:
    """All figures of a dataset run into ``OUT/figures`` (per-clip figures reused when up to date)."""
    figdir = Path(run.out) / "figures"
    made: list[Path] = []
    fps = {r["clip"]: float(r["video_fps"]) for r in run.rows
           if not r.get("error") and r.get("video_fps") not in ("", None)}
    pad_tag = f"{run.padding.before}-{run.padding.after}"
    for lab in tqdm(run.labels, desc="figures", unit="clip", disable=None if progress else True):
        tr = {(m, c): traces[(lab.clip, m, c)] for m in run.models for c in run.conditions
              if (lab.clip, m, c) in traces}
        if not tr:
            continue
        png = inside(figdir, f"traces_{lab.clip}.png")
        inputs = [trace_path(run.out, c, lab.clip, m) for (m, c) in tr]
        stamp = inside(figdir, f".traces_{lab.clip}.key")
        key = (f"{sorted(tr)} pad={pad_tag} window={lab.window_start}-{lab.window_end} contact={lab.contact_frame} "
               f"label={lab.label} fig=3")
        if _up_to_date(png, inputs) and stamp.is_file() and stamp.read_text() == key:
            made.append(png)
            continue
        made.append(plot_clip(png, lab, tr, run.models, run.conditions, fps.get(lab.clip, 30.0), run.padding))
        atomic_write_text(stamp, key)
    if run.sweep:
        made.append(plot_threshold_sweep(figdir / "threshold_sweep.png", run.sweep, specs))
    if run.summary and run.summary.get("scores"):
        made.append(plot_roc(figdir / "roc.png", run.summary["scores"]))
        if any(d.get("warning", {}).get("collision_clips") for per in run.summary["scores"].values()
               for d in per.values()):
            made.append(plot_lead_times(figdir / "lead_times.png", run.summary["scores"]))
    if run.summary:
        made.append(plot_accuracy(figdir / "accuracy.png", run.summary["results"], run.models, run.conditions))
    return made


def _montage(frames: Sequence[np.ndarray], gap: int = 2) -> np.ndarray:
    """Frames side by side, each framed by a 1-px grey border, ``gap`` px of white between."""
    h = max(f.shape[0] for f in frames)
    cols = []
    for f in frames:
        a = np.pad(np.asarray(f, dtype=np.float32), 1, constant_values=0.5)
        if a.shape[0] < h + 2:
            a = np.pad(a, ((0, h + 2 - a.shape[0]), (0, 0)), constant_values=1.0)
        cols.append(a)
        cols.append(np.ones((h + 2, gap), np.float32))
    return np.concatenate(cols[:-1], axis=1)


def _grid(plt, n: int, ncol: int, panel_w: float, panel_h: float, title: str):
    """A figure of ``n`` subfigures (``ncol`` per row) with a title above them all."""
    nrow = (n + ncol - 1) // ncol
    fig = plt.figure(figsize=(panel_w * ncol, panel_h * nrow + 0.5), layout="constrained")
    subs = np.atleast_1d(fig.subfigures(nrow, ncol, wspace=0.04, hspace=0.06)).ravel()
    fig.suptitle(title, fontsize=11)
    for sf in subs[n:]:
        sf.set_visible(False)
    return fig, subs[:n]


def plot_selectivity(path: str | os.PathLike, traces: Mapping[str, Mapping[str, "Trace"]],
                     snapshots: Mapping[str, Sequence[np.ndarray]], labels: Mapping[str, str] | None = None,
                     fps: float = 30.0) -> Path:
    """Fig. 2 style: per stimulus, snapshots, each model's output with threshold, and alerts.

    Parameters
    ----------
    path : path-like
    traces : mapping stimulus -> model -> Trace
    snapshots : mapping stimulus -> frames (2-D, [0, 1]) shown side by side
    labels : mapping stimulus -> title
    fps : float
        Frame rate (frames/s) for the time axis.
    """
    plt = _plt()
    stims = list(traces)
    models = list(dict.fromkeys(m for s in stims for m in traces[s]))
    fig, subs = _grid(plt, len(stims), 3, 4.4, 1.6 + 1.0 * len(models) + 0.4 + 0.15 * len(models),
                      "Basic selectivity (paper Fig. 2 style): snapshots; output with threshold (dashed); alerts")
    for sf, s in zip(subs, stims):
        axs = sf.subplots(len(models) + 2, 1, height_ratios=[1.5] + [1.0] * len(models)
                          + [0.3 + 0.15 * len(models)])
        axs[0].imshow(_montage(snapshots[s]), cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        axs[0].set_axis_off()
        axs[0].set_title((labels or {}).get(s, s), fontsize=10)
        raster = axs[-1]
        t_end = 1.0
        for k, m in enumerate(models):
            ax = axs[1 + k]
            tr = traces[s].get(m)
            colour = MODEL_COLOURS[k % len(MODEL_COLOURS)]
            if tr is None:
                ax.text(0.5, 0.5, "no trace", transform=ax.transAxes, ha="center")
                continue
            t = np.arange(tr.n_frames) / fps
            t_end = max(t_end if k else 0.0, t[-1] if t.size else 1.0)
            ax.plot(t, tr.output, color=colour, lw=1.2)
            if tr.threshold is not None:
                ax.axhline(tr.threshold, color="k", ls="--", lw=0.8)
            ax.set_ylabel(f"{m}\n{tr.output_name}", fontsize=8)
            ax.tick_params(labelsize=7, labelbottom=False)
            ax.grid(alpha=0.3)
            idx = np.flatnonzero(tr.spike)
            raster.plot(t[idx], np.full(idx.size, k), "|", color=colour, ms=8, mew=1.5)
        for ax in list(axs[1:]):
            ax.set_xlim(0, t_end)
        raster.set_yticks(range(len(models)), models, fontsize=7)
        raster.set_ylim(len(models) - 0.4, -0.6)
        raster.set_xlabel("time (s)", fontsize=8)
        raster.tick_params(labelsize=7)
        raster.set_ylabel("alerts", fontsize=7)
    return save_figure(fig, path)


def plot_coherence(path: str | os.PathLike, table: Mapping[str, Mapping[str, Mapping[float, Mapping]]],
                   coherences: Sequence[float], snapshots: Mapping[str, Mapping[float, np.ndarray]] | None = None,
                   labels: Mapping[str, str] | None = None) -> Path:
    """Fig. 4 style: per stimulus, a bar per model across coherences, filled where the model alerts.

    Parameters
    ----------
    path : path-like
    table : mapping stimulus -> model -> coherence -> {"alert": 0/1, "first_alert": int|None, ...}
    coherences : sequence of float
        Column order (e.g. 1.0 down to 0.05).
    snapshots : mapping stimulus -> coherence -> 2-D frame, optional
        Frames shown above each panel (e.g. lowest and highest coherence).
    labels : mapping stimulus -> title
    """
    plt = _plt()
    stims = list(table)
    models = list(dict.fromkeys(m for s in stims for m in table[s]))
    has_snap = bool(snapshots)
    fig, subs = _grid(plt, len(stims), 3, 4.6, (2.0 if has_snap else 0.5) + 0.35 * len(models) + 0.8,
                      "Coherence sweep (paper Fig. 4 style): filled = the model alerts at that coherence")
    cols = list(coherences)
    for sf, s in zip(subs, stims):
        if has_snap:
            ax_img, ax = sf.subplots(2, 1, height_ratios=[2.0, 0.35 * len(models) + 0.5])
            cs = sorted(snapshots[s], reverse=True)
            ax_img.imshow(_montage([snapshots[s][c] for c in cs], gap=4), cmap="gray", vmin=0, vmax=1,
                          interpolation="nearest")
            ax_img.set_axis_off()
            ax_img.set_title(f"{(labels or {}).get(s, s)}\n" + "      ".join(f"c = {100 * c:.0f}%" for c in cs),
                             fontsize=9)
        else:
            ax = sf.subplots(1, 1)
            ax.set_title((labels or {}).get(s, s), fontsize=9)
        for k, m in enumerate(models):
            colour = MODEL_COLOURS[k % len(MODEL_COLOURS)]
            for j, c in enumerate(cols):
                cell = table[s].get(m, {}).get(c)
                if cell is None or cell.get("alert") is None:
                    ax.add_patch(plt.Rectangle((j - 0.45, k - 0.38), 0.9, 0.76, fc="white", ec="0.6", hatch="//",
                                               lw=0.5))
                    continue
                on = bool(cell.get("alert"))
                ax.add_patch(plt.Rectangle((j - 0.45, k - 0.38), 0.9, 0.76, fc=colour if on else "0.93",
                                           ec="0.6", lw=0.5))
        ax.set_xlim(-0.6, len(cols) - 0.4)
        ax.set_ylim(len(models) - 0.5, -0.5)
        ax.set_xticks(range(len(cols)), [f"{100 * c:.0f}" for c in cols], fontsize=7)
        ax.set_yticks(range(len(models)), models, fontsize=8)
        ax.set_xlabel("coherence (%)", fontsize=8)
        for sp in ax.spines.values():
            sp.set_visible(False)
        ax.tick_params(length=0)
    return save_figure(fig, path)
