"""Taichi kernels of the SDNF reconstruction (single field, float32 state).

Two launches per frame: :func:`load_binary` (binary pre-processing of the
luminance change, with the active-pixel count) and :func:`field_update`
(time-delayed lateral interaction: the DoG acts on the previous frame's
field, so each frame is one explicit update, no iteration). The DoG is applied
as separable row/column passes with a replicate border. The kernels return no
value: their sums go to ``out``, a float64 NumPy array that the caller zeroes
before the launch (see :mod:`cdnf_ti.kernels.lgmd`). NumPy float64 oracle:
:class:`cdnf_ti.baselines_reference.NumpySDNFBackend`.
"""

import functools
from types import SimpleNamespace

from . import common
from .common import REPLICATE, context, namespace  # noqa: F401 - part of this module's interface


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The kernels of this module for the DSL module ``ti`` (taichi or quadrants) and ``lanes``
    lanes per vector element of the fast path: a namespace of every name below (and the
    module-level constants). Built once per (compiler, lanes), after the runtime started."""
    C = common.build(ti, lanes)
    block_span = C.block_span
    dog_column_run = C.dog_column_run
    dog_row_pass = C.dog_row_pass
    fill = C.fill
    luminance_change = C.luminance_change
    row_runs = C.row_runs
    run_load = C.run_load
    run_store = C.run_store
    run_sum = C.run_sum
    tanh_rational = C.tanh_rational

    F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    F1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
    D1 = ti.types.ndarray(dtype=ti.f64, ndim=1)  # a launch's results ``out``, set by the caller before it


    LoadRunCtx = context("LoadRunCtx", "frame L P E scale keep t_b")

    @ti.func
    def _load_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        frame, L, P, E = ti.static(ctx.frame, ctx.L, ctx.P, ctx.E)
        scale, keep, t_b = ctx.scale, ctx.keep, ctx.t_b
        p = luminance_change(frame, L, P, i, j, n, scale, keep, False)
        e = ti.select(ti.abs(p) >= t_b, 1.0, 0.0)
        run_store(E, i, j, e, n)
        return run_sum(e, n)


    @ti.kernel
    def load_binary(frame: ti.types.ndarray(ndim=2), L: F2, P: F2, E: F2, scale: ti.f32, first: ti.i32,
                    t_b: ti.f32, blocks: ti.i32, out: D1):
        """``g = frame * scale`` in [0, 1]; ``P = g - L`` (0 when ``first``); ``E = [|P| >= t_b]``;
        adds ``sum E`` to ``out[0]`` (set to 0 by the caller)."""
        H, W = L.shape[0], L.shape[1]
        keep = ti.select(first != 0, 0.0, 1.0)
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(LoadRunCtx(frame, L, P, E, scale, keep, t_b))
            ti.atomic_add(out[0], row_runs(_load_run, ctx, i, j0, j1, H, W, "sum", 1))


    @ti.func
    def _act(u, theta_scale):
        """Firing rate ``f(u) = theta([u]+) = tanh([u]+) / tanh(1)``."""
        return tanh_rational(ti.max(u, 0.0)) * theta_scale


    UpdateRunCtx = context("UpdateRunCtx", "E row1 row2 u_new F_new g1 g2 A B_t h theta_scale R")

    @ti.func
    def _update_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        E, row1, row2, u_new, F_new, g1, g2 = ti.static(ctx.E, ctx.row1, ctx.row2, ctx.u_new, ctx.F_new, ctx.g1, ctx.g2)
        A, B_t, h, theta_scale = ctx.A, ctx.B_t, ctx.h, ctx.theta_scale
        R = ti.static(ctx.R)
        lateral = dog_column_run(row1, row2, g1, g2, A, B_t, i, j, n, REPLICATE, R)
        v = run_load(E, i, j, n) - h + tanh_rational(0.5 * lateral)
        run_store(u_new, i, j, v, n)
        f = _act(v, theta_scale)
        run_store(F_new, i, j, f, n)
        return run_sum(f, n)


    @ti.kernel
    def field_update(
        E: F2, F: F2, row1: F2, row2: F2, u_new: F2, F_new: F2, g1: F1, g2: F1,
        A: ti.f32, B_t: ti.f32, h: ti.f32, theta_scale: ti.f32, blocks: ti.i32, R: ti.template(), out: D1,
    ):
        """``u_new = E - h + vartheta(A g1g1 (*) F - B_t g2g2 (*) F)``, ``F_new = f(u_new)``;
        adds ``sum F_new`` to ``out[0]`` (set to 0 by the caller).

        ``F = f(u(t-1))`` is the previous frame's firing rate (time-delayed lateral
        interaction); ``vartheta(a) = tanh(a / 2)``; ``R``: the DoG radius (``g1``/``g2`` have ``2R + 1`` taps).
        """
        H, W = F.shape[0], F.shape[1]
        dog_row_pass(F, row1, row2, g1, g2, blocks, REPLICATE, R)
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(UpdateRunCtx(E, row1, row2, u_new, F_new, g1, g2, A, B_t, h, theta_scale, R))
            ti.atomic_add(out[0], row_runs(_update_run, ctx, i, j0, j1, H, W, "sum", 1))

    return namespace(globals(), locals())
