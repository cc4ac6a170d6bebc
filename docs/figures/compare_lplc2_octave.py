"""Oracle check of :mod:`cdnf_ti.lplc2_reference` (and, with ``--engine``, of the engine model
:class:`cdnf_ti.models.lplc2.LPLC2`) against the authors' MATLAB, run by GNU Octave.

Uses the user's own checkout of ``zhaojunyu01/EMD-LPLC2-GF-model`` (not part
of cdnf_ti): their functions ``emd.m``, ``OnRect.m``, ``OffRect.m``,
``lplc2conv2.m`` and ``LIF.m`` from ``code/2_Response-Characteristics-LPLC2-
Arrays-And-GF-Unit-To-Looming`` are called, unchanged, by a small Octave
driver written here that repeats the frame loop of their ``loom.m`` and the GF
loop of their ``GF.m`` without the figures. Their stimuli are read from
``code/1_.../Stimuli``: the ``.mat`` files (``patt``, 600x800xT binary
frames, exact) or the ``.avi`` renderings (``--source avi``), downsampled by
``--step`` as ``loom.m`` does (``patt(1:4:end, 1:4:end, :)``).

Printed per stimulus: the largest per-frame difference of the EMD motion maps
(their ``LP``: left, right, up, down, relative to the frame's largest), of the LPLC2 response
maps (absolute, and relative to the frame's largest response), of the centre
unit, of the GF input current and of the GF membrane samples; the number of
frames whose active-unit count differs; and whether the GF spike frames (the
alert) are equal.

With ``--engine`` a second table compares the engine model (its compiled backend, the
compiler of ``$CDNF_TI_COMPILER``) with the same Octave run: the LPLC2 response maps
(relative to the frame's largest), the centre unit, the GF input, the membrane at each
frame's end, the frames whose active-unit count differs and the spike frames.

Usage::

    python docs/figures/compare_lplc2_octave.py --repo PATH/EMD-LPLC2-GF-model \\
        [--stimuli Looming_50ms ...] [--first 195] [--frames 105] [--step 4] [--source mat|avi] [--engine]

Their ``emd.m`` loops over pixels: about 6 s per 150x200 frame under Octave.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np
import scipy.io as sio
from tqdm import tqdm

from cdnf_ti.lplc2_reference import AUTHORS_DT, LPLC2Reference

CODE = "code/2_Response-Characteristics-LPLC2-Arrays-And-GF-Unit-To-Looming"
STIMULI = "code/1_Response-Characteristics-Of-Single-LPLC2-Neurons-To-Different-Stimuli/Stimuli"
DEFAULT_STIMULI = ["Looming_50ms", "Bar_horizontal-motion", "Edge_vertical-motion", "Grating_horizontal-motion",
                   "Cross_centrifugal-motion"]

# The driver: their loom.m frame loop and GF.m membrane loop, figures left out; calls their functions unchanged.
DRIVER = r"""
addpath('{code}');
S = load('{stim}'); patt = double(S.patt); T = size(patt, 3);
STEP = 0.01;
dL = 0.050 / STEP; a_low(1, 1) = 1 / (dL + 1); a_low(1, 2) = 1 - a_low(1, 1);
dH = 0.250 / STEP; b_high(1, 1) = dH / (dH + 1); b_high(1, 2) = b_high(1, 1);
nx = size(patt, 1) - 1; ny = size(patt, 2) - 1;
Fh_before = zeros(nx + 1, ny + 1); Fd_On_before = Fh_before; Fd_Off_before = Fh_before;
maps = zeros(nx, ny, T - 1); motion = zeros(nx, ny, 4, T - 1); nums = zeros(1, T - 1); core = zeros(1, T - 1);
for i = 1:T-1
  [Fh, Fd_On, Fd_Off, He_On, Hi_On, Ve_On, Vi_On, He_Off, Hi_Off, Ve_Off, Vi_Off] = emd(nx, ny, a_low, b_high, ...
      Fh_before, Fd_On_before, Fd_Off_before, patt(:, :, i), patt(:, :, i + 1));
  LP = cat(3, Hi_On + Hi_Off, He_On + He_Off, Vi_On + Vi_Off, Ve_On + Ve_Off);
  L = lplc2conv2(LP);
  maps(:, :, i) = L; motion(:, :, :, i) = LP; nums(i) = numel(find(L > 0)); core(i) = L(floor(end / 2), floor(end / 2));
  Fh_before = Fh; Fd_On_before = Fd_On; Fd_Off_before = Fd_Off;
  printf('frame %d/%d\n', i, T - 1); fflush(stdout);
