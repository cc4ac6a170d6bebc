"""Taichi kernels of the LGMD family: LGMD2, LGMD1 and F-LGMD (float32 layers).

Each model needs two launches per frame: :func:`load_frame` (photoreceptors and
the ON/OFF channels, pointwise, with ``sum |P|`` for the PM/FFI pathway) and
one layer kernel whose top-level loops run one after another (local summation,
grouping); F-LGMD adds its fixed-point iteration. Every pass reads values stored
by the pass before it, so nothing is computed twice per pixel.
Sums are accumulated in float64. Borders replicate (index clamping), as in
the authors' C# code. Loops run over (row, column-block) work items
(:func:`cdnf_ti.kernels.common.block_span`); each item visits its columns in runs
(:func:`cdnf_ti.kernels.common.row_runs`), so the per-pixel equations below are
written once, on vectors of ``n`` consecutive columns.

A model's state is one float32 array per backend (:data:`STATE_LAYERS`): its layers stacked
along the leading axis, named by the layer constants below (``st[S_, i, j]``), then the
buffers of its ON and OFF channels, which the kernels take as indices into that axis. Its
coefficients are one small float32 array per backend (``coef``), set once when the backend is
built and read by name (``coef[DELTA_C]``); only what changes from launch to launch (buffer
indices, LGMD2's ``w_on``/``w_off``, first-frame flags) travels as scalar arguments.

No kernel returns a value (returning a float64 or a vector costs ~0.1-0.2 ms per
launch on the CPU and 1-2 ms on CUDA): each writes its results into ``out``, a
small float64 NumPy array (:data:`D1`) that the caller sets before the launch
(zeros for sums and maxima) and reads after it. Every work item adds (or maxes)
its partial result into ``out`` once; the persistent-worker kernels reduce into
the scheduler's fields and copy the results into ``out`` in their serial tail.

The NumPy float64 oracle of every stage is :mod:`cdnf_ti.baselines_reference`.
"""

import functools
from types import SimpleNamespace

from ..taichi_runtime import vector_kernel
from . import common, schedule
from .common import REPLICATE, namespace
from .schedule import Plan, context

# -- a model's state: its layers (leading axis), then its channel buffers -----------------
L_, P_, S_, G_ = 0, 1, 2, 3  # photoreceptors, luminance change, summation layer, grouping layer
I_ON_, I_OFF_, CE_ = 4, 5, 6  # LGMD2: delayed inhibitions of ON/OFF, excitation Ce
E_OFF_ = 5  # LGMD1: the delayed OFF spread (I_on at I_ON_)
ON0_, OFF0_, Q_ON_, Q_OFF_, S_ON_, S_OFF_ = 4, 5, 6, 7, 8, 9  # F-LGMD: drives, constant inhibitions, S_on, S_off
#: Each model's layers, in the order of its state array; the ON channel's buffers follow, then the OFF channel's.
STATE_LAYERS = {
    "lgmd2": ("L", "P", "S", "G", "I_on", "I_off", "Ce"),
    "lgmd1": ("L", "P", "S", "G", "I_on", "E_off"),
    "flgmd_onn": ("L", "P", "S", "G", "on0", "off0", "q_on", "q_off", "S_on", "S_off"),
}
#: Buffers per channel of LGMD1/LGMD2 (now and the frame before): OFF's buffer ``b`` is ON's ``b + PING_PONG``.
PING_PONG = 2

# -- a model's coefficients: one float32 array, indices by name (the models fill what they use) --
CLIP, DC = 0, 1  # the ON/OFF input stage: half-wave clip, decay of the residue
KN, AN, KF, AF = 2, 5, 8, 11  # LGMD2's delayed inhibitions: (centre, edge, diagonal) each
E_WEIGHTS = 14  # LGMD1, LGMD2: e_on, e_off, e_onoff of the summation (3 values)
DELTA_C, C_W, C_DE, T_DE = 17, 18, 19, 20  # LGMD2's grouping
K1, K2, A1, A2 = 21, 22, 23, 24  # LGMD1, F-LGMD: lateral spread (edge, diagonal) and its delay coefficients
W_I_ON, W_I_OFF, T_S = 25, 26, 27  # LGMD1, F-LGMD: inhibition weights, summation threshold
WN, WF = 28, 31  # F-LGMD: W_x of ON and of OFF (centre, edge, diagonal each)
BETA_ON, BETA_OFF = 34, 35  # F-LGMD: feedback gains
QN1, QN2, QF1, QF2 = 36, 37, 38, 39  # F-LGMD (lanes): edge/diagonal weights of Q of ON, OFF
START_WN, START_KN, START_WF, START_KF = 40, 41, 42, 43  # F-LGMD: the iterate's start (w, kappa of ON, OFF)
TOL, GROW = 44, 45  # F-LGMD (lanes): the solve's stopping rule
N_COEFS = 46
#: The coefficients of the delayed layers, (k, a) of ON then of OFF (centre, edge, diagonal each):
#: indices into ``coef``, NO_CENTRE for LGMD1's spreads (centre 0).
NO_CENTRE = -1
DELAYED = {
    "lgmd2": (KN, KN + 1, KN + 2, AN, AN + 1, AN + 2, KF, KF + 1, KF + 2, AF, AF + 1, AF + 2),
    "lgmd1": (NO_CENTRE, K1, K2, NO_CENTRE, A1, A2) * 2,
}
#: F-LGMD's lane solve: its buffers (``bufs``, an int32 array): ON's iterate (read by the even updates)
#: and the one before it, then OFF's. An array, not a ti.Vector of the four indices: with explicit
#: vector types taichi 1.7.4 crashed (segmentation fault) in a launch that indexed with one.
B_ON, B_ON_N, B_OFF, B_OFF_N = 0, 1, 2, 3
#: ... then the solve launch's updates at most, its workers and whether it iterates OFF too
#: (``bufs[B_N]``, ``bufs[B_NW]``, ``bufs[B_WITH_OFF]``: 0 or 1).
B_N, B_NW, B_WITH_OFF = 4, 5, 6
#: The lane load's channel buffers (``bufs`` of :func:`lgmd_lanes_load`): ON's to read and to write, then OFF's.
L_C_ON, L_S_ON, L_C_OFF, L_S_OFF = 0, 1, 2, 3
#: Work items per row of the lane load (element blocks), so both CPU threads get rows.
LOAD_BLOCKS = 4

