"""The benchmark section of a dataset run's reports: each model's benchmark metric, lead times in seconds.

:func:`benchmark_summary` scores every model and condition of a finished run on its annotations
(:mod:`.annotations`; a ``labels.csv`` run maps its rows with each clip's frame rate) with the scorers of
:mod:`.benchmark_scores`; :func:`benchmark_markdown` writes its section of summary.md (and so of
report.html); :func:`plot_lead_seconds` draws the lead-time distribution per model.
"""
from __future__ import annotations

import inspect
import os
from pathlib import Path
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

from ..atomic import atomic_write_text
from .annotations import Annotation, from_clip_label
from .benchmark_scores import (
    HEADLINE,
    LEAD_SHARES,
    NEXAR_HORIZONS,
    ClipOutput,
    anticipation,
    bootstrap_metric,
    by_condition,
    frame_level,
    horizon_scores,
    lead_times_s,
    nexar_ap,
    scores_before_event,
)
from .figures import _plt, save_figure
from .htmlreport import markdown_table
from .tables import csv_text

if TYPE_CHECKING:  # pragma: no cover
    from .clip_tasks import DatasetRun

#: Bootstrap resamples of the headline metric's interval.
BENCHMARK_BOOT = 500


def clip_outputs(run: "DatasetRun", traces: Mapping, model: str, condition: str,
                 annotations: Mapping[str, Annotation] | None = None) -> list[ClipOutput]:
    """Every successful clip of ``model`` under ``condition``, with its annotation (``annotations``; else its
    ``labels.csv`` row mapped at the clip's frame rate) and per-frame score (the trace's output)."""
    labels = {lab.clip: lab for lab in run.labels}
    out = []
    for r in run.rows:
        key = (r["clip"], model, condition)
        if r["model"] != model or r["condition"] != condition or r.get("error") or key not in traces:
            continue
        fps = float(r.get("video_fps") or 30.0)
        ann = (annotations or {}).get(r["clip"]) or from_clip_label(labels[r["clip"]], fps)
        tr = traces[key]
        out.append(ClipOutput(ann, np.asarray(tr.output, dtype=np.float64), fps, tr.first_alert))
    return out


def benchmark_summary(run: "DatasetRun", traces: Mapping, fmt: str = "labels",
                      annotations: Mapping[str, Annotation] | None = None, seed: int = 0,
                      n_boot: int = BENCHMARK_BOOT) -> dict:
    """The benchmark scores of every model and condition.

    Returns
    -------
    dict
        ``{"format", "headline", "results": {model: {condition: {"headline": bootstrap dict, "nexar",
        "frame_level", "anticipation", "lead_times", "by_condition"}}}}``.
    """
    name, metric = HEADLINE[fmt]
    results: dict = {}
    for m in run.models:
        for c in run.conditions:
            clips = clip_outputs(run, traces, m, c, annotations)
            if not clips:
                continue
            results.setdefault(m, {})[c] = {
                "headline": bootstrap_metric(clips, metric, n_boot=n_boot, seed=seed),
                "nexar": nexar_ap(clips), "frame_level": frame_level(clips), "anticipation": anticipation(clips),
                "lead_times": lead_times_s(clips), "by_condition": by_condition(clips, frame_level),
            }
    return {"format": fmt, "headline": name, "results": results}


def _num(v: float | None, fmt: str = ".3f") -> str:
    return "n/a" if v is None else format(v, fmt)


def _ci(d: Mapping) -> str:
    if d.get("value") is None:
        return "n/a"
    lo, hi = d.get("ci_lo"), d.get("ci_hi")
    return f"{d['value']:.3f}" + ("" if lo is None else f" [{lo:.3f}, {hi:.3f}]")


def res_share(bench: Mapping) -> str:
    """The share of positive videos among those Nexar scores at 0.5 s (the AP of a random ranking), as text."""
    for per in (bench.get("results") or {}).values():
        for d in per.values():
            n, pos = d["nexar"]["videos"].get("0.5"), d["nexar"]["positives"].get("0.5")
            if n:
                return f"{pos}/{n} = {pos / n:.3f} here"
    return ""


