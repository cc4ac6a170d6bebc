"""Regenerate ``cdnf_scatter_translating.png`` of docs/STIMULI.md: C-DNF's I_v on the incoherent
translating bar under the two constructions (flickering dots vs static dots).

    PYTHONPATH=. python docs/figures/make_scatter_figure.py [--size 600] [--stimulus dark_translating]

Panels: (left) I_v over frames at a few coherences, flicker dashed, static solid, with the
alert threshold 0.5 + epsilon; (middle) the mean I_v from frame 1 on against coherence;
(right) the luminance change per frame relative to the coherent bar's against coherence.
Writes the numbers beside the figure as ``cdnf_scatter_translating.json``.
"""
from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
COHERENCES = (1.0, 0.9, 0.8, 0.6, 0.5, 0.2, 0.05)
SHOWN = (1.0, 0.8, 0.5, 0.2)


def run_cdnf(stim):
    from cdnf_ti.models import create_model

    m = create_model("cdnf", fps=stim.fps)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return m.run(stim.frames(), progress=False)


def main() -> None:
    from cdnf_ti.experiments.figures import _plt
    from cdnf_ti.stimuli.incoherent import SCATTERS, incoherent_stimulus, luminance_change_match

    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=600)
    ap.add_argument("--stimulus", default="dark_translating")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    data: dict = {"size": args.size, "stimulus": args.stimulus, "seed": args.seed, "runs": {}}
    iv: dict = {}
    for sc in SCATTERS:
        for c in COHERENCES:
            stim = incoherent_stimulus(args.stimulus, c, args.seed, scatter=sc, height=args.size, width=args.size)
            tr = run_cdnf(stim)
            lum = luminance_change_match(stim)["ratio"]
            iv[(sc, c)] = tr.output
            data["runs"][f"{sc} {c:g}"] = {"first_alert": tr.first_alert, "mean_iv_from_frame_1":
                                           float(np.mean(tr.output[1:])), "max_iv": float(tr.output.max()),
                                           "luminance_change_ratio": lum, "threshold": tr.threshold}
            print(sc, c, data["runs"][f"{sc} {c:g}"], flush=True)
    thr = next(iter(data["runs"].values()))["threshold"]
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(14.5, 4.0))
    ax = axes[0]
    colours = dict(zip(SHOWN, ("k", "C0", "C1", "C3")))
    for c in SHOWN:
        for sc, ls in (("flicker", "--"), ("static", "-")):
            if c == 1.0 and sc == "flicker":
                continue  # c = 1 is the coherent bar under both
            ax.plot(iv[(sc, c)], ls, color=colours[c], lw=1.3,
                    label="coherent bar (c = 1)" if c == 1.0 else f"c = {c:g}, {sc}")
    ax.axhline(thr, color="r", lw=0.9, ls=":", label=f"alert threshold {thr:.3f}")
    ax.set_xlabel("frame")
    ax.set_ylabel("I_v")
    ax.set_title(f"C-DNF I_v, {args.stimulus}, {args.size} px", fontsize=10)
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    for k, (key, ylabel, title) in enumerate((
            ("mean_iv_from_frame_1", "mean I_v, frames 1..end", "mean I_v against coherence"),
            ("luminance_change_ratio", "luminance change / coherent bar's", "luminance change per frame"))):
        ax = axes[k + 1]
        for sc, mk in (("flicker", "s--"), ("static", "o-")):
            ax.plot(COHERENCES, [data["runs"][f"{sc} {c:g}"][key] for c in COHERENCES], mk, ms=4, label=sc)
        if key == "mean_iv_from_frame_1":
            ax.axhline(thr, color="r", lw=0.9, ls=":", label="alert threshold")
        ax.invert_xaxis()
        ax.set_xlabel("coherence c")
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(HERE / "cdnf_scatter_translating.png", dpi=110)
    (HERE / "cdnf_scatter_translating.json").write_text(json.dumps(data, indent=1) + "\n")


if __name__ == "__main__":
    main()
