"""Oracle check of :class:`cdnf_ti.lplc2_reference.LPLC2Reference` with ``variant="real"`` against the
authors' real-environment MATLAB (folder 7), run by GNU Octave.

Uses the user's own checkout of ``zhaojunyu01/EMD-LPLC2-GF-model`` (not part of
cdnf_ti): the functions ``emd.m``, ``OnRect.m``, ``OffRect.m``,
``lplc2conv2.m`` (the 3-of-4 rule) and ``LIF.m`` of
``code/7_Real-Environment-Test-About-Animals`` are called, unchanged, by a small
Octave driver written here that repeats the frame loop of their ``loom.m``
(green channel / 255, ``imresize(movieData, 0.25)``, EMD, LPLC2, active count)
and the GF loop of their ``GF.m``, without the figures. Their ``loom.m`` reads
a video with ``VideoReader``, which Octave lacks: the driver loads the clip's
colour frames (uint8 RGB, what ``readFrame`` returns) from a ``.mat`` file
instead, and takes the green channel as theirs does. (Not from PNG files:
Octave's ``imread`` returns a black-and-white picture as ``logical``, which
would scale it by 1/255.)

Printed per clip: the largest difference of the shrunk luminance (their
``patt``), of the LPLC2 response maps (relative to the frame's largest), of the
GF input and of the membrane samples; the frames whose active-unit count
differs; the largest count; and the first GF spike (alert) of each side.

Their code steps the filters and the GF unit at a fixed 10 ms whatever the
video's frame rate; the reference is run at ``fps = 100`` to match.

Usage::

    python docs/figures/compare_lplc2_real_octave.py --repo PATH/EMD-LPLC2-GF-model \\
        [--size 400] [--stimuli dark_looming ...] [--real CLIP.mp4 ...] [--real-frames 60]

Their ``emd.m`` loops over pixels: seconds per frame under Octave.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np
import scipy.io as sio

from cdnf_ti.lplc2_reference import AUTHORS_DT, LPLC2Reference
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus

CODE = "code/7_Real-Environment-Test-About-Animals"

# Their loom.m frame loop (imread in place of VideoReader) and GF.m membrane loop; their functions unchanged.
DRIVER = r"""
pkg load image;
addpath('{code}');
S = load('{frames}'); F = S.frames;  % uint8 RGB, H x W x 3 x T: what readFrame returns, frame by frame
for k = 1:size(F, 4)
  B = double(F(:, :, :, k));
  movieData(:, :, k) = B(:, :, 2) / 255;
end
patt = imresize(movieData, 0.25);
N = size(patt, 3);
STEP = 0.01;
dL = 0.050 / STEP; a_low(1, 1) = 1 / (dL + 1); a_low(1, 2) = 1 - a_low(1, 1);
dH = 0.250 / STEP; b_high(1, 1) = dH / (dH + 1); b_high(1, 2) = b_high(1, 1);
nx = size(patt, 1) - 1; ny = size(patt, 2) - 1;
Fh_before = zeros(nx + 1, ny + 1); Fd_On_before = Fh_before; Fd_Off_before = Fh_before;
maps = zeros(nx, ny, N - 1); nums = zeros(1, N - 1);
for i = 1:N-1
  [Fh, Fd_On, Fd_Off, He_On, Hi_On, Ve_On, Vi_On, He_Off, Hi_Off, Ve_Off, Vi_Off] = emd(nx, ny, a_low, b_high, ...
      Fh_before, Fd_On_before, Fd_Off_before, patt(:, :, i), patt(:, :, i + 1));
  LP = cat(3, Hi_On + Hi_Off, He_On + He_Off, Vi_On + Vi_Off, Ve_On + Ve_Off);
  L = lplc2conv2(LP);
  maps(:, :, i) = L; nums(i) = numel(find(L > 0));
  Fh_before = Fh; Fd_On_before = Fd_On; Fd_Off_before = Fd_Off;
end
step = 0.01; V0 = -60; Vth = -50; Vre = -70; h = step / 20; w = 250; Normal_I1 = 2500;
Normal_vel = (2116 / Normal_I1 - 676 / Normal_I1) / step;
v = zeros(1, 20 * (N - 1) + 1); v(1) = V0; I = zeros(1, N - 1);
for i = 1:N-1
  I1 = nums(i) / Normal_I1;
  if i == 1, I2 = I1; else, I2 = nums(i - 1) / Normal_I1; end
  vel = ((I1 - I2) / step) / Normal_vel;
  if I2 == 0, I(i) = 0; else, I(i) = w * I1 * vel; end
  for j = 1:20
    V = LIF(V0, h, I(i));
    if V > Vth, v((i - 1) * 20 + j + 1) = 20; V = Vre; else, v((i - 1) * 20 + j + 1) = V; end
    V0 = V;
  end
