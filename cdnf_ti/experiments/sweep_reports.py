"""Reports of a parameter sweep: param_sweep.csv/json/md, figures and report.html."""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from ..atomic import atomic_write_json, atomic_write_text
from ..models import get_model_class
from .clipscores import IN_SAMPLE_NOTE, never_alerts_accuracy
from .figures import _plt, save_figure
from .htmlreport import Page, markdown_table
from .nested import NESTED_MEANING
from .tables import csv_text, pct

if TYPE_CHECKING:  # pragma: no cover
    from .clip_tasks import ParamSweepRun

SCORE_COLUMNS = ("condition", "clips", "errors", "accuracy", "auc", "cv_accuracy", "cv_scheme",
                 "best_in_sample_accuracy", "best_in_sample_level", "alert_parameter", "hits", "hits_before_contact",
                 "median_hit_lead_ms", "false_alarms", "max_output", "accuracy_pre_contact", "auc_pre_contact",
                 "cv_accuracy_pre_contact")


def _f(v, digits: int = 3) -> str:
    return "n/a" if v is None else f"{v:.{digits}f}"


def table_rows(run: "ParamSweepRun") -> tuple[list[str], list[list]]:
    names = [a.name for a in run.axes]
    header = names + ["condition", "clips", "accuracy (own alert rule)", "hits (before contact)", "false alarms",
                      "AUC", "CV accuracy (held-out level)", "best accuracy (in-sample)", "at level (in-sample)",
                      "before-contact hits only: accuracy / AUC / CV accuracy"]
    rows = []
    for r in run.rows:
        rows.append([f"{r[n]:.4g}" if isinstance(r[n], float) else r[n] for n in names]
                    + [r["condition"], r["clips"], pct(r.get("accuracy")),
                       f"{r.get('hits', '')} ({r.get('hits_before_contact', '')})", r.get("false_alarms", ""),
                       _f(r.get("auc")), pct(r.get("cv_accuracy")),
                       pct(r.get("best_in_sample_accuracy")),
                       "" if r.get("best_in_sample_level") is None else f"{r['best_in_sample_level']:.4g}",
                       f"{pct(r.get('accuracy_pre_contact'))} / {_f(r.get('auc_pre_contact'))} / "
                       f"{pct(r.get('cv_accuracy_pre_contact'))}"])
    return header, rows


def _ci(d: dict) -> str:
    if not d or d.get("accuracy") is None:
        return "n/a"
    return f"{pct(d['accuracy'])} [{100 * d['ci_lo']:.1f}, {100 * d['ci_hi']:.1f}]"


def _chosen(d: dict) -> str:
    folds = d.get("folds") or 0
    return "; ".join(f"{k}: {v}/{folds}" for k, v in (d.get("chosen") or {}).items()) or "n/a"


def nested_rows(run: "ParamSweepRun") -> tuple[list[str], list[list]]:
    """Header and rows of the nested cross-validation table: per condition, all hits and before-contact hits,
    next to the best per-setting figures (in-sample picks) for comparison."""
    header = ["condition", "scoring", "nested CV accuracy [bootstrap 95% CI]", "setting chosen (outer folds)",
              "best per-setting accuracy (in-sample pick)", "best per-setting CV accuracy (in-sample pick)"]
    rows = []
    by_cond = (run.nested or {}).get("by_condition") or {}
    for cond, d in by_cond.items():
        mine = [r for r in run.rows if r["condition"] == cond and r.get("accuracy") is not None]
        for label, res, acc_key, cv_key in (("all hits", d, "accuracy", "cv_accuracy"),
                                            ("before-contact hits only", d.get("before_contact") or {},
                                             "accuracy_pre_contact", "cv_accuracy_pre_contact")):
            best = max((r[acc_key] for r in mine if r.get(acc_key) is not None), default=None)
            best_cv = max((r[cv_key] for r in mine if r.get(cv_key) is not None), default=None)
            rows.append([cond, label, _ci(res), _chosen(res), pct(best), pct(best_cv)])
    return header, rows


