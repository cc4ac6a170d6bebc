"""Every module imports on its own, as the first import of a fresh interpreter.

An import cycle shows up only when a module of the cycle is the first one
imported, so each module is imported first in its own interpreter
(``python -c "import cdnf_ti.X"``); then all of them in one interpreter in
sorted and in reverse order.
"""
from __future__ import annotations

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
    return subprocess.run([sys.executable, "-c", statement], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)


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
