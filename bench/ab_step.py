"""A/B of ``Model.step`` between two checkouts of cdnf_ti, alternating round by round.

Each round starts one process per version (in turn, A then B, then B then A in the next round),
which steps each model over the same frames after a warm-up and reports the wall frames/s and
the CPU time per frame (after a garbage collection, so that none falls due in the timed steps:
a full one takes about 100 ms with a compiler loaded). The table gives each version's median
over the rounds and the ratio ``B / A`` (frames/s: above 1, B is faster; CPU time: above 1, B is slower)::

    python bench/ab_step.py --a PYTHON_A:CHECKOUT_A --b PYTHON_B:CHECKOUT_B \\
        [--models cdnf,lgmd2 | all] [--compiler taichi] [--clip CLIP.mp4] [--size 426x240] \\
        [--frames 150] [--rounds 5] [--interleave]

``PYTHON`` is an interpreter in which that checkout's ``cdnf_ti`` is importable (its own venv);
the child runs with the checkout as its working folder and uses the public API only. Without
``--clip`` the frames are the dashcam-like stand-in video.

On a shared host the speed of a process drifts by tens of percent over seconds, more than the
differences an A/B looks for. ``--interleave`` runs both versions in ONE process per round
(both checkouts under the same ``PYTHON``; the load order alternates by round): each model of
each version steps the same frames, A and B frame by frame in alternating order, so a slow
spell of the host slows both alike. Each version's modules are swapped into ``sys.modules``
around its own steps. Two instances of the same code in one process can differ by 10-20 % in
the order they were loaded, so the ``B/A`` columns are the geometric means of the rounds' own
ratios (use an even number of rounds). The table adds the largest difference between the two
versions' outputs (``|dout|``, relative to the larger output) and whether their alerts agree.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

#: The children's frames: ``n + 10`` frames of ``clip`` resized to ``width`` x ``height`` (grey), or of the
#: stand-in video; decoded by the ``cdnf_ti`` package given.
FRAMES = r"""
def load_frames(cdnf_ti, clip, width, height, n):
    if clip:
        import cv2
        frames = []
        for g in cdnf_ti.iter_grey(cdnf_ti.open_source(clip)):
            frames.append(cv2.resize(g, (width, height), interpolation=cv2.INTER_AREA))
            if len(frames) >= n + 10:
                break
        return frames
    from cdnf_ti.bench.inputs import standin_video
    return [f[:height, :width] for f in standin_video(n + 10, seed=1)]
"""

CHILD = FRAMES + r"""
import gc, json, sys, time
import numpy as np
import cdnf_ti
from cdnf_ti import MODELS, create_model
model_names, clip = (list(MODELS) if sys.argv[1] == "all" else sys.argv[1].split(",")), sys.argv[2]
width, height, n = int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
frames = load_frames(cdnf_ti, clip, width, height, n)
out = {}
for name in model_names:
    m = create_model(name)
    for f in frames[:10]:
        m.step(f)  # compile and warm up
    gc.collect()  # none falls due inside the timed steps
    w0, c0 = time.perf_counter(), time.process_time()
    for f in frames[10:]:
        m.step(f)
    w1, c1 = time.perf_counter(), time.process_time()
    k = len(frames) - 10
    out[name] = {"fps": k / (w1 - w0), "cpu_ms": 1000 * (c1 - c0) / k}
print("RESULT " + json.dumps(out))
"""

CHILD_PAIR = FRAMES + r"""
import gc, json, os, sys, time
import numpy as np
PACKAGES = ("cdnf_ti", "kernels", "stimuli", "bench")
checkouts = sys.argv[1].split(os.pathsep)
model_names, clip = sys.argv[2], sys.argv[3]
width, height, n = int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6])


def ours(name):
    return name.split(".")[0] in PACKAGES


def load(checkout):
    # one checkout's packages, imported afresh; returns its modules (swapped back in around its steps)
    for k in [k for k in sys.modules if ours(k)]:
        del sys.modules[k]
    sys.path.insert(0, checkout)
    import cdnf_ti  # noqa: F401
    sys.path.remove(checkout)
    here, root = os.path.realpath(cdnf_ti.__file__), os.path.realpath(checkout)
    if os.path.commonpath([here, root]) != root:
        raise SystemExit(f"{checkout}: cdnf_ti was imported from {here}, not from this checkout")
    print(f"LOADED {here}", file=sys.stderr)
    return cdnf_ti


modules, packages, registered = [], [], []
for checkout in checkouts:
    cdnf_ti = load(checkout)
    registered.append(list(cdnf_ti.MODELS))  # the registry finds its models now, with this version's modules
    modules.append({k: v for k, v in sys.modules.items() if ours(k)})
    packages.append(cdnf_ti)
    if len(packages) == 1:  # the frames, decoded once by the first version
        frames = load_frames(cdnf_ti, clip, width, height, n)
active, own = len(modules) - 1, []


def adopt(k):
    # what version k imported since (a lazy import) is its own; the names only one version has
    modules[k].update({m: v for m, v in sys.modules.items() if ours(m)})
    shared = set.intersection(*(set(v) for v in modules))
    own[:] = [set(v) - shared for v in modules]


def use(k):
    # version k's modules in sys.modules: the other's own names out, k's in
    global active
    for m in own[active]:
        sys.modules.pop(m, None)
    sys.modules.update(modules[k])
    active = k


adopt(active)
# the models both versions have, made and warmed up only after both are loaded, so that
# neither version's process holds models the other lacks
common = [m for m in registered[0] if all(m in r for r in registered[1:])]
names = common if model_names == "all" else [m for m in model_names.split(",") if m in common]
versions = []
for k, cdnf_ti in enumerate(packages):
    use(k)
    models = {}
    for name in names:
        models[name] = cdnf_ti.create_model(name)
        for f in frames[:10]:
            models[name].step(f)  # compile and warm up
    adopt(k)
    versions.append(models)
