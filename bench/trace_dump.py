"""Dump the traces of every registered model on the fast path, to compare two versions of the engine bit for bit.

Run with the interpreter of each version (it uses the public API only)::

    python bench/trace_dump.py before.npz [--clip CLIP.mp4] [--frames N] [--models olgmd,lplc2]
    python bench/trace_dump.py after.npz ...
    python bench/trace_dump.py --compare before.npz after.npz

Stimuli: a basic looming stimulus (240x426), the dashcam-like stand-in video and,
with ``--clip``, the first frames of a video (426 px wide). Every trace column
(output, spike, converged and every diagnostic) is stored; ``--compare`` reports
the columns that differ and exits non-zero if any does.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np


def _stimuli(clip: str | None, n: int) -> dict[str, list[np.ndarray]]:
    from cdnf_ti.bench.inputs import standin_video
    from cdnf_ti.stimuli.basic import basic_stimulus

    out = {"looming": list(basic_stimulus("dark_looming", height=240, width=426, backend="numpy").frames())[:n],
           "standin": standin_video(n, seed=1)}
    if clip:
        import cv2

        from cdnf_ti import iter_grey, open_source

        frames = []
        for g in iter_grey(open_source(clip)):
            h, w = g.shape
            frames.append(cv2.resize(g, (426, max(2, round(h * 426 / w))), interpolation=cv2.INTER_AREA))
            if len(frames) >= n:
                break
        out["clip"] = frames
    return out


def dump(path: str, clip: str | None, n: int, models: list[str] | None = None) -> None:
    """Run ``models`` (default: every registered model) on the stimuli and save their traces to ``path``."""
    from cdnf_ti import MODELS, create_model

    arrays = {}
    for sname, frames in _stimuli(clip, n).items():
        for name in models or list(MODELS):
            tr = create_model(name).run(frames)
            arrays[f"{sname}/{name}/output"] = tr.output
            arrays[f"{sname}/{name}/spike"] = tr.spike
            arrays[f"{sname}/{name}/converged"] = tr.converged
            for k, v in tr.diagnostics.items():
                arrays[f"{sname}/{name}/{k}"] = v
            print(f"{sname:8s} {name:10s} {type(create_model(name)).__name__} frames={tr.n_frames} "
                  f"max_out={np.nanmax(tr.output):.9f}", flush=True)
    np.savez(path, **arrays)


def compare(a: str, b: str) -> int:
    x, y = np.load(a), np.load(b)
    bad = sorted(set(x.files) ^ set(y.files))
    for k in sorted(set(x.files) & set(y.files)):
        if not np.array_equal(x[k], y[k], equal_nan=x[k].dtype.kind == "f"):
            d = np.nanmax(np.abs(x[k].astype(float) - y[k].astype(float)))
            bad.append(f"{k} (max |diff| {d:.3g})")
    print(f"{len(x.files)} columns compared; {len(bad)} differ" + "".join(f"\n  {b}" for b in bad))
    return 1 if bad else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="+")
    ap.add_argument("--compare", action="store_true")
    ap.add_argument("--clip")
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--models", default=None, help="comma-separated model names (default: every registered model)")
    a = ap.parse_args(argv)
    if a.compare:
        return compare(*a.paths)
    dump(a.paths[0], a.clip, a.frames, a.models.split(",") if a.models else None)
    return 0


if __name__ == "__main__":
    sys.exit(main())
