"""``python -m cdnf_ti.run bench``: throughput table of every model, both compilers and the C-DNF peers.

For each input (basic stimulus and real footage, at 426x240 and 600x600) it runs
every registered model (Taichi-DSL kernels) under each installed kernel compiler
(``quadrants``, ``taichi``; a process runs one, so the others run in a child
process of the same command), C-DNF also with the paper's plain scheme, and the
peer implementations of :mod:`cdnf_ti.bench.peers` (plain scheme), and prints:
model, compiler, scheme, input, resolution, frames/s, the ratio to each peer,
ms per field-iteration, and the largest ``|output - output_ref|`` against the
float64 NumPy reference of the same model on the same frames.

Frames are decoded before timing; frames/s counts the model's ``step`` only
(frame 0, which needs no solve, is excluded). Each measurement is repeated and
the median reported, since the machine may be shared; "best frames/s" takes each
frame's fastest step over the repeats and sums those, which filters out what
other work on the machine added (on a shared 2-core VM the median of identical
runs moved by up to 30 %, the best by a few %).
"""
from __future__ import annotations

import argparse
import gc
import statistics
import sys
import time
import warnings
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..models.base import NotConvergedWarning

RESOLUTIONS = ((240, 426), (600, 600))


@dataclass
class BenchRow:
    """One line of the table."""

    model: str
    input: str
    resolution: str
    fps: float
    ratios: dict[str, float] = field(default_factory=dict)
    max_diff: float = float("nan")
    iterations: str = ""
    compiler: str = ""
    scheme: str = ""
    arch: str = "cpu"  # the Taichi backend the row ran on (peers: always the CPU)
    ms_per_iteration: float = float("nan")  # ms per field-iteration (C-DNF: ON, OFF, Summation counted apart)
    best_fps: float = float("nan")  # from each frame's fastest step over the repeats


@dataclass
class Timing:
    """What :func:`time_model` measured."""

    fps: float  #: median over the repeats of frames/s
    best_fps: float  #: frames/s from each frame's fastest step over the repeats
    outputs: np.ndarray  #: the model's output per frame (last repeat), shape (len(frames),)
    diagnostics: dict  #: str -> ndarray of the per-frame diagnostics (frame 0 excluded)


def time_model(make: Callable[[], object], frames: Sequence[np.ndarray], repeats: int = 3) -> Timing:
    """Frames/s of ``make()`` stepping over ``frames`` (frame 0 excluded), each step timed.

    A first untimed pass over three frames compiles the kernels. Every repeat starts
    from a reset model, so the repeats step through the same states, and after a garbage
    collection, so that none falls due inside it.
    """
    model = make()
    for f in frames[:3]:
        model.step(f)
    n = len(frames) - 1
    seconds = np.zeros((max(1, repeats), n))  # per repeat and frame
    outs: list[float] = []
    diags: list[dict] = []
    for rep in range(max(1, repeats)):
        model.reset()
        outs, diags = [], []
        gc.collect()  # a full collection due mid-repeat would be timed as the model's (100 ms with a compiler loaded)
        r = model.step(frames[0])
        outs.append(r.output)
        diags.append(r.diagnostics)
        for t, f in enumerate(frames[1:]):
            t0 = time.perf_counter()
            r = model.step(f)
            seconds[rep, t] = time.perf_counter() - t0
            outs.append(r.output)
            diags.append(r.diagnostics)
    rates = [n / total if total > 0 else float("inf") for total in seconds.sum(axis=1)]
    best = float(seconds.min(axis=0).sum())
    keys = diags[-1].keys() if diags else []
    d = {k: np.array([x.get(k, np.nan) for x in diags[1:]], dtype=float) for k in keys}
    return Timing(statistics.median(rates), n / best if best > 0 else float("inf"), np.array(outs, dtype=float), d)


def reference_outputs(model_name: str, frames: Sequence[np.ndarray]) -> np.ndarray | None:
    """Outputs of the model's float64 NumPy backend on ``frames`` (None if it has none)."""
    from ..models import create_model

    try:
        m = create_model(model_name, backend="numpy")
    except (ValueError, TypeError):
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotConvergedWarning)  # recorded per frame in "converged"
        return np.array([m.step(f).output for f in frames], dtype=float)


