"""A published model is added by its own files alone: the git history shows it.

Each model added on the one-model contract (the engine, one backend, registration by class) came in one
commit, ``Model <name>: ...``, that adds its kernel module and its model module together and touches only
that model's own files (its kernels, model, float64 reference, tests, oracle script) and the docs (its
row in the README's table of models among them): no engine, backend, registry or render file and no list
of models elsewhere. The tests skip, saying why,
outside a git checkout with its history (a source archive, a shallow clone) or before the model exists.
"""
from __future__ import annotations

import fnmatch
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: The models added on the contract (issue "three more published looming models").
ADDED_MODELS = ("lgmd_p_on_off", "dlgmd", "event_looming")

#: The files a model's commit may touch, ``{name}`` its registry name.
OWN_FILES = ("kernels/{name}.py", "cdnf_ti/models/{name}.py", "cdnf_ti/{name}_reference.py", "tests/test_{name}.py",
             "tests/test_{name}_*.py", "tests/data/{name}/*", "docs/*.md", "docs/figures/*{name}*", "README.md",
             "CHANGELOG.md")


def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=True).stdout


def _history_or_skip() -> None:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: no history to read")
    if _git("rev-parse", "--is-shallow-repository").strip() == "true":
        pytest.skip("a shallow clone: the history is cut")


def _adding_commit(name: str) -> str:
    """The commit that added ``kernels/<name>.py`` (skips when the model is not in this checkout)."""
    if not (ROOT / "kernels" / f"{name}.py").exists():
        pytest.skip(f"model {name} is not in this checkout yet")
    _history_or_skip()
    commits = _git("log", "--diff-filter=A", "--format=%H", "--", f"kernels/{name}.py").split()
    assert commits, f"kernels/{name}.py has no adding commit"
    return commits[-1]


def _is_own(path: str, name: str) -> bool:
    return any(fnmatch.fnmatch(path, pattern.format(name=name)) for pattern in OWN_FILES)


@pytest.mark.parametrize("name", ADDED_MODELS)
def test_a_model_is_added_in_one_commit_named_after_it(name):
    commit = _adding_commit(name)
    subject = _git("log", "-1", "--format=%s", commit)
    added = _git("show", "--diff-filter=A", "--name-only", "--format=", commit).split()
    assert subject.startswith(f"Model {name}:"), subject
    assert {f"kernels/{name}.py", f"cdnf_ti/models/{name}.py"} <= set(added)


@pytest.mark.parametrize("name", ADDED_MODELS)
def test_a_models_commit_touches_only_its_own_files_and_the_docs(name):
    commit = _adding_commit(name)
    touched = _git("show", "--name-only", "--format=", commit).split()
    assert [p for p in touched if not _is_own(p, name)] == []


@pytest.mark.parametrize("path, own", [
    ("kernels/dlgmd.py", True), ("tests/test_dlgmd_reference.py", True), ("docs/MODELS.md", True),
    ("kernels/engine.py", False), ("cdnf_ti/backends/engine.py", False), ("cdnf_ti/models/registry.py", False),
    ("cdnf_ti/models/__init__.py", False), ("cdnf_ti/render.py", False), ("tests/test_alert_lines.py", False),
    ("kernels/lgmd_p_on_off.py", False), (".ci/run", False), ("bench/trace_dump.py", False)])
def test_the_own_files_of_a_model_are_its_kernels_model_reference_tests_and_docs(path, own):
    assert _is_own(path, "dlgmd") is own
