"""Command line: ``python -m cdnf_ti.run``.

Usage::

    python -m cdnf_ti.run                                # demo: Table I on the six basic stimuli
    python -m cdnf_ti.run VIDEO [VIDEO ...] --out DIR    # per-frame traces + one summary line per video
    python -m cdnf_ti.run SUBCOMMAND ...                 # see SUBCOMMANDS below

User errors (bad files, bad options) print one line, ``error: <file>: <problem>``,
with no traceback, and exit with code 2.
"""
from __future__ import annotations

import argparse
import csv
import importlib
import io
import sys
import warnings
from pathlib import Path
from typing import Callable, Sequence

from .errors import InputError
from .taichi_runtime import BackendUnavailableError

#: Subcommands: first word on the command line -> "module:function(argv) -> int".
SUBCOMMANDS: dict[str, str] = {
    "bench": "cdnf_ti.bench.cli:main",
    "demo": "cdnf_ti.demo:main",
    "generate": "cdnf_ti.generate:generate_main",
    "rain": "cdnf_ti.generate:rain_main",
    "dataset": "cdnf_ti.experiments.cli:dataset_main",
    "experiment": "cdnf_ti.experiments.cli:experiment_main",
}

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


def add_model_options(ap: argparse.ArgumentParser, default_models: str = "cdnf") -> None:
    """Options shared by every command that runs models."""
    ap.add_argument("--model", "--models", dest="models", default=default_models,
                    help="model name(s), comma separated (default: %(default)s); 'all' for every model")
    ap.add_argument("--backend", default="taichi", choices=("taichi", "numpy"),
                    help="taichi kernels (default) or the NumPy float64 reference")
    ap.add_argument("--arch", default="cpu", choices=("cpu", "cuda", "vulkan", "gpu"),
                    help="Taichi architecture (default: cpu)")
    ap.add_argument("--compiler", choices=("taichi", "quadrants"), default=None, action=_CompilerAction,
                    help="kernel compiler (default: $CDNF_TI_COMPILER, else the fastest installed)")


class _CompilerAction(argparse.Action):
    """``--compiler``: names the process's kernel compiler as soon as it is parsed."""

    def __call__(self, parser, namespace, values, option_string=None):
        from .taichi_runtime import select_compiler

        try:
            select_compiler(values)
        except (ValueError, BackendUnavailableError) as e:
            parser.error(str(e))
        setattr(namespace, self.dest, values)


