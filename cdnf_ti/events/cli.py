"""``python -m cdnf_ti.run events``: turn videos into events, or summarise event recordings.

Usage::

    python -m cdnf_ti.run events VIDEO --out FILE.npy|FILE.h5        # emulate a DVS on one video
    python -m cdnf_ti.run events VIDEO [VIDEO ...] --out DIR [--format h5]
    python -m cdnf_ti.run events --info RECORDING [RECORDING ...]   # format, sensor, counts, problems

``VIDEO`` is anything ``run`` reads (a video file, an image folder, a ``.npy``
frame array, ``stim:NAME?...``). Each bad input prints one ``error:`` line and
the rest go on (exit 1 when some failed, 2 when all did).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Sequence

import numpy as np
from tqdm import tqdm

from ..cli_common import (
    DEFAULT_OUT,
    EXIT_FAILED,
    EXIT_OK,
    EXIT_USAGE,
    ArgumentParser,
    add_event_options,
    add_input_options,
    non_negative_float,
    positive_float,
    seed_arg,
    sensor_size_arg,
    unique_names,
)
from ..errors import UserError
from ..experiments.parallel import _isatty
from ..frames import iter_grey
from ..inputs import STIM_PREFIX, parse_stim_spec, resolve_input, stimulus_label
from ..limits import check_frame_size
from ..paths import inside
from .binning import DEFAULT_BIN_MS
from .emulator import EmulatorParams, emulate
from .readers import is_event_file
from .source import open_event_source
from .writers import WRITE_EXTENSIONS, write_events


def _parser() -> argparse.ArgumentParser:
    ap = ArgumentParser(prog="python -m cdnf_ti.run events",
                        description="Emulate an event camera (DVS) on videos, writing event files; or, with --info, "
                                    "summarise event recordings (.aedat4, .raw EVT2/EVT3, .dat, DSEC .h5, .npy, "
                                    ".npz).")
    ap.add_argument("inputs", nargs="+", metavar="INPUT",
                    help="videos (file, image folder, .npy frames, stim:NAME?...); with --info, event recordings "
                         "or folders of them")
    ap.add_argument("--out", default=None, metavar="DIR",
                    help=f"output folder (created), or the event file (.npy/.h5) when the command makes one "
                         f"(default: {DEFAULT_OUT}/events)")
    ap.add_argument("--format", choices=("npy", "h5"), default="npy",
                    help="file format when --out is a folder (default: %(default)s)")
    ap.add_argument("--info", action="store_true", help="summarise event recordings instead of emulating")
    add_event_options(ap)
    ap.add_argument("--threshold-on", type=positive_float, default=None,
                    help="emulated ON threshold (default: --event-threshold)")
    ap.add_argument("--threshold-off", type=positive_float, default=None,
                    help="emulated OFF threshold (default: --event-threshold)")
    ap.add_argument("--threshold-sigma", type=non_negative_float, default=0.0,
                    help="per-pixel threshold mismatch, relative standard deviation (default: %(default)s)")
    ap.add_argument("--refractory-ms", type=non_negative_float, default=0.0,
                    help="refractory period per pixel, ms (default: %(default)s)")
    ap.add_argument("--shot-noise-hz", type=non_negative_float, default=0.0,
                    help="shot-noise events per pixel per second (default: %(default)s)")
    ap.add_argument("--log-eps", type=positive_float, default=0.01,
                    help="eps of the log intensity ln(L + eps), L in [0, 1] (default: %(default)s)")
    ap.add_argument("--seed", type=seed_arg, default=0, help="seed of the mismatch and the noise (default: 0)")
    add_input_options(ap)
    ap.add_argument("--no-progress", action="store_true", help="hide progress bars")
    return ap


def events_main(argv: Sequence[str]) -> int:
    """Entry point of ``python -m cdnf_ti.run events``; returns the exit code."""
    args = _parser().parse_args(argv)
    if args.info:
        return _info(args)
    return _emulate(args)


def _recordings(inputs: Sequence[str]) -> list[str]:
    """The inputs, a folder replaced by the event recordings in it (sorted by name; none: the folder, which
    then fails with its own error line)."""
    out = []
    for spec in inputs:
        p = Path(spec)
        found = sorted(str(f) for f in p.iterdir() if is_event_file(f)) if p.is_dir() else []
        out.extend(found or [spec])
    return out


def _info(args) -> int:
    ok = failed = 0
    bin_ms = DEFAULT_BIN_MS if args.bin_ms is None else args.bin_ms  # no model: the project's default width
    for path in _recordings(args.inputs):
        try:
            src = open_event_source(path, args.sensor_size, bin_ms, max_gap_s=args.max_gap_s,
                                    max_span_s=args.max_span_s)
            check_frame_size(*src.shape, n_models=1, what=path, binning=True)  # as `run` would with one model
            n_bins = sum(1 for _ in src.counts())
        except UserError as e:
            print(f"error: {e}", file=sys.stderr)
            failed += 1
            continue
        r = src.report
        w, h = src.sensor_size
        origin = "inferred" if src.inferred else ("--sensor-size" if args.sensor_size else "header")
        span = (r.t_last - r.t_first) / 1e6 if r.n_events else 0.0
        on = 100.0 * r.n_on / r.n_events if r.n_events else 0.0
        print(f"{path}: {src.events.format}, {w}x{h} ({origin}), {r.n_events} events ({on:.1f}% ON), "
              f"t {r.t_first}..{r.t_last} us ({span:.3f} s), {n_bins} bins of {bin_ms:.6g} ms")
        for line in r.problems():
            print(f"warning: {path}: {line}", file=sys.stderr)
        ok += 1
    return EXIT_OK if not failed else (EXIT_FAILED if ok else EXIT_USAGE)


def _outputs(args) -> list[Path]:
    out = args.out or str(Path(DEFAULT_OUT) / "events")
    if Path(out).suffix.lower() in WRITE_EXTENSIONS:
        if len(args.inputs) != 1:
            raise UserError(f"--out {out}: one output file takes one input; give a folder for {len(args.inputs)}")
        return [Path(out)]
    def name(spec: str) -> str:
        if spec.startswith(STIM_PREFIX):
            try:
                return stimulus_label(*parse_stim_spec(spec))
            except UserError:
                return spec[len(STIM_PREFIX):]
        return Path(spec).stem
    names = unique_names(list(args.inputs), [name(s) for s in args.inputs])
    ext = ".h5" if args.format == "h5" else ".npy"
    return [inside(out, f"{n}{ext}") for n in names]


def bins_note(n_frames: int, fps: float) -> str:
    """How an emulated video's frames map to bins one frame long (``--bin-ms 1000/fps``).

    Events come from the changes between frames, so ``n`` frames give ``n - 1`` bins: bin ``k``
    holds the change from frame ``k`` to ``k + 1``, which a frame model sees at frame ``k + 1``. A
    window of frames ``s..e`` (a labels file made for the video) is bins ``s - 1 .. e - 1``.
    """
    return (f"{n_frames} frames -> {max(n_frames - 1, 0)} bins of {1000.0 / fps:.4g} ms (bin k = the change from "
            "frame k to k+1: frames s..e are bins s-1..e-1)")


def _emulate(args) -> int:
    c = args.event_threshold
    try:
        params = EmulatorParams(threshold_on=args.threshold_on or c, threshold_off=args.threshold_off or c,
                                threshold_sigma=args.threshold_sigma, refractory_ms=args.refractory_ms,
                                shot_noise_hz=args.shot_noise_hz, log_eps=args.log_eps)
    except ValueError as e:
        raise UserError(str(e)) from None
    outputs = _outputs(args)
    ok = failed = 0
    # progress: a frame bar in a terminal; in a log (stderr not a terminal) one line per finished input
    bar, log = (not args.no_progress and _isatty(sys.stderr)), (not args.no_progress and not _isatty(sys.stderr))
    for k, (spec, out) in enumerate(zip(args.inputs, outputs), start=1):
        t0 = time.perf_counter()
        try:
            src = resolve_input(spec, fps=args.fps, color_order=args.color_order)
            h, w = src.shape
            check_frame_size(h, w, n_models=0, what=str(spec), emulating=True)
            frames = [0]  # frames read

            def counted_frames(src=src, frames=frames):
                for g in iter_grey(src):
                    frames[0] += 1
                    yield g

            chunks = emulate(counted_frames(), src.fps, params, seed=args.seed)
            if bar:
                chunks = tqdm(chunks, total=None if src.n_frames is None else max(src.n_frames - 1, 0),
                              desc=f"{spec} -> events", unit="frame", leave=False)
            counts = [0, 0]  # events, ON events

            def counted(chunks=chunks, counts=counts):
                for c in chunks:
                    counts[0] += c.shape[0]
                    counts[1] += int(np.count_nonzero(c["p"]))
                    yield c

            write_events(out, counted(), (w, h))
        except UserError as e:
            print(f"error: {e}", file=sys.stderr)
            failed += 1
            continue
        finally:
            if log:
                print(f"[{k}/{len(outputs)}] {spec} -> {out}: {time.perf_counter() - t0:.1f} s", file=sys.stderr,
                      flush=True)
        n, n_on = counts
        print(f"{spec} -> {out}: {n} events ({n_on} ON, {n - n_on} OFF), {w}x{h}, "
              f"{src.fps:g} fps; {bins_note(frames[0], src.fps)}")
        ok += 1
    if ok and failed:
        return EXIT_FAILED
    return EXIT_OK if ok else EXIT_USAGE


__all__ = ["add_event_options", "events_main", "sensor_size_arg"]
