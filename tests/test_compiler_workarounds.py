"""Reproductions of the compiler bugs that the engine works around (kernels/compat.py, taichi_runtime).

Each test runs the construct a workaround replaces, in a child process (a bug may abort it),
under the session's compiler, and asserts what a correct compiler does. Where the installed
compiler version is known to have the bug the test is a strict xfail: it fails loudly once
the compiler is fixed, so the workaround can go. A bug that shows only on some machines (the GPU
probe crashes only where no GPU device is found) is tested only where the test sees that machine.
"""
from __future__ import annotations

import importlib.metadata
import os
import subprocess
import sys

import pytest

from cdnf_ti.taichi_runtime import COMPILER_ENV, BackendUnavailableError, check_arch, current_compiler, default_compiler

COMPILER = current_compiler() or default_compiler()
VERSION = importlib.metadata.version(COMPILER)

#: (compiler, version prefix) pairs that have each bug (checked on taichi 1.7.4 and quadrants 1.3.3).
BROKEN = {
    "any": {("taichi", "1.7."), ("quadrants", "1.3.")},
    "negate": {("taichi", "1.7."), ("quadrants", "1.3.")},
    "abs": {("taichi", "1.7."), ("quadrants", "1.3.")},
    "subtract_assign": {("taichi", "1.7."), ("quadrants", "1.3.")},
    "gpu_probe": {("taichi", "1.7.")},
}


def broken(bug: str) -> pytest.MarkDecorator:
    """A strict xfail where the session's compiler version has ``bug``."""
    has = any(COMPILER == c and VERSION.startswith(v) for c, v in BROKEN[bug])
    return pytest.mark.xfail(has, strict=True, reason=f"{COMPILER} {VERSION} has this bug "
                             "(the workaround: kernels/compat.py, cdnf_ti/taichi_runtime.py)")


_HEAD = """
import importlib, sys
import numpy as np
ti = importlib.import_module({compiler!r})
ti.init(arch=ti.cpu, offline_cache=False, log_level=ti.ERROR)
V = ti.types.vector(32, ti.f32)
ti.lang.impl.current_cfg().real_matrix_scalarize = False  # explicit vector types, as the lane kernels
"""

_ANY = _HEAD + """
@ti.kernel
def k(x: ti.types.ndarray(dtype=V, ndim=1), out: ti.types.ndarray(dtype=ti.i32, ndim=1)):
    for i in range(x.shape[0]):
        out[i] = ti.select((x[i] > 0.0).any(), 1, 0)
x = ti.ndarray(V, 32)
x.from_numpy(np.eye(32, dtype=np.float32))  # row l: only lane l set
out = np.zeros(32, np.int32)
k(x, out)
print("RESULT", "".join(str(int(v)) for v in out))
"""

_UNARY = _HEAD + """
@ti.kernel
def k(x: ti.types.ndarray(dtype=V, ndim=1), y: ti.types.ndarray(dtype=V, ndim=1)):
    for i in range(x.shape[0]):
        y[i] = {expr}
x, y = ti.ndarray(V, 4), ti.ndarray(V, 4)
a = np.linspace(-3, 3, 128).astype(np.float32).reshape(4, 32)
x.from_numpy(a)
k(x, y)
print("RESULT", bool(np.array_equal(y.to_numpy(), {want})))
"""


def _child(code: str) -> subprocess.CompletedProcess:
    """Run ``code`` in a child process under the session's compiler, however long it takes."""
    env = dict(os.environ, **{COMPILER_ENV: COMPILER})
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)


def _result(proc: subprocess.CompletedProcess) -> str | None:
    got = [ln.split(" ", 1)[1] for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    return got[-1] if proc.returncode == 0 and got else None


@broken("any")
def test_any_tests_every_lane_of_an_explicit_vector():
    # kernels/compat.py any_lane stands in for it
    assert _result(_child(_ANY.format(compiler=COMPILER))) == "1" * 32


@broken("negate")
def test_unary_minus_compiles_on_an_explicit_vector():
    # kernels/compat.py lane_abs and `0.0 - x` stand in for it
    code = _UNARY.format(compiler=COMPILER, expr="-x[i]", want="-a")
    assert _result(_child(code)) == "True"


@broken("abs")
def test_abs_compiles_on_an_explicit_vector():
    # kernels/compat.py lane_abs stands in for it
    code = _UNARY.format(compiler=COMPILER, expr="ti.abs(x[i])", want="np.abs(a)")
    assert _result(_child(code)) == "True"


_SUBTRACT_ASSIGN = _HEAD + """
@ti.kernel
def k(x: ti.types.ndarray(dtype=V, ndim=1), y: ti.types.ndarray(dtype=V, ndim=1)):
    for i in range(x.shape[0]):
        acc = x[i] * 2.0
        acc -= x[i]
        y[i] = acc
x, y = ti.ndarray(V, 4), ti.ndarray(V, 4)
a = np.linspace(-3, 3, 128).astype(np.float32).reshape(4, 32)
x.from_numpy(a)
k(x, y)
print("RESULT", bool(np.array_equal(y.to_numpy(), a)))
"""


@broken("subtract_assign")
def test_subtract_assign_compiles_on_an_explicit_vector():
    # a lane stage writes `acc = acc - x` (the compilers emit an integer subtraction and abort)
    assert _result(_child(_SUBTRACT_ASSIGN.format(compiler=COMPILER))) == "True"


_GPU_INIT = """
import importlib
ti = importlib.import_module({compiler!r})
ti.init(arch=ti.gpu, log_level=ti.ERROR)
print("RESULT", "returned")
"""


def _gpu_devices() -> list[str]:
    """The GPU backends the session's compiler finds on this machine (each probed in a child process).

    A software driver counts: Mesa's Vulkan driver (lavapipe, installed with Debian's chromium and
    ffmpeg) gives a Vulkan device, and the compiler then starts on it without reaching the probe
    that crashes.
    """
    found = []
    for arch in ("cuda", "vulkan"):
        try:
            found.append(check_arch(arch, timeout=None))  # no time limit: a loaded machine is slow, not GPU-less
        except BackendUnavailableError:
            pass
    return found


@broken("gpu_probe")
def test_asking_for_a_gpu_where_there_is_none_does_not_crash_the_process():
    # taichi_runtime.check_arch probes a GPU arch in a child process for this
    devices = _gpu_devices()
    if devices:
        pytest.skip(f"this machine has a GPU device ({', '.join(devices)}): asking for one says nothing about "
                    "a machine without")
    proc = _child(_GPU_INIT.format(compiler=COMPILER))
    assert proc.returncode == 0 and _result(proc) == "returned", (proc.returncode, proc.stderr[-500:])
