"""``python -m cdnf_ti.run bench``: throughput table of every model and the C-DNF peers.

For each input (basic stimulus and real footage, at 426x240 and 600x600) it runs
every registered model (Taichi backend) and, for C-DNF, the peer
implementations of :mod:`cdnf_ti.bench.peers` in the same process, and prints:
model, input, resolution, frames/s, the ratio to each peer, and the largest
``|output - output_ref|`` against the float64 NumPy reference of the same model
on the same frames.

Frames are decoded before timing; frames/s counts the model's ``step`` only
(frame 0, which needs no solve, is excluded). Each measurement is repeated and
the median reported, since the machine may be shared.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

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


def time_model(make: Callable[[], object], frames: Sequence[np.ndarray], repeats: int = 3) -> tuple[float, np.ndarray, dict]:
    """Median frames/s of ``make()`` stepping over ``frames`` (frame 0 excluded).

    A first untimed pass over three frames compiles the kernels.

    Returns
    -------
    fps : float
    outputs : ndarray, shape (len(frames),)
        The model's output per frame (last repeat).
    diagnostics : dict of str to ndarray
    """
    model = make()
    for f in frames[:3]:
        model.step(f)
    rates = []
    outs: list[float] = []
    diags: list[dict] = []
    for _ in range(max(1, repeats)):
        model.reset()
        outs, diags = [], []
        r = model.step(frames[0])
        outs.append(r.output)
        diags.append(r.diagnostics)
        t0 = time.perf_counter()
        for f in frames[1:]:
            r = model.step(f)
            outs.append(r.output)
            diags.append(r.diagnostics)
        dt = time.perf_counter() - t0
        rates.append((len(frames) - 1) / dt if dt > 0 else float("inf"))
    keys = diags[-1].keys() if diags else []
    d = {k: np.array([x.get(k, np.nan) for x in diags[1:]], dtype=float) for k in keys}
    return statistics.median(rates), np.array(outs, dtype=float), d


def reference_outputs(model_name: str, frames: Sequence[np.ndarray]) -> np.ndarray | None:
    """Outputs of the model's float64 NumPy backend on ``frames`` (None if it has none)."""
    from ..models import create_model

    try:
        m = create_model(model_name, backend="numpy")
    except (ValueError, TypeError):
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
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


def run_bench(models: Sequence[str], n_frames: int = 30, repeats: int = 3, clip: str | None = None,
              reference: bool = True, progress: bool = True,
              resolutions: Sequence[tuple[int, int]] = RESOLUTIONS) -> list[BenchRow]:
    """Measure every model (and the C-DNF peers) on every input; see the module docstring."""
    from tqdm import tqdm

    from ..models import create_model
    from .peers import PeerCDNF, available_peers

    peers = list(available_peers())
    inputs = bench_inputs(n_frames, clip, resolutions)
    rows: list[BenchRow] = []
    bar = tqdm(total=len(inputs) * (len(models) + (len(peers) if "cdnf" in models else 0)),
               desc="bench", unit="run", leave=False, disable=None if progress else True)
    for in_label, res, frames in inputs:
        for name in models:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fps, out, diag = time_model(lambda: create_model(name, backend="taichi"), frames, repeats)
            bar.update(1)
            ref = reference_outputs(name, frames) if reference else None
            row = BenchRow(name, in_label, res, fps,
                           max_diff=float(np.abs(out - ref).max()) if ref is not None else float("nan"))
            if "iterations_on" in diag:
                row.iterations = (f"{np.mean(diag['iterations_on']):.0f}/{np.mean(diag['iterations_off']):.0f}/"
                                  f"{np.mean(diag['iterations_sum']):.0f}")
            rows.append(row)
            if name == "cdnf":
                for peer in peers:
                    pfps, pout, _ = time_model(lambda: PeerCDNF(peer), frames, repeats)
                    bar.update(1)
                    row.ratios[peer] = fps / pfps
                    rows.append(BenchRow(f"cdnf[{peer}]", in_label, res, pfps,
                                         max_diff=float(np.abs(pout - ref).max()) if ref is not None else float("nan")))
    bar.close()
    return rows


def format_table(rows: Sequence[BenchRow]) -> str:
    """Plain-text table (also valid Markdown)."""
    peers = sorted({p for r in rows for p in r.ratios})
    head = ["model", "input", "resolution", "frames/s", *[f"x {p}" for p in peers], "max |dI| vs f64 ref",
            "iters on/off/sum"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for r in rows:
        cells = [r.model, r.input, r.resolution, f"{r.fps:.1f}"]
        cells += [f"{r.ratios[p]:.2f}" if p in r.ratios else "" for p in peers]
        cells += ["n/a" if np.isnan(r.max_diff) else f"{r.max_diff:.1e}", r.iterations]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m cdnf_ti.run bench``."""
    from ..run import parse_models
    from ..taichi_runtime import ensure_taichi

    ap = argparse.ArgumentParser(prog="python -m cdnf_ti.run bench",
                                 description="Throughput table: every model, C-DNF against its peers "
                                             "(SciPy, OpenCV+NumPy, PyTorch if installed), same run.")
    ap.add_argument("--quick", action="store_true", help="few frames, one repeat, C-DNF only (under a minute)")
    ap.add_argument("--frames", type=int, default=None, help="frames per input (default 30; 6 with --quick)")
    ap.add_argument("--repeats", type=int, default=None, help="timed repeats, median reported (default 3)")
    ap.add_argument("--model", "--models", dest="models", default=None,
                    help="model name(s), comma separated, or 'all' (default: all; cdnf with --quick)")
    ap.add_argument("--clip", default=None, help="real video to use (default: the shared c38/serial clip if present)")
    ap.add_argument("--sizes", default=None,
                    help="comma-separated WxH list (default: 426x240,600x600)")
    ap.add_argument("--no-reference", action="store_true", help="skip the float64 reference comparison")
    args = ap.parse_args(argv)
    n = args.frames if args.frames is not None else (6 if args.quick else 30)
    if n < 3:
        raise ValueError(f"--frames must be >= 3, got {n}")
    repeats = args.repeats if args.repeats is not None else (1 if args.quick else 3)
    if repeats < 1:
        raise ValueError(f"--repeats must be >= 1, got {repeats}")
    resolutions = RESOLUTIONS
    if args.sizes:
        try:
            resolutions = tuple((int(h), int(w)) for w, h in (s.lower().split("x") for s in args.sizes.split(",")))
        except ValueError:
            raise ValueError(f"--sizes must look like 426x240,600x600; got {args.sizes!r}") from None
        if any(h < 8 or w < 8 for h, w in resolutions):
            raise ValueError(f"--sizes: frames must be at least 8x8, got {args.sizes!r}")
    if args.clip is not None:
        from ..frames import open_source

        open_source(args.clip)  # raises InputError with a one-line message
    ensure_taichi("cpu")
    models = parse_models(args.models or ("cdnf" if args.quick else "all"))
    rows = run_bench(models, n, repeats, args.clip, reference=not args.no_reference, resolutions=resolutions)
    print(format_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
