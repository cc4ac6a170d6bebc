"""Every module imports on its own, as the first import of a fresh interpreter, and no import cycle exists.

An import cycle that breaks shows up only when a module of the cycle is the first
one imported, so each module is imported first in its own interpreter
(``python -c "import cdnf_ti.X"``); then all of them in one interpreter in
sorted and in reverse order. A cycle that happens to import in every order is
still a cycle: the graph of module-level imports (read with :mod:`ast`) must be
acyclic. Imports stay at module level except for the lazy ones listed in
:data:`LAZY_OK`.
"""
from __future__ import annotations

import ast
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: Package name -> folder (pyproject.toml's package-dir: kernels/, stimuli/ and bench/ map into cdnf_ti).
PACKAGES = {
    "cdnf_ti": ROOT / "cdnf_ti",
    "cdnf_ti.kernels": ROOT / "kernels",
    "cdnf_ti.stimuli": ROOT / "stimuli",
    "cdnf_ti.bench": ROOT / "bench",
}


def all_modules() -> list[str]:
    """Every importable module of the package (``__main__`` runs the CLI; pytest files are not modules)."""
    names = set()
    for package, folder in PACKAGES.items():
        for path in folder.rglob("*.py"):
            parts = path.relative_to(folder).with_suffix("").parts
            if parts[-1] == "__main__" or parts[-1] == "conftest" or parts[-1].startswith("test_"):
                continue
            if parts[-1] == "__init__":
                parts = parts[:-1]
            names.add(".".join((package, *parts)))
    return sorted(names)


MODULES = all_modules()


def _import(statement: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", statement], cwd=ROOT, capture_output=True, text=True)


@pytest.fixture(scope="module")
def first_imports() -> dict[str, subprocess.CompletedProcess]:
    """``import X`` in a fresh interpreter for every module X, run side by side."""
    with ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 2)) as pool:
        return dict(zip(MODULES, pool.map(lambda m: _import(f"import {m}"), MODULES)))


def test_the_module_list_covers_the_package():
    assert {"cdnf_ti", "cdnf_ti.models.base", "cdnf_ti.experiments.dataset", "cdnf_ti.kernels.cdnf",
            "cdnf_ti.stimuli.rain", "cdnf_ti.bench.peers", "cdnf_ti.run"} <= set(MODULES)


@pytest.mark.parametrize("module", MODULES)
def test_module_imports_first_in_a_fresh_interpreter(module, first_imports):
    r = first_imports[module]
    assert r.returncode == 0, f"import {module} failed:\n{r.stderr[-3000:]}"


@pytest.mark.parametrize("order", ["sorted", "reversed"])
def test_all_modules_import_together_in_any_order(order):
    mods = MODULES if order == "sorted" else MODULES[::-1]
    r = _import("; ".join(f"import {m}" for m in mods))
    assert r.returncode == 0, r.stderr[-3000:]


def _module_of(path: Path) -> tuple[str, bool] | None:
    for package, folder in PACKAGES.items():
        if folder in path.parents:
            parts = path.relative_to(folder).with_suffix("").parts
            if parts[-1] == "__init__":
                return ".".join((package, *parts[:-1])), True
            return ".".join((package, *parts)), False
    return None


