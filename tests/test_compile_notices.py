"""Visible compiles: one line when kernels compile for a new model or frame size, naming the cache
folder, and one with its duration; quiet when the cache holds them and under ``--no-progress``."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest
from conftest import REPO

from cdnf_ti import taichi_runtime as rt
from cdnf_ti.run import _videos_parser


@pytest.fixture
def fresh(tmp_path, monkeypatch):
    """A fresh compile-cache folder and a process that has announced nothing yet; notices on."""
    monkeypatch.setenv(rt.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.setenv(rt.NOTICES_ENV, "1")
    monkeypatch.setattr(rt, "_seen", None)
    monkeypatch.setattr(rt, "_announced", set())
    monkeypatch.setattr(rt, "_pending", {})
    return tmp_path / "cache"


def _steps(label: str, compiles: list[int]) -> None:
    """One :class:`~cdnf_ti.taichi_runtime.compiling` step per item, compiling that many kernels."""
    for n in compiles:
        with rt.compiling(label):
            for _ in range(n):
                rt._count_compile()


def _lines(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if "kernels" in ln]


def test_a_first_compile_names_the_model_size_and_cache_then_its_duration(fresh, capsys):
    _steps("toy at 8x6", [1, 2, 0, 0, 0])  # compiles on the first two steps, as the LGMD family does
    lines = _lines(capsys)
    assert lines[0] == f"compiling kernels for toy at 8x6, first time only; cached in {fresh}"
    assert lines[1].startswith("compiled kernels for toy at 8x6 in ") and lines[1].endswith(" s")
    assert len(lines) == 2


def test_a_model_that_compiles_late_is_announced_when_it_compiles(fresh, capsys):
    _steps("late at 8x6", [0, 0])
    assert _lines(capsys) == []
    _steps("late at 8x6", [1, 0, 0, 0])  # oLGMD compiles its layers on frame 2
    assert [ln.split(" for ")[0] for ln in _lines(capsys)] == ["compiling kernels", "compiled kernels"]


def test_the_duration_comes_after_the_last_of_the_first_steps_that_compile(fresh, capsys):
    _steps("olgmd-like at 8x6", [1, 0, 1])  # photoreceptors on frame 0, layers on frame 2
    assert [ln.split(" for ")[0] for ln in _lines(capsys)] == ["compiling kernels"]
    _steps("olgmd-like at 8x6", [0] * rt.QUIET_STEPS)
    assert [ln.split(" for ")[0] for ln in _lines(capsys)] == ["compiled kernels"]


def test_each_new_frame_size_is_announced(fresh, capsys):
    _steps("toy at 8x6", [1, 0, 0, 0])
    _steps("toy at 16x12", [1, 0, 0, 0])
    assert sum(ln.startswith("compiling kernels for toy at 16x12") for ln in _lines(capsys)) == 1


def test_kernels_compiled_into_this_cache_before_are_not_announced_again(fresh, monkeypatch, capsys):
    _steps("toy at 8x6", [1, 0, 0, 0])
    capsys.readouterr()
    monkeypatch.setattr(rt, "_seen", None)  # a new process with the same cache folder
    monkeypatch.setattr(rt, "_announced", set())
    _steps("toy at 8x6", [1, 0])
    assert _lines(capsys) == []


def test_kernels_compiled_outside_a_model_step_are_announced_once_per_cache(fresh, monkeypatch, capsys):
    rt._count_compile("stimuli")
    rt._count_compile("stimuli")
    assert _lines(capsys) == [f"compiling kernels for stimuli, first time only; cached in {fresh}"]
    monkeypatch.setattr(rt, "_seen", None)  # a new process with the same cache folder
    monkeypatch.setattr(rt, "_announced", set())
    rt._count_compile("stimuli")
    assert _lines(capsys) == []


def test_steps_that_compile_nothing_print_nothing(fresh, capsys):
    _steps("toy at 8x6", [0, 0, 0])
    assert _lines(capsys) == []


def test_no_progress_silences_the_compile_notices(fresh, capsys):
    _videos_parser().parse_args(["clip.mp4", "--no-progress"])
    assert not rt.compile_notices()
    _steps("toy at 8x6", [1, 0])
    assert _lines(capsys) == []


def test_a_cold_cache_demo_says_it_compiles_before_its_first_result(tmp_path):
    env = {**os.environ, rt.CACHE_ENV: str(tmp_path / "cache"), "PYTHONUNBUFFERED": "1"}
    env.pop(rt.NOTICES_ENV, None)
    proc = subprocess.Popen([sys.executable, "-m", "cdnf_ti.run", "demo", "--size", "48"], cwd=REPO, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seen = []
    try:
        for line in proc.stdout:  # until the first compile line (or the end: then it never came)
            seen.append(line.strip())
            if line.startswith("compiling kernels for"):
                break
    finally:
        proc.kill()
        proc.communicate()
    assert seen and seen[-1].startswith("compiling kernels for") and str(tmp_path / "cache") in seen[-1]
    assert [ln for ln in seen[:-1] if ln and not ln.startswith("cdnf_ti demo:")] == []
