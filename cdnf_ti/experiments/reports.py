"""Reports of a dataset run: results.csv, threshold_sweep.csv, summary.md and summary.json."""
from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from ..atomic import atomic_write_json, atomic_write_text
from ..models.base import Trace
from ..paper import TABLE2
from .benchmark_reports import benchmark_markdown, write_benchmark
from .clipscores import (
    IN_SAMPLE_NOTE,
    bootstrap_accuracy,
    choose_level,
    correctness_matrix,
    cross_validated_accuracy,
    lead_times,
    never_alerts_accuracy,
    pct_ci,
    roc,
    warning_shares,
)
from .figures import dataset_figures
from .htmlreport import markdown_table
from .layout import RESULT_COLUMNS, trace_path
from .report_page import write_dataset_html
from .scoring import tally
from .sweep import alert_levels, sweep_dataset, sweep_first_alerts, sweep_spec
from .tables import (
    csv_text as csv_text,  # re-exported: their old home
    pct as pct,
    read_results as read_results,
)

if TYPE_CHECKING:  # pragma: no cover
    from .clip_tasks import DatasetRun

CONDITION_LABELS = {"clean": "Normal", "rain": "With synthetic rain"}
SWEEP_COLUMNS = ("model", "condition", "parameter", "value", "is_default", "TP", "TN", "FP", "FN", "FN_early",
                 "FN_late", "FN_none", "clips", "accuracy", "hits", "false_alarms", "method")


def load_traces(run: "DatasetRun") -> dict:
    """The saved traces of every successful row: (clip, model, condition) -> Trace.

    A trace that is missing, unreadable or holds no frame is left out (its figure panel says
    "no trace"); the reports are written all the same.
    """
    traces = {}
    for r in run.rows:
        if r.get("error"):
            continue
        p = trace_path(run.out, r["condition"], r["clip"], r["model"])
        thr = r.get("threshold")
        try:
            tr = Trace.from_csv(p, model=r["model"], threshold=None if thr in ("", None) else float(thr))
        except (OSError, ValueError, KeyError, IndexError) as e:
            print(f"warning: {p}: cannot read the trace ({e}); left out of the figures and the threshold sweep"
                  .splitlines()[0], file=sys.stderr)
            continue
        if tr.n_frames:
            traces[(r["clip"], r["model"], r["condition"])] = tr
    return traces


def threshold_sweep(run: "DatasetRun", traces: Mapping) -> tuple[list[dict], dict]:
    """Sweep rows and the spec of each model (see :mod:`cdnf_ti.experiments.sweep`)."""
    labels = {lab.clip: lab for lab in run.labels}
    fps = {r["clip"]: float(r["video_fps"]) for r in run.rows
           if not r.get("error") and r.get("video_fps") not in ("", None)}
    specs = {}
    for m in run.models:
        mt = [t for (c, mm, cond), t in traces.items() if mm == m]
        specs[m] = sweep_spec(m, mt)
    return sweep_dataset(specs, traces, labels, fps, run.padding), specs


