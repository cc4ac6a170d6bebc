"""Taichi kernels of the C-DNF fields (float32 state, float64 integration).

Two sets of kernels compute the same equations:

* the generic kernels (``load_frame``, ``contrast_solve``, ``summation_solve``, ...)
  take ``ti.ndarray``/NumPy arrays of shape (H, W), so one compiled kernel serves
  every frame size; used for frames narrower than ``2 * LANES`` pixels and on GPUs
  (up to ``MAX_STEPS`` updates per launch, one parallel loop each);
* the fast CPU kernels (``lanes_*``) work on lane arrays (vector ndarrays of ``LANES``
  columns per element, :data:`~cdnf_ti.kernels.common.LANE2`) with ghost columns, visit
  only the rows and columns near a change (pending spans), and run a whole solve in one
  launch with persistent workers (see the sections below and ``docs/PERFORMANCE.md``).
  They compile with explicit vector types (:func:`~cdnf_ti.taichi_runtime.vector_kernel`),
  so their lane arithmetic runs in the host's full-width registers under both compilers;
  hence :func:`~cdnf_ti.kernels.common.any_lane` and :func:`~cdnf_ti.kernels.common.lane_abs`
  in place of ``.any()`` and ``ti.abs`` there.

``mode`` is a compile-time border code from :mod:`cdnf_ti.kernels.common`. The
float64 NumPy reference of the same equations is :mod:`cdnf_ti.reference`.
"""


import functools
from types import SimpleNamespace

from ..taichi_runtime import vector_kernel
from . import common, schedule
from .common import RECORD_COEFS, namespace
from .schedule import Plan, context

# -- pending spans ---------------------------------------------------------------
# Each field group (ON+OFF; Summation) keeps, per ping-pong parity and row, the span
# ``(lo, hi)`` of lane elements where something changed: a field value moved by more
# than ``tau`` in the last update, or the group's input changed (a new frame, a new
# Summation input). An update visits only the elements within one element and one
# kernel radius (rows) of a pending span; a pixel whose update |F(u) - u| is at most
# ``tau`` keeps its value exactly. A pixel left out has seen none of its inputs change
# since it was last visited with every |F(u) - u| <= tau, so its residual is still
# <= tau < tol; both ping-pong buffers hold equal values there.