def plot_param_sweep(path: Path, run: "ParamSweepRun", metric: str = "cv_accuracy") -> list[Path]:
    """Heat maps (two swept parameters) or curves (one, or per parameter) of accuracy, CV accuracy and AUC."""
    plt = _plt()
    made = []
    names = [a.name for a in run.axes]
    for cond in run.conditions:
        rows = [r for r in run.rows if r["condition"] == cond and r.get("accuracy") is not None]
        if not rows:
            continue
        metrics = [("accuracy", "accuracy, own alert rule (%)"), ("cv_accuracy", "CV accuracy, held-out level (%)"),
                   ("auc", "clip-level ROC AUC")]
        if len(names) == 2:
            a0, a1 = run.axes
            fig, axes = plt.subplots(1, 3, figsize=(4.2 * 3, 0.5 * len(a0.values) + 2.4), squeeze=False)
            for ax, (key, title) in zip(axes[0], metrics):
                z = np.full((len(a0.values), len(a1.values)), np.nan)
                for r in rows:
                    i, j = a0.values.index(r[a0.name]), a1.values.index(r[a1.name])
                    v = r.get(key)
                    z[i, j] = np.nan if v is None else (v if key == "auc" else 100 * v)
                im = ax.imshow(z, cmap="viridis", aspect="auto", origin="lower",
                               vmin=0, vmax=1 if key == "auc" else 100)
                for i in range(z.shape[0]):
                    for j in range(z.shape[1]):
                        if np.isfinite(z[i, j]):
                            ax.text(j, i, f"{z[i, j]:.2f}" if key == "auc" else f"{z[i, j]:.0f}", ha="center",
                                    va="center", fontsize=8, color="w" if z[i, j] < (0.6 if key == "auc" else 60)
                                    else "k")
                ax.set_xticks(range(len(a1.values)), [f"{v:g}" if not isinstance(v, str) else v for v in a1.values])
                ax.set_yticks(range(len(a0.values)), [f"{v:g}" if not isinstance(v, str) else v for v in a0.values])
                ax.set_xlabel(a1.name)
                ax.set_ylabel(a0.name)
                ax.set_title(title + " (box: defaults)", fontsize=9)
                dflt = _defaults(run.model)
                if a0.name in dflt and a1.name in dflt:
                    ii = [i for i, v in enumerate(a0.values) if _close(v, dflt[a0.name])]
                    jj = [j for j, v in enumerate(a1.values) if _close(v, dflt[a1.name])]
                    if ii and jj:
                        ax.add_patch(plt.Rectangle((jj[0] - 0.5, ii[0] - 0.5), 1, 1, fill=False, ec="red", lw=2))
                fig.colorbar(im, ax=ax, shrink=0.8)
        else:
            fig, axes = plt.subplots(1, max(1, len(names)), figsize=(4.4 * max(1, len(names)), 3.4), squeeze=False)
            for ax, a in zip(axes[0], run.axes or []):
                for key, title in metrics:
                    xs, ys = [], []
                    for v in a.values:
                        sel = [r.get(key) for r in rows if r[a.name] == v and r.get(key) is not None]
                        if sel:
                            xs.append(v)
                            ys.append(np.mean(sel) * (1 if key == "auc" else 100) * (100 if key == "auc" else 1))
                    ax.plot(xs, ys, "o-", ms=4, label=title.replace(" (%)", "") + (" x100" if key == "auc" else ""))
                ax.set_xlabel(a.name)
                ax.set_ylabel("% (AUC x 100)")
                ax.set_ylim(-3, 103)
                ax.grid(alpha=0.3)
                ax.legend(fontsize=7)
                if len(names) > 1:
                    ax.set_title("mean over the other parameters", fontsize=8)
        nested = ((getattr(run, "nested", None) or {}).get("by_condition") or {}).get(cond) or {}
        nested_txt = (f"\nnested CV (setting and level chosen out of sample): {_ci(nested)}; before contact: "
                      f"{_ci(nested.get('before_contact') or {})}" if nested.get("accuracy") is not None else "")
        fig.suptitle(f"{run.model} parameter sweep ({cond}; {rows[0]['clips']} clips; never-alerts baseline "
                     f"{pct(run_baseline(run))}){nested_txt}", fontsize=10)
        fig.tight_layout()
        made.append(save_figure(fig, path.parent / f"{path.stem}_{cond}.png"))
    return made


def _defaults(model: str) -> dict:
    try:
        return dataclasses.asdict(get_model_class(model).params_type())
    except Exception:  # noqa: BLE001 - only for a marker
        return {}


def _close(a, b) -> bool:
    try:
        return abs(float(a) - float(b)) < 1e-4 * max(1.0, abs(float(b)))
    except (TypeError, ValueError):
        return a == b


def run_baseline(run: "ParamSweepRun") -> float | None:
    return getattr(run, "baseline", None)


