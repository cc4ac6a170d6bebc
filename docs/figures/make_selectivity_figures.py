"""Regenerate the C-DNF I_v figures of docs/MODELS.md (selectivity beyond Table I) and docs/STIMULI.md.

    PYTHONPATH=. python docs/figures/make_selectivity_figures.py [--size 160]

* ``cdnf_incoherent_translating.png``: C-DNF's I_v on the incoherent translating
  bar at several coherences, and two controls built from the c = 0.5 frames:
  the scattered dots alone (bar region painted background) and the holey bar
  alone (dots removed). Shows what drives the alert from frame 1.
* ``cdnf_iv_selectivity.png``: C-DNF's I_v on looming, receding, translating
  at several speeds and drifting gratings (where its looming selectivity holds
  and where it breaks).
"""
from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def run_cdnf(frames, fps=30.0):
    from cdnf_ti.models import create_model

    m = create_model("cdnf", fps=fps)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return m.run(iter(frames), progress=False)


def incoherent_parts(name: str, c: float, size: int, seed: int = 0):
    """(full, dots only, holey bar only) frame lists of an incoherent stimulus."""
    from cdnf_ti.stimuli.basic import basic_stimulus
    from cdnf_ti.stimuli.incoherent import IncoherentStimulus

    base = basic_stimulus(name, height=size, width=size)
    st = IncoherentStimulus(base, c, seed)
    full, dots, bar = [], [], []
    for k, f in enumerate(st.frames()):
        f = f.copy()
        m = base.object_mask(min(k, base.n_frames - 1))
        full.append(f)
        dots.append(np.where(m, np.float32(base.background_value), f))
        bar.append(np.where(m, f, np.float32(base.background_value)))
    return full, dots, bar


def fig_incoherent(size: int, out: Path) -> dict:
    from cdnf_ti.experiments.figures import _plt, save_figure

    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.4))
    summary: dict = {}
    thr = None
    for c in (1.0, 0.95, 0.75, 0.5, 0.2, 0.05):
        full, _, _ = incoherent_parts("dark_translating", c, size)
        tr = run_cdnf(full)
        thr = tr.threshold
        axes[0].plot(tr.output, label=f"c = {c:g}")
        summary[f"c={c:g}"] = {"first_alert": tr.first_alert, "Iv_mean_1..": float(tr.output[1:].mean())}
    axes[0].axhline(thr, color="k", ls="--", lw=0.8, label="threshold")
    axes[0].set_title(f"C-DNF on incoherent dark translating bar ({size} px)", fontsize=9)
    axes[0].set_xlabel("frame")
    axes[0].set_ylabel("I_v")
    axes[0].legend(fontsize=7, ncol=2)
    full, dots, bar = incoherent_parts("dark_translating", 0.5, size)
    for lab, fr in (("c = 0.5: full stimulus", full), ("scattered dots only", dots), ("holey bar only", bar),
                    ("coherent bar (c = 1)", incoherent_parts("dark_translating", 1.0, size)[0])):
        tr = run_cdnf(fr)
        axes[1].plot(tr.output, label=lab)
        summary[lab] = {"first_alert": tr.first_alert, "Iv_mean_1..": float(tr.output[1:].mean())}
    axes[1].axhline(thr, color="k", ls="--", lw=0.8)
    axes[1].set_title("c = 0.5 split into its parts", fontsize=9)
    axes[1].set_xlabel("frame")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out, dpi=80)
    return summary


def fig_selectivity(size: int, out: Path) -> dict:
    from cdnf_ti.experiments.figures import _plt, save_figure
    from cdnf_ti.stimuli.basic import basic_stimulus
    from cdnf_ti.stimuli.grating import GratingStimulus

    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.4))
    summary: dict = {}
    thr = None

    def show(ax, lab, stim):
        nonlocal thr
        tr = run_cdnf(stim.frames(), fps=stim.fps)
        thr = tr.threshold
        t = np.arange(tr.n_frames) / stim.fps
        ax.plot(t, tr.output, label=lab)
        summary[lab] = {"first_alert": tr.first_alert, "max": float(tr.output.max()),
                        "median": float(np.median(tr.output[1:]))}

    for n in ("dark_looming", "light_looming", "dark_receding", "light_receding"):
        show(axes[0], n.replace("_", " "), basic_stimulus(n, height=size, width=size))
    for v in (0.25, 1.0, 2.0, 4.0, 8.0):
        show(axes[1], f"bar {v:g} widths/s", basic_stimulus("dark_translating", height=size, width=size,
                                                              speed=v * size))
    for lab, g in (("grating 240x320, 32 px bars", GratingStimulus(seed=0)),
                   (f"grating {size} px, period 1/5", GratingStimulus(height=size, width=size, seed=0)),
                   ("grating, 4 periods/s", GratingStimulus(height=size, width=size, speed=4.0 * round(size / 5),
                                                             seed=0)),
                   ("grating, period 1/10", GratingStimulus(height=size, width=size, period=round(size / 10),
                                                             seed=0))):
        show(axes[2], lab, g)
    for ax, title in zip(axes, ("looming / receding", "translating bar, speeds", "drifting gratings")):
        ax.axhline(thr, color="k", ls="--", lw=0.8)
        ax.set_title(f"C-DNF I_v: {title} ({size} px)", fontsize=9)
        ax.set_xlabel("time (s)")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("I_v")
    fig.tight_layout()
    save_figure(fig, out, dpi=80)
    return summary


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=160)
    args = ap.parse_args()
    res = {"incoherent": fig_incoherent(args.size, HERE / "cdnf_incoherent_translating.png"),
           "selectivity": fig_selectivity(args.size, HERE / "cdnf_iv_selectivity.png")}
    (HERE / "cdnf_iv_summary.json").write_text(json.dumps(res, indent=1))
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