def honest_scores(run: "DatasetRun", traces: Mapping, specs: Mapping, seed: int = 0, folds: int = 0,
                  n_boot: int = 2000) -> dict:
    """Threshold-free and out-of-sample scores per model and condition.

    Returns
    -------
    dict
        ``{model: {condition: {...}}}`` with ``accuracy_ci`` (seeded bootstrap
        95% interval at the model's own threshold), ``roc`` (clip-level ROC over
        the alert level) and ``auc``, ``cv`` (accuracy with each fold's alert level
        chosen on the other folds), ``in_sample_best`` (best level and accuracy,
        chosen on the scored clips: in-sample), ``lead_times``, ``warning``
        (:func:`~cdnf_ti.experiments.clipscores.warning_shares`: share of
        collision clips warned >= 0.5 s and >= 1 s before contact) and ``held``
        (share of frames a model was held at rest, for models with such a state).
    """
    labels = {lab.clip: lab for lab in run.labels}
    out: dict = {}
    for m in run.models:
        for c in run.conditions:
            rows = [r for r in run.rows if r["model"] == m and r["condition"] == c and not r.get("error")]
            if not rows:
                continue
            tr = {r["clip"]: traces[(r["clip"], m, c)] for r in rows if (r["clip"], m, c) in traces}
            d: dict[str, Any] = {}
            correct = [r["outcome"] in ("TP", "TN") for r in rows]
            d["accuracy_ci"] = bootstrap_accuracy(correct, n_boot=n_boot, seed=seed).to_dict()
            spec = specs[m]
            levels = alert_levels(spec, list(tr.values()))
            spec_l = dataclasses.replace(spec, values=tuple(levels))
            fas = {clip: sweep_first_alerts(spec_l, t) for clip, t in tr.items()}
            r_ = roc(fas, labels, levels, run.padding)
            d["roc"] = r_.to_dict()
            d["auc"] = r_.auc
            d["alert_parameter"] = spec.parameter
            cv = cross_validated_accuracy(fas, labels, levels, run.padding, folds=folds, seed=seed,
                                          default=spec.default)
            d["cv"] = cv.to_dict()
            _, cm = correctness_matrix(fas, labels, run.padding)
            jb = choose_level(cm, levels, spec.default)
            d["in_sample_best"] = {"level": levels[jb], "accuracy": float(cm[:, jb].mean()),
                                   "note": IN_SAMPLE_NOTE}
            d["lead_times"] = lead_times(rows).to_dict()
            d["warning"] = warning_shares(rows)
            held = [t.diagnostics["held"] for t in tr.values() if "held" in t.diagnostics]
            if held:
                h = np.concatenate(held)
                d["held"] = {"frames": int(h.size), "held_frames": int((h > 0).sum()),
                             "share": float((h > 0).mean()) if h.size else None,
                             "what": "held at rest by feed-forward inhibition (FFI >= T_ffi)"}
            out.setdefault(m, {})[c] = d
    return out


def summary_dict(run: "DatasetRun", specs: Mapping, dataset: str, labels_path: str, seed: int,
                 scores: Mapping | None = None) -> dict:
    """The content of summary.json."""
    tallies = tally(run.rows)
    n_col = sum(1 for lab in run.labels if lab.collision)
    acc: dict[str, dict[str, Any]] = {}
    for m in run.models:
        acc[m] = {}
        for c in run.conditions:
            t = tallies.get((m, c))
            acc[m][c] = t.to_dict() if t is not None else None
    snrs = [float(r["snr_db"]) for r in run.rows
            if r["condition"] == "rain" and not r.get("error") and r.get("snr_db") not in ("", None)]
    best: dict[str, dict] = {}
    for m in run.models:
        for c in run.conditions:
            cand = [s for s in run.sweep if s["model"] == m and s["condition"] == c and s["accuracy"] is not None]
            if cand:
                b = max(cand, key=lambda s: (s["accuracy"], -abs(s["value"] - (specs[m].default or 0.0))))
                dflt = [s for s in cand if s["is_default"]]
                best.setdefault(m, {})[c] = {
                    "parameter": b["parameter"], "best_value": b["value"], "best_accuracy": b["accuracy"],
                    "best_is_in_sample": True,
                    "default_value": specs[m].default,
                    "default_accuracy": dflt[0]["accuracy"] if dflt else None, "method": specs[m].method,
                }
    return {
        "dataset": dataset,
        "labels": labels_path,
        "clips": len(run.labels),
        "collision_clips": n_col,
        "non_collision_clips": len(run.labels) - n_col,
        "models": run.models,
        "conditions": run.conditions,
        "padding_frames": run.padding.to_dict(),
        "seed": seed,
        "mean_rain_snr_db": (sum(snrs) / len(snrs)) if snrs else None,
        "results": acc,
        "paper_table2": {m: TABLE2[m] for m in run.models if m in TABLE2},
        "threshold_sweep": best,
        "threshold_sweep_note": "best_value/best_accuracy are in-sample: the alert level was chosen on the same "
                                "clips it is scored on; see scores.*.cv for an out-of-sample accuracy",
        "never_alerts_accuracy": never_alerts_accuracy(run.labels),
        "scores": dict(scores or {}),
        "errors": [{"clip": r["clip"], "model": r["model"], "condition": r["condition"], "error": r["error"]}
                   for r in run.rows if r.get("error")],
        "ran": run.ran,
        "skipped_finished": run.skipped,
    }


