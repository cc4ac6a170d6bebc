"""Oracle check of :mod:`cdnf_ti.event_looming_reference` (``variant="code"``) against the authors' PyTorch model.

Runs ``LoomingDetector`` of ``src/pytorch/looming_detector.py`` from the user's
own checkout of
``FabianSchubert/Bio-Inspired-Event-Based-Looming-Object-Detection-for-Automotive-Collision-Avoidance``
(it is not part of cdnf_ti) with its untrained defaults on the CPU, in
evaluation mode (dropout off), and the float64 reference on the same bins, and
prints per clip the largest differences of the output and of the left/right
responses, and the first alert (``output > 0``) of each side.

Two paths per clip:

* ``frames``: the basic stimulus (or a video) through the project's event
  emulator, one signed bin per frame (:func:`cdnf_ti.event_looming_reference.frame_bins`),
  the same bins to both sides;
* ``recording`` (``--recording``): the emulator's events written in the
  authors' format (a folder with ``events.npy``, ``t`` in ms as ``<u4``, ``p``
  0/1, and ``sim_data.npz``), binned at their ``DT`` (10 ms) by *their*
  ``convert_to_tens`` for their side, and read by
  :func:`cdnf_ti.events.readers.open_events` and binned by
  :func:`~cdnf_ti.event_looming_reference.signed_bins` for ours.

Their model takes a pair of bins ``(B(t-1), B(t))``; its output is our bin
``t``. Bin 0 is paired with an empty map on both sides.

Usage::

    python docs/figures/compare_event_looming.py \\
        --repo PATH/Bio-Inspired-Event-Based-Looming-Object-Detection-for-Automotive-Collision-Avoidance \\
        [--size 96] [--recording] [--recording-fps 100] [--real CLIP.mp4 ...] [--real-frames 60]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

from cdnf_ti.event_looming_reference import EventLoomingReference, frame_bins, signed_bins
from cdnf_ti.events.emulator import emulate
from cdnf_ti.events.readers import open_events
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus

AUTHORS_FILE = "src/pytorch/looming_detector.py"
#: Their DT (src/pytorch/network_settings.py), ms: the bin width of their sequences.
THEIR_DT_MS = 10.0


def load_authors(repo: Path):
    """Their ``src.pytorch`` package from the checkout (``LoomingDetector``, ``data_processing``)."""
    if not (repo / AUTHORS_FILE).is_file():
        sys.exit(f"error: {repo / AUTHORS_FILE}: not found (pass --repo, a checkout of "
                 "FabianSchubert/Bio-Inspired-Event-Based-Looming-Object-Detection-for-Automotive-Collision-Avoidance)")
    sys.path.insert(0, str(repo.resolve()))
    import src.pytorch as theirs  # noqa: PLC0415 - their package, found on the path just set

    return theirs


def run_authors(theirs, bins: list[np.ndarray]) -> dict[str, np.ndarray]:
    """Their untrained ``LoomingDetector`` (eval mode, CPU) on consecutive pairs of ``bins``."""
    import torch

    h, w = bins[0].shape
    model = theirs.LoomingDetector(width=w, height=h).eval()
    out, left, right = [], [], []
    prev = np.zeros((h, w), dtype=np.float32)
    with torch.no_grad():
        for b in bins:
            x = torch.tensor(np.stack([prev, b.astype(np.float32)]))[None]
            out.append(float(model(x)[0]))
            lr = model.fwd(model.vx * model.wx + model.vy * model.wy)[0]
            left.append(float(lr[0]))
            right.append(float(lr[1]))
            prev = b.astype(np.float32)
    return {"output": np.array(out), "left": np.array(left), "right": np.array(right)}


def their_recording_bins(theirs, folder: Path, shape: tuple[int, int]) -> list[np.ndarray]:
    """Their ``convert_to_tens`` on their layout in ``folder`` (whole sequence, no crop): int8 maps per DT bin."""
    h, w = shape
    with contextlib.redirect_stdout(io.StringIO()):
        data, labels, metadata = theirs.data_processing.load_raw_data([folder])
        nt = int(metadata[0]["t_end_ms"] / metadata[0]["dt"])
        x, _, _ = theirs.data_processing.convert_to_tens(data, labels, metadata, nt, w, h, w, h, 0, 0, 0, 0)
    return [b.numpy() for b in x[0]]


def write_their_layout(folder: Path, frames: list[np.ndarray], fps: float) -> None:
    """The emulator's events of ``frames`` in their layout: ``events.npy`` (``t`` ms ``<u4``, ``x``, ``y``,
    ``p`` ``<u2``) and ``sim_data.npz`` (``t_end``, ``dt`` in ms)."""
    ev = np.concatenate(list(emulate(frames, fps)))
    out = np.zeros(len(ev), dtype=[("t", "<u4"), ("x", "<u2"), ("y", "<u2"), ("p", "<u2")])
    out["t"] = ev["t"] // 1000
    out["x"], out["y"], out["p"] = ev["x"], ev["y"], ev["p"]
    np.save(folder / "events.npy", out)
    t_end = THEIR_DT_MS * np.floor((len(frames) - 1) * 1000.0 / fps / THEIR_DT_MS)
    np.savez(folder / "sim_data.npz", coll_type=np.array("cars"), t_end=np.array(t_end), dt=np.array(THEIR_DT_MS),
             vel=np.array(np.nan), diameter_object=np.array(np.nan))


def first(mask: np.ndarray):
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else None


def compare_bins(theirs, bins_theirs: list[np.ndarray], bins_ours: list[np.ndarray]) -> dict:
    """Both models on their own bins (equal bins are checked and counted)."""
    h, w = bins_ours[0].shape
    t = run_authors(theirs, bins_theirs)
    o = EventLoomingReference(h, w, variant="code").run(bins_ours)
    n = min(len(bins_theirs), len(bins_ours))
    same_bins = sum(np.array_equal(a, b) for a, b in zip(bins_theirs[:n], bins_ours[:n]))
    scale = max(float(np.max(np.abs(o["left"][:n]))), float(np.max(np.abs(o["right"][:n]))), 1e-12)
    return {"bins": n, "same_bins": same_bins, "output": float(np.max(np.abs(t["output"][:n] - o["output"][:n]))),
            "lr_rel": float(max(np.max(np.abs(t["left"][:n] - o["left"][:n])),
                                np.max(np.abs(t["right"][:n] - o["right"][:n])))) / scale,
            "max_out": float(o["output"][:n].max()),
            "first_theirs": first(t["output"][:n] > 0), "first_ours": first(o["alert"][:n])}


def grey_frames(name: str, size: int) -> tuple[list[np.ndarray], float]:
    st = basic_stimulus(name, height=size, width=size)
    return list(st.frames()), float(st.fps)


def video_frames(path: str, n: int, size: tuple[int, int]) -> tuple[list[np.ndarray], float]:
    """The first ``n`` frames of a video, grey, resized to ``size`` (W, H) with INTER_AREA."""
    cap = cv2.VideoCapture(path)
    fps = cap.get(cv2.CAP_PROP_FPS) or 30.0
    frames = []
    while len(frames) < n:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(cv2.resize(f, size, interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2GRAY))
    if len(frames) < 8:
        sys.exit(f"error: {path}: fewer than 8 frames")
    return frames, float(fps)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", required=True, type=Path, help="checkout of the authors' repository")
    ap.add_argument("--size", type=int, default=96, help="basic stimuli frame side in px (default 96)")
    ap.add_argument("--stimuli", nargs="*", default=list(BASIC_STIMULI))
    ap.add_argument("--recording", action="store_true", help="also run the stimuli as recordings in their format")
    ap.add_argument("--recording-fps", type=float, default=100.0,
                    help="frame rate the stimuli are rendered at for --recording (default 100)")
    ap.add_argument("--real", nargs="*", default=[], help="video files, resized to their sensor crop 320x240")
    ap.add_argument("--real-frames", type=int, default=60)
    args = ap.parse_args(argv)
    theirs = load_authors(args.repo)
    print(f"{'clip':38s} {'size':>9s} {'bins':>5s} {'same':>5s} {'max|dout|':>9s} {'rel dL/R':>9s} {'max out':>9s} "
          "first alert (theirs/ours)")

    def report(name, r, shape):
        same = "equal" if r["first_theirs"] == r["first_ours"] else "DIFFERENT"
        print(f"{name:38s} {f'{shape[1]}x{shape[0]}':>9s} {r['bins']:5d} {r['same_bins']:5d} {r['output']:9.2e} "
              f"{r['lr_rel']:9.2e} {r['max_out']:9.2e} {r['first_theirs']}/{r['first_ours']} {same}", flush=True)

    sources = [(f"{n} (frames)", lambda n=n: grey_frames(n, args.size)) for n in args.stimuli]
    sources += [(f"{Path(p).name} (frames)", lambda p=p: video_frames(p, args.real_frames, (320, 240)))
                for p in args.real]
    for name, make in sources:
        frames, fps = make()
        bins = list(frame_bins(frames, fps))
        report(name, compare_bins(theirs, bins, bins), bins[0].shape)
    if args.recording:
        for n in args.stimuli:
            st = basic_stimulus(n, height=args.size, width=args.size, fps=args.recording_fps)
            frames = list(st.frames())
            with tempfile.TemporaryDirectory() as tmp:
                folder = Path(tmp) / "sample_0"
                folder.mkdir()
                write_their_layout(folder, frames, args.recording_fps)
                shape = frames[0].shape
                b_theirs = their_recording_bins(theirs, folder, shape)
                ev = open_events(folder / "events.npy")
                b_ours = list(signed_bins(ev.chunks(), shape, THEIR_DT_MS * 1000.0, 0, len(b_theirs)))
            report(f"{n} (recording, {THEIR_DT_MS:g} ms bins)", compare_bins(theirs, b_theirs, b_ours), shape)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
