"""``report.html`` of a dataset run: summary.md's tables plus every figure, self-contained."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Mapping, Sequence

from ..paths import inside
from .clipscores import IN_SAMPLE_NOTE
from .htmlreport import Page, add_markdown

if TYPE_CHECKING:  # pragma: no cover
    from .clip_tasks import DatasetRun


def write_dataset_html(run: "DatasetRun", summary: Mapping, markdown: str, pngs: Sequence[Path] = ()) -> Path:
    """Write ``OUT/report.html``: the summary's text and tables, then ROC, sweep, accuracy and per-clip figures.

    Figures are embedded (base64 PNG), so the page is one file readable offline.

    Parameters
    ----------
    markdown : str
        The run's summary.md text (:func:`cdnf_ti.experiments.reports.summary_markdown`).
    """
    out = Path(run.out)
    page = Page(f"cdnf_ti dataset run: {Path(str(summary.get('dataset', ''))).name or 'dataset'}")
    page.paragraph(f"Any alert level marked 'in-sample' or 'best' is {IN_SAMPLE_NOTE}.", note=True)
    add_markdown(page, markdown)
    figdir = out / "figures"
    named = [(figdir / "accuracy.png", "Accuracy per model and condition (paper Table II: diamonds)"),
             (figdir / "roc.png", "Clip-level ROC over the alert level (AUC in the legend)"),
             (figdir / "lead_times.png", "First alert time relative to contact on every collision clip"),
             (figdir / "lead_time_seconds.png", "Lead time before the event (s) per model: the benchmark section"),
             (figdir / "threshold_sweep.png", "Threshold sweep (in-sample: scored on the same clips)")]
    present = [(p, c) for p, c in named if p.is_file()]
    if present:
        page.heading("Figures")
        page.images(present)
    clips = [inside(figdir, f"traces_{lab.clip}.png") for lab in run.labels]
    clips = [p for p in clips if p.is_file()]
    if clips:
        page.heading("Per-clip traces")
        page.paragraph("Pink: the labelled collision window (from the labels file in use); dotted line: contact; "
                       "ticks under each panel: alert frames; triangle: first alert. Time in frames "
                       "(seconds on the top axis).")
        for p in clips:
            page.image(p, p.stem.replace("traces_", ""))
    return page.write(out / "report.html")
