"""Taichi kernels of the C-DNF fields (float32 state, float64 integration).

Two sets of kernels compute the same equations:

* the generic kernels (``load_frame``, ``contrast_solve``, ``summation_solve_kernel``, ...)
  take ``ti.ndarray``/NumPy arrays of planes (H, W), so one compiled kernel serves
  every frame size; used for frames narrower than ``2 * LANES`` pixels and on GPUs
  (up to ``MAX_STEPS`` updates per launch, one parallel loop each);
* the fast CPU kernels (``lanes_*``) work on lane arrays (vector ndarrays of ``LANES``
  columns per element, :data:`~cdnf_ti.kernels.common.LANE3`) with ghost columns, visit
  only the rows and columns near a change (pending spans), and run a whole solve in one
  launch with persistent workers (see the sections below and ``docs/PERFORMANCE.md``).
  They compile with explicit vector types (:func:`~cdnf_ti.taichi_runtime.vector_kernel`),
  so their lane arithmetic runs in the host's full-width registers under both compilers;
  hence :func:`~cdnf_ti.kernels.common.any_lane` and :func:`~cdnf_ti.kernels.common.lane_abs`
  in place of ``.any()`` and ``ti.abs`` there.

A backend's state is one stacked array (the planes below: ``x[U_ON + parity, i, e]``), its
coefficients one small float32 array set when it is built (the slots below, read once per
stage into locals), and what changes at every launch (buffer parities, updates, the load
flags) scalar arguments or, for the lane solves, its launch record. Compile-time choices
(frame width, border ``mode``, radii, the DoG taps, frames or event bins) are bound by kernel
factories (``lanes_contrast_kernel``, ``lanes_summation_kernel``, ``summation_solve_kernel``),
cached: a second model compiles nothing new. ``mode`` is a border code from
:mod:`cdnf_ti.kernels.common`. The float64 NumPy reference of the same equations is
:mod:`cdnf_ti.reference`.
"""


import functools
from types import SimpleNamespace

from ..taichi_runtime import scalar_kernel, vector_kernel
from . import common, schedule
from .common import RECORD_COEFS, namespace
from .engine import Coefs, Planes
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


# -- the state: one stacked array per backend, its planes declared by name --------------
# Lane kernels: a lane array (LANE_PLANES, H, NB); generic kernels: float32 (PLANES, H, W), with
# the Summation field's buffers as (H, W) arrays of their own (the DoG's input, dog_row_pass).
# Each field keeps two ping-pong buffers, planes ``U_ON + parity`` etc.
#: The planes: photoreceptors ``L`` (the last frame); the luminance change ``P`` (frames), or an event
#: bin's ``P_on`` and ``P_off`` (frames: P_on and P_off are [P]+ and [-P]+ of ``P``); the Summation input
#: ``S``; the Summation DoG's two row passes ``ROW``; the ON and OFF contrast fields ``U_ON``, ``U_OFF``;
#: the Summation field ``V`` (lane kernels); a contrast field's resting state ``REST`` (generic kernels).
STATE = Planes("L P P_OFF S ROW:2 U_ON:2 U_OFF:2 V:2 REST")
L_, P_, P_OFF, S_, ROW1 = STATE.L.slot, STATE.P.slot, STATE.P_OFF.slot, STATE.S.slot, STATE.ROW.slot
U_ON, U_OFF, V_, REST_U = STATE.U_ON.slot, STATE.U_OFF.slot, STATE.V.slot, STATE.REST.slot
LANE_PLANES = V_ + 2  # the lane kernels' planes (their resting state is an array of its own)
PLANES = STATE.count
assert (L_, P_) == (common.L_PLANE, common.P_PLANE)  # the photoreceptor stage's planes

# An event bin comes as one float32 array (2, H, W), ``(p_on, p_off)``, where a frame is (H, W):
# the kernels that take a frame switch on its dimensions at compile time (``ti.static``), and
# the contrast solves on ``events`` (a compile-time choice): on an event bin the ON field takes
# ``P_on = p_on`` and the OFF field ``P_off = p_off`` as they are.

#: Pending spans (lane kernels): one SPANS array (4, H), the contrast group's two parities, then the Summation's.
SPAN_C, SPAN_S = 0, 2

# -- a backend's coefficients: one float32 array by name, set once (cdnf_ti.backends.cdnf) --
#: ``k = (k0, k1)``: the lane kernels' separable contrast kernel ``W_c = k k^T``, ``k = (k1, k0, k1)``;
#: ``wc``: W_c's centre, edge and diagonal weights (generic kernels); ``h``; ``tau``: the freezing
#: threshold; ``tol``, ``grow``: the stopping rule (tolerance, growth); ``alpha_on``, ``alpha_off``: the
#: Summation input's gains; ``theta``: theta's scale 1 / tanh(1); ``dog_a``, ``dog_b``: W_s = A g1 g1^T -
#: B g2 g2^T; ``local``: 1 for the local start (cdnf_ti.solver); ``workers``: the persistent workers of a
#: lane solve; ``start_u``, ``start_v``: the local starts of the contrast and Summation fields; ``taps``:
#: the DoG profiles g1, g2 (2 R + 1 each; generic kernels).
COEF = Coefs(k=2, wc=3, h=1, tau=1, tol=1, grow=1, alpha_on=1, alpha_off=1, theta=1, dog_a=1, dog_b=1,
             local=1, workers=1, start_u=7, start_v=7, taps=0)
K0, K1 = COEF.k.slot, COEF.k.slot + 1
WC0, WC1, WC2 = COEF.wc.slot, COEF.wc.slot + 1, COEF.wc.slot + 2
H_REST, TAU, TOL, GROW = COEF.h.slot, COEF.tau.slot, COEF.tol.slot, COEF.grow.slot
ALPHA_ON, ALPHA_OFF, THETA = COEF.alpha_on.slot, COEF.alpha_off.slot, COEF.theta.slot
DOG_A, DOG_B = COEF.dog_a.slot, COEF.dog_b.slot
LOCAL, WORKERS = COEF.local.slot, COEF.workers.slot
START_U, START_V = COEF.start_u.slot, COEF.start_v.slot
TAPS = COEF.taps.slot