def seed_arg(text: str) -> int:
    """argparse type for seeds: a non-negative integer."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative integer, got {text!r}")
    return value


def parse_models(spec: str) -> list[str]:
    """``"cdnf,lgmd2"`` -> registry names; ``"all"`` -> every registered model."""
    from .models import MODELS, get_model_class

    if spec.strip().lower() == "all":
        return list(MODELS)
    names = [s.strip() for s in spec.split(",") if s.strip()]
    if not names:
        raise ValueError("no model named")
    return [get_model_class(n).name for n in names]


def _videos_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m cdnf_ti.run",
        description="Run looming models on videos (files, image folders, .npy arrays). "
                    "With no arguments: the built-in demo (paper Table I). "
                    f"Subcommands: {', '.join(SUBCOMMANDS)} (e.g. 'python -m cdnf_ti.run demo --help').",
    )
    ap.add_argument("inputs", nargs="+", metavar="VIDEO",
                    help="video file, folder of images, .npy array, or a generated stimulus "
                         "'stim:NAME[?coherence=C&seed=S&size=N...]' (see cdnf_ti.inputs)")
    ap.add_argument("--out", default="cdnf_out", help="output folder for traces (default: %(default)s)")
    add_model_options(ap)
    ap.add_argument("--epsilon", type=float, default=None, help="C-DNF alert margin (default 0.006)")
    ap.add_argument("--no-progress", action="store_true", help="hide progress bars")
    ap.add_argument("--rain", action="store_true",
                    help="add synthetic rain (paper defaults) in memory; prints each video's SNR")
    ap.add_argument("--rain-seed", type=seed_arg, default=0, help="rain seed (default: %(default)s)")
    ap.add_argument("--rain-drops", type=int, default=None,
                    help="rain droplets per frame (default: 500 per 426x240, scaled by area)")
    return ap


def run_videos(argv: Sequence[str]) -> int:
    """Run models over each input, write ``OUT/<clip>.<model>.csv`` and print one line each."""
    from .atomic import atomic_write_text
    from .frames import iter_grey
    from .inputs import resolve_input
    from .models import create_model
    from .models.base import run_models
    from .params import CDNFParams

    args = _videos_parser().parse_args(argv)
    models = parse_models(args.models)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)  # fail before any work if the folder cannot be made
    failed = 0
    rain_params = None
    if args.rain:
        from .stimuli.rain import RainParams, RainyFrames

        rain_params = RainParams(drops=args.rain_drops)
    columns = ["clip", "model", "frames", "first_alert", "max_output", "fps", "status"]
    if args.rain:
        columns.append("rain_snr_db")
    summary: list[dict] = []
    for path in args.inputs:
        try:
            src = resolve_input(path)
        except InputError as e:
            print(f"error: {e}", file=sys.stderr)
            failed += 1
            summary.append({"clip": Path(path).stem, "status": f"error: {e.problem}"})
            continue
        params = CDNFParams(epsilon=args.epsilon) if args.epsilon is not None else None
        instances = [create_model(name, params if name == "cdnf" else None, backend=args.backend,
                                  arch=args.arch, fps=src.fps) for name in models]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                frames = iter_grey(src)
                rain = None
                if rain_params is not None:
                    rain = RainyFrames(frames, rain_params, seed=args.rain_seed)
                    frames = iter(rain)
                # one pass over the input: each frame is decoded (and rained on) once for all models
                traces = run_models(instances, frames, total=src.n_frames,
                                    progress=False if args.no_progress else f"{src.name} [{', '.join(models)}]")
        except InputError as e:
            print(f"error: {e}", file=sys.stderr)
            failed += 1
            summary.append({"clip": src.name, "model": ",".join(models), "status": f"error: {e.problem}"})
            continue
        for name, trace in zip(models, traces):
            trace.to_csv(out / f"{src.name}.{name}.csv")
            fa = trace.first_alert
            fa_txt = f"{fa} ({fa / src.fps:.2f} s)" if fa is not None else "none"
            unconv = int((~trace.converged).sum())
            note = f", {unconv} frames NOT converged" if unconv else ""
            if rain is not None:
                note += f", rain SNR {rain.snr_db:.2f} dB"
            print(f"{path} [{name}]: {trace.n_frames} frames, first alert {fa_txt}, "
                  f"max {trace.output_name} {trace.output.max():.4f}, {trace.fps:.1f} fps{note}")
            summary.append({"clip": src.name, "model": name, "frames": trace.n_frames,
                            "first_alert": "" if fa is None else fa, "max_output": f"{trace.output.max():.6f}",
                            "fps": f"{trace.fps:.2f}", "status": "ok" if not unconv else "unconverged",
                            "rain_snr_db": f"{rain.snr_db:.4f}" if rain is not None else ""})
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    writer.writerows(summary)
    atomic_write_text(out / "summary.csv", buf.getvalue())
    return EXIT_USAGE if failed else EXIT_OK


def _load(target: str) -> Callable[[Sequence[str]], int]:
    mod, fn = target.split(":")
    return getattr(importlib.import_module(mod), fn)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        if not argv:
            return _load(SUBCOMMANDS["demo"])([])
        if argv[0] in SUBCOMMANDS:
            return _load(SUBCOMMANDS[argv[0]])(argv[1:])
        return run_videos(argv)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except BackendUnavailableError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as e:  # e.g. an output folder that cannot be created or written
        where = e.filename if e.filename is not None else "output"
        print(f"error: {where}: {e.strerror or e}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
