"""Oracle check of :mod:`cdnf_ti.dlgmd_reference` against the authors' MATLAB ``D_LGMD.m`` under GNU Octave.

Runs ``D_LGMD.m`` (with ``DOGAnalysis.m``, ``GaussAnalysis.m``, ``gaussC.m``)
from the user's own checkout of ``cquzjn/D-LGMD`` (it is not part of cdnf_ti)
and the float64 reference on the same frames, and prints, per clip, the
largest relative differences of their two outputs (``LGMD_OutputS`` = sum S,
``LGMD_OutputG`` = sum G) and of ``FFI``, and the first alert of each side
(our SFA membrane and threshold applied to their ``sum G``).

Their script reads ``<FilePath><i>.bmp`` from a hard-coded Windows folder. This
script writes the clip's 8-bit grey frames as ``frame_1.bmp, frame_2.bmp, ...``
into a temporary folder and runs a patched copy of ``D_LGMD.m`` written next to
them; each change is one entry of :data:`PATCHES` (all documented in
docs/MODELS.md) and must match the user's file exactly once. Nothing in their
computation is changed. Needs ``octave`` with the ``image`` package
(``im2single``).

Frame alignment: their loop index ``i`` (1-based) reads pictures ``i .. i + 3``;
its outputs are our frame ``i + 2`` (0-based).

Usage::

    python docs/figures/compare_dlgmd.py --repo PATH/D-LGMD [--size 96] [--authors] [--real CLIP.mp4 ...]
        [--real-frames 60] [--real-scale 0.5] [--octave octave]
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

from cdnf_ti.dlgmd_reference import DLGMDParams, DLGMDReference
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus

AUTHORS_FILE = "D_LGMD.m"
#: The authors' own picture sequences: (label, folder in their repository, first index).
AUTHORS_STIMULI = (
    ("SFA Simple_Figures", "Compare with SFA/Simple_Figures", 1),
    ("Relative Expansion Figures", "Compare with Relative Expansion Detection/Figures", 2),
)

#: (pattern, replacement, why): the only changes made to their script.
PATCHES = (
    (r"clear;\s*clc;", "", "keep the wrapper's variables (and print nothing)"),
    (r"FrameEnd_Num\s*=\s*\d+;", "FrameEnd_Num = {n_frames};", "the number of frames of the clip"),
    (r"FilePath\s*=\s*'[^']*';", "FilePath = '{frame_prefix}';", "read the frames from the given folder"),
    (r"figure\(1\)\s*Video_Resize\s*=\s*imresize\(Layer_G,0\.5\);\s*imshow\(Video_Resize\);", "",
     "no window: the G layer is only displayed"),
    (r"Normalized_OutS\(k,1:i\)\s*=\s*mapminmax\([^;]*;\s*Normalized_OutG\(k,1:i\)\s*=\s*mapminmax\([^;]*;", "",
     "no display normalisation (mapminmax is not in Octave; it rescales the whole run to [0, 1])"),
    (r"%\*+plots\*+.*\Z", "", "no plot"),
)


def patched_script(source: str, n_frames: int, frame_prefix: str, out_csv: str, repo: Path) -> str:
    """Their ``D_LGMD.m`` with :data:`PATCHES` applied, the image package loaded, their folder on
    the path, and the outputs written to ``out_csv`` (columns S, G, FFI, Thresh_G; one row per loop index)."""
    text = source
    for pattern, replacement, why in PATCHES:
        new, count = re.subn(pattern, replacement.format(n_frames=n_frames, frame_prefix=frame_prefix), text,
                             flags=re.S)
        if count != 1:
            sys.exit(f"error: {repo / AUTHORS_FILE}: patch '{why}' matched {count} times (expected once)")
        text = new
    head = f"pkg load image;\naddpath('{repo}');\n"
    tail = (f"\ndlmwrite('{out_csv}', [LGMD_OutputS(1,:)' LGMD_OutputG(1,:)' FFI(1,1:i)' Thresh_G(1:i)'], "
            "'precision', '%.17g');\n")
    return head + text + tail


def run_authors(repo: Path, frames: list[np.ndarray], octave: str) -> np.ndarray:
    """Their script on ``frames`` (uint8 grey): rows (S, G, FFI, Thresh_G) per loop index, shape (T-3, 4)."""
    source = (repo / AUTHORS_FILE).read_text(encoding="utf-8", errors="replace")
    with tempfile.TemporaryDirectory() as tmp:
        for i, f in enumerate(frames, start=1):
            cv2.imwrite(str(Path(tmp) / f"frame_{i}.bmp"), f)
        out = Path(tmp) / "out.csv"
        script = Path(tmp) / "run_dlgmd.m"
        script.write_text(patched_script(source, len(frames), f"{tmp}/frame_", str(out), repo.resolve()))
        proc = subprocess.run([octave, "--no-gui", "--quiet", "--no-window-system", str(script)],
                              capture_output=True, text=True, cwd=tmp)
        if not out.is_file():
            sys.exit(f"error: {script}: Octave failed: {proc.stderr.strip().splitlines()[-3:]}")
        return np.loadtxt(out, delimiter=",", ndmin=2)


def their_membrane(g_sum: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Our membrane, SFA and threshold on their ``sum G`` (our frames 3 ..): ``mp`` and the alerts."""
    p = DLGMDParams()
    k = 1.0 / (1.0 + np.exp(-g_sum / (p.k_spread * p.k_norm_per_pixel * shape[0] * shape[1])))
    mp, out = np.zeros(len(k)), np.zeros(len(k), dtype=bool)
    for j in range(2, len(k)):  # frame 5 = loop index 3
        dk = k[j] - k[j - 1]
        mp[j] = p.sfa_gain * k[j] if dk >= p.sfa_rise else p.sfa_gain * mp[j - 1] + p.sfa_gain * dk
        out[j] = mp[j] >= p.threshold
    return mp, out