def table2_markdown(results: Mapping[str, Mapping[str, Any]], models: Sequence[str],
                    conditions: Sequence[str]) -> str:
    """Paper Table II layout: a row per condition, a column per model, paper value beside."""
    lines = ["| Stimuli | " + " | ".join(models) + " |", "|---|" + "---|" * len(models)]
    for c in conditions:
        cells = []
        for m in models:
            d = (results.get(m) or {}).get(c)
            got = pct(d["accuracy"]) if d else "n/a"
            paper = TABLE2.get(m, {}).get(c)
            cells.append(got + (f" (paper {paper:.2f}%)" if paper is not None else ""))
        lines.append(f"| {CONDITION_LABELS.get(c, c)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def summary_markdown(run: "DatasetRun", summary: Mapping, specs: Mapping) -> str:
    """summary.md: Table II style accuracy, counts, per-clip first alerts, threshold sweep, errors."""
    pad = run.padding
    L: list[str] = ["# cdnf_ti dataset run", ""]
    L.append(f"- dataset: `{summary['dataset']}` (labels `{summary['labels']}`): {summary['clips']} clips, "
             f"{summary['collision_clips']} collision, {summary['non_collision_clips']} non-collision")
    L.append(f"- models: {', '.join(run.models)}; conditions: {', '.join(run.conditions)}")
    L.append(f"- window padding: {pad.before} frames before the window start, {pad.after} frames after its end")
    if "rain" in run.conditions:
        snr = summary.get("mean_rain_snr_db")
        L.append(f"- synthetic rain: seed {summary['seed']}, mean SNR "
                 f"{'n/a' if snr is None else f'{snr:.2f} dB'} (paper: 19.7 dB)")
    L.append("- scoring: collision clip TP if the first alert is inside the (padded) window, else FN "
             "(early / late / none); non-collision clip TN if no alert, else FP; "
             "accuracy = (TP+TN)/(TP+TN+FP+FN); clips that failed are not scored")
    L += ["", "## Accuracy (paper Table II layout; the paper's 35-clip numbers in brackets)", ""]
    L.append(table2_markdown(summary["results"], run.models, run.conditions))
    L += ["", "## Outcomes", "",
          "| Model | Condition | TP | TN | FP | FN (early/late/none) | Errors | Accuracy | Mean TP lead time |",
          "|---|---|---|---|---|---|---|---|---|"]
    for m in run.models:
        for c in run.conditions:
            d = summary["results"][m][c]
            if d is None:
                continue
            lt = d["mean_lead_time_ms"]
            L.append(f"| {m} | {c} | {d['TP']} | {d['TN']} | {d['FP']} | {d['FN']} "
                     f"({d['FN_early']}/{d['FN_late']}/{d['FN_none']}) | {d['errors']} | {pct(d['accuracy'])} | "
                     f"{'' if lt is None else f'{lt / 1000:.2f} s'} |")
    L += scores_markdown(run, summary)
    L += lead_time_markdown(run, summary)
    L += benchmark_markdown(summary.get("benchmark") or {})
    L += ["", "## First alert per clip (frame, outcome; lead time before contact)", ""]
    cols = [(m, c) for m in run.models for c in run.conditions]
    L.append("| Clip | Label | Window (padded) | Contact | " + " | ".join(f"{m} {c}" for m, c in cols) + " |")
    L.append("|---|---|---|---|" + "---|" * len(cols))
    by = {(r["clip"], r["model"], r["condition"]): r for r in run.rows}
    for lab in run.labels:
        win = ""
        if lab.collision:
            lo, hi = max(0, lab.window_start - pad.before), lab.window_end + pad.after
            win = f"{lab.window_start}-{lab.window_end}" + (f" ({lo}-{hi})" if (lo, hi) != (lab.window_start,
                                                                                      lab.window_end) else "")
        cells = []
        for m, c in cols:
            r = by[(lab.clip, m, c)]
            if r.get("error"):
                cells.append("error")
                continue
            fa = r["first_alert"]
            txt = "none" if fa in (None, "") else str(fa)
            txt += f" {r['outcome']}" + (f" ({r['fn_reason']})" if r["fn_reason"] else "")
            if r.get("lead_time_ms") not in (None, ""):
                txt += f", {float(r['lead_time_ms']) / 1000:+.2f} s"
            cells.append(txt)
        L.append(f"| {lab.clip} | {lab.label} | {win} | {'' if lab.contact_frame is None else lab.contact_frame} | "
                 + " | ".join(cells) + " |")
    if run.sweep:
        L += ["", "## Threshold sweep (in-sample)", "",
              "In-sample: every row is scored on the same clips, so picking the best row picks the alert level "
              "on the test clips; the cross-validated accuracy above is the out-of-sample figure. "
              "Accuracy, hits (TP) and false alarms (FP + early FN: an alert on a non-collision clip or before "
              "the window) as each model's alert level varies; re-scored from the saved traces. "
              "`threshold_sweep.csv` has every count; `figures/threshold_sweep.png` plots them.", ""]
        for m in run.models:
            spec = specs[m]
            how = {"model": "The model's own alert rule, replayed on the saved traces at each value.",
                   "cdnf-epsilon": "Alert when I_v > 0.5 + epsilon, on the saved I_v.",
                   "fallback": f"Alert when {spec.parameter.split()[0]} > value, on the saved output (the model "
                               "states no rule to replay)."}[spec.method]
            L.append(f"### {m}: {spec.parameter}")
            L.append("")
            L.append(how)
            L.append("")
            L.append(f"| {spec.parameter} | " + " | ".join(f"{c} accuracy | {c} hits | {c} false alarms"
                                                         for c in run.conditions) + " |")
            L.append("|---|" + "---|---|---|" * len(run.conditions))
            for v in spec.values:
                cells = []
                for c in run.conditions:
                    s = [x for x in run.sweep if x["model"] == m and x["condition"] == c and x["value"] == v]
                    cells.append(f"{pct(s[0]['accuracy'])} | {s[0]['hits']} | {s[0]['false_alarms']}" if s
                                 else "n/a | | ")
                mark = " (default)" if spec.default is not None and abs(v - spec.default) < 1e-12 else ""
                L.append(f"| {v:.6g}{mark} | " + " | ".join(cells) + " |")
            L.append("")
    if summary["errors"]:
        L += ["", "## Errors (not scored)", ""]
        L += [f"- {e['clip']} [{e['model']}, {e['condition']}]: {e['error']}" for e in summary["errors"]]
    L += ["", f"Runs done now: {run.ran}; found finished on disk and reused: {run.skipped}.", ""]
    return "\n".join(L)


def scores_table(run: "DatasetRun", summary: Mapping) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the honest-scores table (also used by report.html)."""
    sc = summary.get("scores") or {}
    header = ["Model", "Condition", "Accuracy [bootstrap 95% CI]", "ROC AUC", "CV accuracy (level held out)",
              "Best level, accuracy (IN-SAMPLE)", "Hits before contact: n, median lead (range)",
              "Hits at/after contact", "Frames held at rest"]
    rows: list[list[str]] = []
    for m in run.models:
        for c in run.conditions:
            d = (sc.get(m) or {}).get(c)
            if not d:
                continue
            lt = d["lead_times"]
            lead = f"{lt['hits_before_contact']}"
            if lt["hit_lead_median_ms"] is not None:
                lead += (f", {lt['hit_lead_median_ms'] / 1000:.2f} s ({lt['hit_lead_min_ms'] / 1000:.2f}-"
                         f"{lt['hit_lead_max_ms'] / 1000:.2f})")
            held = d.get("held")
            best = d["in_sample_best"]
            rows.append([m, c, pct_ci(d["accuracy_ci"]), "n/a" if d["auc"] is None else f"{d['auc']:.3f}",
                         pct(d["cv"]["accuracy"]), f"{best['level']:.4g}: {pct(best['accuracy'])} (in-sample)",
                         lead, str(lt["hits_at_or_after_contact"]),
                         "" if not held else f"{100 * held['share']:.1f}% ({held['held_frames']}/{held['frames']})"])
    base = summary.get("never_alerts_accuracy")
    if base is not None:
        n = summary["clips"]
        ci = bootstrap_accuracy([not lab.collision for lab in run.labels], seed=summary.get("seed", 0))
        rows.append(["never alerts (baseline)", "any", pct_ci(ci), "n/a", pct(base), "", "0", "0", ""])
        assert n == len(run.labels)
    return header, rows


def scores_markdown(run: "DatasetRun", summary: Mapping) -> list[str]:
    """The "honest scores" section of summary.md."""
    sc = summary.get("scores") or {}
    if not sc:
        return []
    any_cv = next((d["cv"]["scheme"] for m in sc.values() for d in m.values()), "leave-one-out")
    header, rows = scores_table(run, summary)
    L = ["", "## Threshold-free and out-of-sample scores", "",
         f"- Accuracy at each model's own threshold, with a seeded bootstrap 95% interval over clips "
         f"(2000 resamples, seed {summary.get('seed', 0)}); with {summary['clips']} clips one clip moves accuracy "
         f"by {100 / max(1, summary['clips']):.1f} points.",
         "- ROC AUC: clip-level ROC over the alert level (hit = first alert inside the window, on collision clips; "
         "false alarm = any alert on a non-collision clip); threshold-free. Early alerts count as misses, so AUC "
         "can fall below 0.5.",
         f"- CV accuracy: {any_cv} cross-validation; each clip is scored at the alert level chosen on the other "
         "clips only (out-of-sample).",
         f"- Best level: {IN_SAMPLE_NOTE}.",
         "- Lead time: seconds before the contact frame of first alerts inside the window; hits at or after contact "
         "warn of nothing and are counted separately.",
         f"- never alerts (baseline): a model that never alerts scores the share of non-collision clips, "
         f"{pct(summary.get('never_alerts_accuracy'))} here.",
         "- Frames held at rest: share of frames on which LGMD1 / F-LGMD ONn were held at rest by their "
         "feed-forward inhibition (no output possible); empty for models without such a state.",
         ""]
    L += markdown_table(header, rows)
    return L


def lead_time_table(run: "DatasetRun", summary: Mapping) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the lead-time table: per model and condition, the share of collision clips warned
    at least 0.5 s and 1 s before contact (and how many of those warnings were hits)."""
    sc = summary.get("scores") or {}
    header = ["Model", "Condition", "Collision clips (contact known)", "Warned >= 0.5 s before contact (hits)",
              "Warned >= 1 s before contact (hits)", "First alert at or after contact", "Never alerted",
              "Median first alert vs contact"]
    rows: list[list[str]] = []
    for m in run.models:
        for c in run.conditions:
            w = ((sc.get(m) or {}).get(c) or {}).get("warning")
            if not w or not w["collision_clips"]:
                continue
            n = w["collision_clips"]
            rel = list(w["alert_minus_contact_s"].values())
            share = [f"{w[k]['warned']}/{n} = {pct(w[k]['share'])} ({w[k]['warned_hits']})" for k in ("0.5", "1")]
            rows.append([m, c, str(n), *share, str(sum(1 for t in rel if t >= 0)),
                         str(w["never_alerted"]), f"{np.median(rel):+.2f} s" if rel else "n/a"])
    return header, rows


def lead_time_markdown(run: "DatasetRun", summary: Mapping) -> list[str]:
    """The "lead time" section of summary.md."""
    header, rows = lead_time_table(run, summary)
    if not rows:
        return []
    return ["", "## Lead time: how long before contact each model warns", "",
            "A collision cue is worth what it warns before impact. Per model and condition: the collision clips "
            "whose first alert came at least 0.5 s and at least 1 s before the contact frame (in brackets: how "
            "many of those first alerts were also inside the labelled window, i.e. hits; an alert far ahead of "
            "the window is scored as an early miss). `figures/lead_times.png` shows every first alert's time "
            "relative to contact.", "", *markdown_table(header, rows)]


def write_reports(run: "DatasetRun", dataset: str, labels_path: str, seed: int, figures: bool = True,
                  progress: bool = False, fmt: str = "labels", annotations: Mapping | None = None) -> None:
    """Write results.csv, threshold_sweep.csv, summary.md/json and (optionally) the figures.

    ``fmt`` and ``annotations`` (clip -> :class:`~.annotations.Annotation`; None: the labels.csv rows) say
    which benchmark's scores the summary's benchmark section gives (:mod:`.benchmark_reports`)."""
    out = Path(run.out)
    atomic_write_text(out / "results.csv", csv_text(run.rows, RESULT_COLUMNS))
    traces = load_traces(run)
    run.sweep, specs = threshold_sweep(run, traces)
    atomic_write_text(out / "threshold_sweep.csv", csv_text(run.sweep, SWEEP_COLUMNS))
    scores = honest_scores(run, traces, specs, seed=seed)
    run.summary = summary_dict(run, specs, dataset, labels_path, seed, scores)
    run.summary["benchmark"], bench_pngs = write_benchmark(run, traces, fmt, annotations, seed, figures)
    atomic_write_json(out / "summary.json", run.summary)
    markdown = summary_markdown(run, run.summary, specs)
    atomic_write_text(out / "summary.md", markdown)
    pngs: list = []
    if figures:
        pngs = dataset_figures(run, traces, specs, progress=progress) + bench_pngs
    write_dataset_html(run, run.summary, markdown, pngs)