def bench_inputs(n_frames: int, clip: str | None = None,
                 resolutions: Sequence[tuple[int, int]] = RESOLUTIONS) -> list[tuple[str, str, list[np.ndarray]]]:
    """``(input label, resolution label, frames)`` for every benchmark input.

    ``resolutions`` are ``(H, W)`` pairs; real footage is resized to each.
    """
    import cv2

    from .inputs import basic_frames, real_or_standin

    label, real = real_or_standin(n_frames, clip, start=60)
    out = []
    for h, w in resolutions:
        basic = basic_frames("dark_looming", n_frames, height=h, width=w)
        out.append(("basic:dark_looming", f"{w}x{h}", basic))
        rf = real if real[0].shape == (h, w) else [cv2.resize(f, (w, h), interpolation=cv2.INTER_AREA) for f in real]
        out.append((label, f"{w}x{h}", rf))
    return out


class Progress:
    """Progress of the bench on stderr: a tqdm bar in a terminal, one line per finished run in a log.

    ``update(what)`` counts one finished measurement (``what`` names it and its result).
    """

    def __init__(self, total: int, enabled: bool = True) -> None:
        from tqdm import tqdm

        self.total, self.done, self.enabled = total, 0, enabled
        self.tty = enabled and sys.stderr.isatty()
        self.bar = tqdm(total=total, desc="bench", unit="run", leave=False, file=sys.stderr) if self.tty else None

    def update(self, n: int = 1, what: str = "") -> None:
        self.done += n
        if self.bar is not None:
            self.bar.set_postfix_str(what[:60], refresh=False)
            self.bar.update(n)
        elif self.enabled:
            print(f"bench [{self.done}/{self.total}] {what}", file=sys.stderr, flush=True)

    def set_description(self, text: str) -> None:
        if self.bar is not None:
            self.bar.set_description(text)
        elif self.enabled:
            print(text, file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


#: What the bench's stand-in input is (printed when it is used).
STANDIN_NOTE = ("input 'standin' is a generated dashcam-like clip (made at 426x240, resized to each size): a textured "
                "scene drifting and zooming "
                "(every pixel changes, as under camera motion) with a dark box looming in the middle; it stands in "
                "for real footage because no --clip was given and the sample dashcam clip is not present here. "
                "Pass --clip VIDEO to measure on your own footage")


def _iteration_stats(row: BenchRow, diag: dict) -> None:
    if "iterations_on" in diag:
        its = [float(np.mean(diag[k])) for k in ("iterations_on", "iterations_off", "iterations_sum")]
        row.iterations = "/".join(f"{x:.1f}" for x in its)
        if sum(its) > 0 and row.fps > 0:
            row.ms_per_iteration = 1000.0 / row.fps / sum(its)


def model_rows(models: Sequence[str], inputs, repeats: int, reference: bool, bar=None,
               arch: str = "cpu") -> list[BenchRow]:
    """Rows of every model under this process's compiler on ``arch`` (C-DNF with both schemes)."""
    from ..models import create_model
    from ..params import CDNFParams
    from ..taichi_runtime import current_compiler, ensure_taichi

    arch = ensure_taichi(arch)
    comp = current_compiler() or ""
    rows = []
    for in_label, res, frames in inputs:
        for name in models:
            variants = [("chebyshev", CDNFParams()), ("plain", CDNFParams(scheme="plain"))] if name == "cdnf" \
                else [("", None)]
            ref = reference_outputs(name, frames) if reference else None
            for scheme, params in variants:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", NotConvergedWarning)  # recorded per frame in "converged"
                    tm = time_model(lambda: create_model(name, params, backend="taichi", arch=arch), frames, repeats)
                if bar is not None:
                    bar.update(1, f"{name}{' ' + scheme if scheme else ''} ({comp}) {in_label} {res}: "
                                  f"{tm.fps:.1f} frames/s")
                row = BenchRow(name, in_label, res, tm.fps, compiler=comp, scheme=scheme, arch=arch,
                               max_diff=float(np.abs(tm.outputs - ref).max()) if ref is not None else float("nan"),
                               best_fps=tm.best_fps)
                _iteration_stats(row, tm.diagnostics)
                rows.append(row)
    return rows


def _child_rows(compiler: str, models: Sequence[str], n_frames: int, repeats: int, clip: str | None,
                reference: bool, resolutions, arch: str = "cpu", progress: bool = True) -> list[BenchRow]:
    """:func:`model_rows` under another compiler, in a child process (one compiler per process)."""
    import json
    import os
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "rows.json")
        cmd = [sys.executable, "-m", "cdnf_ti.run", "bench", "--compiler", compiler, "--models-only", out,
               "--model", ",".join(models), "--frames", str(n_frames), "--repeats", str(repeats),
               "--sizes", ",".join(f"{w}x{h}" for h, w in resolutions), "--arch", arch]
        if clip is not None:
            cmd += ["--clip", str(clip)]
        if not reference:
            cmd.append("--no-reference")
        if not progress:
            cmd.append("--no-progress")
        env = dict(os.environ, CDNF_TI_COMPILER=compiler)
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        lines = []
        for line in proc.stderr:  # the child's progress lines, passed on as they come
            lines.append(line.rstrip("\n"))
            if progress and line.startswith("bench ["):
                print(line.rstrip(), file=sys.stderr, flush=True)
        proc.wait()
        if proc.returncode != 0 or not os.path.exists(out):
            msg = ([ln for ln in lines if ln.strip()] or ["no output"])[-1]
            warnings.warn(f"bench under {compiler} failed: {msg}", RuntimeWarning, stacklevel=2)
            return []
        with open(out) as f:
            return [BenchRow(**r) for r in json.load(f)]


