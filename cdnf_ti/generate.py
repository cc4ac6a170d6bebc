"""Subcommands that write stimuli to disk: ``generate`` and ``rain``.

Usage::

    python -m cdnf_ti.run generate dark_looming --coherence 0.2 --stimulus-seed 3 --size 240 --out loom.avi
    python -m cdnf_ti.run generate dark_translating --coherence 0.2 --scatter static --out bar.avi
    python -m cdnf_ti.run generate light_translating --out frames_dir          # PNG folder
    python -m cdnf_ti.run rain clip1.mp4 clip2.mp4 --out rainy/ --rain-seed 7  # rainy/clip1_rain.avi ...

``--seed`` is the default of every seed (``generate``: ``--stimulus-seed`` and ``--rain-seed``).

Output is lossless (FFV1 AVI, or a folder of PNG frames when ``--out`` has no
suffix) plus a JSON sidecar (``x.avi`` -> ``x.json``; folder -> ``folder/sidecar.json``)
with every parameter, the seed and, for rain, the per-video SNR.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Sequence

from . import __version__
from .atomic import prepare_output
from .cli_common import (
    DEFAULT_OUT,
    ArgumentParser,
    add_input_options,
    add_output_option,
    add_rain_options,
    add_seed_options,
    positive_float,
    rain_seed_of,
    stimulus_seed_of,
)
from .errors import OutputError, UserError
from .frames import iter_grey
from .inputs import resolve_input
from .limits import check_drops, check_frame_size
from .stimuli.basic import BASIC_STIMULI, basic_stimulus
from .stimuli.incoherent import SCATTERS, IncoherentStimulus
from .stimuli.io import output_format, write_frames, write_sidecar
from .stimuli.rain import RainParams, RainyFrames


def rain_params_from_args(args: argparse.Namespace):
    """:class:`~cdnf_ti.stimuli.rain.RainParams` from ``--rain-drops`` (other fields: defaults)."""
    return RainParams(drops=args.rain_drops)


def generate_main(argv: Sequence[str]) -> int:
    """``generate NAME ... --out PATH``: write one (incoherent, optionally rainy) basic stimulus."""
    ap = ArgumentParser(prog="python -m cdnf_ti.run generate",
                        description="Generate a basic or incoherent stimulus to a lossless file "
                                    "(FFV1 .avi, or a PNG folder) with a JSON sidecar.")
    ap.add_argument("name", choices=BASIC_STIMULI, metavar="NAME", help=f"one of: {', '.join(BASIC_STIMULI)}")
    ap.add_argument("--coherence", type=float, default=1.0, help="coherence degree c in (0, 1] (default 1)")
    ap.add_argument("--scatter", choices=SCATTERS, default="flicker",
                    help="incoherent construction: displaced dots vanish with their leaving source and reappear "
                         "elsewhere (flicker, default), or pass to an entering source and stay put (static)")
    ap.add_argument("--size", type=int, default=None,
                    help="frame height = width in px (default 600); start half-size scales as size/60 "
                         "(default_start_half_size)")
    ap.add_argument("--height", type=int, default=None,
                    help="frame height in px (default: --size, else 600); with --width, frames need not be square")
    ap.add_argument("--width", type=int, default=None, help="frame width in px (default: --size, else 600)")
    ap.add_argument("--fps", type=positive_float, default=None, help="frames per second (default 30)")
    ap.add_argument("--duration", type=positive_float, default=None, help="motion duration in s (default 1.5)")
    add_rain_options(ap, default="off", what="the stimulus (on or off: the output is one stimulus)")
    add_seed_options(ap, rain=True, stimulus=True)
    ap.add_argument("--out", default=None, metavar="PATH",
                    help=f"the output: a .avi file (FFV1) or a folder (PNG frames) (default: {DEFAULT_OUT}/NAME.avi)")
    ap.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    args = ap.parse_args(list(argv))
    if args.rain == "both":
        raise UserError("generate writes one stimulus: --rain on or off, not both (run it twice)")
    if args.out is None:
        args.out = str(Path(DEFAULT_OUT) / f"{args.name}.avi")
    output_format(args.out)
    seed = stimulus_seed_of(args)
    size = args.size if args.size is not None else 600
    height = args.height if args.height is not None else size
    width = args.width if args.width is not None else size
    check_frame_size(height, width, n_models=0, what="frame size")
    if args.rain == "on":
        check_drops(args.rain_drops, (height, width), what="--rain-drops")
    prepare_output(Path(args.out).parent)  # before any work: the output's folder must be writable
    kw: dict = {}
    if args.size is not None:
        kw.update(height=args.size, width=args.size)  # start half-size: default_start_half_size
    for k in ("height", "width", "fps", "duration"):
        if getattr(args, k) is not None:
            kw[k] = getattr(args, k)
    try:  # the stimulus classes check their parameters (coherence in (0, 1], ...)
        base = basic_stimulus(args.name, **kw)
        stim = IncoherentStimulus(base, args.coherence, seed, scatter=args.scatter)
    except (ValueError, TypeError) as e:
        raise UserError(str(e)) from None
    frames = stim.frames()
    rain = None
    if args.rain == "on":
        rain = RainyFrames(frames, rain_params_from_args(args), seed=rain_seed_of(args))
        frames = iter(rain)
    n = write_frames(frames, args.out, fps=base.fps, progress=False if args.no_progress else args.name,
                     total=base.n_frames)
    meta = {
        "kind": "stimulus",
        "cdnf_ti_version": __version__,
        "format": output_format(args.out),
        "frames": n,
        "height": base.height,
        "width": base.width,
        "fps": base.fps,
        "quantisation": "uint8 = round(255 * x)",
        **stim.to_dict(),
        "rain": None if rain is None else {**rain.params.to_dict(), "seed": rain.seed,
                                           "drops_per_frame": rain.params.drops_for((base.height, base.width)),
                                           "snr_db": rain.snr_db},
    }
    sp = write_sidecar(args.out, meta)
    halt = "" if stim.halted_at is None else f", halted at frame {stim.halted_at}"
    snr = "" if rain is None else f", rain SNR {rain.snr_db:.2f} dB"
    print(f"{args.out}: {args.name} c={args.coherence:g} seed={seed} scatter={args.scatter}, {n} frames "
          f"{base.width}x{base.height}{halt}{snr}; sidecar {sp}")
    return 0


def rain_main(argv: Sequence[str]) -> int:
    """``rain VIDEO... --out DIR``: add synthetic rain to videos; print each video's SNR."""
    ap = ArgumentParser(prog="python -m cdnf_ti.run rain",
                        description="Add synthetic rain (paper, Sec. III-A-2) to videos; write lossless "
                                    "DIR/<clip>_rain.avi (or PNG folders) plus JSON sidecars with the SNR.")
    ap.add_argument("inputs", nargs="+", metavar="VIDEO", help="video file, image folder, .npy, or stim:NAME?...")
    add_output_option(ap, default=f"{DEFAULT_OUT}/rain")
    add_input_options(ap)
    add_rain_options(ap, flag=False)
    add_seed_options(ap, rain=True)
    ap.add_argument("--format", choices=("avi", "png"), default="avi", help="FFV1 AVI (default) or PNG folders")
    ap.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    args = ap.parse_args(list(argv))
    params = RainParams(drops=args.rain_drops)
    seed = rain_seed_of(args)
    out = prepare_output(args.out)  # before any work
    failed = 0
    snrs = []
    for spec in args.inputs:
        t0 = time.perf_counter()
        try:
            src = resolve_input(spec, fps=args.fps, color_order=args.color_order)
            check_frame_size(*src.shape, n_models=0, what=str(spec))
            check_drops(args.rain_drops, src.shape, what="--rain-drops")
            target = out / (f"{src.name}_rain.avi" if args.format == "avi" else f"{src.name}_rain")
            rain = RainyFrames(iter_grey(src), params, seed=seed)
            n = write_frames(rain, target, fps=src.fps, progress=False if args.no_progress else src.name,
                             total=src.n_frames)
        except UserError as e:
            if isinstance(e, OutputError):
                raise  # the output cannot be written: the other inputs would fail the same way
            print(f"error: {e}", file=sys.stderr)
            failed += 1
            continue
        write_sidecar(target, {
            "kind": "rain",
            "cdnf_ti_version": __version__,
            "source": str(spec),
            "format": args.format,
            "frames": n,
            "height": src.shape[0],
            "width": src.shape[1],
            "fps": src.fps,
            "quantisation": "uint8 = round(255 * x)",
            "rain": {**params.to_dict(), "seed": seed, "drops_per_frame": params.drops_for(src.shape)},
            "snr_db": rain.snr_db,
            "snr_db_per_frame": rain.snr_per_frame,
        })
        snrs.append(rain.snr_db)
        print(f"{spec}: {n} frames -> {target}, SNR {rain.snr_db:.2f} dB ({time.perf_counter() - t0:.1f} s)")
    if len(snrs) > 1:
        print(f"mean SNR over {len(snrs)} videos: {sum(snrs) / len(snrs):.2f} dB")
    if not failed:
        return 0
    return 1 if snrs else 2  # as `run`: 1 = some inputs failed, 2 = none could be done
