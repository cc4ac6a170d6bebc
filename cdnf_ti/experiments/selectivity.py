"""Selectivity sweep: every model against its Table I entry over a grid of stimulus settings.

The paper's Table I holds at one setting per stimulus. This experiment varies
one parameter at a time around a base setting (and adds a few named cases and
incoherent versions) and reports, per model and stimulus class, the share of
the grid where the model's alert matches its Table I entry, and where it fails.

Grid (``grid("quick")`` / ``grid("full")``), around the base setting
(``BASE_SIZE`` px square, 30 fps, 1.5 s, start half-size ``size / 60``, end
half-size 45% of the side, 1/t expansion, black/white):

* looming and receding, dark and light: frame size, frame rate, duration,
  size law (1/t vs linear), start size, end size, grey levels (mid and low
  contrast);
* translating bar, dark and light: frame size, frame rate, grey levels, speed
  (frame widths per second), bar width;
* drifting grating (dark bars on light, light bars on dark): frame size,
  frame rate, grey levels, period, speed, orientation; expected: no alert
  (nothing approaches), for every model;
* incoherent looming/receding/translating at a few coherences (base setting),
  with flickering dots (parameter ``coherence``); translating also with static
  dots (``coherence, static dots``: a leaving source hands its dot to an
  entering one). A growing or shrinking square never loses a position, so its
  frames are the same under both constructions and it is run once;
* named cases (``full``): settings other labs use, e.g. a light square
  receding from 550 px to 3 px over 50 frames at 600 px.

Each model x stimulus is one task, saved as
``tasks/<key>.json`` (and its trace as ``traces/<key>.csv``); a rerun with the
same output folder reuses every finished task whose specification and code
are unchanged (:mod:`.tasks`), so an interrupted sweep resumes. Tasks run in batches of one model
at one frame size (:class:`GridBatch`) on local processes or Dask
(:mod:`.parallel`), so each worker compiles a model's kernels once per shape.
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..atomic import atomic_write_json, atomic_write_text
from ..errors import UserError
from ..paper import TABLE1
from .figures import _plt, save_figure
from .stimulus_tasks import (
    GridBatch as GridBatch,  # re-exported: selectivity.py was their home
    GridTask as GridTask,
    changed_params as changed_params,
    make_batches as make_batches,
    make_grid_stimulus as make_grid_stimulus,
    run_grid_batch as run_grid_batch,
    run_grid_task as run_grid_task,
    run_grid_tasks,
)

BASE_SIZE = {"quick": 120, "full": 240}
CLASSES = ("looming", "receding", "translating", "grating")
#: Grey levels (object, background) of the dark polarity; light swaps them.
CONTRASTS = {"full": (0.0, 1.0), "mid": (0.25, 0.75), "low": (0.4, 0.6)}
GRID_SIZES = ("quick", "full")
#: Grid parameter of the incoherent rows built with static dots.
STATIC_COHERENCE = "coherence, static dots"


@dataclass(frozen=True)
class GridPoint:
    """One stimulus of the grid.

    Attributes
    ----------
    cls : str
        Stimulus class: looming, receding, translating, grating.
    polarity : str
        dark or light (grating: dark bars on light, or light bars on dark).
    parameter : str
        The parameter this point varies from the base ("base" for the base
        point, "coherence" for incoherent versions, "case" for named cases).
    value : str
        Its value, as shown in the tables.
    spec : tuple of (str, object)
        Keyword arguments of the stimulus (sorted), plus ``coherence``.
    """

    cls: str
    polarity: str
    parameter: str
    value: str
    spec: tuple = field(default_factory=tuple)

    @property
    def stimulus(self) -> str:
        return f"{self.polarity}_{self.cls}"

    @property
    def kwargs(self) -> dict:
        return dict(self.spec)

    def expected(self, model: str) -> int | None:
        """The alert Table I gives the model (grating: 0 for every model); None if unknown."""
        if self.cls == "grating":
            return 0
        return TABLE1.get(model, {}).get(self.stimulus)


def _point(cls, pol, parameter, value, **kw) -> GridPoint:
    return GridPoint(cls, pol, parameter, str(value), tuple(sorted(kw.items())))


def _grey(pol: str, contrast: str) -> dict:
    o, b = CONTRASTS[contrast]
    if pol == "light":
        o, b = b, o
    if contrast == "full":
        return {}
    return {"object_grey": o, "background_grey": b}


def grid(which: str = "quick", coherences: Sequence[float] | None = None) -> list[GridPoint]:
    """The grid's stimuli (see the module docstring).

    Parameters
    ----------
    which : {"quick", "full"}
        ``quick``: base 120 px, two or three levels per parameter (a few
        minutes on 2 cores); ``full``: base 240 px, every level, named cases.
    coherences : sequence of float, optional
        Coherences of the incoherent versions (default: 0.5 quick; 0.8, 0.5,
        0.2 full).
    """
    if which not in GRID_SIZES:
        raise UserError(f"unknown grid {which!r}; choose one of {', '.join(GRID_SIZES)}")
    full = which == "full"
    S = BASE_SIZE[which]
    sizes = (120, 240, 360, 600) if full else (120, 240)
    fpss = (15, 60)
    durations = (0.5, 1.0, 2.0, 3.0) if full else (0.5, 3.0)
    start_fracs = (1 / 400, 1 / 20, 1 / 8) if full else (1 / 400, 1 / 20)  # start half-size / side
    end_fracs = (0.15, 0.3) if full else (0.15,)  # end half-size / side (base 0.45)
    contrasts = ("mid", "low") if full else ("low",)
    speeds = (0.25, 0.5, 1.0, 2.0, 4.0) if full else (0.25, 2.0, 4.0)  # frame widths per second
    widths = (0.05, 0.2, 0.4) if full else (0.05, 0.3)  # bar width / frame width
    periods = (10, 2.5) if full else (2.5,)  # frame width / grating period (base 5)
    gspeeds = (0.5, 2.0, 4.0) if full else (4.0,)  # grating periods per second (base 1)
    if coherences is None:
        coherences = (0.8, 0.5, 0.2) if full else (0.5,)
    pts: list[GridPoint] = []
    base = {"height": S, "width": S}
    for cls in ("looming", "receding"):
        for pol in ("dark", "light"):
            pts.append(_point(cls, pol, "base", f"{S}px", **base))
            for n in sizes:
                if n != S:
                    pts.append(_point(cls, pol, "frame size (px)", n, height=n, width=n))
            for f in fpss:
                pts.append(_point(cls, pol, "frame rate (fps)", f, **base, fps=float(f)))
            for d in durations:
                pts.append(_point(cls, pol, "duration (s)", d, **base, duration=d))
            pts.append(_point(cls, pol, "size law", "linear", **base, expansion="linear"))
            for q in start_fracs:
                pts.append(_point(cls, pol, "start half-size (side)", f"1/{round(1 / q)}", **base,
                                  start_half_size=S * q))
            for q in end_fracs:
                pts.append(_point(cls, pol, "end half-size (side)", f"{q:g}", **base, end_half_size=S * q))
            for c in contrasts:
                pts.append(_point(cls, pol, "grey levels", c, **base, **_grey(pol, c)))
    for pol in ("dark", "light"):
        pts.append(_point("translating", pol, "base", f"{S}px", **base))
        for n in sizes:
            if n != S:
                pts.append(_point("translating", pol, "frame size (px)", n, height=n, width=n))
        for f in fpss:
            pts.append(_point("translating", pol, "frame rate (fps)", f, **base, fps=float(f)))
        for c in contrasts:
            pts.append(_point("translating", pol, "grey levels", c, **base, **_grey(pol, c)))
        for v in speeds:
            pts.append(_point("translating", pol, "speed (widths/s)", f"{v:g}", **base, speed=v * S))
        for w in widths:
            pts.append(_point("translating", pol, "bar width (side)", f"{w:g}", **base,
                              bar_width=max(1, round(w * S))))
    for pol in ("dark", "light"):
        grey = {"bar_grey": 0.0, "background_grey": 1.0} if pol == "dark" else {"bar_grey": 1.0,
                                                                                 "background_grey": 0.0}
        gb = {"height": S, "width": S, **grey}
        pts.append(_point("grating", pol, "base", f"{S}px", **gb))
        for n in sizes:
            if n != S:
                pts.append(_point("grating", pol, "frame size (px)", n, **{**gb, "height": n, "width": n}))
        for f in fpss:
            pts.append(_point("grating", pol, "frame rate (fps)", f, **gb, fps=float(f)))
        for c in contrasts:
            o, b = CONTRASTS[c] if pol == "dark" else CONTRASTS[c][::-1]
            pts.append(_point("grating", pol, "grey levels", c, **{**gb, "bar_grey": o, "background_grey": b}))
        for p in periods:
            pts.append(_point("grating", pol, "period (side)", f"1/{p:g}", **gb, period=max(2, round(S / p))))
        for v in gspeeds:
            pts.append(_point("grating", pol, "speed (periods/s)", f"{v:g}", **gb, speed=v * round(S / 5)))
        pts.append(_point("grating", pol, "orientation", "horizontal", **gb, orientation="horizontal"))
    for cls in ("looming", "receding", "translating"):
        for pol in ("dark", "light"):
            for c in coherences:
                pts.append(_point(cls, pol, "coherence", f"{c:g}", **base, coherence=float(c)))
                if cls == "translating":
                    pts.append(_point(cls, pol, STATIC_COHERENCE, f"{c:g}", **base, coherence=float(c),
                                      scatter="static"))
    if full:
        # Another lab's setting (issue 11): 600 px, 30 fps, 3 px <-> 550 px over 50 frames.
        for cls in ("looming", "receding"):
            for pol in ("dark", "light"):
                for law in ("inverse", "linear"):
                    pts.append(_point(cls, pol, "case 600px 3-550px 50 frames", law, height=600, width=600,
                                      start_half_size=1.5, end_half_size=275.0, duration=50 / 30,
                                      expansion=law))
    return pts


def selectivity_sweep(models: Sequence[str], out: str | Path, which: str = "quick",
                      coherences: Sequence[float] | None = None, seed: int = 0, workers: int | None = None,
                      scheduler: Any = None, backend: str = "taichi", arch: str = "cpu", progress: bool = True,
                      figures: bool = True, classes: Sequence[str] | None = None,
                      params: dict | None = None) -> dict:
    """Run the grid for every model (in parallel, resuming finished tasks); write the report.

    ``params``: ``{model: parameter object or None}`` (``--param``); a changed parameter is part
    of each task's key, so results of other parameters are not reused.

    Writes ``selectivity.csv`` (a row per model x grid point), ``selectivity.json``,
    ``selectivity.md`` (agreement table and a failure table per stimulus class
    and parameter) and ``figures/selectivity_grid.png``.

    Returns
    -------
    dict
        ``{"rows": [...], "agreement": {model: {class: (matches, total)}}, "ran": int, "reused": int}``.
    """
    out = Path(out)
    pts = grid(which, coherences)
    if classes:
        bad = [c for c in classes if c not in CLASSES]
        if bad:
            raise UserError(f"unknown stimulus class {bad[0]!r}; choose from {', '.join(CLASSES)}")
        pts = [p for p in pts if p.cls in classes]
    tasks = [GridTask(m, p, seed, str(out), backend, arch, changed_params((params or {}).get(m)))
             for p in pts for m in models]

    done = run_grid_tasks(tasks, workers=workers, scheduler=scheduler, arch=arch, progress=progress)
    results = done.records
    rows = []
    for t, r in zip(tasks, results):
        p = t.point
        r = r or {}
        exp = p.expected(t.model)
        incoherent = p.parameter in ("coherence", STATIC_COHERENCE)
        rows.append({"model": t.model, "class": ("incoherent " if incoherent else "") + p.cls,
                     "polarity": p.polarity, "stimulus": p.stimulus, "parameter": p.parameter, "value": p.value,
                     "expected": exp, "alert": r.get("alert"), "first_alert": r.get("first_alert"),
                     "frames": r.get("frames"), "max_output": r.get("max_output"), "error": r.get("error"),
                     "match": None if exp is None or r.get("alert") is None else int(r["alert"] == exp),
                     "key": t.key})
    agreement = agreement_table(rows)
    _write_csv(out / "selectivity.csv", rows)
    atomic_write_json(out / "selectivity.json", {"grid": which, "seed": seed, "models": list(models),
                                                 "agreement": agreement, "rows": rows})
    atomic_write_text(out / "selectivity.md", selectivity_markdown(rows, which))
    if figures:
        plot_selectivity_grid(out / "figures" / "selectivity_grid.png", rows)
    return {"rows": rows, "agreement": agreement, "ran": done.ran + done.failed, "reused": done.reused}


def _write_csv(path: Path, rows: list[dict]) -> None:
    cols = ["model", "class", "polarity", "stimulus", "parameter", "value", "expected", "alert", "match",
            "first_alert", "frames", "max_output", "error", "key"]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in cols})
    atomic_write_text(path, buf.getvalue())


def class_columns(rows: list[dict]) -> list[tuple[str, str]]:
    """(class, polarity) columns in a fixed order, those present in ``rows``."""
    order = [(c, p) for c in ("looming", "receding", "translating", "grating", "incoherent looming",
                              "incoherent receding", "incoherent translating") for p in ("dark", "light")]
    have = {(r["class"], r["polarity"]) for r in rows}
    return [c for c in order if c in have]


def agreement_table(rows: list[dict]) -> dict:
    """``{model: {"<polarity> <class>": [matches, total]}}`` over rows with a known expectation."""
    res: dict[str, dict[str, list[int]]] = {}
    for r in rows:
        if r["match"] is None:
            continue
        cell = res.setdefault(r["model"], {}).setdefault(f"{r['polarity']} {r['class']}", [0, 0])
        cell[0] += r["match"]
        cell[1] += 1
    return res


def _label(cls: str, pol: str) -> str:
    if cls.endswith("grating"):
        return f"{'dark' if pol == 'dark' else 'light'}-bar grating"
    return f"{pol.capitalize()} {cls}"


def agreement_markdown(rows: list[dict]) -> str:
    """The agreement table: a row per stimulus class, a column per model; ``matches/total (share)``."""
    models = list(dict.fromkeys(r["model"] for r in rows))
    cols = class_columns(rows)
    ag = agreement_table(rows)
    exp = {}
    for r in rows:
        if r["expected"] is not None:
            exp.setdefault((r["model"], r["class"], r["polarity"]), r["expected"])
    head = "| Stimulus class | " + " | ".join(models) + " |"
    lines = [head, "|---|" + "---|" * len(models)]
    for cls, pol in cols:
        cells = []
        for m in models:
            c = ag.get(m, {}).get(f"{pol} {cls}")
            e = exp.get((m, cls, pol))
            if c is None:
                cells.append("-")
            else:
                share = 100.0 * c[0] / c[1]
                txt = f"{c[0]}/{c[1]} ({share:.0f}%), Table I: {e}"
                cells.append(f"**{txt}**" if c[0] < c[1] else txt)
        lines.append(f"| {_label(cls, pol)} | " + " | ".join(cells) + " |")
    tot = []
    for m in models:
        d = ag.get(m, {})
        a, b = sum(v[0] for v in d.values()), sum(v[1] for v in d.values())
        tot.append(f"{a}/{b} ({100.0 * a / max(b, 1):.0f}%)")
    lines.append("| **all** | " + " | ".join(tot) + " |")
    return "\n".join(lines)


def failures_markdown(rows: list[dict]) -> str:
    """Per stimulus class, a table of parameter = value rows x models: the alert, marked where it fails."""
    models = list(dict.fromkeys(r["model"] for r in rows))
    by: dict[tuple, dict] = {}
    for r in rows:
        by.setdefault((r["class"], r["polarity"], r["parameter"], r["value"]), {})[r["model"]] = r
    out = []
    for cls, pol in class_columns(rows):
        keys = [k for k in by if k[0] == cls and k[1] == pol]
        lines = [f"#### {_label(cls, pol)}", "",
                 "| parameter | value | " + " | ".join(models) + " |", "|---|---|" + "---|" * len(models)]
        for k in keys:
            cells = []
            for m in models:
                r = by[k].get(m)
                if r is None or r["alert"] is None:
                    cells.append("err")
                    continue
                fa = "" if r["first_alert"] is None else f" @{r['first_alert']}"
                txt = f"{r['alert']}{fa}"
                cells.append(txt if r["match"] in (1, None) else f"**{txt} x**")
            lines.append(f"| {k[2]} | {k[3]} | " + " | ".join(cells) + " |")
        out.append("\n".join(lines))
    return "\n\n".join(out)


def selectivity_markdown(rows: list[dict], which: str = "quick") -> str:
    head = (f"# Selectivity sweep ({which} grid)\n\n"
            "Share of the grid where each model's alert matches its Table I entry (grating: no alert "
            "expected). Bold: some grid points fail.\n\n")
    fail = ("\n\n## Where it fails\n\nEach cell: alert (1/0) and its first frame (@k); **x** = differs from "
            "the expected value.\n\n")
    return head + agreement_markdown(rows) + fail + failures_markdown(rows) + "\n"


def plot_selectivity_grid(path: str | Path, rows: list[dict], dpi: int = 110) -> Path:
    """A panel per stimulus class: grid points (rows) x models (columns); green = alert matches
    Table I, red = differs, grey = no Table I entry; the cell shows the alert (1/0)."""
    plt = _plt()
    models = list(dict.fromkeys(r["model"] for r in rows))
    cols = class_columns(rows)
    by: dict[tuple, dict] = {}
    for r in rows:
        by.setdefault((r["class"], r["polarity"]), {}).setdefault((r["parameter"], r["value"]), {})[r["model"]] = r
    ncol = 2
    nrow = (len(cols) + ncol - 1) // ncol
    heights = [max(len(by[cols[i]]) for i in range(k * ncol, min(len(cols), (k + 1) * ncol))) for k in range(nrow)]
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.2 + 0.55 * len(models)) * np.array([ncol, 0])
                             + np.array([0, 0.19 * sum(heights) + 0.9 * nrow]),
                             gridspec_kw={"height_ratios": heights}, squeeze=False)
    colours = {1: (0.55, 0.85, 0.55), 0: (0.95, 0.45, 0.4), None: (0.85, 0.85, 0.85)}
    for n, (cls, pol) in enumerate(cols):
        ax = axes[n // ncol][n % ncol]
        pts = list(by[(cls, pol)])
        img = np.ones((len(pts), len(models), 3))
        for i, k in enumerate(pts):
            for j, m in enumerate(models):
                r = by[(cls, pol)][k].get(m)
                if r is None or r["alert"] is None:
                    continue
                img[i, j] = colours[r["match"]]
                ax.text(j, i, str(r["alert"]), ha="center", va="center", fontsize=6)
        ax.imshow(img, aspect="auto", interpolation="nearest")
        ax.set_yticks(range(len(pts)))
        ax.set_yticklabels([f"{p} = {v}" if p != "base" else "base" for p, v in pts], fontsize=6)
        ax.set_xticks(range(len(models)))
        ax.set_xticklabels(models, fontsize=7, rotation=30)
        ax.set_title(_label(cls, pol), fontsize=8)
    for n in range(len(cols), nrow * ncol):
        axes[n // ncol][n % ncol].axis("off")
    fig.suptitle("Selectivity grid: green = alert as Table I, red = differs, grey = no Table I entry",
                 fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.985))
    return save_figure(fig, path, dpi=dpi)
