"""The engine's structure (kernels/): one scheduler, stages bound per model, equations written once."""
from __future__ import annotations

import ast
import warnings
from pathlib import Path

import numpy as np

from cdnf_ti import create_model

ROOT = Path(__file__).resolve().parent.parent
KERNELS = sorted((ROOT / "kernels").glob("*.py"))

#: The persistent workers' primitives: only the scheduler may use them.
PRIMITIVES = {"claim_rows", "finish_rows", "wait_phase", "gate", "converged", "reset_sync", "worker_start"}


def _functions(path: Path):
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.FunctionDef):
            yield node


def _uses(fn: ast.FunctionDef) -> set[str]:
    called = {n.func.id for n in ast.walk(fn) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
    names = {n.id for n in ast.walk(fn) if isinstance(n, ast.Name)}
    return (called & PRIMITIVES) | ({"WORKER_STRIDE"} & names)


def test_only_the_scheduler_runs_workers_claims_rows_and_waits_on_phases():
    users = [(p.name, fn.name) for p in KERNELS for fn in _functions(p)
             if fn.name not in PRIMITIVES | {"build", "workers"} and _uses(fn)]  # factories
    assert users and len(users) <= 2 and all(f == "schedule.py" for f, _ in users), users


def _workers_built(path: Path) -> set[str]:
    """Names bound to ``workers(plan)`` in a kernel module: the scheduler bound to a model's plan."""
    return {t.id for n in ast.walk(ast.parse(path.read_text(encoding="utf-8"))) if isinstance(n, ast.Assign)
            and isinstance(n.value, ast.Call) and isinstance(n.value.func, ast.Name) and n.value.func.id == "workers"
            for t in n.targets if isinstance(t, ast.Name)}


def test_every_lane_solve_is_one_scheduler_call_with_its_models_plan():
    # the kernels that run persistent workers call the workers of a plan bound when the kernels were built, once
    calls = {}
    for p in KERNELS:
        bound = _workers_built(p)
        for fn in _functions(p):
            n = sum(isinstance(c, ast.Call) and isinstance(c.func, ast.Name) and c.func.id in bound
                    for c in ast.walk(fn))
            factories = ("build", "kernel")  # around a kernel
            if n and fn.name not in factories:
                calls[fn.name] = n
    assert set(calls) == {"run_lanes"}  # the engine's launch: every model's launches and solves
    assert set(calls.values()) == {1}


def _widths() -> dict[str, int]:
    """The widest call of every kernel and ti.func under kernels/, tuple members counted (tests/kernel_widths.py)."""
    import json
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "kernel_widths.py")], capture_output=True, text=True,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout[proc.stdout.index("{"):])


def test_no_kernel_or_func_is_called_with_more_than_twelve_parameters_counting_tuple_members():
    widths = _widths()
    # the count covers the lane solves and the generic kernels of every model (not a vacuous pass)
    assert {"cdnf.py:contrast", "cdnf.py:summation", "engine.py:_settle", "lgmd.py:update",
            "lgmd.py:summation", "sdnf.py:field", "engine.py:run_lanes", "engine.py:run_pixels",
            "olgmd.py:photoreceptors", "olgmd.py:summation",
            "lplc2.py:arms"} <= set(widths)
    assert {k: v for k, v in widths.items() if v > 12} == {}


def test_a_pixel_layout_launch_keeps_the_compilers_template_cache():
    # a string template argument made quadrants warn "cannot create weak reference to 'str' object. Template
    # mapper caching disabled" at every launch; the launch's part is an int
    model = create_model("olgmd")
    model.fast = False
    frames = np.random.default_rng(0).integers(0, 256, (3, 24, 40), dtype=np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.run(frames)
