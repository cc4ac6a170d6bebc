"""A/B of ``Model.step`` between two checkouts of cdnf_ti, alternating fresh processes round by round.

Each round starts one process per version (in turn, A then B, then B then A in the next round),
which steps each model over the same frames after a warm-up and reports the wall frames/s and
the CPU time per frame. The table gives each version's median over the rounds and the ratio
``B / A`` (frames/s: above 1, B is faster; CPU time: above 1, B is slower)::

    python bench/ab_step.py --a PYTHON_A:CHECKOUT_A --b PYTHON_B:CHECKOUT_B \\
        [--models cdnf,lgmd2 | all] [--compiler taichi] [--clip CLIP.mp4] [--size 426x240] \\
        [--frames 150] [--rounds 5]

``PYTHON`` is an interpreter in which that checkout's ``cdnf_ti`` is importable (its own venv);
the child runs with the checkout as its working folder and uses the public API only. Without
``--clip`` the frames are the dashcam-like stand-in video.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

CHILD = r"""
import json, sys, time
import numpy as np
from cdnf_ti import MODELS, create_model
model_names, clip = (list(MODELS) if sys.argv[1] == "all" else sys.argv[1].split(",")), sys.argv[2]
width, height, n = int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
if clip:
    import cv2
    from cdnf_ti import iter_grey, open_source
    frames = []
    for g in iter_grey(open_source(clip)):
        frames.append(cv2.resize(g, (width, height), interpolation=cv2.INTER_AREA))
        if len(frames) >= n + 10:
            break
else:
    from cdnf_ti.bench.inputs import standin_video
    frames = [f[:height, :width] for f in standin_video(n + 10, seed=1)]
out = {}
for name in model_names:
    m = create_model(name)
    for f in frames[:10]:
        m.step(f)  # compile and warm up
    w0, c0 = time.perf_counter(), time.process_time()
    for f in frames[10:]:
        m.step(f)
    w1, c1 = time.perf_counter(), time.process_time()
    k = len(frames) - 10
    out[name] = {"fps": k / (w1 - w0), "cpu_ms": 1000 * (c1 - c0) / k}
print("RESULT " + json.dumps(out))
"""


def _run(spec: str, models: list[str], args: argparse.Namespace) -> dict:
    python, checkout = spec.split(":", 1)
    env = dict(os.environ)
    if args.compiler:
        env["CDNF_TI_COMPILER"] = args.compiler
    w, h = (int(x) for x in args.size.lower().split("x"))
    proc = subprocess.run([python, "-c", CHILD, ",".join(models), args.clip or "", str(w), str(h), str(args.frames)],
                          cwd=checkout, env=env, capture_output=True, text=True)
    got = [ln[7:] for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not got:
        raise SystemExit(f"error: {checkout}: the child failed:\n{proc.stderr[-2000:]}")
    return json.loads(got[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", required=True, help="PYTHON:CHECKOUT of version A (before)")
    ap.add_argument("--b", required=True, help="PYTHON:CHECKOUT of version B (after)")
    ap.add_argument("--models", default="all", help="comma-separated model names, or all (every registered model)")
    ap.add_argument("--compiler", default=None, help="taichi or quadrants (default: the checkouts' default)")
    ap.add_argument("--clip", default=None, help="a video; default: the stand-in video")
    ap.add_argument("--size", default="426x240", help="WxH of the frames")
    ap.add_argument("--frames", type=int, default=150, help="timed frames per model and process")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args(argv)
    models = args.models.split(",")
    runs = {"a": [], "b": []}
    for r in range(args.rounds):
        for v in (("a", "b") if r % 2 == 0 else ("b", "a")):
            runs[v].append(_run(getattr(args, v), models, args))
        if models == ["all"]:  # the registered models both versions ran
            models = [m for m in runs["a"][-1] if m in runs["b"][-1]]
        print(f"round {r + 1}/{args.rounds}: " + "  ".join(
            f"{m} {runs['a'][-1][m]['fps']:.0f}->{runs['b'][-1][m]['fps']:.0f}" for m in models), file=sys.stderr)
    print(f"| model | frames/s A | frames/s B | B/A | CPU ms A | CPU ms B | B/A |  ({args.rounds} rounds, "
          f"{args.frames} frames, {args.size}, {args.compiler or 'default compiler'})")
    print("|---|---|---|---|---|---|---|")
    for m in models:
        fa, fb = (statistics.median(x[m]["fps"] for x in runs[v]) for v in ("a", "b"))
        ca, cb = (statistics.median(x[m]["cpu_ms"] for x in runs[v]) for v in ("a", "b"))
        print(f"| {m} | {fa:.0f} | {fb:.0f} | {fb / fa:.3f} | {ca:.2f} | {cb:.2f} | {cb / ca:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