# -- F-LGMD: a whole solve in one launch ----------------------------------------------
# The updates of a frame run in one launch on the engine's scheduler (kernels/schedule.py):
# the update stage, then, when the launch converges, the layers at the fixed point (S_on,
# S_off, S) and the grouping (G and sum G), so a converged frame costs two launches in all
# (lgmd_lanes_load and this one).


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The kernels of this module for the DSL module ``ti`` (taichi or quadrants) and ``lanes``
    lanes per vector element of the fast path: a namespace of every name below (and the
    module-level constants). Built once per (compiler, lanes), after the runtime started."""
    C = common.build(ti, lanes)
    run_get, run_put = C.plane_load, C.plane_store  # a layer of the state on a run of columns
    sched = schedule.build(ti, lanes)
    workers = sched.workers
    rbuf, msum = sched.rbuf, sched.msum  # the scheduler's scratch (one set per process)
    LANE3 = C.LANE3
    LANES = C.LANES
    block_span = C.block_span
    fill_ghosts = C.fill_ghosts
    lane_abs = C.lane_abs
    lane_edge_diag = C.lane_edge_diag
    lane_mask = C.lane_mask
    row_runs = C.row_runs
    run_load = C.run_load
    run_max = C.run_max
    run_sum = C.run_sum

    F1 = ti.types.ndarray(dtype=ti.f32, ndim=1)  # a backend's coefficients ``coef``
    I1 = ti.types.ndarray(dtype=ti.i32, ndim=1)  # F-LGMD's solve buffers ``bufs``
    F3 = ti.types.ndarray(dtype=ti.f32, ndim=3)  # a model's state (layers, H, W)
    D1 = ti.types.ndarray(dtype=ti.f64, ndim=1)  # a launch's results ``out``, set by the caller before it


    @ti.func
    def half_wave(p, on_prev, off_prev, clip, dc):
        """ON/OFF channels with residue (scalars or vectors):
        ``ON = P [P >= clip] + dc ON(t-1)``, ``OFF = |P| [P < clip] + dc OFF(t-1)``."""
        return ti.select(p >= clip, p, 0.0) + dc * on_prev, ti.select(p < clip, lane_abs(p), 0.0) + dc * off_prev


    @ti.func
    def half_wave_on_off(p_on, p_off, on_prev, off_prev, clip, dc):
        """ON/OFF channels driven separately (an event bin: ``P_on``, ``P_off >= 0``): :func:`half_wave`
        with ``P = P_on`` for ON and ``P = -P_off`` for OFF, ``ON = P_on [P_on >= clip] + dc ON(t-1)``,
        ``OFF = P_off [-P_off < clip] + dc OFF(t-1)``. A frame's ``P`` is ``P_on = [P]+``, ``P_off = [-P]+``."""
        return (ti.select(p_on >= clip, p_on, 0.0) + dc * on_prev,
                ti.select(0.0 - p_off < clip, p_off, 0.0) + dc * off_prev)


    @ti.func
    def coef3(coef: ti.template(), k: ti.template()):
        """``coef[k], coef[k + 1], coef[k + 2]`` (a centre, edge, diagonal triple) as a vector."""
        return ti.Vector([coef[k], coef[k + 1], coef[k + 2]])


    @ti.func
    def coef_or_zero(coef: ti.template(), k: ti.template()):
        """``coef[k]``, or 0 for ``k == NO_CENTRE``."""
        v = 0.0
        if ti.static(k != NO_CENTRE):
            v = coef[k]
        return v


    @ti.func
    def _symmetric(c, e, d, w0, w1, w2):
        """A symmetric 3x3 correlation from the centre ``c`` and the edge/diagonal neighbour sums ``e``/``d``."""
        return w0 * c + w1 * e + w2 * d


    @ti.func
    def _edge_diag(x: ti.template(), k, im, i, ip, jm, j, jp, n: ti.template()):
        """Sums of the 4 edge and 4 diagonal neighbours of the run ``(i, j .. j + n - 1)`` of layer ``k``."""
        e = run_get(x, k, im, j, n) + run_get(x, k, ip, j, n) + run_get(x, k, i, jm, n) + run_get(x, k, i, jp, n)
        d = run_get(x, k, im, jm, n) + run_get(x, k, im, jp, n) + run_get(x, k, ip, jm, n) + run_get(x, k, ip, jp, n)
        return e, d


    @ti.func
    def _stencil(x: ti.template(), k, im, i, ip, jm, j, jp, n: ti.template(), w0, w1, w2):
        """Symmetric 3x3 correlation (centre w0, edge w1, diagonal w2) of layer ``k`` on a run."""
        e, d = _edge_diag(x, k, im, i, ip, jm, j, jp, n)
        return _symmetric(run_get(x, k, i, j, n), e, d, w0, w1, w2)


    @ti.func
    def _delayed(x: ti.template(), now, before, im, i, ip, jm, j, jp, n: ti.template(), kk, a):
        """``sum K [a X(t) + (1 - a) X(t-1)]`` over the 3x3 window of layers ``now``/``before``
        (``kk``, ``a``: centre, edge, diagonal of ``K`` and of ``a``)."""
        e, d = _edge_diag(x, now, im, i, ip, jm, j, jp, n)
        ep, dp = _edge_diag(x, before, im, i, ip, jm, j, jp, n)
        return delayed_mix(run_get(x, now, i, j, n), e, d, run_get(x, before, i, j, n), ep, dp,
                           kk[0], kk[1], kk[2], a[0], a[1], a[2])


    @ti.func
    def delayed_mix(c, e, d, cp, ep, dp, k0, k1, k2, a0, a1, a2):
        """``sum K [a X(t) + (1 - a) X(t-1)]`` from the centre and edge/diagonal sums of ``X(t)``
        (``c, e, d``) and of ``X(t-1)`` (``cp, ep, dp``)."""
        return (k0 * (a0 * c + (1.0 - a0) * cp) + k1 * (a1 * e + (1.0 - a1) * ep)
                + k2 * (a2 * d + (1.0 - a2) * dp))


    @ti.func
    def lgmd2_summation(on, off, i_on, i_off, w_on, w_off, e):
        """LGMD2's ``S = e_on S_on + e_off S_off + e_onoff S_on S_off``, ``S_on = [ON - w_on I_on]+``."""
        s_on = ti.max(on - w_on * i_on, 0.0)
        s_off = ti.max(off - w_off * i_off, 0.0)
        return e[0] * s_on + e[1] * s_off + e[2] * s_on * s_off


    @ti.func
    def lgmd2_grouping(s, ce, inv_omega, c_de, t_de):
        """LGMD2's ``G = S Ce / omega``, zero unless ``c_de G >= t_de``."""
        g = s * ce * inv_omega
        return ti.select(g * c_de >= t_de, g, 0.0)


    GroupRunCtx = context("GroupRunCtx", "st")

    @ti.func
    def _group_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        st = ti.static(ctx.st)
        g = _stencil(st, S_, im, i, ip, jm, j, jp, n, 1.0 / 9.0, 1.0 / 9.0, 1.0 / 9.0)
        run_put(st, G_, i, j, g, n)
        return run_sum(g, n)


    @ti.func
    def _group(st: ti.template(), blocks, out: ti.template()):
        """Grouping ``G = S (*) (1/9 ones 3x3)`` over the frame (a top-level parallel loop);
        adds ``sum G`` (float64) to ``out[0]``."""
        H, W = st.shape[1], st.shape[2]
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(GroupRunCtx(st))
            ti.atomic_add(out[0], row_runs(_group_run, ctx, i, j0, j1, H, W, "sum", 1))


    #: ``b``: the ON and OFF channels' source buffers (their previous values), then their targets;
    #: ``s``: ``(scale, keep, clip, dc)``.
    LoadRunCtx = context("LoadRunCtx", "frame st b s")

    @ti.func
    def _load_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        frame, st = ti.static(ctx.frame, ctx.st)
        b, s = ctx.b, ctx.s
        g = ti.floor(run_load(frame, i, j, n) * s[0] + 0.5)
        p = s[1] * (g - run_get(st, L_, i, j, n))
        run_put(st, L_, i, j, g, n)
        run_put(st, P_, i, j, p, n)
        a, c = half_wave(p, run_get(st, b[0], i, j, n), run_get(st, b[1], i, j, n), s[2], s[3])
        run_put(st, b[2], i, j, a, n)
        run_put(st, b[3], i, j, c, n)
        return run_sum(ti.abs(p), n)


    @ti.func
    def _load_bin_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        frame, st = ti.static(ctx.frame, ctx.st)
        b, s = ctx.b, ctx.s
        p_on = run_get(frame, 0, i, j, n) * s[0]
        p_off = run_get(frame, 1, i, j, n) * s[0]
        run_put(st, P_, i, j, p_on - p_off, n)
        a, c = half_wave_on_off(p_on, p_off, run_get(st, b[0], i, j, n), run_get(st, b[1], i, j, n), s[2], s[3])
        run_put(st, b[2], i, j, a, n)
        run_put(st, b[3], i, j, c, n)
        return run_sum(p_on + p_off, n)


    @ti.kernel
    def load_frame(frame: ti.types.ndarray(), st: F3, on_src: ti.i32, off_src: ti.i32, on_dst: ti.i32,
                   off_dst: ti.i32, scale: ti.f32, first: ti.i32, coef: F1, blocks: ti.i32, out: D1):
        """Photoreceptors and the ON/OFF channels of one frame; adds ``sum |P|`` to ``out[0]`` (set to 0 by the caller).

        An event bin instead of a frame: ``frame`` of shape (2, H, W), its ``p_on`` and ``p_off``
        (float32, contrast in [0, 1]); the ON channel is driven by ``P_on = scale p_on``, the OFF
        channel by ``P_off = scale p_off`` (:func:`half_wave_on_off`), ``P = P_on - P_off``, ``L``
        stays; adds ``sum (P_on + P_off)`` to ``out[0]``.

        ``g = floor(frame * scale + 0.5)`` (integer grey levels); ``P = g - L`` (0 when
        ``first``); ``L = g``; ``ON = P [P >= clip] + dc ON(t-1)``,
        ``OFF = |P| [P < clip] + dc OFF(t-1)`` (``ON(t-1)``/``OFF(t-1)``: layers ``on_src``/``off_src``
        of ``st``; ``on_dst``/``off_dst`` receive the new ones, which the model uses or,
        on an FFI-held frame, drops). The rounding makes float input (``scale = 255``)
        the 8-bit grey levels the authors' code works on (``HighpassFilter(byte, byte)
        -> int`` in lgmd2OpenSource.cs / LGMDs.cs, fuqinbing/LGMD2-open-source);
        uint8 input (``scale = 1``) is unchanged. NumPy reference:
        :func:`cdnf_ti.baselines_reference.eight_bit`, ``half_wave_on``/``half_wave_off``.
        """
        H, W = st.shape[1], st.shape[2]
        keep = ti.select(first != 0, 0.0, 1.0)
        b = ti.Vector([on_src, off_src, on_dst, off_dst])
        s = ti.Vector([scale, keep, coef[CLIP], coef[DC]])
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(LoadRunCtx(frame, st, b, s))
            if ti.static(len(frame.shape) == 3):  # an event bin
                ti.atomic_add(out[0], row_runs(_load_bin_run, ctx, i, j0, j1, H, W, "sum", 1))
            else:
                ti.atomic_add(out[0], row_runs(_load_run, ctx, i, j0, j1, H, W, "sum", 1))


    #: ``b``: the ON channel's buffers now and the frame before (OFF's: ``+ PING_PONG``); ``w``: ``(w_on, w_off)``.
    Lgmd2RunCtx = context("Lgmd2RunCtx", "st coef b w")

    @ti.func
    def _lgmd2_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        st, coef = ti.static(ctx.st, ctx.coef)
        c, q = ctx.b[0], ctx.b[1]
        kn, an, kf, af, e = coef3(coef, KN), coef3(coef, AN), coef3(coef, KF), coef3(coef, AF), coef3(coef, E_WEIGHTS)
        i_on = _delayed(st, c, q, im, i, ip, jm, j, jp, n, kn, an)
        i_off = _delayed(st, c + PING_PONG, q + PING_PONG, im, i, ip, jm, j, jp, n, kf, af)
        run_put(st, I_ON_, i, j, i_on, n)
        run_put(st, I_OFF_, i, j, i_off, n)
        run_put(st, S_, i, j, lgmd2_summation(run_get(st, c, i, j, n), run_get(st, c + PING_PONG, i, j, n), i_on,
                                              i_off, ctx.w[0], ctx.w[1], e), n)
        return 0.0


    ExcitationRunCtx = context("ExcitationRunCtx", "st")

    @ti.func
    def _excitation_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        st = ti.static(ctx.st)
        c = _stencil(st, S_, im, i, ip, jm, j, jp, n, 1.0 / 9.0, 1.0 / 9.0, 1.0 / 9.0)
        run_put(st, CE_, i, j, c, n)
        return run_max(ti.abs(c), n)


    #: ``g``: ``(1 / omega, c_de, t_de)``.
    GroupingRunCtx = context("GroupingRunCtx", "st g")

    @ti.func
    def _grouping_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        st = ti.static(ctx.st)
        g = lgmd2_grouping(run_get(st, S_, i, j, n), run_get(st, CE_, i, j, n), ctx.g[0], ctx.g[1], ctx.g[2])
        run_put(st, G_, i, j, g, n)
        return run_sum(g, n)


    @ti.kernel
    def lgmd2_layers(st: F3, c: ti.i32, q: ti.i32, w_on: ti.f32, w_off: ti.f32, coef: F1, blocks: ti.i32, out: D1):
        """LGMD2 layers of one frame from its ON/OFF channels (:func:`load_frame`; ON's buffers ``c`` now,
        ``q`` the frame before, OFF's ``c + PING_PONG``, ``q + PING_PONG``).

        Delayed 3x3 inhibitions (centre included);
        ``S = e_on S_on + e_off S_off + e_onoff S_on S_off`` with
        ``S_on = [ON - w_on I_on]+``; ``Ce = S (*) ones/9``;
        ``G = S Ce / (delta_c + max|Ce| / c_w)``, zero unless ``c_de G >= t_de``.
        ``out[0] = sum G``, ``out[1] = max |Ce|`` (both set to 0 by the caller).
        """
        H, W = st.shape[1], st.shape[2]
        b = ti.Vector([c, q])
        w = ti.Vector([w_on, w_off])
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(Lgmd2RunCtx(st, coef, b, w))
            row_runs(_lgmd2_run, ctx, i, j0, j1, H, W, "sum", 1)
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(ExcitationRunCtx(st))
            ti.atomic_max(out[1], row_runs(_excitation_run, ctx, i, j0, j1, H, W, "max", 1))
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            mx = ti.cast(out[1], ti.f32)  # max |Ce| (a float32 value: exact)
            inv_omega = 1.0 / (coef[DELTA_C] + mx / coef[C_W])
            ctx = ti.static(GroupingRunCtx(st, ti.Vector([inv_omega, coef[C_DE], coef[T_DE]])))
            ti.atomic_add(out[0], row_runs(_grouping_run, ctx, i, j0, j1, H, W, "sum", 1))


    @ti.func
    def lgmd1_summation(on, off, i_on, exc_off, w_i_on, w_i_off, e, t_s):
        """LGMD1's ``S = e_on S_on + e_off S_off + e_onoff S_on S_off``, kept where ``S >= t_s``, with
        ``S_on = ON - w_i_on I_on`` and ``S_off = E_off - w_i_off OFF``."""
        s_on = on - w_i_on * i_on
        s_off = exc_off - w_i_off * off
        s = e[0] * s_on + e[1] * s_off + e[2] * s_on * s_off
        return ti.select(s >= t_s, s, 0.0)


    #: ``b``: the ON channel's buffers now and the frame before (OFF's: ``+ PING_PONG``).
    Lgmd1RunCtx = context("Lgmd1RunCtx", "st coef b")

    @ti.func
    def _lgmd1_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        st, coef = ti.static(ctx.st, ctx.coef)
        c, q = ctx.b[0], ctx.b[1]
        kk = ti.Vector([0.0, coef[K1], coef[K2]])  # centre 0
        a = ti.Vector([0.0, coef[A1], coef[A2]])
        i_on = _delayed(st, c, q, im, i, ip, jm, j, jp, n, kk, a)
        e_o = _delayed(st, c + PING_PONG, q + PING_PONG, im, i, ip, jm, j, jp, n, kk, a)
        run_put(st, I_ON_, i, j, i_on, n)
        run_put(st, E_OFF_, i, j, e_o, n)
        run_put(st, S_, i, j, lgmd1_summation(run_get(st, c, i, j, n), run_get(st, c + PING_PONG, i, j, n), i_on,
                                              e_o, coef[W_I_ON], coef[W_I_OFF], coef3(coef, E_WEIGHTS), coef[T_S]), n)
        return 0.0


    @ti.kernel
    def lgmd1_layers(st: F3, c: ti.i32, q: ti.i32, coef: F1, blocks: ti.i32, out: D1):
        """LGMD1 layers of one frame from its ON/OFF channels (:func:`load_frame`; ON's buffers ``c`` now,
        ``q`` the frame before, OFF's ``c + PING_PONG``, ``q + PING_PONG``).

        ``I_on``/``E_off``: delayed 3x3 spreads (centre 0) of ON/OFF;
        ``S_on = ON - w_i_on I_on``, ``S_off = E_off - w_i_off OFF``;
        ``S = e_on S_on + e_off S_off + e_onoff S_on S_off`` kept where ``>= t_s``;
        ``G = S (*) ones/9``. ``out[0] = sum G`` (set to 0 by the caller).
        """
        H, W = st.shape[1], st.shape[2]
        b = ti.Vector([c, q])
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(Lgmd1RunCtx(st, coef, b))
            row_runs(_lgmd1_run, ctx, i, j0, j1, H, W, "sum", 1)
        _group(st, blocks, out)


    # -- F-LGMD: instantaneous feedback solved as a fixed point -----------------------------
    # The local summation of a channel, S_X(X) = [G_e (*) X - w_i sum K (a X + (1 - a) X(t-1))]+,
    # is split once per frame into the part that the iteration changes and the part it does
    # not: S_X(X) = [W_x (*) X - Q]+ with W_x = G_e - w_i a K (one 3x3 stencil, centre
    # g0 since K's centre is 0) and Q = w_i sum K (1 - a) X(t-1), computed by flgmd_prepare.


    @ti.func
    def feedback_local(c, e, d, w, q):
        """``S_X = [W_x (*) X - Q]+`` from the centre ``c`` and the edge/diagonal sums ``e``/``d`` of ``X``
        (``w``: centre, edge, diagonal of ``W_x``)."""
        return ti.max(_symmetric(c, e, d, w[0], w[1], w[2]) - q, 0.0)


    @ti.func
    def feedback_update(x0, x, local, before, beta, lam, mom):
        """One update of a channel: ``(X + mom (X - X_before) + lam (T(X) - X), T(X) - X)`` with
        ``T(X) = [X0 + beta S_X(X)]+`` (``local`` = ``S_X(X)``, :func:`feedback_local`)."""
        d = ti.max(x0 + beta * local, 0.0) - x
        return x + mom * (x - before) + lam * d, d


    @ti.func
    def feedback_start(x0, q, w, kappa):
        """The iterate's start ``X0 + kappa [w X0 - Q]+``: the fixed point of a pixel whose neighbours
        share its drive ``X0`` (``w = sum W_x``, ``kappa = beta / (1 - beta w)``, or 0 to start at the
        drive; :meth:`cdnf_ti.models.flgmd.FLGMDParams.local_start_gains`)."""
        return x0 + kappa * ti.max(w * x0 - q, 0.0)


    @ti.func
    def summed_layer(s_on, s_off, t_s):
        """``S = S_on + S_off`` kept where ``>= t_s``."""
        s = s_on + s_off
        return ti.select(s >= t_s, s, 0.0)


    @ti.func
    def _flgmd_local(x: ti.template(), k, q, im, i, ip, jm, j, jp, n: ti.template(), w):
        """``S_X = [W_x (*) X - Q]+`` on a run (``X``, ``Q``: layers ``k``, ``q``; ``w``: centre, edge,
        diagonal of ``W_x``)."""
        e, d = _edge_diag(x, k, im, i, ip, jm, j, jp, n)
        return feedback_local(run_get(x, k, i, j, n), e, d, w, run_get(x, q, i, j, n))


    #: ``b``: the buffers of the ON and OFF iterate's start, then of the settled previous channels.
    PrepareRunCtx = context("PrepareRunCtx", "st coef b")

    @ti.func
    def _prepare_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        st, coef = ti.static(ctx.st, ctx.coef)
        b = ctx.b
        c = ti.Vector([coef[K1] * (1.0 - coef[A1]), coef[K2] * (1.0 - coef[A2])])
        c_on, c_off = coef[W_I_ON] * c, coef[W_I_OFF] * c  # (edge, diagonal) weights w_i K (1 - a) of each channel
        qn = _stencil(st, b[2], im, i, ip, jm, j, jp, n, 0.0, c_on[0], c_on[1])
        qf = _stencil(st, b[3], im, i, ip, jm, j, jp, n, 0.0, c_off[0], c_off[1])
        run_put(st, Q_ON_, i, j, qn, n)
        run_put(st, Q_OFF_, i, j, qf, n)
        run_put(st, b[0], i, j, feedback_start(run_get(st, ON0_, i, j, n), qn, coef[START_WN], coef[START_KN]), n)
        run_put(st, b[1], i, j, feedback_start(run_get(st, OFF0_, i, j, n), qf, coef[START_WF], coef[START_KF]), n)
        return 0.0


    @ti.kernel
    def flgmd_prepare(st: F3, on: ti.i32, off: ti.i32, on_p: ti.i32, off_p: ti.i32, coef: F1, blocks: ti.i32):
        """The frame's constant inhibition ``Q = w_i sum K (1 - a) X(t-1)`` of both channels
        (buffers ``on_p``/``off_p``: the settled previous channels) and the iterate's start, buffers
        ``on``/``off``, from the drives ``on0``/``off0`` (:func:`load_frame`) by :func:`feedback_start`."""
        H, W = st.shape[1], st.shape[2]
        b = ti.Vector([on, off, on_p, off_p])
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(PrepareRunCtx(st, coef, b))
            row_runs(_prepare_run, ctx, i, j0, j1, H, W, "sum", 1)


    #: ``b``: the buffers of the iterate ``X`` and of the one before it (receives the update);
    #: ``s``: ``(lam, mom)``.
    IterateRunCtx = context("IterateRunCtx", "st coef b s")

    def _iterate_run_of(channel: int):
        """The update of channel ``channel`` (0: ON, 1: OFF) on a run, a row-run body; returns
        ``max |T(X) - X|`` there."""
        x0, q, w, beta = ON0_ + channel, Q_ON_ + channel, WN + 3 * channel, BETA_ON + channel

        @ti.func
        def _iterate_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
            st, coef = ti.static(ctx.st, ctx.coef)
            x, x_n = ctx.b[0], ctx.b[1]
            local = _flgmd_local(st, x, q, im, i, ip, jm, j, jp, n, coef3(coef, w))
            new, d = feedback_update(run_get(st, x0, i, j, n), run_get(st, x, i, j, n), local,
                                     run_get(st, x_n, i, j, n), coef[beta], ctx.s[0], ctx.s[1])
            run_put(st, x_n, i, j, new, n)
            return run_max(ti.abs(d), n)

        return _iterate_run

    _iterate_on_run, _iterate_off_run = _iterate_run_of(0), _iterate_run_of(1)


    @ti.kernel
    def flgmd_iterate(st: F3, on: ti.i32, off: ti.i32, on_n: ti.i32, off_n: ti.i32, lam: ti.f32, mom: ti.f32,
                      coef: F1, blocks: ti.i32, with_off: ti.template(), out: D1):
        """One fixed-point update ``X_n = X + mom (X - X_n) + lam (T(X) - X)``, ``T(X) = [X0 + beta S_X(X)]+``
        (``X``: buffers ``on``/``off``; ``X_n``: ``on_n``/``off_n``).

        ``X_n`` holds the iterate before ``X`` on entry (used when ``mom != 0``:
        a Chebyshev step; ``mom = 0``: plain relaxation).
        ``W_x``: ``coef[WN:WN + 3]``/``coef[WF:WF + 3]`` for the ON/OFF channel
        (:meth:`cdnf_ti.models.flgmd.FLGMDParams.feedback_stencils`). The residuals
        ``out[0] = max|T(ON) - ON|``, ``out[1] = max|T(OFF) - OFF|`` (both set to 0 by the
        caller). With ``with_off`` False (``beta_off == 0``) the OFF channel equals its
        drive and is not iterated (``out[1]`` stays 0).
        """
        H, W = st.shape[1], st.shape[2]
        s = ti.Vector([lam, mom])
        b_on = ti.Vector([on, on_n])
        b_off = ti.Vector([off, off_n])
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(IterateRunCtx(st, coef, b_on, s))
            ti.atomic_max(out[0], row_runs(_iterate_on_run, ctx, i, j0, j1, H, W, "max", 1))
            if ti.static(with_off):
                ctx = ti.static(IterateRunCtx(st, coef, b_off, s))
                ti.atomic_max(out[1], row_runs(_iterate_off_run, ctx, i, j0, j1, H, W, "max", 1))


    #: ``b``: the buffers of the ON and OFF channels at the fixed point.
    FinishRunCtx = context("FinishRunCtx", "st coef b")

    @ti.func
    def _finish_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        st, coef = ti.static(ctx.st, ctx.coef)
        a = _flgmd_local(st, ctx.b[0], Q_ON_, im, i, ip, jm, j, jp, n, coef3(coef, WN))
        b = _flgmd_local(st, ctx.b[1], Q_OFF_, im, i, ip, jm, j, jp, n, coef3(coef, WF))
        run_put(st, S_ON_, i, j, a, n)
        run_put(st, S_OFF_, i, j, b, n)
        run_put(st, S_, i, j, summed_layer(a, b, coef[T_S]), n)
        return 0.0


    @ti.kernel
    def flgmd_finish(st: F3, on: ti.i32, off: ti.i32, coef: F1, blocks: ti.i32, out: D1):
        """Local summation at the fixed point (channels: buffers ``on``/``off``), ``S = S_on + S_off`` kept
        where ``>= t_s``, ``G = S (*) ones/9``; ``out[0] = sum G`` (set to 0 by the caller)."""
        H, W = st.shape[1], st.shape[2]
        b = ti.Vector([on, off])
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(FinishRunCtx(st, coef, b))
            row_runs(_finish_run, ctx, i, j0, j1, H, W, "sum", 1)
        _group(st, blocks, out)


    # -- the family on lane fields (the fast CPU path) ------------------------------------------
    # The same equations (half_wave, delayed_mix, the summations, feedback_local, feedback_update,
    # summed_layer) on lane arrays with ghost columns (vector ndarrays, see kernels/common.py): element
    # (i, e) holds the LANES columns (e - 1) * LANES .. e * LANES - 1 of row i, elements
    # 1..E1 hold the frame, the replicate border sits in the ghost columns -1 and W. The state is one
    # lane array with the layers of STATE_LAYERS stacked along its leading axis, then the channel
    # buffers: two per channel for LGMD1/LGMD2, three for F-LGMD (the settled channel of the last
    # frame and two ping-pong buffers of the iteration). The load's work items are (row, element
    # block) pairs, so both CPU threads get work on 240-row frames.
    # Coefficients are read from ``coef`` into scalar locals once per row (or stage), and travel into
    # the shared equations as scalars, not as small ti.Vectors: with explicit vector types quadrants
    # 1.3.3 compiled a launch with vector coefficients that crashed (segmentation fault in delayed_mix;
    # see kernels/compat.py). F-LGMD's W_x stencils are vectors, as they always were.


    @ti.func
    def _lane_span(k, E1, blocks):
        """Row ``i`` and elements ``[e0, e1)`` of work item ``k`` (row-major, ``blocks`` items per row)."""
        i = k // blocks
        b = k % blocks
        bw = (E1 + blocks - 1) // blocks
        return i, 1 + ti.min(b * bw, E1), 1 + ti.min(b * bw + bw, E1)


    @ti.func
    def _lane_grey(frame: ti.template(), i, e, scale, W: ti.template()):
        """8-bit grey levels ``floor(frame * scale + 0.5)`` of element ``(i, e)`` (columns past W-1 repeat it)."""
        g = ti.Vector([0.0] * LANES, dt=ti.f32)
        for l in ti.static(range(LANES)):
            g[l] = ti.cast(frame[i, ti.min((e - 1) * LANES + l, W - 1)], ti.f32)
        return ti.floor(g * scale + 0.5)


    @ti.func
    def _lane_bin(frame: ti.template(), k, i, e, scale, W: ti.template()):
        """``scale`` times polarity ``k`` of an event bin (``frame``: (2, H, W)) on element ``(i, e)``
        (columns past W-1 repeat it)."""
        g = ti.Vector([0.0] * LANES, dt=ti.f32)
        for l in ti.static(range(LANES)):
            g[l] = ti.cast(frame[k, i, ti.min((e - 1) * LANES + l, W - 1)], ti.f32)
        return g * scale


    @vector_kernel
    @ti.kernel
    def lgmd_lanes_load(
        frame: ti.types.ndarray(), st: LANE3, q: LANE3, bufs: I1, scale: ti.f32, first: ti.i32, coef: F1,
        W: ti.template(), feedback: ti.template(), out: D1,
    ):
        """:func:`load_frame` on lane fields: photoreceptors ``L``/``P`` and the ON/OFF channels,
        ``st[s_on] = P [P >= clip] + dc st[c_on]`` (same for OFF); adds ``sum |P|`` to ``out[0]``
        (set to 0 by the caller).

        With ``feedback`` (F-LGMD) it also does :func:`flgmd_prepare`: the drives
        ``on0``/``off0``, ``Q = w_i sum K (1 - a) X(t-1)`` of the settled channels
        ``st[c_on]``/``st[c_off]`` (``coef[QN1:QN2 + 1]``/``coef[QF1:QF2 + 1]``: edge and diagonal
        weights of ON and OFF) and the iterate's start ``st[s_on]``/``st[s_off]`` (:func:`feedback_start`).

        An event bin (``frame`` of shape (2, H, W)) drives the channels as in :func:`load_frame`.
        """
        H = st.shape[1]
        E1 = ti.static((LANES + W - 1) // LANES)
        keep = ti.select(first != 0, 0.0, 1.0)
        for k in range(H * LOAD_BLOCKS):
            c_on, s_on, c_off, s_off = bufs[L_C_ON], bufs[L_S_ON], bufs[L_C_OFF], bufs[L_S_OFF]
            clip, dc = coef[CLIP], coef[DC]
            qn1, qn2, qf1, qf2 = coef[QN1], coef[QN2], coef[QF1], coef[QF2]
            wn, kn, wf, kf = coef[START_WN], coef[START_KN], coef[START_WF], coef[START_KF]
            i, e0, e1 = _lane_span(k, E1, LOAD_BLOCKS)
            im = ti.max(i - 1, 0)
            ip = ti.min(i + 1, H - 1)
            acc = ti.f64(0.0)
            for e in range(e0, e1):
                a = ti.Vector([0.0] * LANES, dt=ti.f32)  # the channels' new values, set by the input stage
                b = ti.Vector([0.0] * LANES, dt=ti.f32)
                drive = ti.Vector([0.0] * LANES, dt=ti.f32)  # |P| (frames) or P_on + P_off (event bins)
                if ti.static(len(frame.shape) == 3):  # an event bin
                    p_on = _lane_bin(frame, 0, i, e, scale, W)
                    p_off = _lane_bin(frame, 1, i, e, scale, W)
                    st[P_, i, e] = p_on - p_off
                    a, b = half_wave_on_off(p_on, p_off, st[c_on, i, e], st[c_off, i, e], clip, dc)
                    drive = p_on + p_off
                else:
                    g = _lane_grey(frame, i, e, scale, W)
                    p = keep * (g - st[L_, i, e])
                    st[L_, i, e] = g
                    st[P_, i, e] = p
                    a, b = half_wave(p, st[c_on, i, e], st[c_off, i, e], clip, dc)
                    drive = lane_abs(p)
                if ti.static(feedback):
                    st[ON0_, i, e] = a
                    st[OFF0_, i, e] = b
                    cn, en, dn = lane_edge_diag(st, c_on, im, i, ip, e)
                    qn = _symmetric(cn, en, dn, 0.0, qn1, qn2)
                    q[0, i, e] = qn
                    cf, ef, df = lane_edge_diag(st, c_off, im, i, ip, e)
                    qf = _symmetric(cf, ef, df, 0.0, qf1, qf2)
                    q[1, i, e] = qf
                    a = feedback_start(a, qn, wn, kn)
                    b = feedback_start(b, qf, wf, kf)
                st[s_on, i, e] = a
                st[s_off, i, e] = b
                acc += ti.cast((drive * lane_mask(e, W)).sum(), ti.f64)
            fill_ghosts(st, s_on, i, e0 == 1, e1 == E1 + 1, W, 1, REPLICATE)
            fill_ghosts(st, s_off, i, e0 == 1, e1 == E1 + 1, W, 1, REPLICATE)
            ti.atomic_add(out[0], acc)


    @ti.func
    def _lane_relax(st: ti.template(), q: ti.template(), channel: ti.template(), p, n, i, e, w, beta, lam, mom):
        """Element ``(i, e)`` of ``channel`` (0: ON, 1: OFF): buffer ``n`` of the state = the update
        (:func:`feedback_update`) of buffer ``p``; returns ``|T(X) - X|``.

        A function of its own, called by the row (not written into its loop): with float
        reassociation on, the function boundary changes the order of the sums that taichi emits."""
        im = ti.max(i - 1, 0)
        ip = ti.min(i + 1, st.shape[1] - 1)
        c, ed, dg = lane_edge_diag(st, p, im, i, ip, e)
        new, d = feedback_update(st[ON0_ + channel, i, e], c,
                                 feedback_local(c, ed, dg, w, q[channel, i, e]), st[n, i, e], beta, lam, mom)
        st[n, i, e] = new
        return lane_abs(d)


    @ti.func
    def _lane_update_row(st: ti.template(), q: ti.template(), channel: ti.template(), p, n, i, w, beta, lam, mom,
                         W: ti.template()):
        """Row ``i`` of one update of ``channel`` (buffer ``p`` into ``n``, :func:`_lane_relax`).

        Returns the row's ``max |T(X) - X|`` on its frame columns."""
        E1 = ti.static((LANES + W - 1) // LANES)
        m = ti.Vector([0.0] * LANES, dt=ti.f32)
        for e in range(1, E1 + 1):
            m = ti.max(m, _lane_relax(st, q, channel, p, n, i, e, w, beta, lam, mom) * lane_mask(e, W))
        fill_ghosts(st, n, i, 1, 1, W, 1, REPLICATE)
        return run_max(m, LANES)


    @ti.func
    def _lane_finish_row(st: ti.template(), q: ti.template(), f_on, f_off, i, wn, wf, t_s, W: ti.template()):
        """Row ``i`` of ``S_on``, ``S_off`` and ``S`` at the fixed point (channels: buffers ``f_on``/``f_off``)."""
        E1 = ti.static((LANES + W - 1) // LANES)
        im = ti.max(i - 1, 0)
        ip = ti.min(i + 1, st.shape[1] - 1)
        for e in range(1, E1 + 1):
            cn, en, dn = lane_edge_diag(st, f_on, im, i, ip, e)
            a = feedback_local(cn, en, dn, wn, q[0, i, e])
            cf, ef, df = lane_edge_diag(st, f_off, im, i, ip, e)
            b = feedback_local(cf, ef, df, wf, q[1, i, e])
            st[S_ON_, i, e] = a
            st[S_OFF_, i, e] = b
            st[S_, i, e] = summed_layer(a, b, t_s)
        fill_ghosts(st, S_, i, 1, 1, W, 1, REPLICATE)


    @ti.func
    def _lane_box_row(st: ti.template(), src: ti.template(), dst: ti.template(), i, W: ti.template(),
                      reduce: ti.template()):
        """Row ``i`` of layer ``dst = src (*) ones/9`` (LGMD grouping, LGMD2's ``Ce``).

        Returns the row's float64 sum over the frame columns (``reduce == "sum"``) or its
        ``max |dst|`` there (``"max"``).
        """
        E1 = ti.static((LANES + W - 1) // LANES)
        im = ti.max(i - 1, 0)
        ip = ti.min(i + 1, st.shape[1] - 1)
        acc = ti.f64(0.0)
        for e in range(1, E1 + 1):
            cs, es, ds = lane_edge_diag(st, src, im, i, ip, e)
            b = _symmetric(cs, es, ds, 1.0 / 9.0, 1.0 / 9.0, 1.0 / 9.0)
            st[dst, i, e] = b
            v = b * lane_mask(e, W)
            if ti.static(reduce == "max"):
                acc = ti.max(acc, ti.cast(run_max(lane_abs(v), LANES), ti.f64))
            else:
                acc += ti.cast(v.sum(), ti.f64)
        return acc


    @ti.func
    def _feedback_stage(ctx: ti.template(), i0, i1, j):
        """Update ``j`` of the feedback iteration on rows ``[i0, i1)``: ON's buffer ``bufs[B_ON]`` (``j`` even)
        or ``bufs[B_ON_N]`` into the other one, the same for OFF (where ``bufs[B_WITH_OFF]`` is 1); maxes the residuals
        into ``rbuf[j, 0:2]``."""
        st, q, coef, bufs, W = ti.static(ctx.st, ctx.q, ctx.coef, ctx.bufs, ctx.W)
        lam = ctx.record[j, 0]
        mom = ctx.record[j, 1]
        beta_on = coef[BETA_ON]
        beta_off = coef[BETA_OFF]
        on, on_n, off, off_n = bufs[B_ON], bufs[B_ON_N], bufs[B_OFF], bufs[B_OFF_N]
        src_on = ti.select(j % 2 == 0, on, on_n)
        dst_on = on + on_n - src_on
        src_off = ti.select(j % 2 == 0, off, off_n)
        dst_off = off + off_n - src_off
        with_off = bufs[B_WITH_OFF]
        m_on = 0.0
        m_off = 0.0
        for i in range(i0, i1):
            m_on = ti.max(m_on, _lane_update_row(st, q, 0, src_on, dst_on, i, ctx.wn, beta_on, lam, mom, W))
            if with_off != 0:
                m_off = ti.max(m_off, _lane_update_row(st, q, 1, src_off, dst_off, i, ctx.wf, beta_off,
                                                       lam, mom, W))
        ti.atomic_max(rbuf[j, 0], m_on)
        ti.atomic_max(rbuf[j, 1], m_off)

    @ti.func
    def _feedback_finish_stage(ctx: ti.template(), i0, i1, ran):
        """``S_on``, ``S_off``, ``S`` of rows ``[i0, i1)`` at the fixed point (after ``ran`` updates)."""
        bufs = ti.static(ctx.bufs)
        f_on = ti.select(ran % 2 == 0, bufs[B_ON], bufs[B_ON_N])  # the buffers holding the result
        f_off = bufs[B_OFF]
        if bufs[B_WITH_OFF] != 0:
            f_off = ti.select(ran % 2 == 0, bufs[B_OFF], bufs[B_OFF_N])
        for i in range(i0, i1):
            _lane_finish_row(ctx.st, ctx.q, f_on, f_off, i, ctx.wn, ctx.wf, ctx.coef[T_S], ctx.W)

    @ti.func
    def _group_stage(ctx: ti.template(), i0, i1, j):
        """``G = S (*) ones/9`` on rows ``[i0, i1)``; adds their sum of ``G`` to ``msum[0]``, ``msum[1] = 1``."""
        acc = ti.f64(0.0)
        for i in range(i0, i1):
            acc += _lane_box_row(ctx.st, S_, G_, i, ctx.W, "sum")
        ti.atomic_add(msum[0], acc)
        msum[1] = 1.0

    #: F-LGMD's solve: the feedback updates, then at the fixed point the layers and the grouping.
    @ti.func
    def _flgmd_controls(ctx: ti.template()):
        """F-LGMD's solve: its workers, rows, updates at most and stopping rule."""
        return ctx.bufs[B_NW], ctx.st.shape[1], ctx.bufs[B_N], ctx.coef[TOL], ctx.coef[GROW]

    FLGMD_PLAN = Plan(update=(_feedback_stage,), after=(_feedback_finish_stage, _group_stage),
                      controls=_flgmd_controls)
    flgmd_workers = workers(FLGMD_PLAN)
    FLGMDCtx = context("FLGMDCtx", "st q coef bufs record W wn wf")

    @vector_kernel
    @ti.kernel
    def flgmd_lanes_solve(st: LANE3, q: LANE3, bufs: I1, record: ti.types.ndarray(dtype=ti.f32, ndim=2), coef: F1,
                          W: ti.template(), out: D1):
        """Up to ``bufs[B_N]`` feedback updates (:func:`flgmd_iterate`) in one launch, then the layers
        (:data:`FLGMD_PLAN` on the engine's scheduler).

        Update ``j`` uses ``lam, mom = record[j, 0:2]`` and reads the ON channel's buffer
        ``bufs[B_ON]`` (``j`` even) or ``bufs[B_ON_N]`` (``j`` odd), writing the other one (OFF:
        ``bufs[B_OFF]``/``bufs[B_OFF_N]``); OFF is iterated only where ``bufs[B_WITH_OFF]`` is 1; at most
        ``bufs[B_N]`` updates, by ``bufs[B_NW]`` workers. The updates stop after the first one whose
        residuals are both ``<= coef[TOL]``, or one whose worst residual exceeds ``coef[GROW]`` times
        the best of the launch. When the launch converged, the workers compute ``S_on``, ``S_off``, ``S``
        and ``G`` of the result (as :func:`flgmd_lanes_finish`). In its serial tail it writes the ON and
        OFF residuals of each update to ``record[j, 2:4]`` (-1: not run,
        :class:`~cdnf_ti.kernels.common.LaunchRecord`) and ``sum G`` to ``out[0]`` (-1 when the
        launch did not converge).
        """
        msum[0] = 0.0
        msum[1] = 0.0
        # W_x of ON and OFF read here, in the kernel's serial part, and handed down to the rows (as the
        # scalar arguments of the code before the state array were): read in the stages or rows instead,
        # taichi 1.7.4's float reassociation ordered feedback_local's sums differently (not bit-identical).
        wn = coef3(coef, WN)
        wf = coef3(coef, WF)
        ctx = ti.static(FLGMDCtx(st, q, coef, bufs, record, W, wn, wf))
        flgmd_workers(ctx)
        sched.residuals_to(record, 2)
        out[0] = -1.0
        if msum[1] > 0.0:  # the layers were computed (the workers have all finished here)
            out[0] = msum[0]


    @vector_kernel
    @ti.kernel
    def flgmd_lanes_finish(st: LANE3, q: LANE3, on: ti.i32, off: ti.i32, coef: F1, W: ti.template(), out: D1):
        """:func:`flgmd_finish` on lane fields (channels: buffers ``on``/``off``); ``out[0] = sum G``
        (set to 0 by the caller).

        For a frame whose solve launch did not converge (:func:`flgmd_lanes_solve` computes
        the layers itself when it does).
        """
        H = st.shape[1]
        wn = coef3(coef, WN)  # read here and handed down, as in flgmd_lanes_solve
        wf = coef3(coef, WF)
        t_s = coef[T_S]
        for i in range(H):
            _lane_finish_row(st, q, on, off, i, wn, wf, t_s, W)
        for i in range(H):
            ti.atomic_add(out[0], _lane_box_row(st, S_, G_, i, W, "sum"))


    # -- LGMD1 and LGMD2 on lane fields: the layers of a frame in one launch -------------------
    # Stages on the scheduler: the delayed layers and S (_delayed_stage); then LGMD2: Ce and
    # max |Ce|, then G and sum G. LGMD1: G and sum G (_group_stage, as F-LGMD).


    @ti.func
    def _lane_delayed_row(st: ti.template(), coef: ti.template(), c, q, w_on, w_off, i, W: ti.template(),
                          model: ti.template()):
        """Row ``i`` of the delayed layers (:func:`delayed_mix` of ON/OFF: buffer ``c`` now, ``q`` the frame
        before; OFF's ``+ PING_PONG``) and of ``S``: :func:`lgmd1_summation` (``model == "lgmd1"``)
        or :func:`lgmd2_summation` (with ``w_on``, ``w_off``)."""
        E1 = ti.static((LANES + W - 1) // LANES)
        im = ti.max(i - 1, 0)
        ip = ti.min(i + 1, st.shape[1] - 1)
        x = ti.static(DELAYED[model])
        kn0, kn1, kn2 = coef_or_zero(coef, x[0]), coef_or_zero(coef, x[1]), coef_or_zero(coef, x[2])
        an0, an1, an2 = coef_or_zero(coef, x[3]), coef_or_zero(coef, x[4]), coef_or_zero(coef, x[5])
        kf0, kf1, kf2 = coef_or_zero(coef, x[6]), coef_or_zero(coef, x[7]), coef_or_zero(coef, x[8])
        af0, af1, af2 = coef_or_zero(coef, x[9]), coef_or_zero(coef, x[10]), coef_or_zero(coef, x[11])
        e_on, e_off, e_onoff = coef[E_WEIGHTS], coef[E_WEIGHTS + 1], coef[E_WEIGHTS + 2]
        w_i_on, w_i_off, t_s = coef[W_I_ON], coef[W_I_OFF], coef[T_S]
        for e in range(1, E1 + 1):
            cn, en, dn = lane_edge_diag(st, c, im, i, ip, e)
            cnp, enp, dnp = lane_edge_diag(st, q, im, i, ip, e)
            x_on = delayed_mix(cn, en, dn, cnp, enp, dnp, kn0, kn1, kn2, an0, an1, an2)
            cf, ef, df = lane_edge_diag(st, c + PING_PONG, im, i, ip, e)
            cfp, efp, dfp = lane_edge_diag(st, q + PING_PONG, im, i, ip, e)
            x_off = delayed_mix(cf, ef, df, cfp, efp, dfp, kf0, kf1, kf2, af0, af1, af2)
            st[I_ON_, i, e] = x_on
            st[I_ON_ + 1, i, e] = x_off  # LGMD2's I_off, LGMD1's E_off
            if ti.static(model == "lgmd1"):
                st[S_, i, e] = lgmd1_summation(cn, cf, x_on, x_off, w_i_on, w_i_off, (e_on, e_off, e_onoff), t_s)
            else:
                st[S_, i, e] = lgmd2_summation(cn, cf, x_on, x_off, w_on, w_off, (e_on, e_off, e_onoff))
        fill_ghosts(st, S_, i, 1, 1, W, 1, REPLICATE)


    def _delayed_stage_of(model: str):
        """The stage of ``model``'s delayed layers and ``S`` on rows ``[i0, i1)`` (:func:`_lane_delayed_row`)."""

        @ti.func
        def _delayed_stage(ctx: ti.template(), i0, i1, j):
            for i in range(i0, i1):
                _lane_delayed_row(ctx.st, ctx.coef, ctx.c, ctx.q, ctx.w_on, ctx.w_off, i, ctx.W, model)

        return _delayed_stage

    @ti.func
    def _excitation_stage(ctx: ti.template(), i0, i1, j):
        """LGMD2's ``Ce = S (*) ones/9`` on rows ``[i0, i1)``; maxes their ``max |Ce|`` into ``rbuf[0, 0]``."""
        m = 0.0
        for i in range(i0, i1):
            m = ti.max(m, ti.cast(_lane_box_row(ctx.st, S_, CE_, i, ctx.W, "max"), ti.f32))
        ti.atomic_max(rbuf[0, 0], m)

    @ti.func
    def _grouping_stage(ctx: ti.template(), i0, i1, j):
        """LGMD2's grouping ``G`` on rows ``[i0, i1)`` (:func:`lgmd2_grouping`, ``max |Ce|`` from ``rbuf[0, 0]``);
        adds their sum of ``G`` to ``msum[0]``."""
        st, coef, W = ti.static(ctx.st, ctx.coef, ctx.W)
        inv_omega = 1.0 / (coef[DELTA_C] + ti.max(rbuf[0, 0], 0.0) / coef[C_W])
        c_de, t_de = coef[C_DE], coef[T_DE]
        acc = ti.f64(0.0)
        for i in range(i0, i1):
            E1 = ti.static((LANES + W - 1) // LANES)
            for e in range(1, E1 + 1):
                g = lgmd2_grouping(st[S_, i, e], st[CE_, i, e], inv_omega, c_de, t_de)
                st[G_, i, e] = g
                acc += ti.cast((g * lane_mask(e, W)).sum(), ti.f64)
        ti.atomic_add(msum[0], acc)

    #: LGMD2's layers: delayed inhibitions and S, then Ce and max |Ce|, then the grouping.
    @ti.func
    def _layers_controls(ctx: ti.template()):
        """The layers' workers and rows (no updates)."""
        return ctx.nw, ctx.st.shape[1], 0, 0.0, 0.0

    LGMD2_PLAN = Plan(after=(_delayed_stage_of("lgmd2"), _excitation_stage, _grouping_stage),
                      controls=_layers_controls)
    #: LGMD1's layers: delayed spreads and S, then the grouping.
    LGMD1_PLAN = Plan(after=(_delayed_stage_of("lgmd1"), _group_stage), controls=_layers_controls)
    lgmd2_workers = workers(LGMD2_PLAN)
    lgmd1_workers = workers(LGMD1_PLAN)
    #: ``c``, ``q``: the ON channel's buffers now and the frame before (OFF's: ``+ PING_PONG``).
    LayersCtx = context("LayersCtx", "st coef c q w_on w_off nw W")

    @vector_kernel
    @ti.kernel
    def lgmd2_lanes_layers(st: LANE3, c: ti.i32, q: ti.i32, w_on: ti.f32, w_off: ti.f32, coef: F1, nw: ti.i32,
                           W: ti.template(), out: D1):
        """:func:`lgmd2_layers` on lane fields, in one launch by persistent workers (:data:`LGMD2_PLAN`;
        channels: ON's buffer ``c`` now, ``q`` the frame before, OFF's ``+ PING_PONG``).

        Writes ``out[0] = sum G``, ``out[1] = max |Ce|`` in its serial tail.
        """
        msum[0] = 0.0
        ctx = ti.static(LayersCtx(st, coef, c, q, w_on, w_off, nw, W))
        lgmd2_workers(ctx)
        out[0] = msum[0]
        out[1] = ti.cast(ti.max(rbuf[0, 0], 0.0), ti.f64)

    @vector_kernel
    @ti.kernel
    def lgmd1_lanes_layers(st: LANE3, c: ti.i32, q: ti.i32, coef: F1, nw: ti.i32, W: ti.template(), out: D1):
        """:func:`lgmd1_layers` on lane fields, in one launch by persistent workers (:data:`LGMD1_PLAN`;
        channels: ON's buffer ``c`` now, ``q`` the frame before, OFF's ``+ PING_PONG``).

        Writes ``out[0] = sum G`` in its serial tail.
        """
        msum[0] = 0.0
        ctx = ti.static(LayersCtx(st, coef, c, q, 0.0, 0.0, nw, W))
        lgmd1_workers(ctx)
        out[0] = msum[0]

    return namespace(globals(), locals())