def first(mask: np.ndarray, offset: int = 0):
    idx = np.flatnonzero(mask)
    return int(idx[0]) + offset if idx.size else None


def rel(a: np.ndarray, b: np.ndarray) -> float:
    """Largest ``|a - b| / max(|b|, 1e-9)``."""
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-9))) if len(a) else 0.0


def compare(repo: Path, frames: list[np.ndarray], octave: str) -> dict:
    theirs = run_authors(repo, frames, octave)
    h, w = frames[0].shape
    ours = DLGMDReference(h, w).run(frames)
    sl = slice(3, 3 + len(theirs))
    mp, alerts = their_membrane(theirs[:, 1], (h, w))
    return {"mp": float(np.max(np.abs(mp - ours["mp"][sl]))) if len(mp) else 0.0,
            "frames": len(frames), "S": rel(theirs[:, 0], ours["s_sum"][sl]), "G": rel(theirs[:, 1], ours["g_sum"][sl]),
            "FFI": rel(theirs[:, 2], ours["ffi"][sl]), "max_G": float(ours["g_sum"].max()),
            "first_theirs": first(alerts, 3), "first_ours": first(ours["alert"])}


def grey_u8(f: np.ndarray) -> np.ndarray:
    """Any frame -> uint8 grey (float in [0, 1] as floor(255 x + 0.5), BGR by COLOR_BGR2GRAY)."""
    f = np.asarray(f)
    if f.ndim == 3:
        return cv2.cvtColor(f, cv2.COLOR_BGR2GRAY)
    if f.dtype == np.uint8:
        return f
    return np.clip(np.floor(f.astype(np.float64) * 255.0 + 0.5), 0, 255).astype(np.uint8)


def authors_clip(repo: Path, folder: str, start: int) -> list[np.ndarray]:
    """Their numbered pictures ``TestImage_<i>.bmp`` from ``start`` on, as uint8 grey (colour ones by BGR2GRAY)."""
    frames, i = [], start
    while (p := repo / folder / f"TestImage_{i}.bmp").is_file():
        img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if img is None:
            sys.exit(f"error: {p}: cannot read")
        frames.append(grey_u8(img))
        i += 1
    return frames


def real_clip(path: str, n: int, scale: float) -> list[np.ndarray]:
    cap = cv2.VideoCapture(path)
    frames = []
    while len(frames) < n:
        ok, f = cap.read()
        if not ok:
            break
        if scale != 1.0:
            f = cv2.resize(f, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        frames.append(grey_u8(f))
    if len(frames) < 8:
        sys.exit(f"error: {path}: fewer than 8 frames")
    return frames


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", required=True, type=Path, help="checkout of cquzjn/D-LGMD")
    ap.add_argument("--octave", default="octave")
    ap.add_argument("--size", type=int, default=96, help="basic stimuli frame side in px (default 96)")
    ap.add_argument("--stimuli", nargs="*", default=list(BASIC_STIMULI), help="basic stimuli (default: all six)")
    ap.add_argument("--authors", action="store_true", help="also run their two picture sequences (800x600)")
    ap.add_argument("--real", nargs="*", default=[], help="video files: their first --real-frames frames are run")
    ap.add_argument("--real-frames", type=int, default=60)
    ap.add_argument("--real-scale", type=float, default=0.5)
    args = ap.parse_args(argv)
    if not (args.repo / AUTHORS_FILE).is_file():
        sys.exit(f"error: {args.repo / AUTHORS_FILE}: not found (pass --repo, a checkout of cquzjn/D-LGMD)")
    clips = [(n, lambda n=n: [grey_u8(f) for f in basic_stimulus(n, height=args.size, width=args.size).frames()])
             for n in args.stimuli]
    if args.authors:
        clips += [(label, lambda f=folder, s=start: authors_clip(args.repo, f, s))
                  for label, folder, start in AUTHORS_STIMULI]
    clips += [(Path(p).name, lambda p=p: real_clip(p, args.real_frames, args.real_scale)) for p in args.real]
    print(f"alert: mp >= {DLGMDParams().threshold} (ours, on both sides' sum G)")
    print(f"{'clip':30s} {'size':>9s} {'T':>4s} {'rel dS':>9s} {'rel dG':>9s} {'rel dFFI':>9s} {'max G':>9s} "
          f"{'max |d mp|':>10s} first alert (theirs/ours)")
    for name, make in clips:
        frames = make()
        r = compare(args.repo, frames, args.octave)
        h, w = frames[0].shape
        same = "equal" if r["first_theirs"] == r["first_ours"] else "DIFFERENT"
        print(f"{name:30s} {f'{w}x{h}':>9s} {r['frames']:4d} {r['S']:9.2e} {r['G']:9.2e} {r['FFI']:9.2e} "
              f"{r['max_G']:9.1f} {r['mp']:10.1e} {r['first_theirs']}/{r['first_ours']} {same}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