EMPTY_LO = 1 << 30  # (EMPTY_LO, EMPTY_HI): an empty span
EMPTY_HI = -1


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The kernels of this module for the DSL module ``ti`` (taichi or quadrants) and ``lanes``
    lanes per vector element of the fast path: a namespace of every name below (and the
    module-level constants). Built once per (compiler, lanes), after the runtime started."""
    C = common.build(ti, lanes)
    workers = schedule.build(ti, lanes).workers
    LANE2 = C.LANE2
    LANE3 = C.LANE3
    LANES = C.LANES
    any_lane = C.any_lane
    block_span = C.block_span
    border_index = C.border_index
    border_weight = C.border_weight
    dog_column_run = C.dog_column_run
    dog_row_item = C.dog_row_item
    fill = C.fill
    fill_ghosts = C.fill_ghosts
    lane_abs = C.lane_abs
    lane_array = C.lane_array
    lane_layout = C.lane_layout
    lane_mask = C.lane_mask
    lane_neighbours = C.lane_neighbours
    lane_shift = C.lane_shift
    launch_gate = C.launch_gate
    local_start = C.local_start
    luminance_change = C.luminance_change
    record_residuals = C.record_residuals
    row_runs = C.row_runs
    run_load = C.run_load
    run_max = C.run_max
    run_store = C.run_store
    start_coefficients = C.start_coefficients
    tanh_rational = C.tanh_rational

    F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    F1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
    D1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    #: A launch record (:class:`~cdnf_ti.kernels.common.LaunchRecord`): (lam, mom) in, residuals out.
    RECORD = ti.types.ndarray(dtype=ti.f32, ndim=2)
    #: The local starts of the contrast (row 0) and Summation (row 1) fields, float32 (2, 7)
    #: (:func:`cdnf_ti.solver.cdnf_local_starts`); a kernel given ``local = 0`` leaves the fields as they are.
    START = ti.types.ndarray(dtype=ti.f32, ndim=2)




    @ti.func
    def field_update(inp, lateral, u, prev, h, lam, mom):
        """The one statement of a C-DNF field update (scalars or lane vectors alike).

        ``F(u) = inp - h + vartheta(lateral)`` with ``vartheta(a) = tanh(a / 2)``;
        returns ``(u + mom (u - prev) + lam (F(u) - u), F(u) - u)``: plain relaxation for
        ``mom = 0``, a Chebyshev step otherwise (``prev``: the iterate before ``u``).
        """
        d = inp - h + tanh_rational(0.5 * lateral) - u
        return u + mom * (u - prev) + lam * d, d


    @ti.func
    def contrast_input(p, sign):
        """The ON/OFF input stage: ``P_on = [P]+`` (``sign = 1``) or ``P_off = [-P]+`` (``sign = -1``) of the
        luminance change ``P`` (scalar or lane vector), the input of the ON/OFF contrast fields."""
        return ti.max(sign * p, 0.0)

    LoadRunCtx = context("LoadRunCtx", "frame L P u_on u_off scale keep local cs")

    @ti.func
    def _load_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        frame, L, P, u_on, u_off = ti.static(ctx.frame, ctx.L, ctx.P, ctx.u_on, ctx.u_off)
        p = luminance_change(frame, L, P, i, j, n, ctx.scale, ctx.keep, False)
        if ctx.local != 0:
            run_store(u_on, i, j, local_start(contrast_input(p, 1.0), ctx.cs), n)
            run_store(u_off, i, j, local_start(contrast_input(p, -1.0), ctx.cs), n)
        return 0.0


    @ti.kernel
    def load_frame(frame: ti.types.ndarray(ndim=2), L: F2, P: F2, scale: ti.f32, first: ti.i32, blocks: ti.i32,
                   u_on: F2, u_off: F2, start: START, local: ti.i32):
        """``g = frame * scale``; ``P = g - L`` (0 when ``first``); ``L = g``; with ``local``,
        ``u_on = start(P_on)`` and ``u_off = start(P_off)`` (:func:`local_start`, row 0 of ``start``)."""
        H, W = L.shape[0], L.shape[1]
        keep = ti.select(first != 0, 0.0, 1.0)
        for k in range(H * blocks):
            cs = start_coefficients(start, 0)
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(LoadRunCtx(frame, L, P, u_on, u_off, scale, keep, local, cs))
            row_runs(_load_run, ctx, i, j0, j1, H, W, "sum", 1)


    @ti.kernel
    def copy(src: F2, dst: F2):
        """``dst = src``."""
        for i, j in src:
            dst[i, j] = src[i, j]


    @ti.func
    def _lateral_3x3(u: ti.template(), i, j, H, W, wc0, wc1, wc2, mode: ti.template()):
        """``W_c (*) u`` at (i, j): wc0 centre, wc1 edge, wc2 diagonal weight."""
        im = border_index(i - 1, H, mode)
        ip = border_index(i + 1, H, mode)
        jm = border_index(j - 1, W, mode)
        jp = border_index(j + 1, W, mode)
        wim = border_weight(i - 1, H, mode)
        wip = border_weight(i + 1, H, mode)
        wjm = border_weight(j - 1, W, mode)
        wjp = border_weight(j + 1, W, mode)
        edge = wim * u[im, j] + wip * u[ip, j] + wjm * u[i, jm] + wjp * u[i, jp]
        diag = wim * (wjm * u[im, jm] + wjp * u[im, jp]) + wip * (wjm * u[ip, jm] + wjp * u[ip, jp])
        return wc0 * u[i, j] + wc1 * edge + wc2 * diag


    @ti.func
    def _contrast_update(P: ti.template(), u_on: ti.template(), u_off: ti.template(), out_on: ti.template(),
                         out_off: ti.template(), wc0, wc1, wc2, h, record: ti.template(), j: ti.template(), n, tol,
                         grow, blocks, mode: ti.template()):
        """Update ``j`` of a :func:`contrast_solve` launch: one parallel loop, each work item gated by
        :func:`launch_gate`; its residuals go to ``record[j, 2:4]``."""
        H, W = P.shape[0], P.shape[1]
        for k in range(H * blocks):
            if launch_gate(record, j, n, tol, grow, 2) != 0:
                lam = record[j, 0]
                mom = record[j, 1]
                i, j0, j1 = block_span(k, W, blocks)
                m_on = 0.0
                m_off = 0.0
                for c in range(j0, j1):
                    p = P[i, c]
                    s_on = _lateral_3x3(u_on, i, c, H, W, wc0, wc1, wc2, mode)
                    s_off = _lateral_3x3(u_off, i, c, H, W, wc0, wc1, wc2, mode)
                    n_on, d_on = field_update(contrast_input(p, 1.0), s_on, u_on[i, c], out_on[i, c], h, lam, mom)
                    n_off, d_off = field_update(contrast_input(p, -1.0), s_off, u_off[i, c], out_off[i, c], h, lam, mom)
                    out_on[i, c] = n_on
                    out_off[i, c] = n_off
                    m_on = ti.max(m_on, ti.abs(d_on))
                    m_off = ti.max(m_off, ti.abs(d_off))
                ti.atomic_max(record[j, RECORD_COEFS], m_on)
                ti.atomic_max(record[j, RECORD_COEFS + 1], m_off)


    @ti.kernel
    def contrast_solve(
        P: F2, on_a: F2, off_a: F2, on_b: F2, off_b: F2,
        wc0: ti.f32, wc1: ti.f32, wc2: ti.f32, h: ti.f32, record: RECORD, n: ti.i32, tol: ti.f32, grow: ti.f32,
        blocks: ti.i32, mode: ti.template(), steps: ti.template(),
    ):
        """Up to ``n`` ON/OFF updates (fused, :func:`field_update`) in one launch: the generic kernel.

        ``F(u) = P_on - h + vartheta(W_c (*) u)`` (OFF: ``P_off``). Update ``j`` reads the
        ``_a`` buffers (``j`` even) or the ``_b`` ones and writes the others, which hold the
        iterate before on entry, with ``lam, mom = record[j, 0:2]``; its residuals
        ``max|F(u_on) - u_on|``, ``max|F(u_off) - u_off|`` go to ``record[j, 2:4]`` (set to -1 by
        the caller, :class:`~cdnf_ti.kernels.common.LaunchRecord`). The updates stop after the
        first one whose residuals are both ``<= tol``, or one whose worst exceeds ``grow`` times
        the best of the launch. One parallel loop per update (``MAX_STEPS`` of them, those past
        the stop doing nothing): the kernel for GPUs and narrow frames.
        """
        for j in ti.static(range(steps)):
            if ti.static(j % 2 == 0):
                _contrast_update(P, on_a, off_a, on_b, off_b, wc0, wc1, wc2, h, record, j, n, tol, grow, blocks, mode)
            else:
                _contrast_update(P, on_b, off_b, on_a, off_a, wc0, wc1, wc2, h, record, j, n, tol, grow, blocks, mode)


    @ti.kernel
    def summation_input(u_on: F2, u_off: F2, S: F2, alpha_on: ti.f32, alpha_off: ti.f32, theta_scale: ti.f32,
                        v: F2, start: START, local: ti.i32):
        """``S = alpha_on theta([u_on]+) + alpha_off theta([u_off]+)``; with ``local``,
        ``v = start(S)`` (:func:`local_start`, row 1 of ``start``)."""
        for i, j in S:
            a_on = tanh_rational(ti.max(u_on[i, j], 0.0)) * theta_scale
            a_off = tanh_rational(ti.max(u_off[i, j], 0.0)) * theta_scale
            s = alpha_on * a_on + alpha_off * a_off
            S[i, j] = s
            if local != 0:
                v[i, j] = local_start(s, start_coefficients(start, 1))


    SummationRunCtx = context("SummationRunCtx", "S v row1 row2 out g1 g2 A B h lam mom mode R")

    @ti.func
    def _summation_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        S, v, row1, row2, out, g1, g2 = ti.static(ctx.S, ctx.v, ctx.row1, ctx.row2, ctx.out, ctx.g1, ctx.g2)
        A, B, h, lam, mom = ctx.A, ctx.B, ctx.h, ctx.lam, ctx.mom
        mode, R = ti.static(ctx.mode, ctx.R)
        lateral = dog_column_run(row1, row2, g1, g2, A, B, i, j, n, mode, R)
        nv, dv = field_update(run_load(S, i, j, n), lateral, run_load(v, i, j, n), run_load(out, i, j, n), h, lam, mom)
        run_store(out, i, j, nv, n)
        return run_max(ti.abs(dv), n)


    @ti.func
    def _summation_update(S: ti.template(), v: ti.template(), row1: ti.template(), row2: ti.template(),
                          out: ti.template(), g1: ti.template(), g2: ti.template(), A, B, h, record: ti.template(),
                          j: ti.template(), n, tol, grow, blocks, mode: ti.template(), R: ti.template()):
        """Update ``j`` of a :func:`summation_solve` launch: the row pass, then the column pass and
        the update, two parallel loops gated by :func:`launch_gate`; its residual goes to ``record[j, 2]``."""
        H, W = v.shape[0], v.shape[1]
        for k in range(H * blocks):
            if launch_gate(record, j, n, tol, grow, 1) != 0:
                dog_row_item(v, row1, row2, g1, g2, k, blocks, mode, R)
        for k in range(H * blocks):
            if launch_gate(record, j, n, tol, grow, 1) != 0:
                lam = record[j, 0]
                mom = record[j, 1]
                i, j0, j1 = block_span(k, W, blocks)
                ctx = ti.static(SummationRunCtx(S, v, row1, row2, out, g1, g2, A, B, h, lam, mom, mode, R))
                r = row_runs(_summation_run, ctx, i, j0, j1, H, W, "max", 1)
                ti.atomic_max(record[j, RECORD_COEFS], ti.cast(r, ti.f32))


    @ti.kernel
    def summation_solve(
        S: F2, v_a: F2, v_b: F2, row1: F2, row2: F2, g1: F1, g2: F1,
        A: ti.f32, B: ti.f32, h: ti.f32, record: RECORD, n: ti.i32, tol: ti.f32, grow: ti.f32,
        blocks: ti.i32, mode: ti.template(), R: ti.template(), steps: ti.template(),
    ):
        """Up to ``n`` Summation updates (:func:`field_update`) in one launch: the generic kernel.

        The DoG ``W_s = A g1 g1^T - B g2 g2^T`` is applied as separable passes:
        ``row1 = g1 (*)_x v``, ``row2 = g2 (*)_x v``, then
        ``W_s (*) v = A g1 (*)_y row1 - B g2 (*)_y row2`` (exact for every border
        mode; ``R``: the compile-time radius of ``g1``/``g2``).
        ``F(v) = S - h + vartheta(W_s (*) v)``. Buffers, record and stopping as in
        :func:`contrast_solve` (one residual, ``max|F(v) - v|``, in ``record[j, 2]``).
        """
        for j in ti.static(range(steps)):
            if ti.static(j % 2 == 0):
                _summation_update(S, v_a, row1, row2, v_b, g1, g2, A, B, h, record, j, n, tol, grow, blocks, mode, R)
            else:
                _summation_update(S, v_b, row1, row2, v_a, g1, g2, A, B, h, record, j, n, tol, grow, blocks, mode, R)


    @ti.kernel
    def mean_activation(v: F2, theta_scale: ti.f32, blocks: ti.i32, total: D1):
        """``total[0] += sum_xy theta([v]+)``, accumulated in float64 (the caller zeroes it and
        divides by ``H W``: no float64 return value, see :class:`~cdnf_ti.kernels.common.LaunchRecord`)."""
        H, W = v.shape[0], v.shape[1]
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            acc = ti.f64(0.0)
            for j in range(j0, j1):
                acc += ti.cast(tanh_rational(ti.max(v[i, j], 0.0)) * theta_scale, ti.f64)
            ti.atomic_add(total[0], acc)
    SPAN = ti.types.vector(2, ti.i32)
    #: Pending spans of a field group: one :data:`SPAN` per parity and row, shape (2, H).
    SPANS = ti.types.ndarray(dtype=SPAN, ndim=2)


    @ti.func
    def _visit_span(pend: ti.template(), p, i0, i1, H, E1):
        """Elements ``[e0, e1)`` to visit: pending rows ``i0..i1`` (clipped) of parity ``p``, one element
        either side."""
        lo = EMPTY_LO
        hi = EMPTY_HI
        for r in range(ti.max(i0, 0), ti.min(i1, H - 1) + 1):
            lo = ti.min(lo, pend[p, r][0])
            hi = ti.max(hi, pend[p, r][1])
        return ti.max(lo - 1, 1), ti.min(hi + 1, E1) + 1


    @vector_kernel
    @ti.kernel
    def lanes_pending_all(pend: SPANS, W: ti.template()):
        """Every element of every row pending, both parities (after a change made outside the kernels)."""
        for p, i in pend:
            pend[p, i] = ti.Vector([1, (LANES + W - 1) // LANES])


    # -- frame, Summation input, mean activation -------------------------------------------

    @ti.func
    def _start_element(x: ti.template(), p, i, e, inp, cs, W: ti.template()):
        """Element ``(i, e)`` of buffer ``p`` of ``x`` = :func:`local_start` of the input ``inp`` (a lane
        vector, >= 0) on the frame columns; returns whether any value changed.

        An element without input (common: static background, and where a field is off) starts at
        the resting level ``cs[0]`` without evaluating the fit.
        """
        new = ti.Vector([cs[0]] * LANES, dt=ti.f32)
        if any_lane(inp > 0.0):
            new = local_start(inp, cs)
        old = x[p, i, e]
        new = ti.select(lane_mask(e, W) > 0.0, new, old)
        x[p, i, e] = new
        return any_lane(new != old)


    @ti.func
    def _load_row(frame: ti.template(), L: ti.template(), P: ti.template(), scale, first, W: ti.template(),
                  pend: ti.template(), pp, i, u_on: ti.template(), u_off: ti.template(), start: ti.template(), local,
                  mode: ti.template()):
        """Row ``i``: ``g = frame * scale``; ``P = g - L`` (0 when ``first``); ``L = g`` (frame columns only);
        with ``local``, buffer ``pp`` of ``u_on``/``u_off`` = :func:`local_start` of ``P_on``/``P_off``.

        Elements where ``P`` or a field changed join the row's pending span of parity ``pp``
        (contrast group).
        """
        E1 = (LANES + W - 1) // LANES
        cs = start_coefficients(start, 0)
        lo = EMPTY_LO
        hi = EMPTY_HI
        for e in range(1, E1 + 1):
            g = ti.Vector([0.0] * LANES, dt=ti.f32)
            for l in ti.static(range(LANES)):
                c = ti.min((e - 1) * LANES + l, W - 1)
                g[l] = ti.cast(frame[i, c], ti.f32) * scale
            p_new = ti.select(first != 0, 0.0, g - L[i, e])
            moved = any_lane(p_new != P[i, e])
            if local != 0:
                moved |= _start_element(u_on, pp, i, e, ti.max(p_new, 0.0), cs, W)
                moved |= _start_element(u_off, pp, i, e, ti.max(0.0 - p_new, 0.0), cs, W)
            lo = ti.select(moved, ti.min(lo, e), lo)
            hi = ti.select(moved, e, hi)
            P[i, e] = p_new
            L[i, e] = g
        if lo <= hi:
            pend[pp, i] = ti.Vector([ti.min(pend[pp, i][0], lo), ti.max(pend[pp, i][1], hi)])
            if local != 0:
                fill_ghosts(u_on, pp, i, 1, 1, W, 1, mode)
                fill_ghosts(u_off, pp, i, 1, 1, W, 1, mode)


    @vector_kernel
    @ti.kernel
    def lanes_load_frame(frame: ti.types.ndarray(ndim=2), L: LANE2, P: LANE2, scale: ti.f32,
                         first: ti.i32, W: ti.template(), pend: SPANS, pp: ti.i32, u_on: LANE3,
                         u_off: LANE3, start: START, local: ti.i32, mode: ti.template()):
        """:func:`_load_row` for every row. The contrast solve loads a frame itself (its first
        phase); this kernel serves a frame whose fields are needed before that."""
        for i in range(L.shape[0]):
            _load_row(frame, L, P, scale, first, W, pend, pp, i, u_on, u_off, start, local, mode)


    @vector_kernel
    @ti.kernel
    def lanes_refresh_ghosts(x: LANE3, W: ti.template(), mode: ti.template()):
        """Set the ghost columns of every row of both buffers of ``x`` from its frame columns (border mode)."""
        for p, i in ti.ndrange(2, x.shape[1]):
            fill_ghosts(x, p, i, 1, 1, W, LANES - 1, mode)


    @ti.func
    def _summation_input_row(u_on: ti.template(), u_off: ti.template(), c, S: ti.template(), pend: ti.template(), i,
                             alpha_on, alpha_off, theta_scale, W: ti.template(), v: ti.template(), s,
                             start: ti.template(), local, mode: ti.template(), R: ti.template()):
        """Row ``i`` of ``S = alpha_on theta([u_on]+) + alpha_off theta([u_off]+)`` (buffers ``c``);
        with ``local``, buffer ``s`` of ``v`` = :func:`local_start` of ``S`` (``R``: the DoG radius,
        the ghost columns to refresh).

        Elements where S or v changed join the row's pending span in both parities of the
        Summation group (the next update overwrites the other parity anyway).
        """
        E1 = (LANES + W - 1) // LANES
        cs = start_coefficients(start, 1)
        lo = EMPTY_LO
        hi = EMPTY_HI
        for e in range(1, E1 + 1):
            a_on = tanh_rational(ti.max(u_on[c, i, e], 0.0)) * theta_scale
            a_off = tanh_rational(ti.max(u_off[c, i, e], 0.0)) * theta_scale
            s_new = alpha_on * a_on + alpha_off * a_off
            moved = any_lane(s_new != S[i, e])
            if local != 0:
                moved |= _start_element(v, s, i, e, s_new, cs, W)
            lo = ti.select(moved, ti.min(lo, e), lo)
            hi = ti.select(moved, e, hi)
            S[i, e] = s_new
        if lo <= hi:
            for q in ti.static(range(2)):
                pend[q, i] = ti.Vector([ti.min(pend[q, i][0], lo), ti.max(pend[q, i][1], hi)])
            if local != 0:
                fill_ghosts(v, s, i, 1, 1, W, R, mode)


    @vector_kernel
    @ti.kernel
    def lanes_summation_input(u_on: LANE3, u_off: LANE3, c: ti.i32, S: LANE2,
                              alpha_on: ti.f32, alpha_off: ti.f32, theta_scale: ti.f32, W: ti.template(),
                              pend: SPANS, v: LANE3, s: ti.i32, start: START, local: ti.i32,
                              mode: ti.template(), R: ti.template()):
        """``S = alpha_on theta([u_on]+) + alpha_off theta([u_off]+)`` and the Summation field's local
        start (see :func:`_summation_input_row`).

        The contrast solve computes S itself when it converges; this kernel serves the
        other cases (a solve that ended unconverged, a state restored from NumPy).
        """
        for i in range(S.shape[0]):
            _summation_input_row(u_on, u_off, c, S, pend, i, alpha_on, alpha_off, theta_scale, W, v, s, start, local,
                                 mode, R)


    @ti.func
    def _activation_row(v: ti.template(), s, i, theta_scale, W: ti.template()):
        """``sum theta([v]+)`` over the frame columns of row ``i`` of buffer ``s``, in float64."""
        E1 = (LANES + W - 1) // LANES
        acc = ti.f64(0.0)
        for e in range(1, E1 + 1):
            a = tanh_rational(ti.max(v[s, i, e], 0.0)) * theta_scale * lane_mask(e, W)
            acc += ti.cast(a.sum(), ti.f64)
        return acc


    @vector_kernel
    @ti.kernel
    def lanes_mean_activation(v: LANE3, s: ti.i32, theta_scale: ti.f32, W: ti.template(), total: D1):
        """``total[0] += sum_xy theta([v]+)`` of buffer ``s`` over the frame columns, in float64
        (as :func:`mean_activation`: the caller zeroes it and divides by ``H W``).

        The Summation solve computes the mean itself when it converges; this kernel serves the
        other cases.
        """
        for i in range(v.shape[1]):
            ti.atomic_add(total[0], _activation_row(v, s, i, theta_scale, W))


    # -- the contrast solve --------------------------------------------------------------

    @ti.func
    def _relax(x: ti.template(), p, q, i, e, inp, lateral, h, lam, mom, tau, W: ti.template(), m, lo, hi):
        """Element ``e`` of row ``i``: buffer ``q`` = the update (:func:`field_update`) of buffer ``p``.

        Lanes with ``|F(u) - u| <= tau`` keep their value (frozen). Returns the row's running
        lane-wise max |F(u) - u| and first/last element where a value moved, with ``e`` added.
        """
        xc = x[p, i, e]
        nx, d = field_update(inp, lateral, xc, x[q, i, e], h, lam, mom)
        ad = lane_abs(d) * lane_mask(e, W)
        x[q, i, e] = ti.select(ad > tau, nx, xc)
        moved = run_max(ad, LANES) > tau
        return ti.max(m, ad), ti.select(moved, ti.min(lo, e), lo), ti.select(moved, e, hi)


    @ti.func
    def _contrast_row(P: ti.template(), u: ti.template(), p, q, sign: ti.template(), i, im, ip, wim, wip,
                      e0, e1, ctx: ti.template(), lam, mom):
        """Update elements ``e0..e1-1`` of row ``i`` of one contrast field from buffer ``p`` into buffer ``q``.

        ``u[q]`` holds the previous iterate on entry (:func:`field_update`). Returns the
        lane-wise max |F(u) - u| and the first and last element where a value moved.

        ``W_c = k k^T`` is separable (``k = (k1, k0, k1)``): vertical sums
        ``c = k0 u[i] + k1 (u[i-1] + u[i+1])`` are carried along the row (one new
        element per step, only the last lane of the previous one), then
        ``W_c (*) u = k0 c + k1 (c[j-1] + c[j+1])``.
        """
        W = ti.static(ctx.W)
        k0, k1, h, tau = ctx.k0, ctx.k1, ctx.h, ctx.tau
        m = ti.Vector([0.0] * LANES, dt=ti.f32)
        lo = EMPTY_LO
        hi = EMPTY_HI
        c_left = k0 * u[p, i, e0 - 1][LANES - 1] + k1 * (wim * u[p, im, e0 - 1][LANES - 1]
                                                         + wip * u[p, ip, e0 - 1][LANES - 1])
        c_cur = k0 * u[p, i, e0] + k1 * (wim * u[p, im, e0] + wip * u[p, ip, e0])
        for e in range(e0, e1):
            c_next = k0 * u[p, i, e + 1] + k1 * (wim * u[p, im, e + 1] + wip * u[p, ip, e + 1])
            left, right = lane_neighbours(c_left, c_cur, c_next[0])
            s = k0 * c_cur + k1 * (left + right)
            m, lo, hi = _relax(u, p, q, i, e, contrast_input(P[i, e], sign), s, h, lam, mom, tau, W, m, lo, hi)
            c_left = c_cur[LANES - 1]
            c_cur = c_next
        return m, lo, hi


    @ti.func
    def _load_stage(ctx: ti.template(), i0, i1, j):
        """Rows ``[i0, i1)`` of the frame (:func:`_load_row`)."""
        for i in range(i0, i1):
            _load_row(ctx.frame, ctx.L, ctx.P, ctx.scale, ctx.first, ctx.W, ctx.pend, ctx.c, i, ctx.u_on, ctx.u_off,
                      ctx.start, ctx.local, ctx.mode)

    @ti.func
    def _loads(ctx: ti.template()):
        """Whether the contrast launch loads a frame first."""
        return ctx.load

    @ti.func
    def _contrast_stage(ctx: ti.template(), i0, i1, j):
        """Update ``j`` of both contrast fields on rows ``[i0, i1)``; maxes the residuals into ``rbuf[j, 0:2]``."""
        H = ctx.P.shape[0]
        W, mode = ti.static(ctx.W, ctx.mode)
        E1 = (LANES + W - 1) // LANES
        p = (ctx.c + j) % 2
        q = 1 - p
        lam = ctx.record[j, 0]
        mom = ctx.record[j, 1]
        m_on = 0.0
        m_off = 0.0
        for i in range(i0, i1):
            e0, e1 = _visit_span(ctx.pend, p, i - 1, i + 1, H, E1)
            lo = EMPTY_LO
            hi = EMPTY_HI
            if e0 < e1:
                im = border_index(i - 1, H, mode)
                ip = border_index(i + 1, H, mode)
                wim = ti.f32(border_weight(i - 1, H, mode))
                wip = ti.f32(border_weight(i + 1, H, mode))
                r_on, lo_on, hi_on = _contrast_row(ctx.P, ctx.u_on, p, q, 1.0, i, im, ip, wim, wip, e0, e1, ctx, lam,
                                                   mom)
                r_off, lo_off, hi_off = _contrast_row(ctx.P, ctx.u_off, p, q, -1.0, i, im, ip, wim, wip, e0, e1, ctx,
                                                      lam, mom)
                fill_ghosts(ctx.u_on, q, i, e0 == 1, e1 == E1 + 1, W, 1, mode)
                fill_ghosts(ctx.u_off, q, i, e0 == 1, e1 == E1 + 1, W, 1, mode)
                m_on = ti.max(m_on, run_max(r_on, LANES))
                m_off = ti.max(m_off, run_max(r_off, LANES))
                lo = ti.min(lo_on, lo_off)
                hi = ti.max(hi_on, hi_off)
            ctx.pend[q, i] = ti.Vector([lo, hi])
        ti.atomic_max(ctx.rbuf[j, 0], m_on)
        ti.atomic_max(ctx.rbuf[j, 1], m_off)

    @ti.func
    def _summation_input_stage(ctx: ti.template(), i0, i1, ran):
        """Rows ``[i0, i1)`` of the Summation input of the converged contrast fields (after ``ran`` updates)."""
        f = (ctx.c + ran) % 2  # the buffer holding the result
        for i in range(i0, i1):
            _summation_input_row(ctx.u_on, ctx.u_off, f, ctx.S, ctx.pend_s, i, ctx.alpha_on, ctx.alpha_off,
                                 ctx.theta_scale, ctx.W, ctx.v, ctx.s, ctx.start, ctx.local, ctx.mode, ctx.R)

    #: C-DNF's contrast solve: load the frame (the ON/OFF input stage), update both contrast
    #: fields, and at convergence the Summation input.
    @ti.func
    def _contrast_controls(ctx: ti.template()):
        """The contrast solve's workers, rows, updates at most and stopping rule."""
        return ctx.nw, ctx.P.shape[0], ctx.n, ctx.tol, ctx.grow

    CONTRAST_PLAN = Plan(before=(_load_stage,), runs_before=_loads, update=(_contrast_stage,),
                         after=(_summation_input_stage,), controls=_contrast_controls)
    contrast_workers = workers(CONTRAST_PLAN)
    ContrastCtx = context("ContrastCtx", "frame load L scale first P u_on u_off pend c k0 k1 h record tau rbuf W mode "
                                         "S pend_s alpha_on alpha_off theta_scale v s start local R nw n tol grow")

    @vector_kernel
    @ti.kernel
    def lanes_contrast_solve(
        frame: ti.types.ndarray(ndim=2), load: ti.i32, L: LANE2, scale: ti.f32, first: ti.i32,
        P: LANE2, u_on: LANE3, u_off: LANE3, pend: SPANS, c: ti.i32,
        k0: ti.f32, k1: ti.f32, h: ti.f32, record: RECORD, n: ti.i32,
        tau: ti.f32, tol: ti.f32, grow: ti.f32, nw: ti.i32, sync: ti.template(), rbuf: ti.template(),
        W: ti.template(), mode: ti.template(),
        S: LANE2, pend_s: SPANS, alpha_on: ti.f32, alpha_off: ti.f32, theta_scale: ti.f32,
        v: LANE3, s: ti.i32, start: START, local: ti.i32, R: ti.template(),
    ):
        """Up to ``n`` ON/OFF updates (:func:`field_update`) in one launch, by persistent workers
        (:data:`CONTRAST_PLAN` on the engine's scheduler, :func:`~cdnf_ti.kernels.schedule.build`'s ``workers``).

        Update ``j`` reads buffer ``(c + j) % 2`` of ``u_on``/``u_off`` and writes the other
        one, with ``lam, mom = record[j, 0:2]``; the updates stop after the first one whose
        residuals are both ``<= tol``, or one whose worst residual exceeds ``grow`` times the
        best of the launch. The residuals ``max|F(u) - u|`` of each update (ON, OFF; -1 for
        updates not run) go to ``record[j, 2:4]`` (:class:`~cdnf_ti.kernels.common.LaunchRecord`). Only the
        elements near a pending span (``pend``, same parity as the buffers) are visited.
        With ``load`` set, the workers first load ``frame`` (:func:`_load_row`; with ``local``
        it also sets the contrast fields' local start). When the launch converges, they go on
        to compute the Summation input ``S`` of the result and, with ``local``, the local start
        of buffer ``s`` of ``v`` (:func:`_summation_input_row`; pending spans ``pend_s``).
        """
        ctx = ti.static(ContrastCtx(frame, load, L, scale, first, P, u_on, u_off, pend, c, k0, k1, h, record, tau,
                                    rbuf, W, mode, S, pend_s, alpha_on, alpha_off, theta_scale, v, s, start, local,
                                    R, nw, n, tol, grow))
        contrast_workers(ctx)
        record_residuals(rbuf, record, 2)


    # -- the Summation solve ---------------------------------------------------------------

    @functools.lru_cache(maxsize=None)
    def lanes_summation_kernel(g1: tuple, g2: tuple):
        """The lane-vectorised Summation solve for the DoG profiles ``g1``, ``g2``.

        The taps (``2 R + 1`` floats each, symmetric) are compiled in as constants,
        which saves their per-launch argument passing; one kernel per parameter set.
        Buffers, launch record, stopping, workers and residuals as in
        :func:`lanes_contrast_solve`; each update is two phases (row pass, then column
        pass and update).
        """
        R = (len(g1) - 1) // 2
        G1 = tuple(float(x) for x in g1)
        G2 = tuple(float(x) for x in g2)

        @ti.func
        def _row_pass_stage(ctx: ti.template(), i0, i1, j):
            """Phase 1 of update ``j``: horizontal DoG passes of rows ``[i0, i1)`` wherever a row within
            ``2 R`` needs a visit."""
            H = ctx.S.shape[0]
            E1 = (LANES + ctx.W - 1) // LANES
            v, row1, row2 = ti.static(ctx.v, ctx.row1, ctx.row2)
            p = (ctx.c + j) % 2
            for i in range(i0, i1):
                e0, e1 = _visit_span(ctx.pend, p, i - 2 * R, i + 2 * R, H, E1)
                if e0 < e1:
                    a = v[p, i, e0 - 1]
                    cc = v[p, i, e0]
                    for e in range(e0, e1):
                        nx = v[p, i, e + 1]
                        a1 = ti.static(G1[R]) * cc
                        a2 = ti.static(G2[R]) * cc
                        for d in ti.static(range(1, R + 1)):
                            pair = lane_shift(a, cc, nx, -d) + lane_shift(a, cc, nx, d)
                            a1 += ti.static(G1[R + d]) * pair
                            a2 += ti.static(G2[R + d]) * pair
                        row1[i, e] = a1
                        row2[i, e] = a2
                        a = cc
                        cc = nx

        @ti.func
        def _update_stage(ctx: ti.template(), i0, i1, j):
            """Phase 2 of update ``j``: vertical passes and the update of rows ``[i0, i1)``; maxes the
            residual into ``rbuf[j, 0]``."""
            H = ctx.S.shape[0]
            W, mode = ti.static(ctx.W, ctx.mode)
            E1 = (LANES + W - 1) // LANES
            v, row1, row2, S = ti.static(ctx.v, ctx.row1, ctx.row2, ctx.S)
            p = (ctx.c + j) % 2
            q = 1 - p
            lam = ctx.record[j, 0]
            mom = ctx.record[j, 1]
            mx = 0.0
            for i in range(i0, i1):
                e0, e1 = _visit_span(ctx.pend, p, i - R, i + R, H, E1)
                lo = EMPTY_LO
                hi = EMPTY_HI
                if e0 < e1:
                    m = ti.Vector([0.0] * LANES, dt=ti.f32)
                    for e in range(e0, e1):
                        b1 = ti.static(G1[R]) * row1[i, e]
                        b2 = ti.static(G2[R]) * row2[i, e]
                        for d in ti.static(range(1, R + 1)):
                            iu = border_index(i - d, H, mode)
                            idn = border_index(i + d, H, mode)
                            wu = border_weight(i - d, H, mode)
                            wd = border_weight(i + d, H, mode)
                            b1 += ti.static(G1[R + d]) * (wu * row1[iu, e] + wd * row1[idn, e])
                            b2 += ti.static(G2[R + d]) * (wu * row2[iu, e] + wd * row2[idn, e])
                        m, lo, hi = _relax(v, p, q, i, e, S[i, e], ctx.A * b1 - ctx.B * b2, ctx.h, lam, mom,
                                           ctx.tau, W, m, lo, hi)
                    fill_ghosts(v, q, i, e0 == 1, e1 == E1 + 1, W, R, mode)
                    mx = ti.max(mx, run_max(m, LANES))
                ctx.pend[q, i] = ti.Vector([lo, hi])
            ti.atomic_max(ctx.rbuf[j, 0], mx)

        @ti.func
        def _activation_stage(ctx: ti.template(), i0, i1, ran):
            """``sum theta([v]+)`` of rows ``[i0, i1)`` of the converged field (after ``ran`` updates)
            into ``msum[0]``; ``msum[1] = 1``: computed."""
            f = (ctx.c + ran) % 2  # the buffer holding the result
            acc = ti.f64(0.0)
            for i in range(i0, i1):
                acc += _activation_row(ctx.v, f, i, ctx.theta_scale, ctx.W)
            ti.atomic_add(ctx.msum[0], acc)
            ctx.msum[1] = 1.0

        #: The Summation solve: each update a row pass and a column pass with the update;
        #: at convergence, the mean activation.
        @ti.func
        def _controls(ctx: ti.template()):
            """The Summation solve's workers, rows, updates at most and stopping rule."""
            return ctx.nw, ctx.S.shape[0], ctx.n, ctx.tol, ctx.grow

        plan = Plan(update=(_row_pass_stage, _update_stage), after=(_activation_stage,), controls=_controls)
        summation_workers = workers(plan)
        Ctx = context("SummationCtx", "S v row1 row2 pend c A B h record tau rbuf W mode theta_scale msum "
                                      "nw n tol grow")

        @vector_kernel
        @ti.kernel
        def lanes_summation_solve(
            S: LANE2, v: LANE3, row1: LANE2, row2: LANE2, pend: SPANS,
            c: ti.i32, A: ti.f32, B: ti.f32, h: ti.f32, record: RECORD, n: ti.i32,
            tau: ti.f32, tol: ti.f32, grow: ti.f32, nw: ti.i32, sync: ti.template(), rbuf: ti.template(),
            W: ti.template(), mode: ti.template(), theta_scale: ti.f32, msum: ti.template(), total: D1,
        ):
            """Lane-vectorised :func:`summation_solve` by persistent workers (``plan`` on the engine's
            scheduler): separable DoG, same equations.

            The residuals go to ``record`` (as :func:`lanes_contrast_solve`), and
            ``sum_xy theta([v]+)`` of the result (float64), when the launch converged, to
            ``total[0]`` (else -1), as :func:`lanes_mean_activation` computes it.
            """
            msum[0] = 0.0
            msum[1] = 0.0
            ctx = ti.static(Ctx(S, v, row1, row2, pend, c, A, B, h, record, tau, rbuf, W, mode, theta_scale, msum,
                                nw, n, tol, grow))
            summation_workers(ctx)
            record_residuals(rbuf, record, 1)
            total[0] = -1.0
            if msum[1] > 0.0:  # the sum was computed (the workers have all finished here)
                total[0] = msum[0]

        return lanes_summation_solve

    return namespace(globals(), locals())
