"""Built-in demo: every model on the six basic stimuli, printed next to the paper's Table I."""
from __future__ import annotations

import math
import sys
import time
import warnings
from typing import Sequence

from .cli_common import (
    ArgumentParser,
    add_model_options,
    add_param_options,
    check_model_options,
    params_from_args,
    parse_models,
)
from .limits import check_frame_size
from .models import create_model
from .models.base import NotConvergedWarning
from .paper import TABLE1
from .stimuli.basic import BASIC_STIMULI, PAPER_LABELS, basic_stimulus


def selectivity_table(models: Sequence[str], size: int = 600, backend: str = "taichi", arch: str = "cpu",
                      progress: bool = True, params: dict | None = None) -> dict[str, dict[str, dict]]:
    """Run each model on the six basic stimuli (``params``: ``{model: parameter object or None}``).

    Returns
    -------
    dict
        ``result[model][stimulus] = {"alert": 0/1, "first_alert": int|None,
        "max_output": float, "frames": int, "fps": float}``.
    """
    result: dict[str, dict[str, dict]] = {}
    for name in models:
        result[name] = {}
        for stim in BASIC_STIMULI:
            s = basic_stimulus(stim, height=size, width=size)
            model = create_model(name, (params or {}).get(name), backend=backend, arch=arch, fps=s.fps)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", NotConvergedWarning)  # recorded in "converged"
                tr = model.run(s.frames(), progress=f"{name} {stim}" if progress else False, total=s.n_frames)
            result[name][stim] = {
                "alert": int(tr.first_alert is not None),
                "first_alert": tr.first_alert,
                "max_output": float(tr.output.max()),
                "frames": tr.n_frames,
                "fps": tr.fps,
                "converged": bool(tr.converged.all()),
            }
    return result


def format_table1(result: dict[str, dict[str, dict]]) -> str:
    """Markdown table: each model's alert (paper's value in brackets)."""
    models = list(result)
    head = "| Stimulus | " + " | ".join(f"{m} (paper)" for m in models) + " |"
    sep = "|---|" + "---|" * len(models)
    lines = [head, sep]
    for stim in BASIC_STIMULI:
        cells = []
        for m in models:
            got = (result[m].get(stim) or {}).get("alert")
            if got is None:  # the run failed (its error is reported separately)
                cells.append("error")
                continue
            paper = TABLE1.get(m, {}).get(stim)
            mark = "" if paper is None else (f" ({paper})" if paper == got else f" ({paper}) differs")
            cells.append(f"{got}{mark}")
        lines.append(f"| {PAPER_LABELS[stim]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: Sequence[str] = ()) -> int:
    ap = ArgumentParser(prog="python -m cdnf_ti.run demo",
                        description="Basic selectivity (paper Table I) on the six basic stimuli.")
    add_model_options(ap, default_models="cdnf")
    add_param_options(ap)
    ap.add_argument("--size", type=int, default=600, help="frame size in px (default: %(default)s, as the paper)")
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
        fps = [r["fps"] for r in res[m].values()]
        fps = [f for f in fps if math.isfinite(f)]
        rate = f"{sum(fps) / len(fps):.1f} frames/s on average" if fps else "frame rate n/a"
        print(f"{m}: {rate}; max output per stimulus: "
              + ", ".join(f"{k}={v['max_output']:.4f}" for k, v in res[m].items()))
    print(f"done in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return 0
