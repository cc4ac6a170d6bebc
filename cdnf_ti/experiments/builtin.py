"""Built-in experiments: the paper's Table I, the coherence sweep (Fig. 4) and Table II.

Each stimulus x model (x coherence) run is one cache entry of :mod:`.tasks`,
resumed and run on local processes or a Dask cluster like the dataset clips.
Table I has one runner (:func:`table1_results`) and one default size, the
paper's 600 x 600 px (:data:`TABLE1_SIZE`), shared by ``demo`` and
``experiment table1``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..atomic import atomic_write_json, atomic_write_text
from ..models.base import Trace
from ..paper import TABLE1
from ..stimuli.basic import BASIC_STIMULI, PAPER_LABELS
from .figures import plot_coherence, plot_selectivity
from .stimulus_tasks import (
    TABLE1_SIZE as TABLE1_SIZE,  # re-exported: builtin.py was their home
    StimulusTask as StimulusTask,
    frames_of,
    make_stimulus as make_stimulus,
    run_stimulus_task as run_stimulus_task,
    run_stimulus_tasks,
    table1_results as table1_results,
)

__all__ = ["COHERENCES", "COHERENCE_SIZE", "TABLE1_SIZE", "StimulusTask", "coherence_markdown", "coherence_sweep",
           "default_real_folder", "format_table1", "make_stimulus", "run_stimulus_task", "table1", "table1_results"]

#: Coherence degrees of the sweep (paper Fig. 4 goes from 100% down to 5%).
COHERENCES = (1.0, 0.95, 0.9, 0.8, 0.75, 0.6, 0.5, 0.4, 0.2, 0.05)

#: Frame side (px) of the coherence sweep by default: 60 runs per model, so smaller than Table I's.
COHERENCE_SIZE = 160


def _snapshots(name: str, size: int, coherence: float | None, seed: int, k: Sequence[float],
               scatter: str = "flicker") -> list[np.ndarray]:
    frames = [np.asarray(f, dtype=np.float32) for f in frames_of(make_stimulus(name, size, coherence, seed, scatter))]
    n = len(frames)
    return [frames[min(n - 1, int(round(q * (n - 1))))] for q in k]


def format_table1(result: dict[str, dict[str, dict]]) -> str:
    """Markdown table: each model's alert (the paper's value in brackets, for the models in its Table I)."""
    models = list(result)
    head = "| Stimulus | " + " | ".join(f"{m} (paper)" if m in TABLE1 else m for m in models) + " |"
    sep = "|---|" + "---|" * len(models)
    lines = [head, sep]
    for stim in BASIC_STIMULI:
        cells = []
        for m in models:
            got = (result[m].get(stim) or {}).get("alert")
            if got is None:  # the run failed (its error is reported separately)
                cells.append("error")
                continue
            paper = TABLE1.get(m, {}).get(stim)
            mark = "" if paper is None else (f" ({paper})" if paper == got else f" ({paper}) differs")
            cells.append(f"{got}{mark}")
        lines.append(f"| {PAPER_LABELS[stim]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def table1(models: Sequence[str], out: str | Path, size: int = TABLE1_SIZE, seed: int = 0, workers: int | None = None,
           scheduler: Any = None, backend: str = "taichi", arch: str = "cpu", progress: bool = True,
           figures: bool = True, params: dict | None = None) -> dict:
    """Paper Table I: each model on the six basic stimuli; writes table1.md/json and Fig. 2 panel.

    Returns
    -------
    dict
        ``result[model][stimulus] = {"alert", "first_alert", "max_output", ...}``.
    """
    out = Path(out)
    res = table1_results(models, size, out, seed, workers, scheduler, backend, arch, progress, params)
    tasks = [StimulusTask(m, s, size, None, seed, str(out), backend, arch, params=(params or {}).get(m))
             for m in models for s in BASIC_STIMULI]
    atomic_write_json(out / "table1.json", {"size": size, "result": res, "paper": {m: TABLE1.get(m) for m in models}})
    md = (f"# Basic selectivity (paper Table I), {size}x{size} px stimuli at 30 fps\n\n"
          "1 = the model alerts; the paper's value in brackets.\n\n" + format_table1(res) + "\n")
    atomic_write_text(out / "table1.md", md)
    if figures:
        traces = {s: {m: Trace.from_csv(t.trace_file, m, res[m][s].get("threshold"))
                      for t in tasks for m in [t.model] if t.stimulus == s and t.trace_file.is_file()}
                  for s in BASIC_STIMULI}
        snaps = {s: _snapshots(s, size, None, seed, (0.0, 0.5, 0.8, 1.0)) for s in BASIC_STIMULI}
        plot_selectivity(out / "figures" / "basic_selectivity.png", traces, snaps, PAPER_LABELS)
    return res


def coherence_sweep(models: Sequence[str], out: str | Path, size: int = COHERENCE_SIZE,
                    coherences: Sequence[float] = COHERENCES, seed: int = 0, workers: int | None = None,
                    scheduler: Any = None, backend: str = "taichi", arch: str = "cpu", progress: bool = True,
                    figures: bool = True, stimuli: Sequence[str] | None = None, scatter: str = "flicker",
                    params: dict | None = None) -> dict:
    """Fig. 4: each model on each incoherent stimulus at each coherence; writes coherence.md/json/csv + figure.

    ``scatter`` picks the incoherent construction (``flicker`` or ``static``,
    :class:`cdnf_ti.stimuli.incoherent.IncoherentStimulus`).

    Returns
    -------
    dict
        ``table[stimulus][model][coherence] = {"alert", "first_alert", "max_output", ...}``.
    """
    for c in coherences:
        if not (0 < c <= 1):
            raise ValueError(f"coherence must be in (0, 1], got {c}")
    stimuli = list(stimuli or BASIC_STIMULI)
    out = Path(out)
    make_stimulus(stimuli[0], 16, coherences[0], seed, scatter)  # fail early: missing stimuli, bad scatter
    tasks = [StimulusTask(m, s, size, float(c), seed, str(out), backend, arch, scatter,
                          params=(params or {}).get(m))
             for s in stimuli for c in coherences for m in models]
    recs = run_stimulus_tasks(tasks, workers, scheduler, arch, progress, "coherence")
    table: dict[str, dict[str, dict[float, dict]]] = {s: {m: {} for m in models} for s in stimuli}
    for r in recs:
        table[r["stimulus"]][r["model"]][r["coherence"]] = r
    rows = ["stimulus,model,coherence,alert,first_alert,max_output"]
    for s in stimuli:
        for m in models:
            for c in coherences:
                r = table[s][m].get(float(c), {})
                fa = r.get("first_alert")
                rows.append(f"{s},{m},{c:g},{'' if r.get('alert') is None else r['alert']},"
                            f"{'' if fa is None else fa},{r.get('max_output', '')}")
    atomic_write_text(out / "coherence.csv", "\n".join(rows) + "\n")
    atomic_write_json(out / "coherence.json", {"size": size, "seed": seed, "scatter": scatter,
                                               "coherences": list(coherences),
                                               "table": {s: {m: {f"{c:g}": v for c, v in d.items()}
                                                             for m, d in t.items()} for s, t in table.items()}})
    atomic_write_text(out / "coherence.md", coherence_markdown(table, coherences, size, scatter))
    if figures:
        lo = min(coherences)
        snaps = {s: {c: _snapshots(s, size, c, seed, (0.8,), scatter)[0] for c in sorted({lo, max(coherences)})}
                 for s in stimuli}
        plot_coherence(out / "figures" / "coherence_sweep.png", table, coherences, snaps, PAPER_LABELS)
    return table


def coherence_markdown(table: dict, coherences: Sequence[float], size: int | None = None,
                       scatter: str = "flicker") -> str:
    """Markdown: a row per stimulus x model, a column per coherence; 1 = alerts."""
    models = list(dict.fromkeys(m for s in table for m in table[s]))
    head = "| Stimulus | Model | " + " | ".join(f"{100 * c:.0f}%" for c in coherences) + " |"
    lines = [f"# Coherence sweep (paper Fig. 4){'' if size is None else f', {size}x{size} px'}, {scatter} dots", "",
             "1 = the model alerts at that coherence degree (fraction of object pixels kept in place).", "",
             head, "|---|---|" + "---|" * len(coherences)]
    for s in table:
        for m in models:
            cells = []
            for c in coherences:
                r = table[s][m].get(float(c))
                cells.append("err" if r is None or r.get("alert") is None else str(r["alert"]))
            lines.append(f"| {PAPER_LABELS.get(s, s)} | {m} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def default_real_folder() -> Path | None:
    """The development clips, ``shared/data/real`` beside the repository (or the current folder), if present."""
    here = Path(__file__).resolve().parents[2]
    for base in (here.parent, Path.cwd().parent, Path.cwd()):
        cand = base / "shared" / "data" / "real"
        if (cand / "labels.csv").is_file():
            return cand
    return None
