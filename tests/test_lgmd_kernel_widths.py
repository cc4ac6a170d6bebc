"""The LGMD family's kernels are narrow (kernels/lgmd.py): few parameters, small contexts, read by name.

What a kernel receives at run time, tuple members counted, is measured by ``tests/kernel_widths.py``;
these tests read the source, so they need no compiler.
"""
from __future__ import annotations

import ast
from pathlib import Path

LGMD = Path(__file__).resolve().parent.parent / "kernels" / "lgmd.py"
MAX_PARAMETERS = 12
MAX_CONTEXT_MEMBERS = 8


def _tree() -> ast.Module:
    return ast.parse(LGMD.read_text(encoding="utf-8"))


def _is_dsl_function(fn: ast.FunctionDef) -> bool:
    """Decorated with ``@ti.func`` or ``@ti.kernel``."""
    return any(isinstance(d, ast.Attribute) and d.attr in ("func", "kernel") for d in fn.decorator_list)


def test_no_kernel_or_func_declares_more_than_twelve_parameters():
    functions = [n for n in ast.walk(_tree()) if isinstance(n, ast.FunctionDef) and _is_dsl_function(n)]
    wide = {fn.name: len(fn.args.args) for fn in functions if len(fn.args.args) > MAX_PARAMETERS}
    assert len(functions) > 40 and not wide, wide


def test_every_context_has_at_most_eight_members():
    contexts = {}
    for node in ast.walk(_tree()):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "context":
            name, fields = (a.value for a in node.args)
            contexts[name] = fields.split()
    wide = {k: len(v) for k, v in contexts.items() if len(v) > MAX_CONTEXT_MEMBERS}
    assert len(contexts) >= 10 and not wide, wide


def test_contexts_are_read_by_name_not_by_position():
    by_position = [ast.unparse(n) for n in ast.walk(_tree()) if isinstance(n, ast.Subscript)
                   and isinstance(n.value, ast.Name) and n.value.id == "ctx"]
    assert not by_position, by_position
