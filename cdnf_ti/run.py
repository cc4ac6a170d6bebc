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
import importlib
import sys
import warnings
from pathlib import Path
from typing import Callable, Sequence

from .errors import InputError
from .taichi_runtime import BackendUnavailableError

#: Subcommands: first word on the command line -> "module:function(argv) -> int".
SUBCOMMANDS: dict[str, str] = {
    "demo": "cdnf_ti.demo:main",
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
    ap.add_argument("inputs", nargs="+", metavar="VIDEO", help="video file, folder of images, or .npy array")
    ap.add_argument("--out", default="cdnf_out", help="output folder for traces (default: %(default)s)")
    add_model_options(ap)
    ap.add_argument("--epsilon", type=float, default=None, help="C-DNF alert margin (default 0.006)")
    ap.add_argument("--no-progress", action="store_true", help="hide progress bars")
    return ap


def run_videos(argv: Sequence[str]) -> int:
    """Run models over each input, write ``OUT/<clip>.<model>.csv`` and print one line each."""
    from .atomic import atomic_write_text
    from .frames import iter_grey, open_source
    from .models import create_model
    from .params import CDNFParams

    args = _videos_parser().parse_args(argv)
    models = parse_models(args.models)
    out = Path(args.out)
    failed = 0
    summary_rows = ["clip,model,frames,first_alert,max_output,fps,status"]
    for path in args.inputs:
        try:
            src = open_source(path)
        except InputError as e:
            print(f"error: {e}", file=sys.stderr)
            failed += 1
            summary_rows.append(f"{Path(path).stem},,,,,,error: {e.problem}")
            continue
        for name in models:
            params = None
            if name == "cdnf" and args.epsilon is not None:
                params = CDNFParams(epsilon=args.epsilon)
            model = create_model(name, params, backend=args.backend, arch=args.arch, fps=src.fps)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    trace = model.run(iter_grey(src), progress=False if args.no_progress else f"{src.name} [{name}]",
                                      total=src.n_frames)
            except InputError as e:
                print(f"error: {e}", file=sys.stderr)
                failed += 1
                summary_rows.append(f"{src.name},{name},,,,,error: {e.problem}")
                break
            trace.to_csv(out / f"{src.name}.{name}.csv")
            fa = trace.first_alert
            fa_txt = f"{fa} ({fa / src.fps:.2f} s)" if fa is not None else "none"
            unconv = int((~trace.converged).sum())
            note = f", {unconv} frames NOT converged" if unconv else ""
            print(f"{path} [{name}]: {trace.n_frames} frames, first alert {fa_txt}, "
                  f"max {trace.output_name} {trace.output.max():.4f}, {trace.fps:.1f} fps{note}")
            summary_rows.append(f"{src.name},{name},{trace.n_frames},{'' if fa is None else fa},"
                                f"{trace.output.max():.6f},{trace.fps:.2f},{'ok' if not unconv else 'unconverged'}")
    atomic_write_text(out / "summary.csv", "\n".join(summary_rows) + "\n")
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
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
