"""Command lines ``python -m cdnf_ti.run dataset ...`` and ``python -m cdnf_ti.run experiment ...``.

Exit codes (as for ``run``): 0 all done; 1 the run finished but some
clip/model failed (error rows in results.csv); 2 bad usage, an unavailable
``--arch``, an output folder that cannot be written or a bad labels file
(nothing was run); 130 interrupted (finished work is kept; rerun to resume).

Everything the command needs is checked before any work: options, the Taichi
arch, the labels and videos, and that ``--out`` can be written. ``--out`` is
locked for the run: a second run into the same folder waits for the first and
then reuses its results.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

from ..atomic import output_lock, prepare_output
from ..cli_common import (
    RAIN_ENGINE_WORD,
    ArgumentParser,
    add_event_options,
    add_input_options,
    add_model_options,
    add_output_option,
    add_param_options,
    add_rain_options,
    add_seed_options,
    check_model_options,
    event_options_of,
    given_event_options,
    note,
    note_unused_rain_options,
    params_from_args,
    parse_models,
    rain_seed_of,
    stimulus_seed_of,
)
from ..errors import InputError, UserError
from ..events.readers import is_event_file
from ..limits import check_frame_size
from ..render import render_dataset
from ..stimuli.basic import BASIC_STIMULI
from ..stimuli.incoherent import SCATTERS
from . import builtin
from .benchmark_formats import FORMATS
from .dataset import run_dataset
from .labels import drop_missing, find_clip, read_labels
from .paramsweep import run_param_sweep
from .reports import pct, table2_markdown
from .scoring import Padding
from .selectivity import agreement_markdown, selectivity_sweep
from .tune import run_tune

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


def _nonneg_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 0")
    return v


def _add_parallel(ap: argparse.ArgumentParser, rain: bool = False, stimulus: bool = False) -> None:
    ap.add_argument("--workers", type=_nonneg_int, default=None,
                    help="local worker processes (default: one per CPU core; 0 or 1: run in this process)")
    ap.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="Dask distributed scheduler address (e.g. tcp://10.0.0.5:8786): run the tasks there")
    add_seed_options(ap, rain=rain, stimulus=stimulus)
    ap.add_argument("--no-progress", action="store_true", help="hide progress bars")
    ap.add_argument("--no-figures", action="store_true", help="do not draw figures")


def _add_dataset_options(ap: argparse.ArgumentParser, rain_default: str, one_model: bool = False) -> None:
    ap.add_argument("--labels", default=None, help="labels CSV (default: DIR/labels.csv)")
    if one_model:
        add_model_options(ap, default_models="cdnf")
        ap.set_defaults(models="cdnf")
        for a in ap._actions:  # the sweep runs one model: say so
            if a.dest == "models":
                a.help = "the one model whose parameters are swept (default: cdnf)"
    else:
        add_model_options(ap, default_models="cdnf" if rain_default == "off" else "all")
    if not one_model:  # (the sweep sets its parameters with its own grid --param)
        add_param_options(ap)
    add_input_options(ap)
    add_event_options(ap)
    add_rain_options(ap, default=rain_default, what="each clip (videos; rain applies to frames only, not to "
                                                      "event recordings)", drops=not one_model)
    ap.add_argument("--skip-missing", action="store_true",
                    help="run the clips whose video exists and leave out label rows naming a missing video "
                         "(a note lists them; default: a missing video is an error and nothing runs)")
    ap.add_argument("--pad-before", type=_nonneg_int, default=0, metavar="N",
                    help="frames of tolerance before each window start (default 0)")
    ap.add_argument("--pad-after", type=_nonneg_int, default=0, metavar="N",
                    help="frames of tolerance after each window end (default 0)")
    _add_parallel(ap, rain=True)


def _rain_params(args) -> dict | None:
    """``RainParams`` keywords from ``--rain-drops`` (None: the paper's defaults)."""
    return None if args.rain_drops is None else {"drops": args.rain_drops}


def _skip_missing(args, folder: Path) -> None:
    """``--skip-missing``: say which label rows name a missing video (and stop when every one does)."""
    if not getattr(args, "skip_missing", False):
        return
    labels_path = Path(args.labels) if args.labels else folder / "labels.csv"
    kept, missing = drop_missing(read_labels(labels_path), folder)
    if missing:
        shown = ", ".join(missing[:10]) + (", ..." if len(missing) > 10 else "")
        note(f"--skip-missing: {len(missing)} labelled clip(s) have no video in {folder} and are left out: {shown}")
    if not kept:
        raise InputError(labels_path, f"no labelled clip has a video in {folder}")


def _note_event_options(args, folder: Path) -> None:
    """A ``note:`` for options that do not apply to the clips of ``folder``: event options without any
    event recording, ``--fps``/``--color-order`` with event recordings only (their rate is 1000 / the bin
    width: ``--bin-ms``, else the models')."""
    labels_path = Path(args.labels) if args.labels else folder / "labels.csv"
    try:
        labels = read_labels(labels_path)
    except InputError:
        return  # reported by the run itself
    files = [f for f in (find_clip(folder, lab.clip) for lab in labels) if f is not None]
    n_events = sum(1 for f in files if is_event_file(f))
    given = given_event_options(args)
    if given and files and not n_events:
        note(f"{' and '.join(given)} change(s) nothing: no labelled clip in {folder} is an event recording")
    frame_opts = [o for o, d in (("--fps", args.fps is not None), ("--color-order", args.color_order != "bgr")) if d]
    if frame_opts and files and n_events == len(files):
        rate = ("bins of the models' own width" if args.bin_ms is None
                else f"bins of --bin-ms, {1000.0 / args.bin_ms:g} per second")
        note(f"{' and '.join(frame_opts)} change(s) nothing: every labelled clip in {folder} is an event recording "
             f"({rate})")


def _dataset(args, folder: Path, out: Path) -> int:
    note_unused_rain_options(args)
    models = parse_models(args.models)
    check_model_options(args)
    params = params_from_args(args, models)
    fmt = getattr(args, "format", "labels")
    if fmt == "labels":
        _skip_missing(args, folder)
        _note_event_options(args, folder)
    elif getattr(args, "render", False):
        raise UserError(f"--render works with --format labels only (not {fmt})")
    run = run_dataset(folder, args.labels, out, models=models, rain=RAIN_ENGINE_WORD[args.rain],
                      padding=Padding(args.pad_before, args.pad_after), seed=rain_seed_of(args),
                      workers=args.workers, scheduler=args.scheduler, backend=args.backend, arch=args.arch,
                      progress=not args.no_progress, figures=not args.no_figures, rain_params=_rain_params(args),
                      params=params, fps=args.fps, color_order=args.color_order, skip_missing=args.skip_missing,
                      events=event_options_of(args), fmt=fmt, split=getattr(args, "split", None))
    print(table2_markdown(run.summary["results"], run.models, run.conditions))
    for line in headline(run):
        print(line)
    for line in benchmark_headline(run):
        print(line)
    print(f"{len(run.labels)} clips x {len(run.models)} models x {len(run.conditions)} conditions: "
          f"{run.ran} run now, {run.skipped} reused; results in {out}/ (results.csv, summary.md)")
    if run.unlabelled:
        shown = ", ".join(run.unlabelled[:10]) + (", ..." if len(run.unlabelled) > 10 else "")
        print(f"note: {len(run.unlabelled)} video(s) in {folder} have no row in the labels file and were "
              f"not run: {shown}", file=sys.stderr)
    for e in run.summary["errors"]:
        print(f"error: {e['error']} [{e['model']}, {e['condition']}]", file=sys.stderr)

    if getattr(args, "render", False):
        movies = render_dataset(run, folder, progress=not args.no_progress, params=params, fps=args.fps,
                                color_order=args.color_order, backend=args.backend, arch=args.arch,
                                events=event_options_of(args))
        print(f"{len(movies)} field movies in {out}/movies/", file=sys.stderr)
    if run.failed:
        print(f"{run.n_errors} of {len(run.rows)} clip x model x condition run(s) failed; see {out}/results.csv",
              file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def headline(run) -> list[str]:
    """One line per model and condition: accuracy, how many clips were scored and how many failed."""
    lines = []
    for m in run.models:
        for c in run.conditions:
            rows = [r for r in run.rows if r["model"] == m and r["condition"] == c]
            failed = sum(1 for r in rows if r.get("error"))
            scored = len(rows) - failed
            d = (run.summary.get("results", {}).get(m) or {}).get(c) or {}
            acc = pct(d.get("accuracy")) if scored else "n/a"
            lines.append(f"{m}, {c}: accuracy {acc} over {scored} scored clip(s) of {len(rows)}"
                         + (f"; {failed} failed (not scored)" if failed else ""))
    return lines


def benchmark_headline(run) -> list[str]:
    """One line per model and condition: the benchmark's headline metric with its interval, and the median
    lead time before the event in seconds (summary.md, "Benchmark scores", has the rest)."""
    bench = run.summary.get("benchmark") or {}
    lines = []
    for m, per in (bench.get("results") or {}).items():
        for c, d in per.items():
            h, lt = d["headline"], d["lead_times"]
            val = "n/a" if h["value"] is None else f"{h['value']:.3f}"
            if h["value"] is not None and h["ci_lo"] is not None:
                val += f" [{h['ci_lo']:.3f}, {h['ci_hi']:.3f}]"
            med = "n/a" if lt["median_s"] is None else f"{lt['median_s']:+.2f} s"
            alerted = lt["positive_clips"] - lt["never_alerted"]
            lines.append(f"{m}, {c}: {bench['format']} {bench['headline']} {val}; median lead time {med} "
                         f"over {alerted} of {lt['positive_clips']} positive clip(s)")
    return lines


def _param_sweep(args) -> int:
    models = parse_models(args.models)
    if len(models) != 1:
        raise UserError("experiment sweep takes exactly one --model (its parameters are swept)")
    if not args.param:
        raise UserError("experiment sweep needs at least one --param NAME=SPEC")
    folder = Path(args.folder)
    if not folder.is_dir():
        raise InputError(folder, "dataset folder not found")
    _skip_missing(args, folder)
    _note_event_options(args, folder)
    run = run_param_sweep(folder, args.labels, Path(args.out), models[0], args.param,
                          rain=RAIN_ENGINE_WORD[args.rain], padding=Padding(args.pad_before, args.pad_after),
                          seed=rain_seed_of(args), folds=args.folds,
                          workers=args.workers, scheduler=args.scheduler, backend=args.backend, arch=args.arch,
                          progress=not args.no_progress, figures=not args.no_figures, downscale=args.downscale,
                          html=not args.no_html, fps=args.fps, color_order=args.color_order,
                          skip_missing=args.skip_missing, events=event_options_of(args))
    print((Path(args.out) / "param_sweep.md").read_text(encoding="utf-8"))
    print(f"{len(run.settings)} settings x {len(run.conditions)} conditions: {run.ran} tasks run now, "
          f"{run.skipped} reused; results in {args.out}/", file=sys.stderr)
    for e in run.errors:
        print(f"error: {e.get('error')} [{e.get('key')}, {e.get('condition')}]", file=sys.stderr)
    return EXIT_FAILED if run.errors else EXIT_OK


def _tune(args) -> int:
    """``experiment tune``: checks the options, runs :func:`~.tune.run_tune`, prints tune.md."""
    check_model_options(args)
    models = parse_models(args.models)
    if len(models) != 1:
        raise UserError("experiment tune takes exactly one --model (its parameters are searched)")
    if args.rain != "off":
        raise UserError("experiment tune scores the clean clips; leave out --rain")
    folder = Path(args.folder)
    if not folder.is_dir():
        raise InputError(folder, "dataset folder not found")
    with output_lock(prepare_output(args.out)):
        res = run_tune(folder, args.labels, Path(args.out), models[0], args.param, trials=args.trials,
                       folds=args.folds, seed=rain_seed_of(args), padding=Padding(args.pad_before, args.pad_after),
                       workers=args.workers, scheduler=args.scheduler, backend=args.backend, arch=args.arch,
                       progress=not args.no_progress, downscale=args.downscale, fps=args.fps,
                       color_order=args.color_order, skip_missing=args.skip_missing, events=event_options_of(args))
    print((Path(args.out) / "tune.md").read_text(encoding="utf-8"))
    for e in res["errors"]:
        print(f"error: {e.get('error')} [{e.get('key')}]", file=sys.stderr)
    return EXIT_FAILED if res["errors"] else EXIT_OK


def dataset_main(argv: Sequence[str]) -> int:
    """``python -m cdnf_ti.run dataset DIR --labels CSV --out OUT [...]``."""
    ap = ArgumentParser(
        prog="python -m cdnf_ti.run dataset",
        description="Run models on every labelled clip of a folder (videos, clean and/or with synthetic rain; "
                    "event recordings, binned), score "
                    "them (docs/EVALUATION.md) and write traces, results.csv, summary.md/json and "
                    "figures. Rerunning with the same OUT skips finished work.")
    ap.add_argument("folder", metavar="DIR",
                    help="folder of videos and/or event recordings (docs/EVENTS.md: a recording's frames "
                         "are its bins, of --bin-ms or else of the models' own width, and its labels count bins)")
    add_output_option(ap, default="cdnf_out/dataset")
    ap.add_argument("--render", action="store_true",
                    help="also write a field movie of each scored clip and model (OUT/movies/<clip>.<model>.mp4)")
    ap.add_argument("--format", choices=FORMATS, default="labels",
                    help="layout of DIR: cdnf_ti's labels.csv (default) or a public benchmark's as distributed: "
                         "nexar (train.csv, train/<id>.mp4), ccd (Crash-1500.txt, Crash-1500/, Normal/), dad "
                         "(videos/{training,testing}/{positive,negative}/), dota (annotations/*.json, frames/); "
                         "--labels then names its annotation file when it is elsewhere (docs/EVALUATION.md)")
    ap.add_argument("--split", default=None,
                    help="the benchmark's split: dad training|testing, dota train|val (its metadata_<split>.json); "
                         "default: every clip")
    _add_dataset_options(ap, rain_default="off")
    args = ap.parse_args(list(argv))
    folder = Path(args.folder)
    if not folder.exists():
        raise InputError(folder, "dataset folder not found")
    if not folder.is_dir():
        raise InputError(folder, "not a folder (give the folder that holds the videos and labels.csv)")
    return _dataset(args, folder, Path(args.out))


def _selectivity(args) -> int:
    coh = None
    if args.coherences:
        try:
            coh = [float(c) for c in args.coherences.split(",") if c.strip()]
        except ValueError:
            raise UserError(f"--coherences must be numbers, got {args.coherences!r}") from None
        for c in coh:
            if not (0 < c <= 1):
                raise UserError(f"coherence must be in (0, 1], got {c:g}")
    classes = [c.strip() for c in args.classes.split(",")] if args.classes else None
    models = parse_models(args.models)
    res = selectivity_sweep(models, args.out, which=args.grid, coherences=coh, params=args.model_params,
                            seed=stimulus_seed_of(args), workers=args.workers, scheduler=args.scheduler,
                            backend=args.backend, arch=args.arch, progress=not args.no_progress,
                            figures=not args.no_figures, classes=classes)
    print(agreement_markdown(res["rows"]))
    errs = [r for r in res["rows"] if r.get("error")]
    for r in errs:
        print(f"error: {r['stimulus']} {r['parameter']}={r['value']} [{r['model']}]: {r['error']}", file=sys.stderr)
    print(f"{len(res['rows'])} runs: {res['ran']} run now, {res['reused']} reused; results in {args.out}/ "
          "(selectivity.md, selectivity.csv, figures/)", file=sys.stderr)
    return EXIT_FAILED if errs else EXIT_OK


def experiment_main(argv: Sequence[str]) -> int:
    """``python -m cdnf_ti.run experiment table1|coherence|selectivity|table2 [...]``."""
    ap = ArgumentParser(prog="python -m cdnf_ti.run experiment",
                        description="Regenerate the paper's experiments.")
    sub = ap.add_subparsers(dest="which", required=True,
                            metavar="{table1,coherence,selectivity,table2,sweep,tune}")
    on_frames = ("It runs on frames drawn in memory; for the event versions of the stimuli, emulate them "
                 "('python -m cdnf_ti.run events stim:NAME --out DIR') and run the recordings with 'run' or "
                 "'dataset'.")
    p1 = sub.add_parser("table1", help="basic selectivity on the six basic stimuli (Table I, Fig. 2)",
                        description="Basic selectivity on the six basic stimuli (Table I, Fig. 2). " + on_frames)
    p2 = sub.add_parser("coherence", help="coherence sweep on the six incoherent stimuli (Fig. 4)",
                        description="Coherence sweep on the six incoherent stimuli (Fig. 4). " + on_frames)
    for p, name in ((p1, "table1"), (p2, "coherence")):
        add_output_option(p, default=f"cdnf_experiments/{name}")
        add_model_options(p, default_models="all")
        add_param_options(p)
        p.add_argument("--size", type=int, default=builtin.TABLE1_SIZE if name == "table1" else builtin.COHERENCE_SIZE,
                       help="frame side in px (default: %(default)s" + (", the paper's, as `demo`)" if name == "table1"
                            else ", so that the 60 runs per model take minutes; the stimuli scale with the "
                                 "size, but an alert near a threshold can differ from 600 px)"))
        _add_parallel(p, stimulus=True)
    p2.add_argument("--coherences", default=",".join(f"{c:g}" for c in builtin.COHERENCES),
                    help="comma-separated coherence degrees in (0, 1] (default: %(default)s)")
    p2.add_argument("--stimuli", default=None, help="comma-separated basic stimuli (default: all six)")
    p2.add_argument("--scatter", choices=SCATTERS, default="flicker",
                    help="incoherent construction: displaced dots vanish with their leaving source and reappear "
                         "elsewhere (flicker, default) or pass to an entering source and stay put (static)")
    p4 = sub.add_parser("selectivity", help="every model against Table I over a grid of stimulus settings "
                                             "(sizes, speeds, grey levels, gratings, coherences)",
                        description="Every model against Table I over a grid of stimulus settings (sizes, speeds, "
                                    "grey levels, gratings, coherences). " + on_frames)
    add_output_option(p4, default="cdnf_experiments/selectivity")
    add_model_options(p4, default_models="all")
    add_param_options(p4)
    grid_size = p4.add_mutually_exclusive_group()
    grid_size.add_argument("--quick", dest="grid", action="store_const", const="quick", default="quick",
                           help="small grid, base 120 px (default; a few minutes on 2 cores)")
    grid_size.add_argument("--full", dest="grid", action="store_const", const="full",
                           help="every level, base 240 px, up to 600 px frames, named cases")
    p4.add_argument("--coherences", default=None,
                    help="coherences of the incoherent versions (default: 0.5 quick; 0.8,0.5,0.2 full)")
    p4.add_argument("--classes", default=None,
                    help="comma-separated stimulus classes (looming,receding,translating,grating; default: all)")
    _add_parallel(p4, stimulus=True)
    p3 = sub.add_parser("table2", help="accuracy on a labelled folder, clean and with synthetic rain (Table II)")
    p3.add_argument("folder", nargs="?", default=None, metavar="DIR",
                    help="folder of videos and/or event recordings with labels.csv (default: the development "
                         "clips, shared/data/real beside the repository, when present)")
    add_output_option(p3, default="cdnf_experiments/table2")
    _add_dataset_options(p3, rain_default="both")
    p4 = sub.add_parser("sweep", help="a grid of ONE model's parameters over a labelled folder: accuracy, "
                                      "ROC AUC and cross-validated accuracy per setting")
    p4.add_argument("folder", metavar="DIR", help="folder of videos and/or event recordings with labels.csv")
    add_output_option(p4, default="cdnf_experiments/sweep")
    p4.add_argument("--param", action="append", default=[], metavar="NAME=SPEC",
                    help="a parameter of the model and its values: NAME=START:STOP:N (N values, ends included), "
                         "NAME=V1,V2,... or NAME=V; repeat for a grid")
    p4.add_argument("--folds", type=_nonneg_int, default=0,
                    help="cross-validation folds (default 0: leave-one-out), for the alert level of each "
                         "setting and for the nested choice of setting and level")
    p4.add_argument("--downscale", type=float, default=1.0,
                    help="resize every frame by this factor in (0, 1] (default 1: native size)")
    p4.add_argument("--no-html", action="store_true", help="do not write report.html")
    _add_dataset_options(p4, rain_default="off", one_model=True)
    p5 = sub.add_parser("tune", help="ONE model's parameters searched by Optuna (TPE, seeded) inside nested "
                                     "cross-validation: out-of-sample accuracy and what each fold chose")
    p5.add_argument("folder", metavar="DIR", help="folder of videos and/or event recordings with labels.csv")
    add_output_option(p5, default="cdnf_experiments/tune")
    p5.add_argument("--param", action="append", default=[], metavar="NAME=SPEC",
                    help="a parameter and its search space: NAME=LO:HI (uniform), NAME=LO:HI:log or NAME=V1,V2,... "
                         "(a choice); repeat for several")
    p5.add_argument("--trials", type=_nonneg_int, default=20, help="Optuna trials per outer fold (default 20)")
    p5.add_argument("--folds", type=_nonneg_int, default=0,
                    help="outer (and inner) cross-validation folds (default 0: leave-one-out)")
    p5.add_argument("--downscale", type=float, default=1.0,
                    help="resize every frame by this factor in (0, 1] (default 1: native size)")
    _add_dataset_options(p5, rain_default="off", one_model=True)
    args = ap.parse_args(list(argv))
    if args.which == "tune":
        return _tune(args)

    if args.which in ("sweep", "selectivity"):
        check_model_options(args)
        if args.which == "selectivity":  # checked before the output folder is made
            args.model_params = params_from_args(args, parse_models(args.models))
        with output_lock(prepare_output(args.out)):
            return _param_sweep(args) if args.which == "sweep" else _selectivity(args)
    if args.which == "table2":
        folder = Path(args.folder) if args.folder else builtin.default_real_folder()
        if folder is None:
            raise InputError("table2", "no labelled folder given and the development clips were not found; "
                                       "pass one: python -m cdnf_ti.run experiment table2 DIR")
        return _dataset(args, folder, Path(args.out))
    if args.size < 16:
        raise UserError(f"--size must be at least 16 px, got {args.size}")
    check_frame_size(args.size, args.size, n_models=1, what="--size")
    models = parse_models(args.models)
    check_model_options(args)
    args.model_params = params_from_args(args, models)
    out = prepare_output(args.out)  # before any work
    with output_lock(out):
        return _stimulus_experiment(args, models, builtin)


def _stimulus_experiment(args, models, builtin) -> int:
    kw = dict(size=args.size, seed=stimulus_seed_of(args), params=args.model_params, workers=args.workers,
              scheduler=args.scheduler, backend=args.backend, arch=args.arch, progress=not args.no_progress,
              figures=not args.no_figures)
    if args.which == "table1":
        res = builtin.table1(models, args.out, **kw)
        print(builtin.format_table1(res))
        errs = [r for d in res.values() for r in d.values() if r.get("error")]
        for r in errs:
            print(f"error: {r['stimulus']} [{r['model']}]: {r['error']}", file=sys.stderr)
        failed = bool(errs)
    else:
        try:
            coh = [float(c) for c in args.coherences.split(",") if c.strip()]
        except ValueError:
            raise UserError(f"--coherences must be numbers, got {args.coherences!r}") from None
        if not coh:
            raise UserError("--coherences is empty")
        bad_c = [c for c in coh if not (0.0 < c <= 1.0)]
        if bad_c:
            raise UserError(f"--coherences: coherence must be in (0, 1], got {bad_c[0]:g}")
        stimuli = [s.strip() for s in args.stimuli.split(",")] if args.stimuli else None
        if stimuli:
            bad = [s for s in stimuli if s not in BASIC_STIMULI]
            if bad:
                raise UserError(f"unknown stimulus {bad[0]!r}; choose from {', '.join(BASIC_STIMULI)}")
        table = builtin.coherence_sweep(models, args.out, coherences=coh, stimuli=stimuli, scatter=args.scatter, **kw)
        print(builtin.coherence_markdown(table, coh, args.size, args.scatter))
        errs = [r for t in table.values() for d in t.values() for r in d.values() if r.get("error")]
        for r in errs:
            print(f"error: {r['stimulus']} c={r['coherence']:g} [{r['model']}]: {r['error']}", file=sys.stderr)
        failed = bool(errs)
    print(f"results in {args.out}/", file=sys.stderr)
    return EXIT_FAILED if failed else EXIT_OK