def run_bench(models: Sequence[str], n_frames: int = 30, repeats: int = 3, clip: str | None = None,
              reference: bool = True, progress: bool = True,
              resolutions: Sequence[tuple[int, int]] = RESOLUTIONS,
              compilers: Sequence[str] | None = None, arch: str = "cpu") -> list[BenchRow]:
    """Measure every model under every compiler, and the C-DNF peers; see the module docstring.

    ``compilers`` defaults to every installed one; this process's compiler runs here, the
    others in child processes. The models run on the Taichi backend ``arch`` (``"cuda"``:
    a GPU), the peers on the CPU. Ratios ``x peer`` divide a row's frames/s by the peer's
    (plain scheme) on the same input, all from this one run.
    """
    from ..taichi_runtime import current_compiler, ensure_taichi, installed_compilers
    from .peers import PeerCDNF, available_peers

    arch = ensure_taichi(arch)
    here = current_compiler()
    compilers = list(compilers) if compilers is not None else list(installed_compilers())
    peers = list(available_peers())
    inputs = bench_inputs(n_frames, clip, resolutions)
    n_runs = sum(2 if m == "cdnf" else 1 for m in models)
    per_input = n_runs * sum(1 for c in compilers if c == here) + (len(peers) if "cdnf" in models else 0)
    bar = Progress(len(inputs) * per_input, enabled=progress)
    rows: list[BenchRow] = []
    if here in compilers:
        rows += model_rows(models, inputs, repeats, reference, bar, arch)
    for comp in compilers:
        if comp != here:
            bar.set_description(f"bench: {len(inputs) * n_runs} runs under {comp} in a child process "
                                f"(one compiler per process)")
            t0 = time.perf_counter()
            child = _child_rows(comp, models, n_frames, repeats, clip, reference, resolutions, arch, progress)
            bar.set_description(f"bench: {comp} done, {len(child)} rows in {time.perf_counter() - t0:.0f} s")
            rows += child
    peer_rows = []
    if "cdnf" in models:
        for in_label, res, frames in inputs:
            ref = reference_outputs("cdnf", frames) if reference else None
            for peer in peers:
                tm = time_model(lambda: PeerCDNF(peer), frames, repeats)
                bar.update(1, f"cdnf[{peer}] {in_label} {res}: {tm.fps:.1f} frames/s")
                prow = BenchRow(f"cdnf[{peer}]", in_label, res, tm.fps, scheme="plain", best_fps=tm.best_fps,
                                max_diff=float(np.abs(tm.outputs - ref).max()) if ref is not None else float("nan"))
                _iteration_stats(prow, tm.diagnostics)
                peer_rows.append(prow)
    bar.close()
    for row in rows:
        if row.model == "cdnf":
            for prow in peer_rows:
                if (prow.input, prow.resolution) == (row.input, row.resolution):
                    row.ratios[prow.model[5:-1]] = row.fps / prow.fps
    order = {(lab, res): k for k, (lab, res, _) in enumerate(inputs)}
    allrows = rows + peer_rows
    allrows.sort(key=lambda r: (order.get((r.input, r.resolution), 0), r.model.startswith("cdnf[") ,
                                r.model != "cdnf", r.model, r.compiler, r.scheme))
    return allrows


