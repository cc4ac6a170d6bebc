"""How wide the SIMD code is that each kernel compiler makes of the C-DNF update loops.

``python -m cdnf_ti.run bench --simd`` compiles C-DNF's fast path afresh under each installed
compiler (in a child process per compiler, with the compile cache off and the optimised LLVM
IR written out), then counts, in each solve launch, the float arithmetic instructions
(``fadd``, ``fsub``, ``fmul``, ``fdiv``, ``fneg``) by vector width: ``1`` is scalar code,
``8`` an AVX2 ``<8 x float>`` operation, and so on.

It answers the question behind most of the C-DNF engine's speed on a given machine: does the
compiler turn the lane layout (``kernels/common.py``, ``LANES`` columns per vector element)
into vector code, and how wide? Two facts found in the compilers' source make this differ
between machines and compilers (docs/PERFORMANCE.md, "Design decisions that still hold"):

* taichi 1.7.4 optimises for ``sys::getHostCPUName()`` with an empty feature string; its
  LLVM 15 names CPUs newer than it (AMD Zen 5) ``generic``, so the vectoriser forms 128-bit
  vectors only there, on any AVX-512 machine;
* quadrants 1.3.3 builds its LLVM 22 pipeline with the default ``PipelineTuningOptions``,
  which leave the SLP vectoriser off; the lane layout is made for that vectoriser, so
  quadrants' update loops stay scalar.
"""
from __future__ import annotations

import collections
import os
import re
import subprocess
import sys
import tempfile
from typing import Mapping, Sequence

#: Float arithmetic instructions counted (an LLVM IR line ``%x = <op> [flags] <type> ...``).
_ARITH = re.compile(r"=\s+(?:fadd|fsub|fmul|fdiv|fneg)\b")
_VECTOR = re.compile(r"<(\d+) x float>")
_SCALAR = re.compile(r"\bfloat\b")
_DEFINE = re.compile(r"^define\s[^@]*@([A-Za-z_][A-Za-z0-9_]*)", re.M)

#: The C-DNF launches reported: (name prefix of the kernel in the IR, label).
SOLVE_KERNELS = (("run_lanes", "lane launches (solves among them)"),)


def float_arith_widths(ir: str) -> collections.Counter:
    """Count float arithmetic instructions of an LLVM IR text by vector width.

    Parameters
    ----------
    ir : str
        Textual LLVM IR (one module).

    Returns
    -------
    collections.Counter
        ``{width: count}``; width 1 counts scalar ``float`` instructions, width ``n`` the
        ``<n x float>`` ones. Instructions on other types (double, integers) are not counted.
    """
    widths: collections.Counter = collections.Counter()
    for line in ir.splitlines():
        if not _ARITH.search(line):
            continue
        vec = _VECTOR.search(line)
        if vec is not None:
            widths[int(vec.group(1))] += 1
        elif _SCALAR.search(line):
            widths[1] += 1
    return widths


def vector_share(widths: Mapping[int, int]) -> float:
    """Fraction of the counted instructions that are vector ones (0 when none were counted)."""
    total = sum(widths.values())
    return 0.0 if total == 0 else 1.0 - widths.get(1, 0) / total


def kernel_widths(ir_dir: str) -> dict[str, collections.Counter]:
    """The widths of :func:`float_arith_widths` of C-DNF's lane launches (its two solves among them) in ``ir_dir``.

    Parameters
    ----------
    ir_dir : str
        Folder holding the ``*_llvm_ir_optimized_*.ll`` files that a compiler run with
        ``print_kernel_llvm_ir_optimized=True`` wrote (one module per kernel).

    Returns
    -------
    dict
        ``{label: Counter}`` for each of :data:`SOLVE_KERNELS` found.
    """
    out: dict[str, collections.Counter] = {}
    for name in sorted(os.listdir(ir_dir)):
        if not (name.endswith(".ll") and "llvm_ir_optimized" in name):
            continue
        with open(os.path.join(ir_dir, name)) as f:
            ir = f.read()
        kernels = _DEFINE.findall(ir)
        for prefix, label in SOLVE_KERNELS:
            if any(k.startswith(prefix) for k in kernels):
                out.setdefault(label, collections.Counter()).update(float_arith_widths(ir))
    return out


# The child process: start the compiler with the IR printed to the working folder and the
# compile cache off (a cached kernel is not compiled, so not printed), then run C-DNF on a
# few frames so that every launch of its fast path is compiled.
_CHILD = """
import importlib, sys
import numpy as np
ti = importlib.import_module(sys.argv[1])
ti.init(arch=ti.cpu, default_fp=ti.f32, default_ip=ti.i32, offline_cache=False,
        print_kernel_llvm_ir_optimized=True, log_level=ti.ERROR)
from cdnf_ti import CDNF
model = CDNF()
rng = np.random.default_rng(0)
for _ in range(3):
    model.step(rng.integers(0, 256, size=(int(sys.argv[2]), int(sys.argv[3])), dtype=np.uint8))
"""


SimdRow = tuple[str, str, collections.Counter]  # (compiler, launch label, widths)


def measure_simd(compilers: Sequence[str], size: tuple[int, int] = (240, 426), progress: bool = False) -> list[SimdRow]:
    """Compile C-DNF under each compiler in a child process; return (compiler, launch, widths) rows.

    Parameters
    ----------
    compilers : sequence of str
        Kernel compilers to inspect (``"taichi"``, ``"quadrants"``).
    size : (int, int)
        Frame height and width (pixels) of the frames run to compile the launches.
    progress : bool
        Show a progress bar (one step per compiler; each takes a cold compile, ~20-60 s).

    Raises
    ------
    RuntimeError
        A child process failed, or its IR held none of the C-DNF solve launches.
    """
    from tqdm import tqdm

    rows = []
    for comp in tqdm(compilers, desc="simd: compiling C-DNF", unit="compiler", leave=False,
                     disable=None if progress else True):
        with tempfile.TemporaryDirectory() as tmp:
            env = dict(os.environ, CDNF_TI_COMPILER=comp)
            proc = subprocess.run([sys.executable, "-c", _CHILD, comp, str(size[0]), str(size[1])],
                                  cwd=tmp, env=env, capture_output=True, text=True)
            if proc.returncode != 0:
                last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
                raise RuntimeError(f"compiling C-DNF under {comp} failed: {last}")
            found = kernel_widths(tmp)
            if not found:
                raise RuntimeError(f"{comp} wrote no IR of the C-DNF solve launches")
            rows += [(comp, label, found[label]) for _, label in SOLVE_KERNELS if label in found]
    return rows


def format_simd(rows: Sequence[SimdRow]) -> str:
    """Markdown table of :func:`measure_simd`'s rows."""
    lines = ["| compiler | launch | float arithmetic in vector instructions | instructions by width |",
             "|---|---|---|---|"]
    for comp, label, widths in rows:
        spread = ", ".join(f"{'scalar' if w == 1 else f'{w} lanes'}: {n}" for w, n in sorted(widths.items()))
        lines.append(f"| {comp} | {label} | {100 * vector_share(widths):.0f} % | {spread} |")
    return "\n".join(lines)
