"""Command line: ``python -m cdnf_ti.run``.

Usage::

    python -m cdnf_ti.run                                # demo: Table I on the six basic stimuli
    python -m cdnf_ti.run run VIDEO [VIDEO ...] --out DIR  # per-frame traces + one summary line per video
    python -m cdnf_ti.run VIDEO [VIDEO ...] --out DIR      # the same ('run' may be left out)
    python -m cdnf_ti.run live SOURCE [--model M,...]      # camera / stream URL: JSON lines (cdnf_ti.live)
    python -m cdnf_ti.run SUBCOMMAND ...                   # see SUBCOMMANDS below

A first word that names a subcommand is the subcommand, even where a file or folder of that
name exists (a note says so): run such an input as ``run demo`` or ``demo/``.

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
import contextlib
import csv
import dataclasses
import importlib
import io
import math
import os
import sys
import warnings
from multiprocessing import util as mp_util
from pathlib import Path
from typing import Callable, Sequence

from .alert_rule import alert_summary
from .atomic import atomic_write_text, output_lock, prepare_output
from .cli_common import (
    EXIT_FAILED as EXIT_FAILED,  # re-exported: cdnf_ti.run was their home
    EXIT_INTERRUPTED as EXIT_INTERRUPTED,
    EXIT_OK as EXIT_OK,
    EXIT_USAGE as EXIT_USAGE,
    ArgumentParser,
    add_event_options,
    add_input_options,
    add_model_options as add_model_options,
    add_output_option,
    add_param_options,
    add_rain_options,
    add_seed_options,
    check_model_options as check_model_options,
    drops_arg as drops_arg,
    finite_float as finite_float,
    note_unused_rain_options,
    params_from_args,
    parse_models as parse_models,
    positive_float as positive_float,
    rain_conditions,
    rain_seed_of,
    seed_arg as seed_arg,
    unique_names as unique_names,
)
from .errors import InputError, UserError
from .events.binning import DEFAULT_BIN_MS
from .events.readers import is_event_file
from .events.source import EventSource, open_event_source
from .experiments.parallel import (
    exit_on_second_interrupt,
    handle_sigterm_as_interrupt,
    stop_all_pools,
    watch_interrupts,
)
from .frames import IMAGE_EXTENSIONS, iter_frames
from .inputs import resolve_input
from .limits import check_drops, check_frame_size
from .models import create_model, get_model_class
from .models.base import NotConvergedWarning, bin_ms_for, run_models, takes_colour
from .paths import inside
from .stimuli.rain import RainParams, RainyFrames
from .taichi_runtime import lanes_override

#: Subcommands: first word on the command line -> "module:function(argv) -> int".
SUBCOMMANDS: dict[str, str] = {
    "run": "cdnf_ti.run:run_videos",  # (main calls run_videos directly)
    "bench": "cdnf_ti.bench.cli:main",
    "demo": "cdnf_ti.demo:main",
    "generate": "cdnf_ti.generate:generate_main",
    "rain": "cdnf_ti.generate:rain_main",
    "dataset": "cdnf_ti.experiments.cli:dataset_main",
    "experiment": "cdnf_ti.experiments.cli:experiment_main",
    "live": "cdnf_ti.live:main",
    "render": "cdnf_ti.render:render_main",
    "events": "cdnf_ti.events.cli:events_main",
}


def _videos_parser() -> argparse.ArgumentParser:
    ap = ArgumentParser(
        prog="python -m cdnf_ti.run [run]",
        description="Run looming models on videos (files, image folders, .npy arrays, stim: specs) and write "
                    "a trace per input, model and condition plus OUT/summary.csv. 'run' may be left out "
                    "unless the first input is named like a subcommand (then write 'run NAME' or 'NAME/'). "
                    "With no arguments: the built-in demo (paper Table I). "
                    f"Subcommands: {', '.join(SUBCOMMANDS)} (e.g. 'python -m cdnf_ti.run demo --help').",
    )
    ap.add_argument("inputs", nargs="+", metavar="VIDEO",
                    help="video file, folder of images, .npy array, event recording (docs/EVENTS.md), or a "
                         "generated stimulus "
                         "'stim:NAME[?coherence=C&seed=S&size=N...]' (see cdnf_ti.inputs)")
    add_output_option(ap)
    add_model_options(ap)
    add_param_options(ap)
    add_input_options(ap)
    add_event_options(ap)
    add_rain_options(ap, default="off")
    add_seed_options(ap, rain=True)
    ap.add_argument("--no-progress", action="store_true", help="hide progress bars")
    return ap


def run_videos(argv: Sequence[str]) -> int:
    """Run models over each input, write ``OUT/<clip>.<model>[.rain].csv`` and print one line each.

    Inputs that share a name get distinct output names (:func:`unique_names`).
    """
    args = _videos_parser().parse_args(list(argv))
    note_unused_rain_options(args)
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


def _error_row(index: int, path, clip: str, model: str, condition: str, problem: str) -> dict:
    return {"_i": index, "input": str(path), "clip": clip, "model": model, "condition": condition,
            "status": f"error: {problem}".splitlines()[0]}


def _run_videos(args, models: list[str], params: dict, out: Path, write_text) -> int:
    conditions = rain_conditions(args)
    rain_params = RainParams(drops=args.rain_drops) if "rain" in conditions else None
    rain_seed = rain_seed_of(args)
    summary: list[dict] = []  # rows in input order ("_i": index of the input)
    sources: list = []
    order: list[int] = []
    for index, path in enumerate(args.inputs):  # open every input first: bad ones are reported before any work
        try:
            if is_event_file(path):
                if rain_params is not None:
                    raise InputError(path, "is an event recording; --rain applies to frames only")
                width = DEFAULT_BIN_MS if args.bin_ms is None else args.bin_ms  # each model's: input_passes
                src = open_event_source(path, args.sensor_size, width, max_gap_s=args.max_gap_s,
                                        max_span_s=args.max_span_s)
            else:
                src = resolve_input(path, fps=args.fps, color_order=args.color_order)
            check_frame_size(*src.shape, n_models=len(models), what=str(path), binning=isinstance(src, EventSource))
            if rain_params is not None:
                check_drops(args.rain_drops, src.shape, what="--rain-drops")
            sources.append((path, src))
            order.append(index)
        except UserError as e:
            print(f"error: {e}", file=sys.stderr)
            problem = e.problem if isinstance(e, InputError) else str(e)
            summary += [_error_row(index, path, Path(str(path)).stem, ",".join(models), c, problem)
                        for c in conditions]
    if not sources:  # nothing could be opened: leave the output folder (and a summary of an earlier run) as it was
        return EXIT_USAGE
    names = unique_names([str(p) for p, _ in sources], [src.name for _, src in sources])
    dup = [(p, n) for (p, src), n in zip(sources, names) if n != src.name]
    if dup:
        print("note: inputs share a name; output names: " + ", ".join(f"{p} -> {n}" for p, n in dup),
              file=sys.stderr)
    ran = 0
    for (path, src), clip, index in zip(sources, names, order):
        for condition in conditions:
            rows, n_ok = _run_one(args, models, params, out, path, src, clip, index, condition,
                                  rain_params if condition == "rain" else None, rain_seed)
            summary += rows
            ran += n_ok
    if not ran:  # every input failed: the output folder is left as it was (a folder made for the run is removed)
        return EXIT_USAGE
    merge_summary(out / "summary.csv", sorted(summary, key=lambda r: r["_i"]), write_text)
    print(f"results in {out}/ (summary.csv lists every run made into this folder)", file=sys.stderr)
    n_failed = sum(1 for r in summary if str(r.get("status", "")).startswith("error"))
    if n_failed == 0:
        return EXIT_OK
    return EXIT_FAILED if ran else EXIT_USAGE


def _run_one(args, models, params, out: Path, path, src, clip: str, index: int, condition: str,
             rain_params, rain_seed: int) -> tuple[list[dict], int]:
    """Every model on one input under one condition: traces written, one line printed per model.

    Returns the summary rows and how many models finished.
    """
    if isinstance(src, EventSource) and str(args.models).strip().lower() == "all":
        skipped = [name for name in models if not get_model_class(name).takes_events]
        if skipped:  # 'all' means every model that takes events
            print(f"note: {path}: left out of --model all (no event input): {', '.join(skipped)}", file=sys.stderr)
            models = [name for name in models if name not in skipped]
    rain = None
    label = clip if condition == "clean" else f"{clip} ({condition})"
    instances: list = [None] * len(models)
    traces: list = [None] * len(models)
    errors: list = [None] * len(models)
    sources: list = [src] * len(models)  # the source each model read: its recording's bins at its width
    events = isinstance(src, EventSource)
    colour_input = not events and rain_params is None  # rain makes grey frames; event bins have no colour
    problems: list[str] = []
    for source, idx in input_passes(src, models, params, args.bin_ms):
        names = [models[i] for i in idx]
        readers = [create_model(models[i], params[models[i]], backend=args.backend, arch=args.arch, fps=source.fps)
                   for i in idx]
        errs: list = []
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", NotConvergedWarning)  # reported per line below
                colour = colour_input and takes_colour(readers)  # frames in both forms where a model takes colour
                frames = source.contrast(args.event_threshold) if events else iter_frames(source, colour)
                if rain_params is not None:
                    rain = RainyFrames(frames, rain_params, seed=rain_seed)
                    frames = iter(rain)
                # one pass over the input: each frame is decoded (and rained on) once for all its models
                bar = f"{label} [{', '.join(names)}]" + (f" ({source.bin_ms:.4g} ms bins)" if events else "")
                done = run_models(readers, frames, total=source.n_frames, errors=errs,
                                  progress=False if args.no_progress else bar)
        except InputError as e:
            print(f"error: {e}", file=sys.stderr)
            return [_error_row(index, path, clip, ",".join(models), condition, e.problem)], 0
        for k, i in enumerate(idx):
            instances[i], traces[i], errors[i], sources[i] = readers[k], done[k], errs[k], source
        if events:
            problems += [p for p in source.report.problems() if p not in problems]
    for problem in problems:
        print(f"warning: {path}: {problem}", file=sys.stderr)
    rows = []
    ran = 0
    for name, model, trace, err, source in zip(models, instances, traces, errors, sources):
        if err is not None:
            msg = str(err) if isinstance(err, UserError) else f"{type(err).__name__}: {err}"
            print(f"error: {path} [{name}]: {msg}".splitlines()[0], file=sys.stderr)
            rows.append(_error_row(index, path, clip, name, condition, msg))
            continue
        if trace.n_frames == 0:  # a source that yielded nothing (an event recording says so itself)
            print(f"error: {path}: holds no frames", file=sys.stderr)
            rows.append(_error_row(index, path, clip, name, condition, "holds no frames"))
            continue
        ran += 1
        trace_name = trace_file_name(clip, name, condition)
        trace.to_csv(inside(out, trace_name))
        settings = run_settings(args, path, source, rain_params, rain_seed,
                                colour=colour_input and takes_colour([model]))
        alert = alert_summary(trace, model.alert_rule(), source.fps)
        fa = alert.first_alert
        fa_txt = f"{fa} ({alert.first_alert_s:.2f} s)" if fa is not None else "none"
        unconv = int((~trace.converged).sum())
        note = f", {unconv} frames NOT converged" if unconv else ""
        if rain is not None:
            note += f", rain SNR {rain.snr_db:.2f} dB"
        fps = trace.fps
        fps_txt = f"{fps:.1f} fps" if math.isfinite(fps) else "n/a fps (no frame without set-up)"
        if trace.compile_seconds >= 0.05:
            fps_txt += f" (set-up and compiling {trace.compile_seconds:.1f} s apart)"
        out_name = "" if clip == src.name else f" -> {clip}"
        cond_txt = "" if condition == "clean" else f" ({condition})"
        extra = "" if alert.quantity == trace.output_name else f" (max {trace.output_name} {trace.output.max():.4f})"
        print(f"{path}{out_name} [{name}]{cond_txt}: {trace.n_frames} frames, first alert {fa_txt}; "
              f"{alert.text()}{extra}; {fps_txt}{note}")
        rows.append({"_i": index, "input": str(path), "clip": clip, "model": name, "condition": condition,
                     "params": params_text(model), "settings": settings_text(settings), "trace": trace_name,
                     "frames": trace.n_frames, "video_fps": f"{source.fps:g}",
                     "first_alert": "" if fa is None else fa,
                     "first_alert_s": "" if alert.first_alert_s is None else f"{alert.first_alert_s:.4f}",
                     "alert_rule": alert.rule, "alert_peak": f"{alert.peak:.6g}", "alert_level": f"{alert.level:g}",
                     "max_output": f"{trace.output.max():.6f}",
                     "proc_fps": f"{fps:.2f}" if math.isfinite(fps) else "",
                     "compile_s": f"{trace.compile_seconds:.3f}",
                     "status": "ok" if not unconv else "unconverged",
                     "rain_snr_db": f"{rain.snr_db:.4f}" if rain is not None else ""})
    return rows, ran


def input_passes(src, models: Sequence[str], params: dict, bin_ms: float | None) -> list[tuple[object, list[int]]]:
    """The passes ``run`` makes over one input: ``(source, indices of the models that read it)``.

    A video is one pass for every model. An event recording is binned once per distinct width
    (:func:`~cdnf_ti.models.base.bin_ms_for`: ``bin_ms``, ``--bin-ms``, when given, else each
    model's own), in the order the models first name it; models of one width share a pass.
    """
    if not isinstance(src, EventSource):
        return [(src, list(range(len(models))))]
    groups: dict[float, list[int]] = {}
    for i, name in enumerate(models):
        groups.setdefault(bin_ms_for(get_model_class(name), params.get(name), bin_ms), []).append(i)
    return [(dataclasses.replace(src, bin_ms=width), idx) for width, idx in groups.items()]


#: Columns of ``run``'s summary.csv, in order (see the README's table of CSV columns).
SUMMARY_COLUMNS = ("input", "clip", "model", "condition", "params", "settings", "trace", "frames", "video_fps",
                   "first_alert", "first_alert_s", "alert_rule", "alert_peak", "alert_level", "max_output", "proc_fps",
                   "compile_s", "status", "rain_snr_db")


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


def run_settings(args, path, src, rain_params, rain_seed: int, colour: bool = False) -> dict[str, str]:
    """The options besides the model's parameters that change a run's result, as ``{name: value}``.

    With the clip, model, condition and parameters they are the run's identity (docs/EXPERIMENTS.md,
    "Run identity"): the engine (``backend``); for frames the frame rate (``fps``: ``--fps`` or
    the video's own) and, for a ``.npy`` array, ``color_order``; for an event recording
    ``bin_ms`` (the width of the bins ``src`` gives: the model's, :func:`input_passes`),
    ``event_threshold`` and ``sensor_size`` (WxH, given or found); under rain the
    droplets per frame (``rain_drops``, the default resolved for the frame size) and
    ``rain_seed``; ``frames=bgr`` where the model took the decoded colour frames (``colour``:
    :meth:`~cdnf_ti.models.base.Model.frame_colour`; absent: the grey frames every model took before).
    Values are the settings in effect, not the options as typed.
    """
    settings = {"backend": str(args.backend)}
    if isinstance(src, EventSource):
        w, h = src.sensor_size
        settings.update(bin_ms=f"{src.bin_ms:g}", event_threshold=f"{args.event_threshold:g}",
                        sensor_size=f"{w}x{h}")
    else:
        settings["fps"] = f"{src.fps:g}"
        if str(path).lower().endswith(".npy"):
            settings["color_order"] = str(args.color_order)
    if colour:
        settings["frames"] = "bgr"
    if rain_params is not None:
        settings.update(rain_drops=str(rain_params.drops_for(src.shape)), rain_seed=str(int(rain_seed)))
    return settings


def settings_text(settings: dict[str, str]) -> str:
    """``NAME=VALUE;...`` of :func:`run_settings` (the ``settings`` column of summary.csv)."""
    return ";".join(f"{k}={v}" for k, v in settings.items())


def _settings_of_row(row: dict) -> dict[str, str]:
    """The settings recorded in a summary row; a row written before the ``settings`` column has only its
    frame rate (``video_fps``)."""
    text = row.get("settings")
    if text is None:
        return {"fps": row["video_fps"]} if row.get("video_fps") else {}
    return dict(item.split("=", 1) for item in str(text).split(";") if "=" in item)


def identity_changes(old: dict, new: dict) -> list[str]:
    """What differs between the runs of two summary rows, ``["fps 30 -> 10", "params defaults -> n_ts=3"]``.

    Compares the parameters and every setting of :func:`run_settings` that either row records (a
    setting only one row records is named with ``(not recorded)`` on the other side).
    """
    changes = []
    old_params, new_params = old.get("params") or "", new.get("params") or ""
    if old_params != new_params:
        changes.append(f"params {old_params or 'defaults'} -> {new_params or 'defaults'}")
    a, b = _settings_of_row(old), _settings_of_row(new)
    for key in dict.fromkeys([*a, *b]):
        if a.get(key) != b.get(key):
            changes.append(f"{key} {a.get(key, '(not recorded)')} -> {b.get(key, '(not recorded)')}")
    return changes


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
    note on stderr names each difference when the earlier one was made with other parameters or
    settings: :func:`identity_changes`); a failed input
    replaces no earlier row; every other earlier row is kept, so separate runs into one folder
    add up.
    """
    old = read_summary(path)
    old_keys = {_summary_key(r) for r in old}
    # a failed input replaces nothing: the earlier trace of that key is still on disk, and so stays its row
    new_rows = [r for r in new_rows if not (str(r.get("status", "")).startswith("error")
                                             and _summary_key(r) in old_keys)]
    by_key = {_summary_key(r): r for r in new_rows}
    for r in old:
        mine = by_key.get(_summary_key(r))
        if mine is None or r.get("status") == "" or str(r.get("status", "")).startswith("error"):
            continue
        changes = identity_changes(r, mine)
        if changes:
            print(f"note: {path.parent / mine['trace']} replaces the trace of an earlier run made with other "
                  f"settings: {'; '.join(changes)}", file=sys.stderr)
    kept = [r for r in old if _summary_key(r) not in by_key]
    columns = list(SUMMARY_COLUMNS) + [c for r in kept for c in r if c not in SUMMARY_COLUMNS and c != "_i"]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(dict.fromkeys(columns)), extrasaction="ignore",
                            lineterminator="\n")
    writer.writeheader()
    writer.writerows(kept + new_rows)
    write_text(path, buf.getvalue())


def _exit_now(code: int) -> None:
    """Flush stdout/stderr and end the process with ``code`` (no interpreter shutdown).

    The semaphores of the stopped worker pools are released first (multiprocessing's own exit
    finalizers, which ``os._exit`` skips), so its resource tracker reports none as leaked.
    """
    with contextlib.suppress(Exception):
        mp_util._run_finalizers(0)
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


def _looks_like_input(path: str) -> bool:
    """Whether ``path`` (a subcommand's name) is also a file, or a folder of images, that ``run`` could read."""
    p = Path(path)
    try:
        if p.is_file():
            return True
        return p.is_dir() and any(f.suffix.lower() in IMAGE_EXTENSIONS for f in p.iterdir())
    except OSError:
        return False


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code (see the module docstring).

    A :class:`~cdnf_ti.errors.UserError` becomes one ``error:`` line and exit
    code 2; any other exception propagates with its traceback (it is a bug).
    """
    program = argv is None
    if program:  # run as a program: a second Ctrl-C after a first one ends it at once, and one during
        exit_on_second_interrupt(True)  # a kernel compile within seconds; SIGTERM is a first Ctrl-C
        handle_sigterm_as_interrupt()
        watch_interrupts()
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        lanes_override()  # a bad $CDNF_TI_LANES is one line now, not one error per clip later
        if not argv:
            return _load(SUBCOMMANDS["demo"])([])
        if argv[0] == "run":
            return run_videos(argv[1:])
        if argv[0] in SUBCOMMANDS:
            if _looks_like_input(argv[0]):
                print(f"note: {argv[0]!r} is taken as the subcommand; to run the input of that name, write "
                      f"'run {argv[0]}' or '{argv[0]}{os.sep}'", file=sys.stderr)
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