end
save('-mat7-binary', '{out}', 'patt', 'nums', 'maps', 'I', 'v');
"""


def run_octave(octave: str, repo: Path, frames: list[np.ndarray], work: Path) -> dict:
    """The driver on ``frames`` (uint8 BGR) under Octave: patt, nums, maps, I, v."""
    stack = work / "frames.mat"
    sio.savemat(stack, {"frames": np.stack([f[:, :, ::-1] for f in frames], axis=3)})  # BGR -> RGB
    out, script = work / "out.mat", work / "driver.m"
    script.write_text(DRIVER.format(code=(repo / CODE).as_posix(), frames=stack.as_posix(), out=out.as_posix()))
    proc = subprocess.run([octave, "-q", "--no-gui", "--no-window-system", str(script)], capture_output=True,
                          text=True)
    if not out.exists():
        sys.exit("error: octave failed:\n" + "\n".join((proc.stdout + proc.stderr).splitlines()[-20:]))
    return sio.loadmat(out)


def compare(octave: str, repo: Path, frames: list[np.ndarray]) -> dict:
    """Largest differences between their folder-7 MATLAB (under Octave) and ``variant="real"`` on ``frames``."""
    if not (repo / CODE / "lplc2conv2.m").is_file():
        sys.exit(f"error: {repo / CODE}: not found (pass --repo, a checkout of zhaojunyu01/EMD-LPLC2-GF-model)")
    with tempfile.TemporaryDirectory() as tmp:
        theirs = run_octave(octave, repo, frames, Path(tmp))
    h, w = frames[0].shape[:2]
    ref = LPLC2Reference(h, w, fps=1.0 / AUTHORS_DT, variant="real")
    patt = theirs["patt"].reshape(ref.height, ref.width, len(frames))
    maps_t = theirs["maps"].reshape(ref.height - 1, ref.width - 1, len(frames) - 1)
    lum = map_rel = current = 0.0
    count_diff = 0
    trace, alerts = [], []
    for k, f in enumerate(frames):
        lum = max(lum, float(np.max(np.abs(ref.luminance(f) - patt[:, :, k]))))
        s = ref.step(f)
        if k == 0:
            continue
        m_t = maps_t[:, :, k - 1]
        map_rel = max(map_rel, float(np.max(np.abs(ref.lplc2 - m_t))) / max(float(np.max(np.abs(m_t))), 1e-300))
        current = max(current, abs(s.current - float(theirs["I"].ravel()[k - 1])))
        count_diff += int(s.active != int(theirs["nums"].ravel()[k - 1]))
        trace.extend(s.trace)
        alerts.append(s.alert)
    v_t = theirs["v"].ravel()[1:]
    spikes_t = (v_t.reshape(len(frames) - 1, -1) == 20.0).any(axis=1)
    first_t = int(np.argmax(spikes_t)) + 1 if spikes_t.any() else None
    first_o = int(np.argmax(alerts)) + 1 if any(alerts) else None
    return {"frames": len(frames), "shape": (ref.height, ref.width), "lum": lum, "map_rel": map_rel,
            "current": current, "v": float(np.max(np.abs(np.array(trace) - v_t))), "count_diff": count_diff,
            "active_max": int(theirs["nums"].max()), "first": (first_t, first_o)}


def basic_frames(name: str, size: int) -> list[np.ndarray]:
    """A basic stimulus as uint8 BGR frames (grey in all channels)."""
    out = []
    for f in basic_stimulus(name, height=size, width=size).frames():
        g = np.clip(np.floor(f.astype(np.float64) * 255.0 + 0.5), 0, 255).astype(np.uint8)
        out.append(cv2.cvtColor(g, cv2.COLOR_GRAY2BGR))
    return out


def video_frames(path: str, n: int) -> list[np.ndarray]:
    cap = cv2.VideoCapture(path)
    out = []
    while len(out) < n:
        ok, f = cap.read()
        if not ok:
            break
        out.append(f)
    if len(out) < 8:
        sys.exit(f"error: {path}: fewer than 8 frames")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", required=True, type=Path, help="checkout of zhaojunyu01/EMD-LPLC2-GF-model")
    ap.add_argument("--octave", default="octave")
    ap.add_argument("--size", type=int, default=400, help="basic stimuli frame side in px before the shrink")
    ap.add_argument("--stimuli", nargs="*", default=list(BASIC_STIMULI))
    ap.add_argument("--real", nargs="*", default=[], help="video files: their first --real-frames frames")
    ap.add_argument("--real-frames", type=int, default=60)
    args = ap.parse_args(argv)
    clips = [(n, lambda n=n: basic_frames(n, args.size)) for n in args.stimuli]
    clips += [(Path(p).name, lambda p=p: video_frames(p, args.real_frames)) for p in args.real]
    print(f"{'clip':30s} {'array':>8s} {'T':>4s} {'max|dL|':>9s} {'rel dmap':>9s} {'max|dI|':>9s} {'max|dV|':>9s} "
          f"{'n!=':>4s} {'max n':>6s} first spike (theirs/ours)")
    for name, make in clips:
        frames = make()
        r = compare(args.octave, args.repo, frames)
        first_t, first_o = r["first"]
        same = "equal" if first_t == first_o else "DIFFERENT"
        array = f"{r['shape'][1]}x{r['shape'][0]}"
        print(f"{name:30s} {array:>8s} {r['frames']:4d} {r['lum']:9.2e} {r['map_rel']:9.2e} {r['current']:9.2e} "
              f"{r['v']:9.2e} {r['count_diff']:4d} {r['active_max']:6d} {first_t}/{first_o} {same}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
