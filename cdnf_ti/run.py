"""Command line: ``python -m cdnf_ti.run``.

Usage::

    python -m cdnf_ti.run                                # demo: Table I on the six basic stimuli
    python -m cdnf_ti.run VIDEO [VIDEO ...] --out DIR    # per-frame traces + one summary line per video
    python -m cdnf_ti.run SUBCOMMAND ...                 # see SUBCOMMANDS below

Errors: a user error (bad file, bad option, unavailable device, output folder
that cannot be written: :class:`~cdnf_ti.errors.UserError`) prints one line,
``error: <file>: <problem>``, with no traceback. Any other exception is a bug
and shows its traceback.

Exit codes (every command): 0 all done; 1 the run finished and wrote its
results, but some input (clip, model) failed (its ``error:`` line is printed and
it is recorded in the summary); 2 a user error stopped the run before any
result (for ``run``: also when every input failed); 130 interrupted (Ctrl-C).
"""
from __future__ import annotations

import argparse
import csv
import importlib
import io
import math
import os
import sys
import warnings
from pathlib import Path
from typing import Callable, Sequence

from .atomic import atomic_write_text, output_lock, prepare_output
from .cli_common import (
    EXIT_FAILED as EXIT_FAILED,  # re-exported: cdnf_ti.run was their home
    EXIT_INTERRUPTED as EXIT_INTERRUPTED,
    EXIT_OK as EXIT_OK,
    EXIT_USAGE as EXIT_USAGE,
    ArgumentParser,
    add_model_options as add_model_options,
    add_param_options,
    check_model_options as check_model_options,
    drops_arg as drops_arg,
    finite_float as finite_float,
    params_from_args,
    parse_models as parse_models,
    positive_float as positive_float,
    seed_arg as seed_arg,
    unique_names as unique_names,
)
from .errors import InputError, UserError
from .experiments.parallel import exit_on_second_interrupt, stop_all_pools
from .frames import iter_grey
from .inputs import resolve_input
from .limits import check_drops, check_frame_size
from .models import create_model
from .models.base import NotConvergedWarning, run_models
from .stimuli.rain import RainParams, RainyFrames
from .taichi_runtime import lanes_override

#: Subcommands: first word on the command line -> "module:function(argv) -> int".
SUBCOMMANDS: dict[str, str] = {
    "bench": "cdnf_ti.bench.cli:main",
    "demo": "cdnf_ti.demo:main",
    "generate": "cdnf_ti.generate:generate_main",
    "rain": "cdnf_ti.generate:rain_main",
    "dataset": "cdnf_ti.experiments.cli:dataset_main",
    "experiment": "cdnf_ti.experiments.cli:experiment_main",
    "render": "cdnf_ti.render:render_main",
}