def format_table(rows: Sequence[BenchRow]) -> str:
    """Plain-text table (also valid Markdown)."""
    peers = sorted({p for r in rows for p in r.ratios})
    head = ["model", "compiler", "scheme", "input", "resolution", "frames/s", "best frames/s",
            *[f"x {p}" for p in peers], "ms/field-iter", "max |dI| vs f64 ref", "iters on/off/sum"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for r in rows:
        comp = r.compiler if r.arch == "cpu" else f"{r.compiler} ({r.arch})"
        cells = [r.model, comp, r.scheme, r.input, r.resolution, f"{r.fps:.1f}",
                 "" if np.isnan(r.best_fps) else f"{r.best_fps:.1f}"]
        cells += [f"{r.ratios[p]:.2f}" if p in r.ratios else "" for p in peers]
        cells += ["" if np.isnan(r.ms_per_iteration) else f"{r.ms_per_iteration:.3f}"]
        cells += ["n/a" if np.isnan(r.max_diff) else f"{r.max_diff:.1e}", r.iterations]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m cdnf_ti.run bench``."""
    from ..cli_common import ArgumentParser
    from ..errors import UserError
    from ..limits import check_frame_size
    from ..run import parse_models
    from ..taichi_runtime import ARCHS, COMPILERS, check_arch, ensure_taichi, installed_compilers, select_compiler

    ap = ArgumentParser(prog="python -m cdnf_ti.run bench",
                        description="Throughput table: every model, C-DNF against its peers "
                                    "(SciPy, OpenCV+NumPy, PyTorch if installed), same run.")
    ap.add_argument("--quick", action="store_true", help="few frames, one repeat, C-DNF only (under a minute)")
    ap.add_argument("--frames", type=int, default=None, help="frames per input (default 30; 6 with --quick)")
    ap.add_argument("--repeats", type=int, default=None, help="timed repeats, median reported (default 3)")
    ap.add_argument("--model", "--models", dest="models", default=None,
                    help="model name(s), comma separated, or 'all' (default: all; cdnf with --quick)")
    ap.add_argument("--clip", default=None,
                    help="real video to use (default: the development clip serial_vehicle_collision if present, "
                         "else a generated stand-in that the output describes)")
    ap.add_argument("--sizes", default=None,
                    help="comma-separated WxH list (default: 426x240,600x600)")
    ap.add_argument("--no-reference", action="store_true", help="skip the float64 reference comparison")
    ap.add_argument("--compiler", default=None,
                    help="comma-separated kernel compilers to measure (default: every installed one)")
    ap.add_argument("--arch", default="cpu", choices=ARCHS,
                    help="Taichi backend of the models (default: cpu; the peers always run on the CPU)")
    ap.add_argument("--models-only", default=None, metavar="JSON", help=argparse.SUPPRESS)  # child process mode
    ap.add_argument("--startup", action="store_true",
                    help="also measure start-up (process start to the first frame) with a cold and a warm cache")
    ap.add_argument("--simd", action="store_true",
                    help="also report how wide the vector code is that each compiler makes of C-DNF's update loops")
    ap.add_argument("--no-progress", action="store_true", help="hide progress (a bar, or one line per run in a log)")
    args = ap.parse_args(argv)
    n = args.frames if args.frames is not None else (6 if args.quick else 30)
    if n < 3:
        raise UserError(f"--frames must be >= 3, got {n}")
    repeats = args.repeats if args.repeats is not None else (1 if args.quick else 3)
    if repeats < 1:
        raise UserError(f"--repeats must be >= 1, got {repeats}")
    resolutions = RESOLUTIONS
    if args.sizes is not None:
        try:
            resolutions = tuple((int(h), int(w)) for w, h in (s.lower().split("x") for s in args.sizes.split(",")))
        except ValueError:
            raise UserError(f"--sizes must look like 426x240,600x600; got {args.sizes!r}") from None
        if any(h < 8 or w < 8 for h, w in resolutions):
            raise UserError(f"--sizes: frames must be at least 8x8, got {args.sizes!r}")
        for h, w in resolutions:  # one line now, not an out-of-memory kill later
            check_frame_size(h, w, what=f"--sizes {w}x{h}")
    if args.clip is not None:
        from ..frames import open_source

        open_source(args.clip)  # raises InputError with a one-line message

    compilers = list(installed_compilers())
    if args.compiler is not None:
        compilers = [c.strip().lower() for c in args.compiler.split(",") if c.strip()]
        for c in compilers:
            if c not in COMPILERS:
                raise UserError(f"--compiler: unknown compiler {c!r}; choose from {', '.join(COMPILERS)}")
        if not compilers:
            raise UserError(f"--compiler names no compiler: got {args.compiler!r}")
        if args.models_only or len(compilers) == 1:
            select_compiler(compilers[0])
    if args.arch != "cpu":
        check_arch(args.arch)  # one line, exit 2, where there is no such device
    ensure_taichi(args.arch)
    models = parse_models(args.models or ("cdnf" if args.quick else "all"))
    if args.models_only:
        import json
        from dataclasses import asdict

        inputs = bench_inputs(n, args.clip, resolutions)
        n_runs = sum(2 if m == "cdnf" else 1 for m in models)
        bar = Progress(len(inputs) * n_runs, enabled=not args.no_progress)
        rows = model_rows(models, inputs, repeats, not args.no_reference, bar, arch=args.arch)
        bar.close()
        with open(args.models_only, "w") as f:
            json.dump([asdict(r) for r in rows], f)
        return 0
    rows = run_bench(models, n, repeats, args.clip, reference=not args.no_reference, resolutions=resolutions,
                     compilers=compilers, arch=args.arch, progress=not args.no_progress)
    print(format_table(rows))
    if any(r.input == "standin" for r in rows):
        print(f"\nNote: {STANDIN_NOTE}.")
    if args.startup:
        print()
        print(format_startup(measure_startup(compilers)))
    if args.simd:
        from .simd import format_simd, measure_simd

        print()
        print(format_simd(measure_simd(compilers, progress=True)))
    return 0


@dataclass
class StartupRow:
    """Start-up of one compiler with one state of its compile cache."""

    compiler: str
    cache: str  # "cold" (empty compile cache) or "warm" (the cache the cold run filled)
    seconds: float  # fresh ``python`` to C-DNF's first solved frame; nan if the child failed
    torch_imported: bool | None  # whether the compiler imported PyTorch on the way (None: failed)


#: What the child process of :func:`measure_startup` runs (``{size}``: the frame shape).
STARTUP_CODE = ("import time; t0 = time.perf_counter(); import sys; import numpy as np; from cdnf_ti import CDNF; "
                "m = CDNF(); f = np.zeros({size}, np.float32); m.step(f); m.step(f + 0.5); "
                "print(time.perf_counter() - t0, 'torch' in sys.modules)")


def measure_startup(compilers: Sequence[str], size: tuple[int, int] = (240, 426)) -> list[StartupRow]:
    """Seconds from a fresh ``python`` to C-DNF's first solved frame, per compiler, cold and warm cache.

    "cold" runs with an empty compile cache (a fresh ``$CDNF_TI_CACHE_DIR`` folder),
    "warm" runs again with the cache that run filled. Each row also says whether PyTorch
    was imported: quadrants imports it whenever it is installed (about 2 s of its start-up
    here; cdnf_ti itself never imports it).

    Parameters
    ----------
    compilers : sequence of {"taichi", "quadrants"}
    size : (height, width)
        Frame shape in pixels.
    """
    import os
    import subprocess
    import tempfile

    code = STARTUP_CODE.format(size=tuple(size))
    out = []
    for comp in compilers:
        with tempfile.TemporaryDirectory() as cache:
            env = dict(os.environ, CDNF_TI_COMPILER=comp, CDNF_TI_CACHE_DIR=cache)
            for label in ("cold", "warm"):
                t0 = time.perf_counter()
                proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
                wall = time.perf_counter() - t0
                words = proc.stdout.split()
                if proc.returncode != 0 or not words:
                    out.append(StartupRow(comp, label, float("nan"), None))
                else:
                    out.append(StartupRow(comp, label, wall, words[-1] == "True"))
    return out


def format_startup(rows: Sequence[StartupRow]) -> str:
    """The start-up rows as a Markdown table."""
    def torch(r: StartupRow) -> str:
        return "failed" if r.torch_imported is None else ("yes" if r.torch_imported else "no")

    lines = ["| compiler | cache | start-up to first frame (s) | PyTorch imported |", "|---|---|---|---|"]
    lines += [f"| {r.compiler} | {r.cache} | {r.seconds:.2f} | {torch(r)} |" for r in rows]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
