"""The DSL side of the compilers' workarounds, in one place: helpers that stand in for constructs
that taichi 1.7.4 or quadrants 1.3.3 get wrong, or compile slowly, in the lane kernels.

Each correctness workaround has a reproduction test of the construct it replaces
(``tests/test_compiler_workarounds.py``, strict xfail per compiler version: it fails once a
compiler is fixed, and the helper can go). The Python-side workarounds (explicit vector types
around a kernel's compilation, the compile cache's size, the taichi parser patch, the GPU probe
in a child process) live in :mod:`cdnf_ti.taichi_runtime`.

============  =======================================================  ==========================
helper        replaces                                                 why
============  =======================================================  ==========================
any_lane      ``mask.any()`` on a lane vector                          wrong result with explicit
                                                                       vector types (both)
lane_abs      ``ti.abs(x)``, ``-x`` on a lane vector                   the compile aborts with
                                                                       explicit vector types (both)
run_max       a chain ``max(max(v0, v1), v2)...``                      speed: a tree vectorises
============  =======================================================  ==========================

A stencil's small coefficient sets reach the shared equations of the lane kernels as scalars
(read from the backend's coefficient array into locals), not as small ``ti.Vector`` values:
with explicit vector types a launch of quadrants 1.3.3 crashed on those (``kernels/lgmd.py``).
Nor do a launch's buffer indices travel as an int ``ti.Vector``: taichi 1.7.4 crashed
(segmentation fault) on one in an explicit-vector launch (F-LGMD's solve takes an int32 array).
"""

import functools
from types import SimpleNamespace


def halvings(n: int) -> list[int]:
    """Widths of the reduction tree of ``run_max``: ``n``, then ``n - n // 2``, ... down to 2."""
    widths = []
    while n > 1:
        widths.append(n)
        n -= n // 2
    return widths


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The workaround helpers for the DSL module ``ti`` and ``lanes`` lanes per vector element."""
    LANES = lanes

    @ti.func
    def run_max(v, n: ti.template()):
        """Largest of the first ``n`` values of ``v`` (float32; a run, or a lane vector with ``n = LANES``).

        A tree of pairwise maxima: a chain ``max(max(v0, v1), v2)...`` has ``n - 1`` dependent
        steps, which the vectoriser leaves scalar; halving ``log2(n)`` times gives the same value
        (a maximum does not depend on the order) in vector instructions. It runs once per element
        in the solves' update loops, where the tree made a full-frame ON/OFF update 11 % and a
        Summation update 23 % faster at 32 lanes (docs/PERFORMANCE.md, "Engine A/B and workarounds").
        """
        b = v  # a copy: ti.func arguments are passed by value
        for width in ti.static(halvings(n)):
            for c in ti.static(range(width // 2)):
                b[c] = ti.max(b[c], b[c + width - width // 2])
        return b[0]

    @ti.func
    def any_lane(mask):
        """Whether any lane of the comparison ``mask`` (a lane vector of booleans) is set.

        Not ``mask.any()``: in a kernel compiled with explicit vector types, ``any()`` tests only
        some of the lanes under taichi 1.7.4 and quadrants 1.3.3 (reproduced by
        ``tests/test_compiler_workarounds.py``).
        """
        return run_max(ti.select(mask, 1, 0), LANES) != 0

    @ti.func
    def lane_abs(x):
        """``|x|`` of a lane vector (``ti.abs`` and unary minus on vectors abort the compilation under
        taichi 1.7.4 and quadrants 1.3.3 with explicit vector types)."""
        return ti.max(x, 0.0 - x)

    return SimpleNamespace(**locals())