def _module_level_imports(body: list) -> list:
    """Import statements run at import time: at top level or in top-level if/try blocks
    (``if TYPE_CHECKING:`` blocks never run)."""
    found = []
    for node in body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(node)
        elif isinstance(node, ast.If):
            if not (isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING"):
                found += _module_level_imports(node.body) + _module_level_imports(node.orelse)
        elif isinstance(node, ast.Try):
            found += _module_level_imports(node.body + node.orelse + node.finalbody)
            for handler in node.handlers:
                found += _module_level_imports(handler.body)
    return found


def _imported(node, module: str, is_package: bool, known: set[str]) -> set[str]:
    """The package modules one import statement imports (``from P import name``: ``P.name`` if
    that is a module, else ``P``)."""
    if isinstance(node, ast.Import):
        return {a.name for a in node.names if a.name in known}
    if node.level:
        base = (module if is_package else module.rpartition(".")[0]).split(".")
        base = ".".join(base[:len(base) - (node.level - 1)] + ([node.module] if node.module else []))
    else:
        base = node.module or ""
    out = set()
    for a in node.names:
        if f"{base}.{a.name}" in known:
            out.add(f"{base}.{a.name}")
        elif base in known:
            out.add(base)
    return out


def import_graph() -> dict[str, set[str]]:
    """Module -> the package modules it imports at module level."""
    files = {}
    for folder in PACKAGES.values():
        for path in folder.rglob("*.py"):
            info = _module_of(path)
            if info and info[0] in MODULES:
                files[info[0]] = (path, info[1])
    known = set(files)
    graph = {}
    for module, (path, is_package) in files.items():
        edges = set()
        for node in _module_level_imports(ast.parse(path.read_text(encoding="utf-8")).body):
            edges |= _imported(node, module, is_package, known)
        edges.discard(module)
        graph[module] = edges
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a list of nodes (first == last), or None if it is acyclic."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(v: str) -> list[str] | None:
        state[v] = 1
        path.append(v)
        for w in sorted(graph.get(v, ())):
            if state.get(w) == 1:
                return path[path.index(w):] + [w]
            if w not in state and (cycle := visit(w)):
                return cycle
        path.pop()
        state[v] = 2
        return None

    for v in sorted(graph):
        if v not in state and (cycle := visit(v)):
            return cycle
    return None


def test_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_import_graph_reads_relative_imports():
    graph = import_graph()
    assert "cdnf_ti.cli_common" in graph["cdnf_ti.run"]
    assert "cdnf_ti.experiments.layout" in graph["cdnf_ti.experiments.reports"]
    assert "cdnf_ti.models.base" in graph["cdnf_ti.models"]


def test_no_module_level_import_cycle():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


#: Imports that may stay inside functions: optional or heavy dependencies, platform modules,
#: and Taichi itself, which must be imported only after the compiler and arch are chosen at
#: run time (cdnf_ti.taichi_runtime.ensure_taichi; the kernel modules import without it).
LAZY_OK = ("taichi", "quadrants", "matplotlib", "distributed", "dask", "scipy", "torch", "fcntl",
           "aedat", "h5py", "hdf5plugin",  # the `events` extra: imported where an event file needs them
           "optuna")  # the `tune` extra: imported by `experiment tune` alone

#: Files not yet held to the rule: the compiler layer (it loads the compiler it chose), the solver and params.
ENGINE_FILES = {"cdnf_ti/taichi_runtime.py", "cdnf_ti/solver.py", "cdnf_ti/params.py"}


def _absolute(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    if not node.level:
        return node.module or ""
    base = (module if is_package else module.rpartition(".")[0]).split(".")
    return ".".join(base[:len(base) - (node.level - 1)] + ([node.module] if node.module else []))


def test_imports_are_at_module_level_except_the_lazy_ones():
    late = []
    for folder in (ROOT / "cdnf_ti", ROOT / "stimuli"):
        for path in sorted(folder.rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel in ENGINE_FILES:
                continue
            module, is_package = _module_of(path)
            tree = ast.parse(path.read_text(encoding="utf-8"))
            in_functions = {id(n): n for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                            for n in ast.walk(f) if isinstance(n, (ast.Import, ast.ImportFrom))}
            for node in in_functions.values():
                names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                         else [_absolute(node, module, is_package)])
                if not all(n.split(".")[0] in LAZY_OK for n in names):
                    late.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
    assert not late, "imports inside functions (move them to module level):\n" + "\n".join(late)


EXPERIMENTS = ROOT / "cdnf_ti" / "experiments"

#: The experiment engines: they run tasks and return records; the reporters run after them.
ENGINES = ("tasks", "parallel", "layout", "clip_tasks", "stimulus_tasks")
#: The reporters: they write tables, figures and pages from what an engine returned.
REPORTERS = ("reports", "sweep_reports", "figures", "report_page", "htmlreport", "tables")


def experiments_graph() -> dict[str, set[str]]:
    """Module -> the modules of ``cdnf_ti/experiments`` it imports, counting ``if TYPE_CHECKING:``
    imports and imports inside functions too (read with :mod:`ast`; names relative to the folder)."""
    names = {p.stem for p in EXPERIMENTS.glob("*.py")}
    graph: dict[str, set[str]] = {}
    for path in sorted(EXPERIMENTS.glob("*.py")):
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                if node.module:
                    edges.add(node.module.split(".")[0])
                else:
                    edges.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and \
                    node.module.startswith("cdnf_ti.experiments."):
                edges.add(node.module.split(".")[2])
            elif isinstance(node, ast.Import):
                edges.update(a.name.split(".")[2] for a in node.names if a.name.startswith("cdnf_ti.experiments."))
        graph[path.stem] = (edges & names) - {path.stem, "__init__"}
    return graph


def test_experiments_graph_counts_type_checking_imports():
    graph = experiments_graph()
    assert "clip_tasks" in graph["reports"]  # only under TYPE_CHECKING
    assert "tasks" in graph["layout"]


def test_no_import_cycle_in_experiments_even_through_type_checking_imports():
    cycle = find_cycle(experiments_graph())
    assert cycle is None, "import cycle in cdnf_ti/experiments: " + " -> ".join(cycle)


def _reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        for w in graph.get(todo.pop(), ()):
            if w not in seen:
                seen.add(w)
                todo.append(w)
    return seen


@pytest.mark.parametrize("engine", ENGINES)
def test_no_engine_imports_a_reporter(engine):
    assert not _reachable(experiments_graph(), engine) & set(REPORTERS)


#: The kernel modules (kernels/ at the repository root, installed as cdnf_ti.kernels).
KERNEL_MODULES = tuple(f"cdnf_ti.kernels.{p.stem}" for p in sorted((ROOT / "kernels").glob("*.py"))
                       if p.stem != "__init__")


def test_importing_the_models_and_every_kernel_module_loads_no_compiler():
    code = ("import sys\nimport cdnf_ti.models\n"
            + "".join(f"import {m}\n" for m in KERNEL_MODULES)
            + "print(sorted(m for m in ('taichi', 'quadrants') if m in sys.modules))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert len(KERNEL_MODULES) >= 5 and proc.stdout.split("\n")[-2] == "[]"


#: What models/ may not import: the compilers, the kernels' DSL modules and the compiler layer.
ENGINE_MODULES = ("taichi", "quadrants", "cdnf_ti.kernels", "cdnf_ti.taichi_runtime", "cdnf_ti.backends")


def test_the_models_import_neither_the_compiler_nor_the_kernels():
    found = []
    for path in sorted((ROOT / "cdnf_ti" / "models").glob("*.py")):
        module, is_package = _module_of(path)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _absolute(node, module, is_package)
                names = [base] + [f"{base}.{a.name}" for a in node.names]
            else:
                continue
            if any(n == e or n.startswith(e + ".") for n in names for e in ENGINE_MODULES):
                found.append(f"{path.relative_to(ROOT).as_posix()}:{node.lineno}: {ast.unparse(node)}")
    assert not found, "models/ reaches into the engine:\n" + "\n".join(found)