def benchmark_markdown(bench: Mapping) -> list[str]:
    """The benchmark section of summary.md: protocol, metric table, lead-time table, per-condition table."""
    res = bench.get("results") or {}
    if not res:
        return []
    fmt = bench["format"]
    hz = "/".join(f"{h:g}" for h in NEXAR_HORIZONS)
    L = ["", f"## Benchmark scores ({fmt})", "",
         f"- Headline: {bench['headline']}, with a seeded bootstrap 95% interval over clips. Every score ranks "
         "each model's per-frame output (its I_v, K, ...); no alert level is chosen.",
         f"- Nexar AP at {hz} s: one score per video, the highest per-frame score over the frames seen by "
         "t_event - horizon (frame k is seen at k / fps); negative clips score over all frames; AP over videos. "
         "Positive clips with no frame by then are left out. A score that ranks at random has an AP equal to "
         "the share of positive videos" + (f" ({res_share(bench)})" if res_share(bench) else "") + ".",
         "- Frame AP / AUC: every frame of every clip pooled, labelled by the per-frame labels (labels.csv: "
         "the window's frames).",
         "- Video AP / mTTA: a video is alerted at a threshold when a frame before its event scores at or above "
         "it; mTTA (s) is the mean time-to-accident of the alerted positives, best per recall, averaged over "
         "recalls (docs/EVALUATION.md).",
         ""]
    header = ["Model", "Condition", bench["headline"] + " [95% CI]", *[f"Nexar AP {h:g} s" for h in NEXAR_HORIZONS],
              "Nexar mean AP", "Frame AP", "Frame AUC", "Video AP", "mTTA (s)"]
    rows = []
    for m, per in res.items():
        for c, d in per.items():
            nx = d["nexar"]
            rows.append([m, c, _ci(d["headline"]), *[_num(nx[f"{h:g}"]) for h in NEXAR_HORIZONS], _num(nx["mean"]),
                         _num(d["frame_level"]["ap"]), _num(d["frame_level"]["auc"]), _num(d["anticipation"]["ap"]),
                         _num(d["anticipation"]["mtta_s"], ".2f")])
    L += markdown_table(header, rows)
    L += ["", "### Lead time before the event (s)", "",
          "Lead time = event time - first alert time, in seconds (positive: the alert came first). "
          "`figures/lead_time_seconds.png` shows each model's distribution.", ""]
    header = ["Model", "Condition", "Positive clips", "Median lead (s)",
              *[f"Warned >= {s:g} s" for s in LEAD_SHARES], "Never alerted", "Leads (s)"]
    rows = []
    for m, per in res.items():
        for c, d in per.items():
            lt = d["lead_times"]
            leads = sorted(lt["leads_s"].values(), reverse=True)
            rows.append([m, c, lt["positive_clips"], _num(lt["median_s"], "+.2f"),
                         *[("n/a" if lt["shares"][f"{s:g}"] is None else f"{100 * lt['shares'][f'{s:g}']:.0f}%")
                           for s in LEAD_SHARES],
                         lt["never_alerted"], ", ".join(f"{v:+.2f}" for v in leads[:12]) + (" ..." if len(leads) > 12
                                                                                            else "")])
    L += markdown_table(header, rows)
    cond_rows = []
    for m, per in res.items():
        for c, d in per.items():
            for key, vals in d["by_condition"].items():
                for v, fl in vals.items():
                    cond_rows.append([m, c, f"{key} = {v}", fl["frames"], _num(fl["ap"]), _num(fl["auc"])])
    if cond_rows:
        L += ["", "### Frame-level scores per condition", ""]
        L += markdown_table(["Model", "Condition", "Clips where", "Frames", "Frame AP", "Frame AUC"], cond_rows)
    return L


def _horizontal(ax) -> dict:
    """``boxplot``'s keyword for a horizontal box (``orientation`` from Matplotlib 3.10, ``vert`` before)."""
    return ({"orientation": "horizontal"} if "orientation" in inspect.signature(ax.boxplot).parameters
            else {"vert": False})