#: A lane contrast launch's values (its record's row 0, from ``LaunchRecord.values_at``): the buffer
#: parities of the contrast and Summation fields, updates at most, whether to load a frame, whether
#: it is the first, and its scale.
CONTRAST_VALUES = ("c", "s", "n", "load", "first", "scale")
AT_C, AT_S, AT_N, AT_LOAD, AT_FIRST, AT_SCALE = range(RECORD_COEFS + 2, RECORD_COEFS + 8)
#: A lane Summation launch's values: the Summation field's parity, updates at most.
SUMMATION_VALUES = ("s", "n")
AT_SUM_S, AT_SUM_N = range(RECORD_COEFS + 1, RECORD_COEFS + 3)


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The kernels of this module for the DSL module ``ti`` (taichi or quadrants) and ``lanes``
    lanes per vector element of the fast path: a namespace of every name below (and the
    module-level constants). Built once per (compiler, lanes), after the runtime started."""
    C = common.build(ti, lanes)
    sched = schedule.build(ti, lanes)
    workers = sched.workers
    LANE3 = C.LANE3
    LANES = C.LANES
    COEFS = C.COEFS
    F3 = C.F3
    F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    any_lane = C.any_lane
    block_span = C.block_span
    border_index = C.border_index
    border_weight = C.border_weight
    copy_plane = C.copy_plane
    fill = C.fill
    dog_column_run = C.dog_column_run
    dog_row_item = C.dog_row_item
    fill_ghosts = C.fill_ghosts
    fill_planes = C.fill_planes
    frame_runs = C.frame_runs
    lane_abs = C.lane_abs
    lane_array = C.lane_array
    lane_layout = C.lane_layout
    lane_mask = C.lane_mask
    lane_neighbours = C.lane_neighbours
    lane_shift = C.lane_shift
    launch_gate = C.launch_gate
    local_start = C.local_start
    photoreceptors = C.photoreceptors
    plane_load = C.plane_load
    plane_store = C.plane_store
    run_load = C.run_load
    run_max = C.run_max
    run_store = C.run_store
    start_coefficients = C.start_coefficients
    tanh_rational = C.tanh_rational

    D1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    #: A launch record (:class:`~cdnf_ti.kernels.common.LaunchRecord`): (lam, mom) in, residuals out.
    RECORD = ti.types.ndarray(dtype=ti.f32, ndim=2)


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


    @ti.func
    def field_input(x: ti.template(), f: ti.template(), i, e, events: ti.template()):
        """The input of the contrast field ``f`` (:data:`U_ON` or :data:`U_OFF`) at element ``(i, e)`` of
        the planes of ``x``: :func:`contrast_input` of ``P`` (frames), or an event bin's ``P_on`` /
        ``P_off`` as they are (``events``)."""
        inp = x[P_, i, e]
        if ti.static(events):
            if ti.static(f == U_OFF):
                inp = x[P_OFF, i, e]
        else:
            inp = contrast_input(inp, ti.static(1.0 if f == U_ON else -1.0))
        return inp

    LoadRunCtx = context("LoadRunCtx", "frame x coef scale keep c", grid="x")

    @ti.func
    def _load_run(ctx: ti.template(), i, j, n: ti.template()):
        x, coef, frame = ti.static(ctx.x, ctx.coef, ctx.frame)
        p_on = ti.Vector([0.0] * n, dt=ti.f32)
        p_off = ti.Vector([0.0] * n, dt=ti.f32)
        if ti.static(len(frame.shape) == 3):  # an event bin: (p_on, p_off)
            p_on = plane_load(frame, 0, i, j, n)
            p_off = plane_load(frame, 1, i, j, n)
            plane_store(x, P_, i, j, p_on, n)
            plane_store(x, P_OFF, i, j, p_off, n)
        else:
            p = photoreceptors(frame, x, i, j, n, ctx.scale, ctx.keep)
            p_on = contrast_input(p, 1.0)
            p_off = contrast_input(p, -1.0)
        if coef[LOCAL] != 0:
            cs = start_coefficients(coef, START_U)
            plane_store(x, U_ON + ctx.c, i, j, local_start(p_on, cs), n)
            plane_store(x, U_OFF + ctx.c, i, j, local_start(p_off, cs), n)
        return 0.0


    @ti.kernel
    def load_frame(frame: ti.types.ndarray(), x: F3, coef: COEFS, scale: ti.f32, first: ti.i32, c: ti.i32,
                   blocks: ti.i32):
        """``g = frame * scale``; ``P = g - L`` (0 when ``first``); ``L = g``; or, for an event bin ``frame``
        (2, H, W), ``P_on``, ``P_off`` = its planes; with ``coef[LOCAL]``, buffer ``c`` of ``u_on`` =
        ``start(P_on)`` and of ``u_off`` = ``start(P_off)`` (:func:`local_start`)."""
        keep = ti.select(first != 0, 0.0, 1.0)
        for k in range(x.shape[1] * blocks):
            frame_runs(_load_run, ti.static(LoadRunCtx(frame, x, coef, scale, keep, c)), k, blocks, "sum", 1)


    @ti.func
    def _lateral_3x3(x: ti.template(), f, i, j, wc0, wc1, wc2, mode: ti.template()):
        """``W_c (*) u`` at (i, j) of plane ``f`` of ``x``: wc0 centre, wc1 edge, wc2 diagonal weight."""
        H, W = x.shape[1], x.shape[2]
        im = border_index(i - 1, H, mode)
        ip = border_index(i + 1, H, mode)
        jm = border_index(j - 1, W, mode)
        jp = border_index(j + 1, W, mode)
        wim = border_weight(i - 1, H, mode)
        wip = border_weight(i + 1, H, mode)
        wjm = border_weight(j - 1, W, mode)
        wjp = border_weight(j + 1, W, mode)
        edge = wim * x[f, im, j] + wip * x[f, ip, j] + wjm * x[f, i, jm] + wjp * x[f, i, jp]
        diag = wim * (wjm * x[f, im, jm] + wjp * x[f, im, jp]) + wip * (wjm * x[f, ip, jm] + wjp * x[f, ip, jp])
        return wc0 * x[f, i, j] + wc1 * edge + wc2 * diag


    @ti.func
    def _contrast_update(x: ti.template(), coef: ti.template(), record: ti.template(), p, j: ti.template(), n,
                         blocks, mode: ti.template(), events: ti.template()):
        """Update ``j`` of a :func:`contrast_solve` launch, from buffer ``p`` of each field into the other:
        one parallel loop, each work item gated by :func:`launch_gate`; its residuals go to ``record[j, 2:4]``."""
        H, W = x.shape[1], x.shape[2]
        q = 1 - p
        for k in range(H * blocks):
            if launch_gate(record, j, n, coef[TOL], coef[GROW], 2) != 0:
                lam = record[j, 0]
                mom = record[j, 1]
                wc0, wc1, wc2, h = coef[WC0], coef[WC1], coef[WC2], coef[H_REST]
                i, j0, j1 = block_span(k, W, blocks)
                m_on = 0.0
                m_off = 0.0
                for c in range(j0, j1):
                    s_on = _lateral_3x3(x, U_ON + p, i, c, wc0, wc1, wc2, mode)
                    s_off = _lateral_3x3(x, U_OFF + p, i, c, wc0, wc1, wc2, mode)
                    n_on, d_on = field_update(field_input(x, U_ON, i, c, events), s_on, x[U_ON + p, i, c],
                                              x[U_ON + q, i, c], h, lam, mom)
                    n_off, d_off = field_update(field_input(x, U_OFF, i, c, events), s_off, x[U_OFF + p, i, c],
                                                x[U_OFF + q, i, c], h, lam, mom)
                    x[U_ON + q, i, c] = n_on
                    x[U_OFF + q, i, c] = n_off
                    m_on = ti.max(m_on, ti.abs(d_on))
                    m_off = ti.max(m_off, ti.abs(d_off))
                ti.atomic_max(record[j, RECORD_COEFS], m_on)
                ti.atomic_max(record[j, RECORD_COEFS + 1], m_off)


    @ti.kernel
    def contrast_solve(x: F3, coef: COEFS, record: RECORD, c: ti.i32, n: ti.i32, blocks: ti.i32,
                       mode: ti.template(), steps: ti.template(), events: ti.template()):
        """Up to ``n`` ON/OFF updates (fused, :func:`field_update`) in one launch: the generic kernel.

        ``F(u) = P_on - h + vartheta(W_c (*) u)`` (OFF: ``P_off``; :func:`field_input`). Update ``j`` reads buffer
        ``(c + j) % 2`` of ``u_on``/``u_off`` and writes the other, which holds the iterate before
        on entry, with ``lam, mom = record[j, 0:2]``; its residuals
        ``max|F(u_on) - u_on|``, ``max|F(u_off) - u_off|`` go to ``record[j, 2:4]`` (set to -1 by
        the caller, :class:`~cdnf_ti.kernels.common.LaunchRecord`). The updates stop after the
        first one whose residuals are both ``<= tol``, or one whose worst exceeds ``grow`` times
        the best of the launch. One parallel loop per update (``MAX_STEPS`` of them, those past
        the stop doing nothing): the kernel for GPUs and narrow frames.
        """
        for j in ti.static(range(steps)):
            _contrast_update(x, coef, record, (c + j) % 2, j, n, blocks, mode, events)


    @ti.kernel
    def copy(src: F2, dst: F2):
        """``dst = src``."""
        for i, j in src:
            dst[i, j] = src[i, j]


    @ti.kernel
    def summation_input(x: F3, v: F2, coef: COEFS, c: ti.i32):
        """``S = alpha_on theta([u_on]+) + alpha_off theta([u_off]+)`` (buffers ``c``); with
        ``coef[LOCAL]``, ``v = start(S)`` (:func:`local_start`)."""
        for i, j in v:
            theta = coef[THETA]
            a_on = tanh_rational(ti.max(x[U_ON + c, i, j], 0.0)) * theta
            a_off = tanh_rational(ti.max(x[U_OFF + c, i, j], 0.0)) * theta
            sv = coef[ALPHA_ON] * a_on + coef[ALPHA_OFF] * a_off
            x[S_, i, j] = sv
            if coef[LOCAL] != 0:
                v[i, j] = local_start(sv, start_coefficients(coef, START_V))


    SummationRunCtx = context("SummationRunCtx", "x v out coef lam mom", grid="v")

    @functools.lru_cache(maxsize=None)
    def summation_solve_kernel(mode: int, R: int, steps: int):
        """The generic Summation solve for border ``mode``, DoG radius ``R`` and ``steps`` updates per
        launch at most (compile-time choices: one kernel each, compiled once)."""

        @ti.func
        def _summation_run(ctx: ti.template(), i, j, n: ti.template()):
            x, coef, out = ti.static(ctx.x, ctx.coef, ctx.out)
            lateral = dog_column_run(x, ROW1, coef, TAPS, coef[DOG_A], coef[DOG_B], i, j, n, mode, R)
            nv, dv = field_update(plane_load(x, S_, i, j, n), lateral, run_load(ctx.v, i, j, n), run_load(out, i, j, n),
                                  coef[H_REST], ctx.lam, ctx.mom)
            run_store(out, i, j, nv, n)
            return run_max(ti.abs(dv), n)

        @ti.func
        def _summation_update(x: ti.template(), v: ti.template(), out: ti.template(), coef: ti.template(),
                              record: ti.template(), j: ti.template(), n, blocks):
            """Update ``j`` of a launch, from ``v`` into ``out``: the row pass, then the column pass and the
            update, two parallel loops gated by :func:`launch_gate`; its residual goes to ``record[j, 2]``."""
            H = v.shape[0]
            for k in range(H * blocks):
                if launch_gate(record, j, n, coef[TOL], coef[GROW], 1) != 0:
                    dog_row_item(v, x, ROW1, coef, TAPS, k, blocks, mode, R)
            for k in range(H * blocks):
                if launch_gate(record, j, n, coef[TOL], coef[GROW], 1) != 0:
                    lam = record[j, 0]
                    mom = record[j, 1]
                    ctx = ti.static(SummationRunCtx(x, v, out, coef, lam, mom))
                    r = frame_runs(_summation_run, ctx, k, blocks, "max", 1)
                    ti.atomic_max(record[j, RECORD_COEFS], ti.cast(r, ti.f32))

        @ti.kernel
        def summation_solve(x: F3, v_a: F2, v_b: F2, coef: COEFS, record: RECORD, n: ti.i32, blocks: ti.i32):
            """Up to ``n`` Summation updates (:func:`field_update`) in one launch: the generic kernel.

            The DoG ``W_s = A g1 g1^T - B g2 g2^T`` is applied as separable passes:
            ``row1 = g1 (*)_x v``, ``row2 = g2 (*)_x v``, then
            ``W_s (*) v = A g1 (*)_y row1 - B g2 (*)_y row2`` (exact for every border mode).
            ``F(v) = S - h + vartheta(W_s (*) v)``. Update ``j`` reads ``v_a`` (``j`` even) or ``v_b`` and
            writes the other; record and stopping as in :func:`contrast_solve` (one residual,
            ``max|F(v) - v|``, in ``record[j, 2]``).
            """
            for j in ti.static(range(steps)):
                if ti.static(j % 2 == 0):
                    _summation_update(x, v_a, v_b, coef, record, j, n, blocks)
                else:
                    _summation_update(x, v_b, v_a, coef, record, j, n, blocks)

        return scalar_kernel(summation_solve)


    @ti.kernel
    def mean_activation(v: F2, coef: COEFS, blocks: ti.i32, total: D1):
        """``total[0] += sum_xy theta([v]+)``, accumulated in float64 (the caller zeroes it and divides
        by ``H W``: no float64 return value, see :class:`~cdnf_ti.kernels.common.LaunchRecord`)."""
        H, W = v.shape[0], v.shape[1]
        for k in range(H * blocks):
            theta = coef[THETA]
            i, j0, j1 = block_span(k, W, blocks)
            acc = ti.f64(0.0)
            for j in range(j0, j1):
                acc += ti.cast(tanh_rational(ti.max(v[i, j], 0.0)) * theta, ti.f64)
            ti.atomic_add(total[0], acc)

    SPAN = ti.types.vector(2, ti.i32)
    #: Pending spans: one :data:`SPAN` per group and parity (:data:`SPAN_C`, :data:`SPAN_S`) and row, shape (4, H).
    SPANS = ti.types.ndarray(dtype=SPAN, ndim=2)


    @ti.func
    def _visit_span(pend: ti.template(), p, i0, i1, H, E1):
        """Elements ``[e0, e1)`` to visit: pending rows ``i0..i1`` (clipped) of span row ``p`` (a group's
        parity), one element either side."""
        lo = EMPTY_LO
        hi = EMPTY_HI
        for r in range(ti.max(i0, 0), ti.min(i1, H - 1) + 1):
            lo = ti.min(lo, pend[p, r][0])
            hi = ti.max(hi, pend[p, r][1])
        return ti.max(lo - 1, 1), ti.min(hi + 1, E1) + 1


    @vector_kernel
    @ti.kernel
    def lanes_pending_all(pend: SPANS, W: ti.template()):
        """Every element of every row pending, both groups and parities (after a change made outside the kernels)."""
        for p, i in pend:
            pend[p, i] = ti.Vector([1, (LANES + W - 1) // LANES])


    @vector_kernel
    @ti.kernel
    def lanes_fill_planes(x: LANE3, k0: ti.i32, k1: ti.i32, value: ti.f32):
        """Every lane of planes ``k0 .. k1 - 1`` of ``x`` (ghost columns included) = ``value``."""
        for k, i, e in ti.ndrange((k0, k1), x.shape[1], x.shape[2]):
            x[k, i, e] = ti.Vector([value] * LANES, dt=ti.f32)


    @vector_kernel
    @ti.kernel
    def lanes_put_planes(src: LANE3, x: LANE3, k0: ti.i32):
        """Planes ``k0 .. k0 + len(src) - 1`` of ``x`` = ``src`` (ghost columns included)."""
        for k, i, e in src:
            x[k0 + k, i, e] = src[k, i, e]


    # -- frame, Summation input, mean activation -------------------------------------------

    @ti.func
    def _start_element(x: ti.template(), p, i, e, inp, cs, W: ti.template()):
        """Element ``(i, e)`` of plane ``p`` of ``x`` = :func:`local_start` of the input ``inp`` (a lane
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
    def _load_row(frame: ti.template(), x: ti.template(), pend: ti.template(), coef: ti.template(), pp, i, scale,
                  first, W: ti.template(), mode: ti.template()):
        """Row ``i``: ``g = frame * scale``; ``P = g - L`` (0 when ``first``); ``L = g`` (frame columns only);
        or, for an event bin ``frame`` (2, H, W), ``P_on``, ``P_off`` = its planes; with ``coef[LOCAL]``,
        buffer ``pp`` of ``u_on``/``u_off`` = :func:`local_start` of ``P_on``/``P_off``.

        Elements where the input or a field changed join the row's pending span of parity ``pp``
        (contrast group).
        """
        E1 = (LANES + W - 1) // LANES
        cs = start_coefficients(coef, START_U)
        local = coef[LOCAL]
        lo = EMPTY_LO
        hi = EMPTY_HI
        for e in range(1, E1 + 1):
            if ti.static(len(frame.shape) == 3):  # an event bin: (p_on, p_off)
                p_on = ti.Vector([0.0] * LANES, dt=ti.f32)
                p_off = ti.Vector([0.0] * LANES, dt=ti.f32)
                for l in ti.static(range(LANES)):
                    c = ti.min((e - 1) * LANES + l, W - 1)
                    p_on[l] = frame[0, i, c]
                    p_off[l] = frame[1, i, c]
                moved = any_lane(p_on != x[P_, i, e]) | any_lane(p_off != x[P_OFF, i, e])
                if local != 0:
                    moved |= _start_element(x, U_ON + pp, i, e, p_on, cs, W)
                    moved |= _start_element(x, U_OFF + pp, i, e, p_off, cs, W)
                lo = ti.select(moved, ti.min(lo, e), lo)
                hi = ti.select(moved, e, hi)
                x[P_, i, e] = p_on
                x[P_OFF, i, e] = p_off
            else:
                g = ti.Vector([0.0] * LANES, dt=ti.f32)
                for l in ti.static(range(LANES)):
                    c = ti.min((e - 1) * LANES + l, W - 1)
                    g[l] = ti.cast(frame[i, c], ti.f32) * scale
                p_new = ti.select(first != 0, 0.0, g - x[L_, i, e])
                moved = any_lane(p_new != x[P_, i, e])
                if local != 0:
                    moved |= _start_element(x, U_ON + pp, i, e, ti.max(p_new, 0.0), cs, W)
                    moved |= _start_element(x, U_OFF + pp, i, e, ti.max(0.0 - p_new, 0.0), cs, W)
                lo = ti.select(moved, ti.min(lo, e), lo)
                hi = ti.select(moved, e, hi)
                x[P_, i, e] = p_new
                x[L_, i, e] = g
        if lo <= hi:
            pend[SPAN_C + pp, i] = ti.Vector([ti.min(pend[SPAN_C + pp, i][0], lo), ti.max(pend[SPAN_C + pp, i][1], hi)])
            if local != 0:
                fill_ghosts(x, U_ON + pp, i, 1, 1, W, 1, mode)
                fill_ghosts(x, U_OFF + pp, i, 1, 1, W, 1, mode)


    @vector_kernel
    @ti.kernel
    def lanes_load_frame(frame: ti.types.ndarray(), x: LANE3, pend: SPANS, coef: COEFS, pp: ti.i32,
                         scale: ti.f32, first: ti.i32, W: ti.template(), mode: ti.template()):
        """:func:`_load_row` for every row. The contrast solve loads a frame itself (its first
        phase); this kernel serves a frame whose fields are needed before that."""
        for i in range(x.shape[1]):
            _load_row(frame, x, pend, coef, pp, i, scale, first, W, mode)


    @vector_kernel
    @ti.kernel
    def lanes_refresh_ghosts(x: LANE3, k0: ti.i32, k1: ti.i32, W: ti.template(), mode: ti.template()):
        """Set the ghost columns of every row of planes ``k0 .. k1 - 1`` of ``x`` from its frame columns
        (border mode)."""
        for p, i in ti.ndrange((k0, k1), x.shape[1]):
            fill_ghosts(x, p, i, 1, 1, W, LANES - 1, mode)


    @ti.func
    def _summation_input_row(x: ti.template(), pend: ti.template(), coef: ti.template(), c, s, i, W: ti.template(),
                             mode: ti.template(), R: ti.template()):
        """Row ``i`` of ``S = alpha_on theta([u_on]+) + alpha_off theta([u_off]+)`` (buffers ``c``);
        with ``coef[LOCAL]``, buffer ``s`` of ``v`` = :func:`local_start` of ``S`` (``R``: the DoG radius,
        the ghost columns to refresh).

        Elements where S or v changed join the row's pending span in both parities of the
        Summation group (the next update overwrites the other parity anyway).
        """
        E1 = (LANES + W - 1) // LANES
        cs = start_coefficients(coef, START_V)
        local = coef[LOCAL]
        alpha_on, alpha_off, theta_scale = coef[ALPHA_ON], coef[ALPHA_OFF], coef[THETA]
        lo = EMPTY_LO
        hi = EMPTY_HI
        for e in range(1, E1 + 1):
            a_on = tanh_rational(ti.max(x[U_ON + c, i, e], 0.0)) * theta_scale
            a_off = tanh_rational(ti.max(x[U_OFF + c, i, e], 0.0)) * theta_scale
            s_new = alpha_on * a_on + alpha_off * a_off
            moved = any_lane(s_new != x[S_, i, e])
            if local != 0:
                moved |= _start_element(x, V_ + s, i, e, s_new, cs, W)
            lo = ti.select(moved, ti.min(lo, e), lo)
            hi = ti.select(moved, e, hi)
            x[S_, i, e] = s_new
        if lo <= hi:
            for q in ti.static(range(SPAN_S, SPAN_S + 2)):
                pend[q, i] = ti.Vector([ti.min(pend[q, i][0], lo), ti.max(pend[q, i][1], hi)])
            if local != 0:
                fill_ghosts(x, V_ + s, i, 1, 1, W, R, mode)


    @vector_kernel
    @ti.kernel
    def lanes_summation_input(x: LANE3, pend: SPANS, coef: COEFS, c: ti.i32, s: ti.i32, W: ti.template(),
                              mode: ti.template(), R: ti.template()):
        """``S = alpha_on theta([u_on]+) + alpha_off theta([u_off]+)`` and the Summation field's local
        start (see :func:`_summation_input_row`).

        The contrast solve computes S itself when it converges; this kernel serves the
        other cases (a solve that ended unconverged, a state restored from NumPy).
        """
        for i in range(x.shape[1]):
            _summation_input_row(x, pend, coef, c, s, i, W, mode, R)


    @ti.func
    def _activation_row(x: ti.template(), f, i, theta_scale, W: ti.template()):
        """``sum theta([v]+)`` over the frame columns of row ``i`` of plane ``f``, in float64."""
        E1 = (LANES + W - 1) // LANES
        acc = ti.f64(0.0)
        for e in range(1, E1 + 1):
            a = tanh_rational(ti.max(x[f, i, e], 0.0)) * theta_scale * lane_mask(e, W)
            acc += ti.cast(a.sum(), ti.f64)
        return acc


    @vector_kernel
    @ti.kernel
    def lanes_mean_activation(x: LANE3, coef: COEFS, s: ti.i32, W: ti.template(), total: D1):
        """``total[0] += sum_xy theta([v]+)`` of buffer ``s`` of ``v`` over the frame columns, in float64
        (as :func:`mean_activation`: the caller zeroes it and divides by ``H W``).

        The Summation solve computes the mean itself when it converges; this kernel serves the
        other cases.
        """
        for i in range(x.shape[1]):
            ti.atomic_add(total[0], _activation_row(x, V_ + s, i, coef[THETA], W))


    @ti.func
    def _relax(x: ti.template(), p, q, i, e, inp, lateral, h, lam, mom, tau, W: ti.template()):
        """Element ``e`` of row ``i``: plane ``q`` of ``x`` = the update (:func:`field_update`) of plane ``p``.

        Lanes with ``|F(u) - u| <= tau`` keep their value (frozen). Returns the lane-wise
        ``|F(u) - u|`` (0 off the frame) and whether a value moved.
        """
        xc = x[p, i, e]
        nx, d = field_update(inp, lateral, xc, x[q, i, e], h, lam, mom)
        ad = lane_abs(d) * lane_mask(e, W)
        x[q, i, e] = ti.select(ad > tau, nx, xc)
        return ad, run_max(ad, LANES) > tau


    # -- the contrast solve --------------------------------------------------------------

    @functools.lru_cache(maxsize=None)
    def lanes_contrast_kernel(W: int, mode: int, R: int, events: bool = False):
        """The lane-vectorised contrast solve for frames ``W`` px wide, border ``mode`` and Summation
        radius ``R``, loading frames or (``events``) event bins (compile-time choices: one kernel each,
        compiled once)."""
        E1 = (LANES + W - 1) // LANES

        @ti.func
        def _contrast_row(x: ti.template(), f: ti.template(), p, i, e0, e1, k0, k1, h, lam, mom, tau):
            """Update elements ``e0..e1-1`` of row ``i`` of the contrast field ``f`` (:data:`U_ON` or
            :data:`U_OFF`) from buffer ``p`` into the other one.

            The other buffer holds the previous iterate on entry (:func:`field_update`). Returns the
            lane-wise max |F(u) - u| and the first and last element where a value moved.

            ``W_c = k k^T`` is separable (``k = (k1, k0, k1)``): vertical sums
            ``c = k0 u[i] + k1 (u[i-1] + u[i+1])`` are carried along the row (one new
            element per step, only the last lane of the previous one), then
            ``W_c (*) u = k0 c + k1 (c[j-1] + c[j+1])``.
            """
            H = x.shape[1]
            u = ti.static(f)
            up = u + p
            im = border_index(i - 1, H, mode)
            ip = border_index(i + 1, H, mode)
            wim = ti.f32(border_weight(i - 1, H, mode))
            wip = ti.f32(border_weight(i + 1, H, mode))
            m = ti.Vector([0.0] * LANES, dt=ti.f32)
            lo = EMPTY_LO
            hi = EMPTY_HI
            c_left = k0 * x[up, i, e0 - 1][LANES - 1] + k1 * (wim * x[up, im, e0 - 1][LANES - 1]
                                                              + wip * x[up, ip, e0 - 1][LANES - 1])
            c_cur = k0 * x[up, i, e0] + k1 * (wim * x[up, im, e0] + wip * x[up, ip, e0])
            for e in range(e0, e1):
                c_next = k0 * x[up, i, e + 1] + k1 * (wim * x[up, im, e + 1] + wip * x[up, ip, e + 1])
                left, right = lane_neighbours(c_left, c_cur, c_next[0])
                s = k0 * c_cur + k1 * (left + right)
                ad, moved = _relax(x, up, u + 1 - p, i, e, field_input(x, f, i, e, events), s, h, lam, mom, tau, W)
                m = ti.max(m, ad)
                lo = ti.select(moved, ti.min(lo, e), lo)
                hi = ti.select(moved, e, hi)
                c_left = c_cur[LANES - 1]
                c_cur = c_next
            return m, lo, hi

        @ti.func
        def _load_stage(ctx: ti.template(), i0, i1, j):
            """Rows ``[i0, i1)`` of the frame (:func:`_load_row`)."""
            c = ti.cast(ctx.record[0, AT_C], ti.i32)
            scale = ctx.record[0, AT_SCALE]
            first = ctx.record[0, AT_FIRST]
            for i in range(i0, i1):
                _load_row(ctx.frame, ctx.x, ctx.pend, ctx.coef, c, i, scale, first, W, mode)

        @ti.func
        def _loads(ctx: ti.template()):
            """Whether the contrast launch loads a frame first."""
            return ti.cast(ctx.record[0, AT_LOAD], ti.i32)

        @ti.func
        def _contrast_stage(ctx: ti.template(), i0, i1, j):
            """Update ``j`` of both contrast fields on rows ``[i0, i1)``; maxes the residuals into ``rbuf[j, 0:2]``."""
            x, coef, pend = ti.static(ctx.x, ctx.coef, ctx.pend)
            H = x.shape[1]
            p = (ti.cast(ctx.record[0, AT_C], ti.i32) + j) % 2
            q = 1 - p
            lam = ctx.record[j, 0]
            mom = ctx.record[j, 1]
            k0, k1, h, tau = coef[K0], coef[K1], coef[H_REST], coef[TAU]
            m_on = 0.0
            m_off = 0.0
            for i in range(i0, i1):
                e0, e1 = _visit_span(pend, SPAN_C + p, i - 1, i + 1, H, E1)
                lo = EMPTY_LO
                hi = EMPTY_HI
                if e0 < e1:
                    r_on, lo_on, hi_on = _contrast_row(x, U_ON, p, i, e0, e1, k0, k1, h, lam, mom, tau)
                    r_off, lo_off, hi_off = _contrast_row(x, U_OFF, p, i, e0, e1, k0, k1, h, lam, mom, tau)
                    fill_ghosts(x, U_ON + q, i, e0 == 1, e1 == E1 + 1, W, 1, mode)
                    fill_ghosts(x, U_OFF + q, i, e0 == 1, e1 == E1 + 1, W, 1, mode)
                    m_on = ti.max(m_on, run_max(r_on, LANES))
                    m_off = ti.max(m_off, run_max(r_off, LANES))
                    lo = ti.min(lo_on, lo_off)
                    hi = ti.max(hi_on, hi_off)
                pend[SPAN_C + q, i] = ti.Vector([lo, hi])
            ti.atomic_max(sched.rbuf[j, 0], m_on)
            ti.atomic_max(sched.rbuf[j, 1], m_off)

        @ti.func
        def _summation_input_stage(ctx: ti.template(), i0, i1, ran):
            """Rows ``[i0, i1)`` of the Summation input of the converged contrast fields (after ``ran`` updates)."""
            f = (ti.cast(ctx.record[0, AT_C], ti.i32) + ran) % 2  # the buffer holding the result
            s = ti.cast(ctx.record[0, AT_S], ti.i32)
            for i in range(i0, i1):
                _summation_input_row(ctx.x, ctx.pend, ctx.coef, f, s, i, W, mode, R)

        @ti.func
        def _contrast_controls(ctx: ti.template()):
            """The contrast solve's workers, rows, updates at most and stopping rule."""
            coef = ti.static(ctx.coef)
            return (ti.cast(coef[WORKERS], ti.i32), ctx.x.shape[1], ti.cast(ctx.record[0, AT_N], ti.i32), coef[TOL],
                    coef[GROW])

        #: C-DNF's contrast solve: load the frame (the ON/OFF input stage), update both contrast
        #: fields, and at convergence the Summation input.
        plan = Plan(before=(_load_stage,), runs_before=_loads, update=(_contrast_stage,),
                    after=(_summation_input_stage,), controls=_contrast_controls)
        contrast_workers = workers(plan)
        ContrastCtx = context("ContrastCtx", "frame x pend record coef")

        FRAME = ti.types.ndarray(ndim=3 if events else 2)  # a frame (H, W), or an event bin (2, H, W)

        @vector_kernel
        @ti.kernel
        def lanes_contrast_solve(frame: FRAME, x: LANE3, pend: SPANS, record: RECORD, coef: COEFS):
            """Up to ``n`` ON/OFF updates (:func:`field_update`) in one launch, by persistent workers
            (``plan`` on the engine's scheduler, :func:`~cdnf_ti.kernels.schedule.build`'s ``workers``).

            The launch's values are in ``record`` (:data:`CONTRAST_VALUES`). Update ``j`` reads buffer
            ``(c + j) % 2`` of ``u_on``/``u_off`` and writes the other one, with
            ``lam, mom = record[j, 0:2]``; the updates stop after the first one whose residuals are
            both ``<= tol``, or one whose worst residual exceeds ``grow`` times the best of the
            launch. The residuals ``max|F(u) - u|`` of each update (ON, OFF; -1 for updates not run)
            go to ``record[j, 2:4]`` (:class:`~cdnf_ti.kernels.common.LaunchRecord`). Only the
            elements near a pending span (same parity as the buffers) are visited.
            With ``load`` set, the workers first load ``frame`` (an event bin (2, H, W) with ``events``;
            :func:`_load_row`; with ``coef[LOCAL]``
            it also sets the contrast fields' local start). When the launch converges, they go on
            to compute the Summation input ``S`` of the result and, with ``coef[LOCAL]``, the local
            start of buffer ``s`` of ``v`` (:func:`_summation_input_row`).
            """
            contrast_workers(ti.static(ContrastCtx(frame, x, pend, record, coef)))
            sched.residuals_to(record, 2)

        return lanes_contrast_solve


    # -- the Summation solve ---------------------------------------------------------------

    @functools.lru_cache(maxsize=None)
    def lanes_summation_kernel(g1: tuple, g2: tuple, W: int, mode: int):
        """The lane-vectorised Summation solve for the DoG profiles ``g1``, ``g2``, frames ``W`` px wide
        and border ``mode``.

        The taps (``2 R + 1`` floats each, symmetric) are compiled in as constants,
        which saves their per-launch argument passing; one kernel per parameter set.
        Buffers, launch record, stopping, workers and residuals as in
        :func:`lanes_contrast_kernel`; each update is two phases (row pass, then column
        pass and update).
        """
        R = (len(g1) - 1) // 2
        G1 = tuple(float(x) for x in g1)
        G2 = tuple(float(x) for x in g2)
        E1 = (LANES + W - 1) // LANES

        @ti.func
        def _row_pass_stage(ctx: ti.template(), i0, i1, j):
            """Phase 1 of update ``j``: horizontal DoG passes of rows ``[i0, i1)`` wherever a row within
            ``2 R`` needs a visit."""
            x = ti.static(ctx.x)
            H = x.shape[1]
            p = (ti.cast(ctx.record[0, AT_SUM_S], ti.i32) + j) % 2
            vp = V_ + p
            for i in range(i0, i1):
                e0, e1 = _visit_span(ctx.pend, SPAN_S + p, i - 2 * R, i + 2 * R, H, E1)
                if e0 < e1:
                    a = x[vp, i, e0 - 1]
                    cc = x[vp, i, e0]
                    for e in range(e0, e1):
                        nx = x[vp, i, e + 1]
                        a1 = ti.static(G1[R]) * cc
                        a2 = ti.static(G2[R]) * cc
                        for d in ti.static(range(1, R + 1)):
                            pair = lane_shift(a, cc, nx, -d) + lane_shift(a, cc, nx, d)
                            a1 += ti.static(G1[R + d]) * pair
                            a2 += ti.static(G2[R + d]) * pair
                        x[ROW1, i, e] = a1
                        x[ROW1 + 1, i, e] = a2
                        a = cc
                        cc = nx

        @ti.func
        def _update_stage(ctx: ti.template(), i0, i1, j):
            """Phase 2 of update ``j``: vertical passes and the update of rows ``[i0, i1)``; maxes the
            residual into ``rbuf[j, 0]``."""
            x, coef, pend = ti.static(ctx.x, ctx.coef, ctx.pend)
            H = x.shape[1]
            p = (ti.cast(ctx.record[0, AT_SUM_S], ti.i32) + j) % 2
            q = 1 - p
            lam = ctx.record[j, 0]
            mom = ctx.record[j, 1]
            A, B, h, tau = coef[DOG_A], coef[DOG_B], coef[H_REST], coef[TAU]
            mx = 0.0
            for i in range(i0, i1):
                e0, e1 = _visit_span(pend, SPAN_S + p, i - R, i + R, H, E1)
                lo = EMPTY_LO
                hi = EMPTY_HI
                if e0 < e1:
                    m = ti.Vector([0.0] * LANES, dt=ti.f32)
                    for e in range(e0, e1):
                        b1 = ti.static(G1[R]) * x[ROW1, i, e]
                        b2 = ti.static(G2[R]) * x[ROW1 + 1, i, e]
                        for d in ti.static(range(1, R + 1)):
                            iu = border_index(i - d, H, mode)
                            idn = border_index(i + d, H, mode)
                            wu = border_weight(i - d, H, mode)
                            wd = border_weight(i + d, H, mode)
                            b1 += ti.static(G1[R + d]) * (wu * x[ROW1, iu, e] + wd * x[ROW1, idn, e])
                            b2 += ti.static(G2[R + d]) * (wu * x[ROW1 + 1, iu, e] + wd * x[ROW1 + 1, idn, e])
                        ad, moved = _relax(x, V_ + p, V_ + q, i, e, x[S_, i, e], A * b1 - B * b2, h, lam, mom, tau, W)
                        m = ti.max(m, ad)
                        lo = ti.select(moved, ti.min(lo, e), lo)
                        hi = ti.select(moved, e, hi)
                    fill_ghosts(x, V_ + q, i, e0 == 1, e1 == E1 + 1, W, R, mode)
                    mx = ti.max(mx, run_max(m, LANES))
                pend[SPAN_S + q, i] = ti.Vector([lo, hi])
            ti.atomic_max(sched.rbuf[j, 0], mx)

        @ti.func
        def _activation_stage(ctx: ti.template(), i0, i1, ran):
            """``sum theta([v]+)`` of rows ``[i0, i1)`` of the converged field (after ``ran`` updates)
            into ``msum[0]``; ``msum[1] = 1``: computed."""
            f = (ti.cast(ctx.record[0, AT_SUM_S], ti.i32) + ran) % 2  # the buffer holding the result
            theta_scale = ctx.coef[THETA]
            acc = ti.f64(0.0)
            for i in range(i0, i1):
                acc += _activation_row(ctx.x, V_ + f, i, theta_scale, W)
            ti.atomic_add(sched.msum[0], acc)
            sched.msum[1] = 1.0

        #: The Summation solve: each update a row pass and a column pass with the update;
        #: at convergence, the mean activation.
        @ti.func
        def _controls(ctx: ti.template()):
            """The Summation solve's workers, rows, updates at most and stopping rule."""
            coef = ti.static(ctx.coef)
            return (ti.cast(coef[WORKERS], ti.i32), ctx.x.shape[1], ti.cast(ctx.record[0, AT_SUM_N], ti.i32),
                    coef[TOL], coef[GROW])

        plan = Plan(update=(_row_pass_stage, _update_stage), after=(_activation_stage,), controls=_controls)
        summation_workers = workers(plan)
        Ctx = context("SummationCtx", "x pend record coef")

        @vector_kernel
        @ti.kernel
        def lanes_summation_solve(x: LANE3, pend: SPANS, record: RECORD, coef: COEFS, total: D1):
            """Lane-vectorised :func:`summation_solve` by persistent workers (``plan`` on the engine's
            scheduler): separable DoG, same equations; the launch's values in ``record``
            (:data:`SUMMATION_VALUES`).

            The residuals go to ``record`` (as :func:`lanes_contrast_kernel`), and
            ``sum_xy theta([v]+)`` of the result (float64), when the launch converged, to
            ``total[0]`` (else -1), as :func:`lanes_mean_activation` computes it.
            """
            sched.msum[0] = 0.0
            sched.msum[1] = 0.0
            summation_workers(ti.static(Ctx(x, pend, record, coef)))
            sched.residuals_to(record, 1)
            total[0] = -1.0
            if sched.msum[1] > 0.0:  # the sum was computed (the workers have all finished here)
                total[0] = sched.msum[0]

        return lanes_summation_solve

    return namespace(globals(), locals())
