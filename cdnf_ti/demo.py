"""Built-in demo: every model on the six basic stimuli, printed next to the paper's Table I.

The same runner and default size (600 x 600 px, as the paper) as ``experiment table1``
(:func:`cdnf_ti.experiments.builtin.table1_results`); the demo saves nothing.
"""
from __future__ import annotations

import math
import sys
import time
from typing import Sequence

from .cli_common import (
    ArgumentParser,
    add_model_options,
    add_param_options,
    check_model_options,
    params_from_args,
    parse_models,
)
from .experiments.builtin import TABLE1_SIZE, format_table1, table1_results
from .limits import check_frame_size

__all__ = ["format_table1", "main", "selectivity_table"]


def selectivity_table(models: Sequence[str], size: int = TABLE1_SIZE, backend: str = "taichi", arch: str = "cpu",
                      progress: bool = True, workers: int | None = None,
                      params: dict | None = None) -> dict[str, dict[str, dict]]:
    """Run each model on the six basic stimuli (:func:`cdnf_ti.experiments.builtin.table1_results`,
    the runner of ``experiment table1``; nothing is saved; ``params``: ``{model: parameter object
    or None}``).

    Returns
    -------
    dict
        ``result[model][stimulus] = {"alert": 0/1, "first_alert": int|None,
        "max_output": float, "frames": int, "fps": float (stimulus), "proc_fps": float (model
        throughput), ...}``.
    """
    return table1_results(models, size, None, workers=workers, backend=backend, arch=arch, progress=progress,
                          params=params)


def main(argv: Sequence[str] = ()) -> int:
    ap = ArgumentParser(prog="python -m cdnf_ti.run demo",
                        description="Basic selectivity (paper Table I) on the six basic stimuli.")
    add_model_options(ap, default_models="cdnf")
    add_param_options(ap)
    ap.add_argument("--size", type=int, default=TABLE1_SIZE,
                    help="frame size in px (default: %(default)s, as the paper and `experiment table1`)")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(list(argv))
    models = parse_models(args.models)
    check_frame_size(args.size, args.size, n_models=1, what="--size")
    check_model_options(args)
    params = params_from_args(args, models)
    t0 = time.perf_counter()
    print(f"cdnf_ti demo: basic selectivity on six {args.size}x{args.size} stimuli at 30 fps "
          f"(models: {', '.join(models)})", flush=True)
    res = selectivity_table(models, args.size, args.backend, args.arch, progress=not args.no_progress,
                            params=params)
    print(format_table1(res))
    for m in models:
        fps = [r["proc_fps"] for r in res[m].values() if r.get("proc_fps") is not None]
        fps = [f for f in fps if math.isfinite(f)]
        rate = f"{sum(fps) / len(fps):.1f} frames/s on average" if fps else "frame rate n/a"
        print(f"{m}: {rate}; max output per stimulus: "
              + ", ".join(f"{k}={v['max_output']:.4f}" for k, v in res[m].items() if not v.get("error")))
    errs = [(m, s, r["error"]) for m in models for s, r in res[m].items() if r.get("error")]
    for m, s, e in errs:
        print(f"error: {s} [{m}]: {e}", file=sys.stderr)
    print(f"done in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return 1 if errs else 0