def plot_lead_seconds(path: str | os.PathLike, bench: Mapping) -> Path | None:
    """Each model's lead times before the event (s): one dot per positive clip that alerted, a box of their
    spread, dotted lines at 0.5, 1 and 1.5 s, and the shares warned that far ahead in the margin."""
    rows = [(m, c, d["lead_times"]) for m, per in (bench.get("results") or {}).items() for c, d in per.items()
            if d["lead_times"]["positive_clips"]]
    if not rows:
        return None
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10.5, 1.0 + 0.55 * len(rows)))
    for k, (_m, _c, lt) in enumerate(rows):
        y = len(rows) - 1 - k
        v = np.asarray(sorted(lt["leads_s"].values()))
        if v.size:
            ax.boxplot([v], positions=[y], widths=0.5, showfliers=False, manage_ticks=False, **_horizontal(ax))
            jitter = np.linspace(-0.15, 0.15, v.size) if v.size > 1 else np.zeros(1)
            ax.plot(v, y + jitter, "o", ms=5, color="tab:blue", alpha=0.75)
        sh = lt["shares"]
        txt = ", ".join(f">= {s:g} s: {100 * sh[f'{s:g}']:.0f}%" for s in LEAD_SHARES if sh[f"{s:g}"] is not None)
        med = "n/a" if lt["median_s"] is None else f"{lt['median_s']:+.2f} s"
        ax.text(1.02, y, f"{txt}; median {med}; {lt['never_alerted']} never",
                transform=ax.get_yaxis_transform(), va="center", fontsize=7)
    for x, ls in ((0.0, "-"), *((s, ":") for s in LEAD_SHARES)):
        ax.axvline(x, color="k", ls=ls, lw=0.9)
    ax.set_yticks(range(len(rows)), [f"{m} {c}" for m, c, _ in reversed(rows)])
    ax.set_ylim(-0.7, len(rows) - 0.3)
    ax.set_xlabel("lead time = event time - first alert time (s); right of 0: warned before the event")
    ax.grid(axis="x", alpha=0.3)
    ax.set_title(f"Lead time before the event ({bench['format']}); dotted: 0.5, 1, 1.5 s", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


#: Columns of ``benchmark_clips.csv``: each clip's per-frame-score summary beside its first alert.
CLIP_COLUMNS = ("clip", "model", "condition", "event_s", "alert_s", "fps", "frames", "first_alert",
                "first_alert_s", "lead_s", "max_score", *[f"score_{h:g}s_before" for h in NEXAR_HORIZONS],
                "max_score_before_event")


def clip_rows(run: "DatasetRun", traces: Mapping, annotations: Mapping[str, Annotation] | None) -> list[dict]:
    """One ``benchmark_clips.csv`` row per clip, model and condition: the event and alert times (s), the
    first alert (frame, s) and its lead before the event (s), and the per-frame score's summaries the
    benchmark scores use (its maximum, its maximum over the frames seen by each Nexar horizon, and before
    the event); empty where undefined."""
    rows = []
    for m in run.models:
        for c in run.conditions:
            for co in clip_outputs(run, traces, m, c, annotations):
                a = co.annotation
                row = {"clip": a.clip, "model": m, "condition": c, "event_s": a.event_s, "alert_s": a.alert_s,
                       "fps": co.fps, "frames": int(co.scores.size), "first_alert": co.first_alert,
                       "first_alert_s": None if co.first_alert is None else round(co.first_alert / co.fps, 4),
                       "lead_s": None if co.first_alert is None or a.event_s is None
                       else round(a.event_s - co.first_alert / co.fps, 4),
                       "max_score": float(np.nanmax(co.scores)) if co.scores.size else None}
                for h in NEXAR_HORIZONS:
                    y, s, _ = horizon_scores([co], h)
                    row[f"score_{h:g}s_before"] = float(s[0]) if s.size and a.event_s is not None else None
                before = scores_before_event(co)
                row["max_score_before_event"] = float(before.max()) if a.event_s is not None and before.size else None
                rows.append(row)
    return rows


def write_benchmark(run: "DatasetRun", traces: Mapping, fmt: str, annotations: Mapping[str, Annotation] | None,
                    seed: int, figures: bool) -> tuple[dict, list[Path]]:
    """Score the benchmark: write ``benchmark_clips.csv`` (:func:`clip_rows`) and return its summary
    (``summary.json``'s ``benchmark``; :func:`benchmark_markdown` writes it into summary.md) and its figures."""
    bench = benchmark_summary(run, traces, fmt, annotations, seed)
    atomic_write_text(Path(run.out) / "benchmark_clips.csv", csv_text(clip_rows(run, traces, annotations),
                                                                      CLIP_COLUMNS))
    pngs: Sequence[Path | None] = [plot_lead_seconds(Path(run.out) / "figures" / "lead_time_seconds.png", bench)
                                   ] if figures else []
    return bench, [p for p in pngs if p is not None]