out = [{} for _ in versions]
for name in names:
    wall, cpu, output, spike = ([[] for _ in versions] for _ in range(4))
    gc.collect()  # none falls due inside the timed steps
    for t, f in enumerate(frames[10:]):
        for k in (range(len(versions)) if t % 2 == 0 else reversed(range(len(versions)))):
            use(k)
            size = len(sys.modules)
            w0, c0 = time.perf_counter(), time.process_time()
            r = versions[k][name].step(f)
            wall[k].append(time.perf_counter() - w0)
            cpu[k].append(time.process_time() - c0)
            if len(sys.modules) != size:
                adopt(k)
            output[k].append(float(r.output))
            spike[k].append(bool(r.spike))
    o0, o1 = np.asarray(output[0]), np.asarray(output[-1])
    dout = float(np.max(np.abs(o1 - o0))) / max(float(np.max(np.abs(o0))), float(np.max(np.abs(o1))), 1e-30)
    for k in range(len(versions)):
        out[k][name] = {"fps": len(frames[10:]) / sum(wall[k]), "cpu_ms": 1000 * sum(cpu[k]) / len(cpu[k]),
                        "dout": dout, "alerts_equal": spike[-1] == spike[0]}
print("RESULT " + json.dumps(out))
"""


def _env(args: argparse.Namespace) -> dict:
    env = dict(os.environ)
    if args.compiler:
        env["CDNF_TI_COMPILER"] = args.compiler
    return env


def _size(args: argparse.Namespace) -> tuple[str, str]:
    w, h = (int(x) for x in args.size.lower().split("x"))
    return str(w), str(h)


def _run_pair(first: str, second: str, models: list[str], args: argparse.Namespace) -> tuple[dict, dict]:
    """One process running both versions interleaved (``first`` loaded first): their results, in that order."""
    (python, c1), (python2, c2) = first.split(":", 1), second.split(":", 1)
    if python != python2:
        raise SystemExit("error: --interleave: A and B must name the same PYTHON (both checkouts run in one process)")
    proc = subprocess.run([python, "-c", CHILD_PAIR, os.pathsep.join([c1, c2]), ",".join(models), args.clip or "",
                           *_size(args), str(args.frames)], env=_env(args), capture_output=True, text=True)
    for line in proc.stderr.splitlines():  # where each version's code came from
        if line.startswith("LOADED "):
            print(line, file=sys.stderr)
    a, b = _result(proc, f"{c1}, {c2}")
    return a, b


def _result(proc: subprocess.CompletedProcess, what: str):
    """The child's ``RESULT`` line, parsed; one error line naming ``what`` if the child failed."""
    got = [ln[7:] for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not got:
        raise SystemExit(f"error: {what}: the child failed:\n{proc.stderr[-2000:]}")
    return json.loads(got[-1])


def _run(spec: str, models: list[str], args: argparse.Namespace) -> dict:
    python, checkout = spec.split(":", 1)
    proc = subprocess.run([python, "-c", CHILD, ",".join(models), args.clip or "", *_size(args), str(args.frames)],
                          cwd=checkout, env=_env(args), capture_output=True, text=True)
    return _result(proc, checkout)


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
    ap.add_argument("--interleave", action="store_true",
                    help="both versions in one process per round, frame by frame (same PYTHON for both)")
    args = ap.parse_args(argv)
    models = args.models.split(",")
    runs = {"a": [], "b": []}
    for r in range(args.rounds):
        order = ("a", "b") if r % 2 == 0 else ("b", "a")
        if args.interleave:
            got = _run_pair(getattr(args, order[0]), getattr(args, order[1]), models, args)
            for v, result in zip(order, got):
                runs[v].append(result)
        else:
            for v in order:
                runs[v].append(_run(getattr(args, v), models, args))
        if models == ["all"]:  # the registered models both versions ran
            models = [m for m in runs["a"][-1] if m in runs["b"][-1]]
        print(f"round {r + 1}/{args.rounds}: " + "  ".join(
            f"{m} {runs['a'][-1][m]['fps']:.0f}->{runs['b'][-1][m]['fps']:.0f}" for m in models), file=sys.stderr)
    extra = " |dout| | alerts equal |" if args.interleave else ""
    print(f"| model | frames/s A | frames/s B | B/A | CPU ms A | CPU ms B | B/A |{extra}  ({args.rounds} "
          f"{'interleaved ' if args.interleave else ''}rounds, {args.frames} frames, {args.size}, "
          f"{args.compiler or 'default compiler'})")
    print("|---" * (9 if args.interleave else 7) + "|")
    for m in models:
        fa, fb = (statistics.median(x[m]["fps"] for x in runs[v]) for v in ("a", "b"))
        ca, cb = (statistics.median(x[m]["cpu_ms"] for x in runs[v]) for v in ("a", "b"))
        f_ratio, c_ratio = fb / fa, cb / ca
        if args.interleave:  # the rounds' own ratios: a round's load order favours one version, the next the other
            f_ratio, c_ratio = (statistics.geometric_mean(b[m][key] / a[m][key] for a, b in zip(runs["a"], runs["b"]))
                                for key in ("fps", "cpu_ms"))
        row = f"| {m} | {fa:.0f} | {fb:.0f} | {f_ratio:.3f} | {ca:.2f} | {cb:.2f} | {c_ratio:.3f} |"
        if args.interleave:
            dout = max(x[m]["dout"] for x in runs["b"])
            row += f" {dout:.1e} | {'yes' if all(x[m]['alerts_equal'] for x in runs['b']) else 'NO'} |"
        print(row)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
