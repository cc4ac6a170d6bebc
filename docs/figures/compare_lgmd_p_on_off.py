"""Oracle check of :mod:`cdnf_ti.lgmd_p_on_off_reference` (``variant="code"``) against the authors' Python.

Runs ``Harmonizing motion and contrast vision.py`` from the user's own checkout
of ``fuqinbing/harmonizing-motion-and-contrast-vision-for-looming-detection``
(it is not part of cdnf_ti) and the float64 reference on the same frames, and
prints, per clip, the largest differences of the membrane potential ``mp`` and of the
summation layer ``S`` (every pixel, every frame), and
the first frame with ``mp >= threshold`` on each side.

Their class reads a video with ``cv2.VideoCapture``; here their module's
``cv2`` is the proxy of ``compare_olgmd.py`` whose ``VideoCapture`` serves the
clip's BGR uint8 frames from memory, so no codec sits between the two. Their
``mp[t]`` is our ``mp`` at frame ``t`` (no shift).

Usage::

    python docs/figures/compare_lgmd_p_on_off.py \\
        --repo PATH/harmonizing-motion-and-contrast-vision-for-looming-detection \\
        [--size 96] [--real CLIP.mp4 ...] [--real-frames 60] [--real-scale 0.5]

Their code keeps about 25 float64 arrays of H x W x T: scale real clips down.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_olgmd import _CV2Proxy, basic_clip, real_clip  # noqa: E402

from cdnf_ti.lgmd_p_on_off_reference import LGMDPOnOffParams, LGMDPOnOffReference  # noqa: E402
from cdnf_ti.stimuli.basic import BASIC_STIMULI  # noqa: E402

AUTHORS_FILE = "Harmonizing motion and contrast vision.py"


def load_authors(repo: Path):
    """Import their module from the checkout (its top level only defines the class)."""
    path = repo / AUTHORS_FILE
    if not path.is_file():
        sys.exit(f"error: {path}: not found (pass --repo, a checkout of "
                 "fuqinbing/harmonizing-motion-and-contrast-vision-for-looming-detection)")
    spec = importlib.util.spec_from_file_location("lgmd_p_on_off_authors", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_authors(module, frames: list[np.ndarray], fps: float):
    """Their ``LGMD_P_ON_OFF(path).run()`` on ``frames``: the instance (``mp`` (T,), ``S`` (H, W, T), ...)."""
    module.cv2 = _CV2Proxy(frames, fps)
    model = module.LGMD_P_ON_OFF("<memory>")
    with contextlib.redirect_stdout(io.StringIO()):
        model.run()
    return model


def first(mask: np.ndarray):
    """First index where ``mask`` is true, or None."""
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else None


def compare(module, frames: list[np.ndarray], fps: float) -> dict:
    """Run both on ``frames`` (BGR uint8): the largest ``|d mp|`` and ``|d S|`` and the first alert of each side."""
    theirs = run_authors(module, frames, fps)
    mp_theirs = np.asarray(theirs.mp, dtype=np.float64)
    h, w = frames[0].shape[:2]
    ref = LGMDPOnOffReference(h, w, variant="code")
    mp, alert, d_s = [], [], 0.0
    for t, f in enumerate(frames):
        r = ref.step(f)
        mp.append(r.mp)
        alert.append(r.alert)
        if t >= 1:
            d_s = max(d_s, float(np.max(np.abs(theirs.S[:, :, t] - ref.layers["S"]))))
    mp = np.array(mp)
    threshold = LGMDPOnOffParams().threshold
    return {"frames": len(frames), "mp": float(np.max(np.abs(mp_theirs - mp))), "S": d_s,
            "max_mp": float(mp.max()), "first_theirs": first(mp_theirs >= threshold),
            "first_ours": first(np.array(alert))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", required=True, type=Path,
                    help="checkout of fuqinbing/harmonizing-motion-and-contrast-vision-for-looming-detection")
    ap.add_argument("--size", type=int, default=96, help="basic stimuli frame side in px (default 96)")
    ap.add_argument("--stimuli", nargs="*", default=list(BASIC_STIMULI), help="basic stimuli (default: all six)")
    ap.add_argument("--real", nargs="*", default=[], help="video files: their first --real-frames frames are run")
    ap.add_argument("--real-frames", type=int, default=60)
    ap.add_argument("--real-scale", type=float, default=0.5, help="resize factor for the real clips (default 0.5)")
    args = ap.parse_args(argv)
    module = load_authors(args.repo)
    clips = [(name, lambda name=name: basic_clip(name, args.size)) for name in args.stimuli]
    clips += [(Path(p).name, lambda p=p: real_clip(p, args.real_frames, args.real_scale)) for p in args.real]
    print(f"threshold mp >= {LGMDPOnOffParams().threshold} (ours; their code has no alert)")
    print(f"{'clip':36s} {'size':>9s} {'T':>4s} {'max|dmp|':>9s} {'max|dS|':>9s} {'max mp':>7s} "
          "first alert (theirs/ours)")
    for name, make in clips:
        frames, fps = make()
        r = compare(module, frames, fps)
        h, w = frames[0].shape[:2]
        same = "equal" if r["first_theirs"] == r["first_ours"] else "DIFFERENT"
        print(f"{name:36s} {f'{w}x{h}':>9s} {r['frames']:4d} {r['mp']:9.2e} {r['S']:9.2e} {r['max_mp']:7.4f} "
              f"{r['first_theirs']}/{r['first_ours']} {same}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
