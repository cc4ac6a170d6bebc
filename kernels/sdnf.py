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

from ..taichi_runtime import scalar_kernel
from . import common
from .common import REPLICATE, context, namespace  # noqa: F401 - part of this module's interface

# -- the state: a stacked float32 array (PLANES, H, W) per backend; the DoG's row passes, (2, H, W);
# the firing rates f(u) of the last two frames, two (H, W) arrays (the DoG's input, dog_row_pass).
# The row passes are an array of their own: read from the array that the update writes (u), the
# column pass compiled to other roundings (the traces were no longer bit-identical).
L_, P_ = common.L_PLANE, common.P_PLANE  # photoreceptors (the last frame), luminance change P
E_ = 2  # the binary input E
U_ = 3  # the field u
PLANES = 4

# -- a backend's coefficients: one float32 array, set once (cdnf_ti.backends.sdnf) --
DOG_A, H_REST, THETA, T_B = 0, 1, 2, 3  # A; h; theta's scale 1 / tanh(1); the binary threshold T_b
TAPS = 4  # the DoG profiles g1, g2 (2 R + 1 each)
#: The update's coefficients in a work item's local vector (read once per work item, not once per run:
#: read where the runs use them, they compiled to other roundings).
RUN_A, RUN_H, RUN_THETA = 0, 1, 2


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The kernels of this module for the DSL module ``ti`` (taichi or quadrants) and ``lanes``
    lanes per vector element of the fast path: a namespace of every name below (and the
    module-level constants). Built once per (compiler, lanes), after the runtime started."""
    C = common.build(ti, lanes)
    COEFS = C.COEFS
    F3 = C.F3
    F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    dog_column_run = C.dog_column_run
    dog_row_pass = C.dog_row_pass
    fill = C.fill
    fill_planes = C.fill_planes
    frame_runs = C.frame_runs
    photoreceptors = C.photoreceptors
    plane_load = C.plane_load
    plane_store = C.plane_store
    run_store = C.run_store
    run_sum = C.run_sum
    tanh_rational = C.tanh_rational

    D1 = ti.types.ndarray(dtype=ti.f64, ndim=1)  # a launch's results ``out``, set by the caller before it


    LoadRunCtx = context("LoadRunCtx", "frame x coef scale keep", grid="x")

    @ti.func
    def _load_run(ctx: ti.template(), i, j, n: ti.template()):
        x, frame = ti.static(ctx.x, ctx.frame)
        e = ti.Vector([0.0] * n, dt=ti.f32)
        if ti.static(len(frame.shape) == 3):  # an event bin: (p_on, p_off)
            p_on = plane_load(frame, 0, i, j, n)
            p_off = plane_load(frame, 1, i, j, n)
            plane_store(x, P_, i, j, p_on - p_off, n)
            e = ti.select(ti.max(p_on, p_off) >= ctx.coef[T_B], 1.0, 0.0)
        else:
            p = photoreceptors(frame, x, i, j, n, ctx.scale, ctx.keep)
            e = ti.select(ti.abs(p) >= ctx.coef[T_B], 1.0, 0.0)
        plane_store(x, E_, i, j, e, n)
        return run_sum(e, n)


    @ti.kernel
    def load_binary(frame: ti.types.ndarray(), x: F3, coef: COEFS, scale: ti.f32, first: ti.i32,
                    blocks: ti.i32, out: D1):
        """``g = frame * scale`` in [0, 1]; ``P = g - L`` (0 when ``first``); ``E = [|P| >= T_b]``;
        or, for an event bin ``frame`` (2, H, W) of ``(p_on, p_off)``, ``P = p_on - p_off`` and
        ``E = [max(p_on, p_off) >= T_b]``; adds ``sum E`` to ``out[0]`` (set to 0 by the caller)."""
        keep = ti.select(first != 0, 0.0, 1.0)
        for k in range(x.shape[1] * blocks):
            ctx = ti.static(LoadRunCtx(frame, x, coef, scale, keep))
            ti.atomic_add(out[0], frame_runs(_load_run, ctx, k, blocks, "sum", 1))


    @ti.func
    def _act(u, theta_scale):
        """Firing rate ``f(u) = theta([u]+) = tanh([u]+) / tanh(1)``."""
        return tanh_rational(ti.max(u, 0.0)) * theta_scale


    UpdateRunCtx = context("UpdateRunCtx", "x rows F_new coef B_t run", grid="x")

    @functools.lru_cache(maxsize=None)
    def field_update_kernel(R: int):
        """The field update for a DoG of radius ``R`` (a compile-time choice: the taps unroll;
        one kernel per radius, compiled once)."""

        @ti.func
        def _update_run(ctx: ti.template(), i, j, n: ti.template()):
            x, F_new = ti.static(ctx.x, ctx.F_new)
            lateral = dog_column_run(ctx.rows, 0, ctx.coef, TAPS, ctx.run[RUN_A], ctx.B_t, i, j, n, REPLICATE, R)
            v = plane_load(x, E_, i, j, n) - ctx.run[RUN_H] + tanh_rational(0.5 * lateral)
            plane_store(x, U_, i, j, v, n)
            f = _act(v, ctx.run[RUN_THETA])
            run_store(F_new, i, j, f, n)
            return run_sum(f, n)

        @ti.kernel
        def field_update(x: F3, F: F2, F_new: F2, rows: F3, coef: COEFS, B_t: ti.f32, blocks: ti.i32, out: D1):
            """``u = E - h + vartheta(A g1g1 (*) F - B_t g2g2 (*) F)``, ``F_new = f(u)``;
            adds ``sum F_new`` to ``out[0]`` (set to 0 by the caller).

            ``F = f(u(t-1))`` is the previous frame's firing rate (time-delayed lateral
            interaction); ``vartheta(a) = tanh(a / 2)``; ``rows``: the DoG's row passes (scratch).
            """
            dog_row_pass(F, rows, 0, coef, TAPS, blocks, REPLICATE, R)
            for k in range(x.shape[1] * blocks):
                # the coefficients into a local (RUN_A, ...; an expression in the context would be
                # evaluated where the runs use it)
                run = ti.Vector([coef[DOG_A], coef[H_REST], coef[THETA]], dt=ti.f32)
                ctx = ti.static(UpdateRunCtx(x, rows, F_new, coef, B_t, run))
                ti.atomic_add(out[0], frame_runs(_update_run, ctx, k, blocks, "sum", 1))

        return scalar_kernel(field_update)

    return namespace(globals(), locals())