end
step = 0.01; V0 = -60; Vth = -50; Vre = -70; h = step / 20; w = 250; Normal_I1 = 2500;
Normal_vel = (2116 / Normal_I1 - 676 / Normal_I1) / step;
v = zeros(1, 20 * (T - 1) + 1); v(1) = V0; I = zeros(1, T - 1);
for i = 1:T-1
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
save('-mat7-binary', '{out}', 'nums', 'core', 'maps', 'motion', 'I', 'v');
"""


def load_stimulus(repo: Path, name: str, source: str, step: int, first: int, frames: int) -> np.ndarray:
    """Their stimulus ``name`` as float64 (H, W, T) in [0, 1]: frames ``first .. first + frames - 1`` (0-based)."""
    folder = repo / STIMULI
    if source == "mat":
        patt = sio.loadmat(folder / f"{name}.mat")["patt"].astype(np.float64)
    else:
        cap = cv2.VideoCapture(str(folder / f"{name}.avi"))
        grey = []
        while True:
            ok, f = cap.read()
            if not ok:
                break
            grey.append(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY).astype(np.float64) / 255.0)
        if not grey:
            sys.exit(f"error: {folder / name}.avi: cannot read frames")
        patt = np.stack(grey, axis=2)
    patt = patt[::step, ::step, first : first + frames]
    if patt.shape[2] < 3:
        sys.exit(f"error: {name}: fewer than 3 frames from frame {first}")
    return patt


def run_octave(octave: str, repo: Path, patt: np.ndarray, work: Path) -> dict:
    """Run the driver on ``patt`` under Octave; returns nums, core, maps, motion (their LP), I, v."""
    stim, out, script = work / "stim.mat", work / "out.mat", work / "driver.m"
    sio.savemat(stim, {"patt": patt})
    script.write_text(DRIVER.format(code=(repo / CODE).as_posix(), stim=stim.as_posix(), out=out.as_posix()))
    with subprocess.Popen([octave, "-q", "--no-gui", "--no-window-system", str(script)], stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True) as proc:
        bar = tqdm(total=patt.shape[2] - 1, desc="octave frames", file=sys.stderr, leave=False)
        log = []
        for line in proc.stdout:
            log.append(line)
            if line.startswith("frame "):
                bar.update(1)
        bar.close()
    if proc.returncode != 0 or not out.exists():
        sys.exit("error: octave failed:\n" + "".join(log[-20:]))
    return sio.loadmat(out)


def compare_engine(theirs: dict, patt: np.ndarray) -> dict:
    """Largest differences between their MATLAB run ``theirs`` and the engine model on ``patt``."""
    from cdnf_ti.models import LPLC2

    h, w, t = patt.shape
    model = LPLC2(fps=1.0 / AUTHORS_DT)
    maps_t = theirs["maps"].reshape(h - 1, w - 1, t - 1)
    v_t = theirs["v"].ravel()[1:].reshape(t - 1, -1)
    map_rel = core = current = v_end = 0.0
    count_diff = 0
    spikes_o = []
    for k in range(t):
        s = model.step(patt[:, :, k].astype(np.float32))
        if k == 0:
            continue
        m_t = maps_t[:, :, k - 1]
        ours = model.fields()["lplc2"][: h - 1, : w - 1]
        map_rel = max(map_rel, float(np.max(np.abs(ours - m_t))) / max(float(np.max(np.abs(m_t))), 1e-300))
        core = max(core, abs(s.diagnostics["core"] - float(theirs["core"].ravel()[k - 1])))
        current = max(current, abs(s.diagnostics["current"] - float(theirs["I"].ravel()[k - 1])))
        end = v_t[k - 1, -1]
        v_end = max(v_end, abs(s.output - (model.params.v_reset if end == 20.0 else end)))
        count_diff += int(s.diagnostics["active"] != int(theirs["nums"].ravel()[k - 1]))
        spikes_o.append(s.spike)
    spikes_t = (v_t == 20.0).any(axis=1)
    first_t = int(np.argmax(spikes_t)) + 1 if spikes_t.any() else None
    first_o = int(np.argmax(spikes_o)) + 1 if any(spikes_o) else None
    return {"map_rel": map_rel, "core": core, "current": current, "v": v_end, "count_diff": count_diff,
            "spike_frames": int(spikes_t.sum()), "spikes_equal": bool(np.array_equal(spikes_t, np.array(spikes_o))),
            "first": (first_t, first_o)}


def compare(octave: str, repo: Path, patt: np.ndarray, engine: bool = False) -> dict:
    """Largest differences between their MATLAB (under Octave) and the reference on ``patt`` (and, with
    ``engine``, the engine model's under the key ``"engine"``)."""
    with tempfile.TemporaryDirectory() as tmp:
        theirs = run_octave(octave, repo, patt, Path(tmp))
    h, w, t = patt.shape
    ref = LPLC2Reference(h, w, fps=1.0 / AUTHORS_DT)
    map_abs = map_rel = motion_rel = core = current = 0.0
    count_diff = 0
    ours_trace, spikes_o = [], []
    maps_t = theirs["maps"].reshape(h - 1, w - 1, t - 1)
    motion_t = theirs["motion"].reshape(h - 1, w - 1, 4, t - 1)
    for k in range(t):
        s = ref.step(patt[:, :, k])
        if k == 0:
            continue
        m_motion = motion_t[:, :, :, k - 1].transpose(2, 0, 1)  # their LP: left, right, up, down
        motion_rel = max(motion_rel, float(np.max(np.abs(ref.motion_maps - m_motion)))
                         / max(float(np.max(np.abs(m_motion))), 1e-300))
        m_t = maps_t[:, :, k - 1]
        d = float(np.max(np.abs(ref.lplc2 - m_t)))
        map_abs = max(map_abs, d)
        map_rel = max(map_rel, d / max(float(np.max(np.abs(m_t))), 1e-300))
        core = max(core, abs(s.core - float(theirs["core"].ravel()[k - 1])))
        current = max(current, abs(s.current - float(theirs["I"].ravel()[k - 1])))
        count_diff += int(s.active != int(theirs["nums"].ravel()[k - 1]))
        ours_trace.extend(s.trace)
        spikes_o.append(s.alert)
    v_t = theirs["v"].ravel()[1:]
    spikes_t = (v_t.reshape(t - 1, -1) == 20.0).any(axis=1)
    first_t = int(np.argmax(spikes_t)) + 1 if spikes_t.any() else None
    first_o = int(np.argmax(spikes_o)) + 1 if any(spikes_o) else None
    out = {"motion_rel": motion_rel, "map_abs": map_abs, "map_rel": map_rel, "core": core, "current": current,
           "v": float(np.max(np.abs(np.array(ours_trace) - v_t))), "count_diff": count_diff,
           "active_max": int(theirs["nums"].max()), "spike_frames": int(spikes_t.sum()),
           "spikes_equal": bool(np.array_equal(spikes_t, np.array(spikes_o))), "first": (first_t, first_o)}
    if engine:
        out["engine"] = compare_engine(theirs, patt)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", required=True, type=Path, help="checkout of zhaojunyu01/EMD-LPLC2-GF-model")
    ap.add_argument("--octave", default="octave-cli")
    ap.add_argument("--stimuli", nargs="*", default=DEFAULT_STIMULI)
    ap.add_argument("--source", choices=("mat", "avi"), default="mat")
    ap.add_argument("--step", type=int, default=4, help="spatial downsampling (their loom.m: 4)")
    ap.add_argument("--first", type=int, default=195, help="first frame (0-based; their motion starts at 200)")
    ap.add_argument("--frames", type=int, default=105)
    ap.add_argument("--engine", action="store_true", help="also compare the engine model (a second table)")
    args = ap.parse_args(argv)
    if shutil.which(args.octave) is None:
        sys.exit(f"error: {args.octave}: not found (install GNU Octave)")
    if not (args.repo / CODE / "emd.m").is_file():
        sys.exit(f"error: {args.repo / CODE}: emd.m not found (pass --repo, a checkout of EMD-LPLC2-GF-model)")
    print(f"{'stimulus':28s} {'size':>8s} {'T':>4s} {'rel dEMD':>9s} {'max|dMap|':>9s} {'rel':>9s} {'max|dCore|':>10s} "
          f"{'max|dI|':>9s} {'max|dV|mV':>9s} {'#active!=':>9s} {'max act':>7s} {'spk frames':>10s} spikes equal"
          " (first spike frame theirs/ours)")
    engine_rows = []
    for name in args.stimuli:
        patt = load_stimulus(args.repo, name, args.source, args.step, args.first, args.frames)
        r = compare(args.octave, args.repo, patt, args.engine)
        h, w, t = patt.shape
        print(f"{name:28s} {f'{w}x{h}':>8s} {t:4d} {r['motion_rel']:9.2e} {r['map_abs']:9.2e} {r['map_rel']:9.2e} "
              f"{r['core']:10.2e} "
              f"{r['current']:9.2e} {r['v']:9.2e} {r['count_diff']:9d} {r['active_max']:7d} {r['spike_frames']:10d} "
              f"{'yes' if r['spikes_equal'] else 'NO'} ({r['first'][0]}/{r['first'][1]})", flush=True)
        if args.engine:
            e = r["engine"]
            engine_rows.append(f"{name:28s} {f'{w}x{h}':>8s} {t:4d} {e['map_rel']:9.2e} {e['core']:10.2e} "
                               f"{e['current']:9.2e} {e['v']:9.2e} {e['count_diff']:9d} {e['spike_frames']:10d} "
                               f"{'yes' if e['spikes_equal'] else 'NO'} ({e['first'][0]}/{e['first'][1]})")
            print("engine: " + engine_rows[-1], file=sys.stderr, flush=True)  # as it comes (the table at the end)
    if args.engine:
        from cdnf_ti.taichi_runtime import current_compiler

        print(f"\nengine model (compiler {current_compiler()}) against the same Octave runs:")
        print(f"{'stimulus':28s} {'size':>8s} {'T':>4s} {'rel dMap':>9s} {'max|dCore|':>10s} {'max|dI|':>9s} "
              f"{'|dV| end':>9s} {'#active!=':>9s} {'spk frames':>10s} spikes equal (first spike frame theirs/ours)")
        print("\n".join(engine_rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