def write_param_sweep_reports(run: "ParamSweepRun", labels: Sequence, padding, folds: int, seed: int,
                              figures: bool = True, html: bool = True) -> None:
    """param_sweep.csv / .json / .md, the figures and report.html in ``run.out``."""
    out = Path(run.out)
    run.baseline = never_alerts_accuracy(labels)  # type: ignore[attr-defined]
    names = [a.name for a in run.axes]
    atomic_write_text(out / "param_sweep.csv", csv_text(run.rows, ["setting", *names, *SCORE_COLUMNS]))
    cv_txt = "leave-one-out" if folds == 0 else f"{folds}-fold (seed {seed})"
    best_cv = max((r for r in run.rows if r.get("cv_accuracy") is not None),
                  key=lambda r: (r["cv_accuracy"], r.get("auc") or 0), default=None)
    atomic_write_json(out / "param_sweep.json", {
        "model": run.model, "params": {a.name: list(a.values) for a in run.axes}, "conditions": run.conditions,
        "padding_frames": padding.to_dict(), "cross_validation": cv_txt, "never_alerts_accuracy": run.baseline,
        "in_sample_note": IN_SAMPLE_NOTE, "nested_cv": {**(run.nested or {}), "meaning": NESTED_MEANING},
        "rows": run.rows, "ran": run.ran, "reused": run.skipped,
        "errors": [{k: e.get(k) for k in ("clip", "condition", "key", "error")} for e in run.errors],
    })
    header, rows = table_rows(run)
    n_col = sum(1 for lab in labels if lab.collision)
    def axis_text(a) -> str:
        return f"{a.name} = " + ", ".join(f"{v:g}" if not isinstance(v, str) else v for v in a.values)

    intro = [
        f"- model: {run.model}; grid: " + "; ".join(axis_text(a) for a in run.axes),
        f"- {len(labels)} clips ({n_col} collision, {len(labels) - n_col} non-collision); conditions: "
        f"{', '.join(run.conditions)}; window padding {padding.before}/{padding.after} frames",
        f"- never-alerts baseline: {pct(run.baseline)} (a model that never alerts scores the share of "
        "non-collision clips)",
        "- accuracy (own alert rule): each setting with its own alert threshold (e.g. C-DNF epsilon).",
        "- AUC: clip-level ROC over the alert level (hit = first alert inside the window; false alarm = any alert "
        "on a non-collision clip); threshold-free.",
        f"- CV accuracy: {cv_txt} cross-validation; each held-out clip is scored at the alert level chosen on the "
        "other clips only (out-of-sample for the alert level; the parameter setting itself is still picked by "
        "looking at this table, so the best row of the table is optimistic).",
        f"- best accuracy / at level: {IN_SAMPLE_NOTE}.",
        "- hits (before contact): true positives, and how many of them came strictly before the contact frame; "
        "before-contact hits only: the same scores with each window cut to end one frame before contact, so an "
        "alert at or after contact (which warns of nothing) counts as late.",
        f"- tasks run now: {run.ran}; reused from disk: {run.skipped}; failed: {len(run.errors)}",
    ]
    n_header, n_rows = nested_rows(run)
    md = [f"# Parameter sweep: {run.model}", "", *intro, "", "## Scores per setting", "",
          *markdown_table(header, rows), "", "## Nested cross-validation: setting and alert level chosen out of sample",
          "", NESTED_MEANING + f" Scheme: {cv_txt}, outer and inner.", "", *markdown_table(n_header, n_rows), ""]
    if best_cv is not None:
        md += [f"Best CV accuracy: {pct(best_cv['cv_accuracy'])} at {best_cv['setting']} ({best_cv['condition']}); "
               "choosing this setting from the table is itself in-sample.", ""]
    if run.errors:
        md += ["## Errors", ""] + [f"- {e.get('clip')} [{e.get('key')}, {e.get('condition')}]: {e.get('error')}"
                                   for e in run.errors] + [""]
    atomic_write_text(out / "param_sweep.md", "\n".join(md))
    pngs: list[Path] = []
    if figures:
        pngs = plot_param_sweep(out / "figures" / "param_sweep.png", run)
    if html:
        page = Page(f"cdnf_ti parameter sweep: {run.model}")
        page.bullets([s.lstrip("- ") for s in intro])
        page.paragraph(f"Any 'best' or 'at level' column is {IN_SAMPLE_NOTE}.", note=True)
        page.heading("Scores per setting")
        page.table(header, rows)
        page.heading("Nested cross-validation: setting and alert level chosen out of sample")
        page.paragraph(NESTED_MEANING + f" Scheme: {cv_txt}, outer and inner.")
        page.table(n_header, n_rows)
        if pngs:
            page.heading("Accuracy and AUC against the parameters")
            for p in pngs:
                page.image(p, p.stem)
        if run.errors:
            page.heading("Errors")
            page.table(["clip", "setting", "condition", "error"],
                       [[e.get("clip"), e.get("key"), e.get("condition"), e.get("error")] for e in run.errors])
        page.write(out / "report.html")