def _videos_parser() -> argparse.ArgumentParser:
    ap = ArgumentParser(
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
    add_param_options(ap)
    ap.add_argument("--fps", type=positive_float, default=None,
                    help="frame rate of the inputs in frames/s (default: a video's own rate; 30 for image "
                         "folders and .npy arrays, which carry none)")
    ap.add_argument("--color-order", choices=("bgr", "rgb"), default="bgr",
                    help="channel order of colour .npy arrays (default: %(default)s, as OpenCV; arrays "
                         "from imageio, PIL or matplotlib are rgb). Video files and images are decoded by "
                         "OpenCV and are always right")
    ap.add_argument("--no-progress", action="store_true", help="hide progress bars")
    ap.add_argument("--rain", action="store_true",
                    help="add synthetic rain (paper defaults) in memory; prints each video's SNR")
    ap.add_argument("--rain-seed", type=seed_arg, default=0, help="rain seed (default: %(default)s)")
    ap.add_argument("--rain-drops", type=drops_arg, default=None,
                    help="rain droplets per frame (default: 500 per 426x240, scaled by area)")
    return ap


def run_videos(argv: Sequence[str]) -> int:
    """Run models over each input, write ``OUT/<clip>.<model>.csv`` and print one line each.

    Inputs that share a name get distinct output names (:func:`unique_names`).
    """
    args = _videos_parser().parse_args(argv)
    models = parse_models(args.models)
    check_model_options(args)
    params = params_from_args(args, models)
    existed = Path(args.out).expanduser().exists()
    out = prepare_output(args.out)  # before any work
    with output_lock(out):
        code = _run_videos(args, models, params, Path(args.out), atomic_write_text)
    if not existed:
        try:
            out.rmdir()  # a folder made for this run that got nothing: left as it was (absent)
        except OSError:
            pass
    return code


def _run_videos(args, models: list[str], params: dict, out: Path, write_text) -> int:
    rain_params = None
    if args.rain:
        rain_params = RainParams(drops=args.rain_drops)
    condition = "rain" if args.rain else "clean"
    summary: list[dict] = []  # rows in input order ("_i": index of the input)
    sources: list = []
    order: list[int] = []
    for index, path in enumerate(args.inputs):  # open every input first: bad ones are reported before any work
        try:
            src = resolve_input(path, fps=args.fps, color_order=args.color_order)
            check_frame_size(*src.shape, n_models=len(models), what=str(path))
            if rain_params is not None:
                check_drops(args.rain_drops, src.shape, what="--rain-drops")
            sources.append((path, src))
            order.append(index)
        except UserError as e:
            print(f"error: {e}", file=sys.stderr)
            problem = e.problem if isinstance(e, InputError) else str(e)
            summary.append({"_i": index, "input": str(path), "clip": Path(str(path)).stem,
                            "model": ",".join(models), "condition": condition, "status": f"error: {problem}"})
    if not sources:  # nothing could be opened: leave the output folder (and a summary of an earlier run) as it was
        return EXIT_USAGE
    names = unique_names([str(p) for p, _ in sources], [src.name for _, src in sources])
    dup = [(p, n) for (p, src), n in zip(sources, names) if n != src.name]
    if dup:
        print("note: inputs share a name; output names: " + ", ".join(f"{p} -> {n}" for p, n in dup),
              file=sys.stderr)
    ran = 0
    for (path, src), clip, index in zip(sources, names, order):
        instances = [create_model(name, params[name], backend=args.backend,
                                  arch=args.arch, fps=src.fps) for name in models]
        rain = None
        errors: list = []
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", NotConvergedWarning)  # reported per line below
                frames = iter_grey(src)
                if rain_params is not None:
                    rain = RainyFrames(frames, rain_params, seed=args.rain_seed)
                    frames = iter(rain)
                # one pass over the input: each frame is decoded (and rained on) once for all models
                traces = run_models(instances, frames, total=src.n_frames, errors=errors,
                                    progress=False if args.no_progress else f"{clip} [{', '.join(models)}]")
        except InputError as e:
            print(f"error: {e}", file=sys.stderr)
            summary.append({"_i": index, "input": str(path), "clip": clip, "model": ",".join(models),
                            "condition": condition, "status": f"error: {e.problem}"})
            continue
        for name, trace, err in zip(models, traces, errors):
            if err is not None:
                msg = str(err) if isinstance(err, UserError) else f"{type(err).__name__}: {err}"
                print(f"error: {path} [{name}]: {msg}".splitlines()[0], file=sys.stderr)
                summary.append({"_i": index, "input": str(path), "clip": clip, "model": name,
                                "condition": condition, "status": f"error: {msg}".splitlines()[0]})
                continue
            ran += 1
            trace_name = trace_file_name(clip, name, condition)
            trace.to_csv(out / trace_name)
            fa = trace.first_alert
            fa_txt = f"{fa} ({fa / src.fps:.2f} s)" if fa is not None else "none"
            unconv = int((~trace.converged).sum())
            note = f", {unconv} frames NOT converged" if unconv else ""
            if rain is not None:
                note += f", rain SNR {rain.snr_db:.2f} dB"
            fps = trace.fps
            fps_txt = f"{fps:.1f} fps" if math.isfinite(fps) else "n/a fps (one frame)"
            out_name = "" if clip == src.name else f" -> {clip}"
            print(f"{path}{out_name} [{name}]: {trace.n_frames} frames, first alert {fa_txt}, "
                  f"max {trace.output_name} {trace.output.max():.4f}, {fps_txt}{note}")
            summary.append({"_i": index, "input": str(path), "clip": clip, "model": name, "condition": condition,
                            "params": params_text(instances[models.index(name)]), "trace": trace_name,
                            "frames": trace.n_frames, "video_fps": f"{src.fps:g}",
                            "first_alert": "" if fa is None else fa, "max_output": f"{trace.output.max():.6f}",
                            "proc_fps": f"{fps:.2f}" if math.isfinite(fps) else "",
                            "status": "ok" if not unconv else "unconverged",
                            "rain_snr_db": f"{rain.snr_db:.4f}" if rain is not None else ""})
    merge_summary(out / "summary.csv", sorted(summary, key=lambda r: r["_i"]), write_text)
    print(f"results in {out}/ (summary.csv lists every run made into this folder)", file=sys.stderr)
    n_failed = sum(1 for r in summary if str(r.get("status", "")).startswith("error"))
    if n_failed == 0:
        return EXIT_OK
    return EXIT_FAILED if ran else EXIT_USAGE


#: Columns of ``run``'s summary.csv, in order (see the README's table of CSV columns).
SUMMARY_COLUMNS = ("input", "clip", "model", "condition", "params", "trace", "frames", "video_fps", "first_alert",
                   "max_output", "proc_fps", "status", "rain_snr_db")


def trace_file_name(clip: str, model: str, condition: str) -> str:
    """``<clip>.<model>.csv`` for clean input, ``<clip>.<model>.<condition>.csv`` otherwise (``.rain``)."""
    return f"{clip}.{model}.csv" if condition == "clean" else f"{clip}.{model}.{condition}.csv"


def params_text(model) -> str:
    """The model's parameters that differ from its defaults, ``NAME=VALUE;...`` (empty: all defaults)."""
    params = getattr(model, "params", None)
    if params is None or not hasattr(params, "to_dict"):
        return ""
    try:
        default = type(params)().to_dict()
    except TypeError:
        default = {}
    return ";".join(f"{k}={v}" for k, v in params.to_dict().items() if default.get(k, object()) != v)


def _summary_key(row: dict) -> tuple[str, str, str]:
    return (str(row.get("clip", "")), str(row.get("model", "")), str(row.get("condition") or "clean"))


def read_summary(path: Path) -> list[dict]:
    """The rows of an existing ``summary.csv`` (none when absent or unreadable).

    Rows written before the summary had a ``condition`` column get one: ``rain`` where a rain SNR
    was recorded, else ``clean``; the old ``fps`` column (processing speed) becomes ``proc_fps``.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return []
    rows = []
    for row in csv.DictReader(io.StringIO(text)):
        if not row.get("condition"):
            row["condition"] = "rain" if row.get("rain_snr_db") else "clean"
        if "fps" in row and "proc_fps" not in row:
            row["proc_fps"] = row.pop("fps")
        rows.append(row)
    return rows


def merge_summary(path: Path, new_rows: list[dict], write_text) -> None:
    """Merge ``new_rows`` into ``path`` (atomically), keyed by clip, model and condition.

    A new row replaces the earlier row of the same key (its trace file was replaced too, and a
    note on stderr says so when the earlier one was made with other parameters); a failed input
    replaces no earlier row; every other earlier row is kept, so separate runs into one folder
    add up.
    """
    old = read_summary(path)
    old_keys = {_summary_key(r) for r in old}
    # a failed input replaces nothing: the earlier trace of that key is still on disk, and so stays its row
    new_rows = [r for r in new_rows if not (str(r.get("status", "")).startswith("error")
                                             and _summary_key(r) in old_keys)]
    new_keys = {_summary_key(r) for r in new_rows}
    for r in old:
        mine = next((n for n in new_rows if _summary_key(n) == _summary_key(r)), None)
        if mine is not None and r.get("status") != "" and not str(r.get("status", "")).startswith("error") \
                and (r.get("params") or "") != (mine.get("params") or ""):
            print(f"note: {path.parent / mine['trace']} replaces the trace of an earlier run made with other "
                  f"parameters ({r.get('params') or 'defaults'} -> {mine.get('params') or 'defaults'})",
                  file=sys.stderr)
    kept = [r for r in old if _summary_key(r) not in new_keys]
    columns = list(SUMMARY_COLUMNS) + [c for r in kept for c in r if c not in SUMMARY_COLUMNS and c != "_i"]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(dict.fromkeys(columns)), extrasaction="ignore",
                            lineterminator="\n")
    writer.writeheader()
    writer.writerows(kept + new_rows)
    write_text(path, buf.getvalue())


def _exit_now(code: int) -> None:
    """Flush stdout/stderr and end the process with ``code`` (no interpreter shutdown)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


def _load(target: str) -> Callable[[Sequence[str]], int]:
    """The subcommand's ``main`` from its ``"module:function"`` name.

    The entry point imports a subcommand module only when it runs (by name, not by an
    import statement): start-up stays fast, and the subcommand modules may import this
    package's shared CLI helpers (:mod:`cdnf_ti.cli_common`) without an import cycle.
    """
    mod, fn = target.split(":")
    return getattr(importlib.import_module(mod), fn)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code (see the module docstring).

    A :class:`~cdnf_ti.errors.UserError` becomes one ``error:`` line and exit
    code 2; any other exception propagates with its traceback (it is a bug).
    """
    program = argv is None
    if program:  # run as a program: a second Ctrl-C after a first one ends it at once
        exit_on_second_interrupt(True)
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        lanes_override()  # a bad $CDNF_TI_LANES is one line now, not one error per clip later
        if not argv:
            return _load(SUBCOMMANDS["demo"])([])
        if argv[0] in SUBCOMMANDS:
            return _load(SUBCOMMANDS[argv[0]])(argv[1:])
        return run_videos(argv)
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        stop_all_pools()  # workers are never waited for
        print("interrupted: finished results are saved; run the same command again to resume",
              file=sys.stderr)
        if program:  # leave now: nothing is left to wait for, and a Ctrl-C during shutdown changes nothing
            _exit_now(EXIT_INTERRUPTED)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    raise SystemExit(main())
