"""Oracle check of :mod:`cdnf_ti.olgmd_reference` (``variant="code"``), and of the engine model
:class:`cdnf_ti.models.OLGMD` (``--ours engine``), against the authors' Python.

Runs ``Core_of_Source_Code/Computer_oLGMD_Python/optimized_LGMD.py`` from the
user's own checkout of ``Ryannnice/Supplementary_Materials_FFI_ON_OFF`` (it is
not part of cdnf_ti) and the float64 reference on the same frames, and prints,
per clip, the largest per-frame differences of every output their code keeps
and whether the first alerts are equal.

Their code reads a video with ``cv2.VideoCapture``; here their module's ``cv2``
is a proxy whose ``VideoCapture`` serves the clip's frames from memory (BGR
uint8, exactly what OpenCV would return), so no codec sits between the two.
Their plot is drawn on matplotlib's Agg backend and discarded.

Frame alignment (see :mod:`cdnf_ti.olgmd_reference`): their ``K[i]`` is our
``k`` at frame ``i + 1``, ``Kf[i]`` our ``k_raw`` at ``i + 2``, ``AIM[t]`` our
``aim`` at ``t``, ``Spike[t]`` our ``spike_sum`` at ``t`` (``t <= 5``) or
``t - 1`` (``t >= 6``), ``Col[j]`` our ``alert`` at :func:`their_col_frame`.

Usage::

    python docs/figures/compare_olgmd.py --repo PATH/Supplementary_Materials_FFI_ON_OFF \\
        [--size 96] [--real CLIP.mp4 ...] [--real-frames 60] [--real-scale 1.0] [--ours reference|engine]

``--ours engine`` runs the engine model (float32 kernels, ``OLGMDParams(variant="code")``, colour
frames given to its ``step`` as they are) in place of the float64 reference.

Their code takes seconds per frame at 426x240 (pure-Python pixel loops).
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import sys
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from cdnf_ti.olgmd_reference import OLGMDReference, their_col_frame  # noqa: E402
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus  # noqa: E402

AUTHORS_FILE = "Core_of_Source_Code/Computer_oLGMD_Python/optimized_LGMD.py"


class _Capture:
    """``cv2.VideoCapture`` stand-in serving BGR uint8 frames from memory."""

    def __init__(self, frames: list[np.ndarray], fps: float):
        self.frames, self.fps, self.i = frames, fps, 0

    def get(self, prop: int) -> float:
        h, w = self.frames[0].shape[:2]
        return {cv2.CAP_PROP_FRAME_HEIGHT: h, cv2.CAP_PROP_FRAME_WIDTH: w,
                cv2.CAP_PROP_FRAME_COUNT: len(self.frames), cv2.CAP_PROP_FPS: self.fps}[prop]

    def read(self):
        if self.i >= len(self.frames):
            return False, None
        self.i += 1
        return True, self.frames[self.i - 1].copy()


class _CV2Proxy:
    """The real ``cv2`` module except ``VideoCapture``."""

    def __init__(self, frames: list[np.ndarray], fps: float):
        self._frames, self._fps = frames, fps

    def VideoCapture(self, _path):  # noqa: N802 - OpenCV's name
        return _Capture(self._frames, self._fps)

    def __getattr__(self, name):
        return getattr(cv2, name)


def load_authors(repo: Path):
    """Import their module from the checkout (its top level only defines the class and a path)."""
    path = repo / AUTHORS_FILE
    if not path.is_file():
        sys.exit(f"error: {path}: not found (pass --repo, a checkout of Ryannnice/Supplementary_Materials_FFI_ON_OFF)")
    spec = importlib.util.spec_from_file_location("olgmd_authors", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_authors(module, frames: list[np.ndarray], fps: float):
    """Their ``LGMD2().LGMD()`` on ``frames``; returns the instance (K, Kf, AIM, Spike, Col)."""
    import matplotlib.pyplot as plt

    module.cv2 = _CV2Proxy(frames, fps)
    module.PathVal = "<memory>"
    model = module.LGMD2()
    model.LGMD()
    plt.close("all")
    return model


def run_ours(frames: list[np.ndarray], fps: float, ours: str = "reference") -> dict[str, np.ndarray]:
    """Our ``variant="code"`` on ``frames``: ``k``, ``k_raw``, ``aim``, ``spike_sum``, ``alert`` per frame,
    from the float64 reference or (``ours="engine"``) the engine model."""
    if ours == "engine":
        from cdnf_ti.models import OLGMD, OLGMDParams

        tr = OLGMD(OLGMDParams(variant="code"), fps=fps).run(frames)
        return {"k": tr.output, "alert": tr.spike, **{k: tr.diagnostics[k] for k in ("k_raw", "aim", "spike_sum")}}
    h, w = frames[0].shape[:2]
    return OLGMDReference(h, w, variant="code", fps=fps).run(frames)


def compare(module, frames: list[np.ndarray], fps: float, which: str = "reference") -> dict:
    """Run both on ``frames`` (BGR uint8) and return the largest differences and the first alerts."""
    theirs = run_authors(module, frames, fps)
    ours = run_ours(frames, fps, which)
    n = len(frames)
    k_t = np.array(theirs.K[1:], dtype=np.float64)  # K[i] <-> frame i + 1
    kf_t = np.array(theirs.Kf, dtype=np.float64)  # Kf[i] <-> frame i + 2
    aim_t = np.array(theirs.AIM[2:], dtype=np.float64)  # AIM[t] <-> frame t
    spike_t = np.array([float(theirs.Spike[t]) for t in range(3, n)])
    spike_o = np.array([ours["spike_sum"][t if t <= 5 else t - 1] for t in range(3, n)])
    col_t = np.array([int(theirs.Col[j]) for j in range(0, n - 3)], dtype=bool)
    col_o = np.array([ours["alert"][their_col_frame(j)] for j in range(0, n - 3)], dtype=bool)
    first_t = their_col_frame(int(np.argmax(col_t))) if col_t.any() else None
    mapped = ours["alert"][3 : n - 1]  # the frames that have a Col entry
    first_o = 3 + int(np.argmax(mapped)) if mapped.any() else None
    aim_o = ours["aim"][2:]
    return {
        "frames": n,
        "K": float(np.max(np.abs(k_t - ours["k"][2:]))),
        "Kf": float(np.max(np.abs(kf_t - ours["k_raw"][2:]))),
        "AIM": float(np.max(np.abs(aim_t - aim_o))),
        "AIM_rel": float(np.max(np.abs(aim_t - aim_o) / np.maximum(np.abs(aim_o), 1e-12))),
        "Spike": float(np.max(np.abs(spike_t - spike_o))),
        "Col_mismatch": int(np.sum(col_t != col_o)),
        "first_theirs": first_t,
        "first_ours": first_o,
        "first_equal": first_t == first_o,
    }


def basic_clip(name: str, size: int) -> tuple[list[np.ndarray], float]:
    """A basic stimulus as BGR uint8 frames (grey in all three channels), and its fps."""
    st = basic_stimulus(name, height=size, width=size)
    frames = []
    for f in st.frames():
        g = np.clip(np.floor(f.astype(np.float64) * 255.0 + 0.5), 0, 255).astype(np.uint8)
        frames.append(cv2.cvtColor(g, cv2.COLOR_GRAY2BGR))
    return frames, float(st.fps)


def real_clip(path: str, n: int, scale: float) -> tuple[list[np.ndarray], float]:
    """The first ``n`` BGR frames of a video (resized by ``scale`` with INTER_AREA when not 1), and its fps."""
    cap = cv2.VideoCapture(path)
    if not cap.isOpened():
        sys.exit(f"error: {path}: cannot open video")
    fps = cap.get(cv2.CAP_PROP_FPS) or 30.0
    frames = []
    while len(frames) < n:
        ok, f = cap.read()
        if not ok:
            break
        if scale != 1.0:
            f = cv2.resize(f, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        frames.append(f)
    if len(frames) < 8:
        sys.exit(f"error: {path}: fewer than 8 frames")
    return frames, float(fps)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", required=True, type=Path, help="checkout of Ryannnice/Supplementary_Materials_FFI_ON_OFF")
    ap.add_argument("--size", type=int, default=96, help="basic stimuli frame side in px (default 96)")
    ap.add_argument("--stimuli", nargs="*", default=list(BASIC_STIMULI), help="basic stimuli to run (default: all six)")
    ap.add_argument("--real", nargs="*", default=[], help="video files: their first --real-frames frames are run")
    ap.add_argument("--real-frames", type=int, default=60)
    ap.add_argument("--real-scale", type=float, default=1.0, help="resize factor for the real clips (default 1)")
    ap.add_argument("--ours", choices=("reference", "engine"), default="reference",
                    help="our side: the float64 reference (default) or the engine model")
    args = ap.parse_args(argv)
    module = load_authors(args.repo)
    clips = [(name, lambda name=name: basic_clip(name, args.size)) for name in args.stimuli]
    clips += [(Path(p).name, lambda p=p: real_clip(p, args.real_frames, args.real_scale)) for p in args.real]
    print(f"{'clip':36s} {'size':>9s} {'T':>4s} {'max|dK|':>9s} {'max|dKf|':>9s} {'max|dAIM|':>9s} "
          f"{'rel dAIM':>9s} {'max|dSpk|':>9s} {'Col!=':>5s} first alert (theirs/ours, our frame)")
    import contextlib
    import io
    for name, make in tqdm(clips, desc="clips", file=sys.stderr):
        frames, fps = make()
        with contextlib.redirect_stdout(io.StringIO()):
            r = compare(module, frames, fps, args.ours)
        h, w = frames[0].shape[:2]
        print(f"{name:36s} {f'{w}x{h}':>9s} {r['frames']:4d} {r['K']:9.2e} {r['Kf']:9.2e} {r['AIM']:9.2e} "
              f"{r['AIM_rel']:9.2e} {r['Spike']:9.2e} {r['Col_mismatch']:5d} "
              f"{r['first_theirs']}/{r['first_ours']} {'equal' if r['first_equal'] else 'DIFFERENT'}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
