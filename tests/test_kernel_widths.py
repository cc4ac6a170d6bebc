"""The engine's kernels are narrow (every module of kernels/): few parameters, small contexts, read by name.

What a kernel receives at run time, tuple members counted, is measured by ``tests/kernel_widths.py``;
these tests read the source, so they need no compiler.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

KERNELS = Path(__file__).resolve().parent.parent / "kernels"
MODULES = sorted(p.name for p in KERNELS.glob("*.py") if p.name != "__init__.py")
MAX_PARAMETERS = 12
MAX_CONTEXT_MEMBERS = 8


def _tree(module: str) -> ast.Module:
    return ast.parse((KERNELS / module).read_text(encoding="utf-8"))


def _is_dsl_function(fn: ast.FunctionDef) -> bool:
    """Decorated with ``@ti.func`` or ``@ti.kernel``."""
    return any(isinstance(d, ast.Attribute) and d.attr in ("func", "kernel") for d in fn.decorator_list)


@pytest.mark.parametrize("module", MODULES)
def test_no_kernel_or_func_declares_more_than_twelve_parameters(module):
    functions = [n for n in ast.walk(_tree(module)) if isinstance(n, ast.FunctionDef) and _is_dsl_function(n)]
    wide = {fn.name: len(fn.args.args) for fn in functions if len(fn.args.args) > MAX_PARAMETERS}
    assert functions and not wide, wide


def test_every_context_has_at_most_eight_members():
    contexts = {}
    for node in (n for module in MODULES for n in ast.walk(_tree(module))):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "context":
            name, fields = (a.value for a in node.args[:2])
            contexts[name] = fields.split()
    wide = {k: len(v) for k, v in contexts.items() if len(v) > MAX_CONTEXT_MEMBERS}
    # the contexts left are those of the kernels not on the engine (C-DNF's, the shared DoG's); engine stages have none
    assert contexts and not wide, wide


@pytest.mark.parametrize("module", MODULES)
def test_contexts_are_read_by_name_not_by_position(module):
    by_position = [ast.unparse(n) for n in ast.walk(_tree(module)) if isinstance(n, ast.Subscript)
                   and isinstance(n.value, ast.Name) and n.value.id == "ctx"]
    assert not by_position, by_position


def test_a_stage_and_a_helper_taking_its_cell_and_two_more_fit_twelve_members():
    # a stage is stage(a): the cell's slots are its members (its layout is its class's); a stage's helper
    # takes the cell and at most two more arguments (kernels/olgmd.py's channel(a, e))
    cell = next(n for n in ast.walk(_tree("engine.py")) if isinstance(n, ast.ClassDef) and n.name == "Cell")
    slots = next(ast.literal_eval(a.value) for a in cell.body if isinstance(a, ast.Assign)
                 and isinstance(a.targets[0], ast.Name) and a.targets[0].id == "__slots__")
    assert {"i", "j", "x"} <= set(slots) and len(slots) + 2 <= MAX_PARAMETERS, slots


def test_a_row_run_body_and_its_runner_fit_twelve_parameters_with_the_widest_context():
    # frame_runs(body, ctx, k, blocks, reduce, halo) and body(ctx, i, j, n): 5 and 3 besides the context
    # (the models not yet on the engine's cells)
    sizes = []
    for module in MODULES:
        for node in ast.walk(_tree(module)):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "context" \
                    and any(k.arg == "grid" for k in node.keywords):
                sizes.append(len(node.args[1].value.split()))
    assert 5 + max(sizes, default=0) <= MAX_PARAMETERS, sizes
