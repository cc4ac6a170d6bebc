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

No kernel returns a value (returning a float64 or a vector costs ~0.1-0.2 ms per
launch on the CPU and 1-2 ms on CUDA): each writes its results into ``out``, a
small float64 NumPy array (:data:`D1`) that the caller sets before the launch
(zeros for sums and maxima) and reads after it. Every work item adds (or maxes)
its partial result into ``out`` once; the persistent-worker kernels reduce into
their own fields and copy the results into ``out`` in their serial tail.

The NumPy float64 oracle of every stage is :mod:`cdnf_ti.baselines_reference`.
"""

import functools
from types import SimpleNamespace

from ..taichi_runtime import vector_kernel
from . import common, schedule
from .common import REPLICATE, namespace
from .schedule import Plan, context

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
    workers = schedule.build(ti, lanes).workers
    LANE2 = C.LANE2
    LANE3 = C.LANE3
    LANES = C.LANES
    block_span = C.block_span
    fill = C.fill
    fill_ghosts = C.fill_ghosts
    lane_abs = C.lane_abs
    lane_edge_diag = C.lane_edge_diag
    lane_mask = C.lane_mask
    luminance_change = C.luminance_change
    record_residuals = C.record_residuals
    row_runs = C.row_runs
    run_load = C.run_load
    run_max = C.run_max
    run_store = C.run_store
    run_sum = C.run_sum

    F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    D1 = ti.types.ndarray(dtype=ti.f64, ndim=1)  # a launch's results ``out``, set by the caller before it


    @ti.func
    def half_wave(p, on_prev, off_prev, clip, dc):
        """ON/OFF channels with residue (scalars or vectors):
        ``ON = P [P >= clip] + dc ON(t-1)``, ``OFF = |P| [P < clip] + dc OFF(t-1)``."""
        return ti.select(p >= clip, p, 0.0) + dc * on_prev, ti.select(p < clip, lane_abs(p), 0.0) + dc * off_prev


    @ti.func
    def _symmetric(c, e, d, w0, w1, w2):
        """A symmetric 3x3 correlation from the centre ``c`` and the edge/diagonal neighbour sums ``e``/``d``."""
        return w0 * c + w1 * e + w2 * d


    @ti.func
    def _edge_diag(x: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        """Sums of the 4 edge and 4 diagonal neighbours of the run ``(i, j .. j + n - 1)``."""
        e = run_load(x, im, j, n) + run_load(x, ip, j, n) + run_load(x, i, jm, n) + run_load(x, i, jp, n)
        d = run_load(x, im, jm, n) + run_load(x, im, jp, n) + run_load(x, ip, jm, n) + run_load(x, ip, jp, n)
        return e, d


    @ti.func
    def _stencil(x: ti.template(), im, i, ip, jm, j, jp, n: ti.template(), w0, w1, w2):
        """Symmetric 3x3 correlation (centre w0, edge w1, diagonal w2) on a run."""
        e, d = _edge_diag(x, im, i, ip, jm, j, jp, n)
        return _symmetric(run_load(x, i, j, n), e, d, w0, w1, w2)


    @ti.func
    def _delayed(x: ti.template(), xp: ti.template(), im, i, ip, jm, j, jp, n: ti.template(), k0, k1, k2, a0, a1, a2):
        """``sum K [a X(t) + (1 - a) X(t-1)]`` over the 3x3 window (centre k0/a0, edge k1/a1, diagonal k2/a2)."""
        e, d = _edge_diag(x, im, i, ip, jm, j, jp, n)
        ep, dp = _edge_diag(xp, im, i, ip, jm, j, jp, n)
        return delayed_mix(run_load(x, i, j, n), e, d, run_load(xp, i, j, n), ep, dp, k0, k1, k2, a0, a1, a2)


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


    GroupRunCtx = context("GroupRunCtx", "S G")

    @ti.func
    def _group_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        S, G = ti.static(ctx.S, ctx.G)
        g = _stencil(S, im, i, ip, jm, j, jp, n, 1.0 / 9.0, 1.0 / 9.0, 1.0 / 9.0)
        run_store(G, i, j, g, n)
        return run_sum(g, n)


    @ti.func
    def _group(S: ti.template(), G: ti.template(), blocks, out: ti.template()):
        """Grouping ``G = S (*) (1/9 ones 3x3)`` over the frame (a top-level parallel loop);
        adds ``sum G`` (float64) to ``out[0]``."""
        H, W = S.shape[0], S.shape[1]
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(GroupRunCtx(S, G))
            ti.atomic_add(out[0], row_runs(_group_run, ctx, i, j0, j1, H, W, "sum", 1))


    LoadRunCtx = context("LoadRunCtx", "frame L P on off on_p off_p scale keep clip dc")

    @ti.func
    def _load_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        frame, L, P, on, off, on_p, off_p = ti.static(ctx.frame, ctx.L, ctx.P, ctx.on, ctx.off, ctx.on_p, ctx.off_p)
        scale, keep, clip, dc = ctx.scale, ctx.keep, ctx.clip, ctx.dc
        p = luminance_change(frame, L, P, i, j, n, scale, keep, True)
        a, b = half_wave(p, run_load(on_p, i, j, n), run_load(off_p, i, j, n), clip, dc)
        run_store(on, i, j, a, n)
        run_store(off, i, j, b, n)
        return run_sum(ti.abs(p), n)


    @ti.kernel
    def load_frame(frame: ti.types.ndarray(ndim=2), L: F2, P: F2, on: F2, off: F2, on_p: F2, off_p: F2,
                   scale: ti.f32, first: ti.i32, clip: ti.f32, dc: ti.f32, blocks: ti.i32, out: D1):
        """Photoreceptors and the ON/OFF channels of one frame; adds ``sum |P|`` to ``out[0]`` (set to 0 by the caller).

        ``g = floor(frame * scale + 0.5)`` (integer grey levels); ``P = g - L`` (0 when
        ``first``); ``L = g``; ``ON = P [P >= clip] + dc ON(t-1)``,
        ``OFF = |P| [P < clip] + dc OFF(t-1)`` (``on_p``/``off_p``: the channels of the
        previous frame; ``on``/``off`` receive the new ones, which the model uses or,
        on an FFI-held frame, drops). The rounding makes float input (``scale = 255``)
        the 8-bit grey levels the authors' code works on (``HighpassFilter(byte, byte)
        -> int`` in lgmd2OpenSource.cs / LGMDs.cs, fuqinbing/LGMD2-open-source);
        uint8 input (``scale = 1``) is unchanged. NumPy reference:
        :func:`cdnf_ti.baselines_reference.eight_bit`, ``half_wave_on``/``half_wave_off``.
        """
        H, W = L.shape[0], L.shape[1]
        keep = ti.select(first != 0, 0.0, 1.0)
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(LoadRunCtx(frame, L, P, on, off, on_p, off_p, scale, keep, clip, dc))
            ti.atomic_add(out[0], row_runs(_load_run, ctx, i, j0, j1, H, W, "sum", 1))


    Lgmd2RunCtx = context("Lgmd2RunCtx", "on off on_p off_p I_on I_off S kn an kf af w_on w_off e")

    @ti.func
    def _lgmd2_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        on, off, on_p, off_p, I_on, I_off, S = ti.static(ctx.on, ctx.off, ctx.on_p,
                                                         ctx.off_p, ctx.I_on, ctx.I_off, ctx.S)
        kn, an, kf, af, w_on, w_off, e = ctx.kn, ctx.an, ctx.kf, ctx.af, ctx.w_on, ctx.w_off, ctx.e
        i_on = _delayed(on, on_p, im, i, ip, jm, j, jp, n, kn[0], kn[1], kn[2], an[0], an[1], an[2])
        i_off = _delayed(off, off_p, im, i, ip, jm, j, jp, n, kf[0], kf[1], kf[2], af[0], af[1], af[2])
        run_store(I_on, i, j, i_on, n)
        run_store(I_off, i, j, i_off, n)
        run_store(S, i, j, lgmd2_summation(run_load(on, i, j, n), run_load(off, i, j, n), i_on, i_off, w_on, w_off, e),
                  n)
        return 0.0


    ExcitationRunCtx = context("ExcitationRunCtx", "S Ce")

    @ti.func
    def _excitation_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        S, Ce = ti.static(ctx.S, ctx.Ce)
        c = _stencil(S, im, i, ip, jm, j, jp, n, 1.0 / 9.0, 1.0 / 9.0, 1.0 / 9.0)
        run_store(Ce, i, j, c, n)
        return run_max(ti.abs(c), n)


    GroupingRunCtx = context("GroupingRunCtx", "S Ce G inv_omega c_de t_de")

    @ti.func
    def _grouping_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        S, Ce, G = ti.static(ctx.S, ctx.Ce, ctx.G)
        inv_omega, c_de, t_de = ctx.inv_omega, ctx.c_de, ctx.t_de
        g = lgmd2_grouping(run_load(S, i, j, n), run_load(Ce, i, j, n), inv_omega, c_de, t_de)
        run_store(G, i, j, g, n)
        return run_sum(g, n)


    @ti.kernel
    def lgmd2_layers(
        on: F2, off: F2, on_p: F2, off_p: F2, I_on: F2, I_off: F2, S: F2, Ce: F2, G: F2,
        w_on: ti.f32, w_off: ti.f32,
        kn0: ti.f32, kn1: ti.f32, kn2: ti.f32, an0: ti.f32, an1: ti.f32, an2: ti.f32,
        kf0: ti.f32, kf1: ti.f32, kf2: ti.f32, af0: ti.f32, af1: ti.f32, af2: ti.f32,
        e_on: ti.f32, e_off: ti.f32, e_onoff: ti.f32,
        delta_c: ti.f32, c_w: ti.f32, c_de: ti.f32, t_de: ti.f32, blocks: ti.i32, out: D1,
    ):
        """LGMD2 layers of one frame from its ON/OFF channels (:func:`load_frame`).

        Delayed 3x3 inhibitions (centre included);
        ``S = e_on S_on + e_off S_off + e_onoff S_on S_off`` with
        ``S_on = [ON - w_on I_on]+``; ``Ce = S (*) ones/9``;
        ``G = S Ce / (delta_c + max|Ce| / c_w)``, zero unless ``c_de G >= t_de``.
        ``out[0] = sum G``, ``out[1] = max |Ce|`` (both set to 0 by the caller).
        """
        H, W = on.shape[0], on.shape[1]
        kn = ti.Vector([kn0, kn1, kn2])
        an = ti.Vector([an0, an1, an2])
        kf = ti.Vector([kf0, kf1, kf2])
        af = ti.Vector([af0, af1, af2])
        e = ti.Vector([e_on, e_off, e_onoff])
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(Lgmd2RunCtx(on, off, on_p, off_p, I_on, I_off, S, kn, an, kf, af, w_on, w_off, e))
            row_runs(_lgmd2_run, ctx, i, j0, j1, H, W, "sum", 1)
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(ExcitationRunCtx(S, Ce))
            ti.atomic_max(out[1], row_runs(_excitation_run, ctx, i, j0, j1, H, W, "max", 1))
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            mx = ti.cast(out[1], ti.f32)  # max |Ce| (a float32 value: exact)
            inv_omega = 1.0 / (delta_c + mx / c_w)
            ctx = ti.static(GroupingRunCtx(S, Ce, G, inv_omega, c_de, t_de))
            ti.atomic_add(out[0], row_runs(_grouping_run, ctx, i, j0, j1, H, W, "sum", 1))


    @ti.func
    def lgmd1_summation(on, off, i_on, exc_off, w_i_on, w_i_off, e, t_s):
        """LGMD1's ``S = e_on S_on + e_off S_off + e_onoff S_on S_off``, kept where ``S >= t_s``, with
        ``S_on = ON - w_i_on I_on`` and ``S_off = E_off - w_i_off OFF``."""
        s_on = on - w_i_on * i_on
        s_off = exc_off - w_i_off * off
        s = e[0] * s_on + e[1] * s_off + e[2] * s_on * s_off
        return ti.select(s >= t_s, s, 0.0)


    Lgmd1RunCtx = context("Lgmd1RunCtx", "on off on_p off_p I_on E_off S k a w_i_on w_i_off e t_s")

    @ti.func
    def _lgmd1_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        on, off, on_p, off_p, I_on, E_off, S = ti.static(ctx.on, ctx.off, ctx.on_p,
                                                         ctx.off_p, ctx.I_on, ctx.E_off, ctx.S)
        k, a, w_i_on, w_i_off, e, t_s = ctx.k, ctx.a, ctx.w_i_on, ctx.w_i_off, ctx.e, ctx.t_s
        i_on = _delayed(on, on_p, im, i, ip, jm, j, jp, n, 0.0, k[0], k[1], 0.0, a[0], a[1])
        e_o = _delayed(off, off_p, im, i, ip, jm, j, jp, n, 0.0, k[0], k[1], 0.0, a[0], a[1])
        run_store(I_on, i, j, i_on, n)
        run_store(E_off, i, j, e_o, n)
        run_store(S, i, j, lgmd1_summation(run_load(on, i, j, n), run_load(off, i, j, n), i_on, e_o, w_i_on, w_i_off,
                                           e, t_s), n)
        return 0.0


    @ti.kernel
    def lgmd1_layers(
        on: F2, off: F2, on_p: F2, off_p: F2, I_on: F2, E_off: F2, S: F2, G: F2,
        w_i_on: ti.f32, w_i_off: ti.f32, k1: ti.f32, k2: ti.f32, a1: ti.f32, a2: ti.f32,
        e_on: ti.f32, e_off: ti.f32, e_onoff: ti.f32, t_s: ti.f32, blocks: ti.i32, out: D1,
    ):
        """LGMD1 layers of one frame from its ON/OFF channels (:func:`load_frame`).

        ``I_on``/``E_off``: delayed 3x3 spreads (centre 0) of ON/OFF;
        ``S_on = ON - w_i_on I_on``, ``S_off = E_off - w_i_off OFF``;
        ``S = e_on S_on + e_off S_off + e_onoff S_on S_off`` kept where ``>= t_s``;
        ``G = S (*) ones/9``. ``out[0] = sum G`` (set to 0 by the caller).
        """
        H, W = on.shape[0], on.shape[1]
        kk = ti.Vector([k1, k2])
        a = ti.Vector([a1, a2])
        e = ti.Vector([e_on, e_off, e_onoff])
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(Lgmd1RunCtx(on, off, on_p, off_p, I_on, E_off, S, kk, a, w_i_on, w_i_off, e, t_s))
            row_runs(_lgmd1_run, ctx, i, j0, j1, H, W, "sum", 1)
        _group(S, G, blocks, out)


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
    def _flgmd_local(x: ti.template(), q: ti.template(), im, i, ip, jm, j, jp, n: ti.template(), w):
        """``S_X = [W_x (*) X - Q]+`` on a run (``w``: centre, edge, diagonal of ``W_x``)."""
        e, d = _edge_diag(x, im, i, ip, jm, j, jp, n)
        return feedback_local(run_load(x, i, j, n), e, d, w, run_load(q, i, j, n))


    PrepareRunCtx = context("PrepareRunCtx", "on0 off0 on off on_p off_p q_on q_off c_on c_off g_on g_off")

    @ti.func
    def _prepare_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        on0, off0, on, off = ti.static(ctx.on0, ctx.off0, ctx.on, ctx.off)
        on_p, off_p, q_on, q_off = ti.static(ctx.on_p, ctx.off_p, ctx.q_on, ctx.q_off)
        c_on, c_off = ctx.c_on, ctx.c_off  # (edge, diagonal) weights w_i K (1 - a) of each channel
        g_on, g_off = ctx.g_on, ctx.g_off  # (w, kappa) of each channel's start
        qn = _stencil(on_p, im, i, ip, jm, j, jp, n, 0.0, c_on[0], c_on[1])
        qf = _stencil(off_p, im, i, ip, jm, j, jp, n, 0.0, c_off[0], c_off[1])
        run_store(q_on, i, j, qn, n)
        run_store(q_off, i, j, qf, n)
        run_store(on, i, j, feedback_start(run_load(on0, i, j, n), qn, g_on[0], g_on[1]), n)
        run_store(off, i, j, feedback_start(run_load(off0, i, j, n), qf, g_off[0], g_off[1]), n)
        return 0.0


    @ti.kernel
    def flgmd_prepare(on0: F2, off0: F2, on: F2, off: F2, on_p: F2, off_p: F2, q_on: F2, q_off: F2,
                      k1: ti.f32, k2: ti.f32, a1: ti.f32, a2: ti.f32, w_i_on: ti.f32, w_i_off: ti.f32,
                      wn: ti.f32, kn: ti.f32, wf: ti.f32, kf: ti.f32, blocks: ti.i32):
        """The frame's constant inhibition ``Q = w_i sum K (1 - a) X(t-1)`` of both channels
        (``on_p``/``off_p``: the settled previous channels) and the iterate's start ``on``/``off``
        from the drives ``on0``/``off0`` (:func:`load_frame`) by :func:`feedback_start`
        (``wn``/``kn``, ``wf``/``kf``: ``w`` and ``kappa`` of ON and OFF)."""
        H, W = on0.shape[0], on0.shape[1]
        c = ti.Vector([k1 * (1.0 - a1), k2 * (1.0 - a2)])
        g_on, g_off = ti.Vector([wn, kn]), ti.Vector([wf, kf])
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(PrepareRunCtx(on0, off0, on, off, on_p, off_p, q_on, q_off, w_i_on * c, w_i_off * c,
                                          g_on, g_off))
            row_runs(_prepare_run, ctx, i, j0, j1, H, W, "sum", 1)


    @ti.func
    def _relax_run(x0: ti.template(), x: ti.template(), q: ti.template(), x_n: ti.template(), im, i, ip, jm, j, jp,
                   n: ti.template(), w, beta, lam, mom):
        """One update of a channel on a run; returns ``max |T(X) - X|`` there."""
        local = _flgmd_local(x, q, im, i, ip, jm, j, jp, n, w)
        new, d = feedback_update(run_load(x0, i, j, n), run_load(x, i, j, n), local, run_load(x_n, i, j, n),
                                 beta, lam, mom)
        run_store(x_n, i, j, new, n)
        return run_max(ti.abs(d), n)


    IterateRunCtx = context("IterateRunCtx", "on0 on q_on on_n w beta lam mom")

    @ti.func
    def _iterate_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        on0, on, q_on, on_n = ti.static(ctx.on0, ctx.on, ctx.q_on, ctx.on_n)
        return _relax_run(on0, on, q_on, on_n, im, i, ip, jm, j, jp, n, ctx.w, ctx.beta, ctx.lam, ctx.mom)


    @ti.kernel
    def flgmd_iterate(
        on0: F2, off0: F2, on: F2, off: F2, q_on: F2, q_off: F2, on_n: F2, off_n: F2,
        wn0: ti.f32, wn1: ti.f32, wn2: ti.f32, wf0: ti.f32, wf1: ti.f32, wf2: ti.f32,
        beta_on: ti.f32, beta_off: ti.f32, lam: ti.f32, mom: ti.f32, blocks: ti.i32, with_off: ti.template(),
        out: D1,
    ):
        """One fixed-point update ``X_n = X + mom (X - X_n) + lam (T(X) - X)``, ``T(X) = [X0 + beta S_X(X)]+``.

        ``on_n``/``off_n`` hold the iterate before ``X`` on entry (used when ``mom != 0``:
        a Chebyshev step; ``mom = 0``: plain relaxation).
        ``wn``/``wf``: ``(centre, edge, diagonal)`` of ``W_x`` for the ON/OFF channel
        (:meth:`cdnf_ti.models.flgmd.FLGMDParams.feedback_stencils`). The residuals
        ``out[0] = max|T(ON) - ON|``, ``out[1] = max|T(OFF) - OFF|`` (both set to 0 by the
        caller). With ``with_off`` False (``beta_off == 0``) the OFF channel equals its
        drive and is not iterated (``out[1]`` stays 0).
        """
        H, W = on.shape[0], on.shape[1]
        wn = ti.Vector([wn0, wn1, wn2])
        wf = ti.Vector([wf0, wf1, wf2])
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(IterateRunCtx(on0, on, q_on, on_n, wn, beta_on, lam, mom))
            ti.atomic_max(out[0], row_runs(_iterate_run, ctx, i, j0, j1, H, W, "max", 1))
            if ti.static(with_off):
                ctx = ti.static(IterateRunCtx(off0, off, q_off, off_n, wf, beta_off, lam, mom))
                ti.atomic_max(out[1], row_runs(_iterate_run, ctx, i, j0, j1, H, W, "max", 1))


    FinishRunCtx = context("FinishRunCtx", "on off q_on q_off S_on S_off S wn wf t_s")

    @ti.func
    def _finish_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
        on, off, q_on, q_off, S_on, S_off, S = ti.static(ctx.on, ctx.off, ctx.q_on,
                                                         ctx.q_off, ctx.S_on, ctx.S_off, ctx.S)
        wn, wf, t_s = ctx.wn, ctx.wf, ctx.t_s
        a = _flgmd_local(on, q_on, im, i, ip, jm, j, jp, n, wn)
        b = _flgmd_local(off, q_off, im, i, ip, jm, j, jp, n, wf)
        run_store(S_on, i, j, a, n)
        run_store(S_off, i, j, b, n)
        run_store(S, i, j, summed_layer(a, b, t_s), n)
        return 0.0


    @ti.kernel
    def flgmd_finish(
        on: F2, off: F2, q_on: F2, q_off: F2, S_on: F2, S_off: F2, S: F2, G: F2,
        wn0: ti.f32, wn1: ti.f32, wn2: ti.f32, wf0: ti.f32, wf1: ti.f32, wf2: ti.f32,
        t_s: ti.f32, blocks: ti.i32, out: D1,
    ):
        """Local summation at the fixed point, ``S = S_on + S_off`` kept where ``>= t_s``,
        ``G = S (*) ones/9``; ``out[0] = sum G`` (set to 0 by the caller)."""
        H, W = on.shape[0], on.shape[1]
        wn = ti.Vector([wn0, wn1, wn2])
        wf = ti.Vector([wf0, wf1, wf2])
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            ctx = ti.static(FinishRunCtx(on, off, q_on, q_off, S_on, S_off, S, wn, wf, t_s))
            row_runs(_finish_run, ctx, i, j0, j1, H, W, "sum", 1)
        _group(S, G, blocks, out)


    # -- F-LGMD on lane fields (the fast CPU path) ------------------------------------------
    # The same equations (half_wave, feedback_local, feedback_update, summed_layer) on
    # lane arrays with ghost columns (vector ndarrays, see kernels/common.py): element
    # (i, e) holds the LANES columns (e - 1) * LANES .. e * LANES - 1 of row i, elements
    # 1..E1 hold the frame, the replicate border sits in the ghost columns -1 and W.
    # The channels have three buffers (leading index): the settled channel of the last
    # frame and two ping-pong buffers of the iteration. Work items are (row, element
    # block) pairs, so both CPU threads get work on 240-row frames.


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


    @vector_kernel
    @ti.kernel
    def lgmd_lanes_load(
        frame: ti.types.ndarray(ndim=2), L: LANE2, P: LANE2, on: LANE3, off: LANE3,
        c_on: ti.i32, s_on: ti.i32, c_off: ti.i32, s_off: ti.i32, scale: ti.f32, first: ti.i32, clip: ti.f32,
        dc: ti.f32, W: ti.template(), blocks: ti.i32, feedback: ti.template(), on0: LANE2,
        off0: LANE2, q_on: LANE2, q_off: LANE2, qn1: ti.f32, qn2: ti.f32, qf1: ti.f32,
        qf2: ti.f32, wn: ti.f32, kn: ti.f32, wf: ti.f32, kf: ti.f32, out: D1,
    ):
        """:func:`load_frame` on lane fields: photoreceptors ``L``/``P`` and the ON/OFF channels,
        ``on[s_on] = P [P >= clip] + dc on[c_on]`` (same for OFF); adds ``sum |P|`` to ``out[0]``
        (set to 0 by the caller).

        With ``feedback`` (F-LGMD) it also does :func:`flgmd_prepare`: the drives
        ``on0``/``off0``, ``Q = w_i sum K (1 - a) X(t-1)`` of the settled channels
        ``on[c_on]``/``off[c_off]`` (``qn``/``qf``: edge and diagonal weights of ON and OFF)
        and the iterate's start ``on[s_on]``/``off[s_off]`` (:func:`feedback_start`, ``wn``/``kn``,
        ``wf``/``kf``: ``w`` and ``kappa`` of ON and OFF); otherwise those arguments are not used.
        """
        H = L.shape[0]
        E1 = ti.static((LANES + W - 1) // LANES)
        keep = ti.select(first != 0, 0.0, 1.0)
        for k in range(H * blocks):
            i, e0, e1 = _lane_span(k, E1, blocks)
            im = ti.max(i - 1, 0)
            ip = ti.min(i + 1, H - 1)
            acc = ti.f64(0.0)
            for e in range(e0, e1):
                g = _lane_grey(frame, i, e, scale, W)
                p = keep * (g - L[i, e])
                L[i, e] = g
                P[i, e] = p
                a, b = half_wave(p, on[c_on, i, e], off[c_off, i, e], clip, dc)
                if ti.static(feedback):
                    on0[i, e] = a
                    off0[i, e] = b
                    cn, en, dn = lane_edge_diag(on, c_on, im, i, ip, e)
                    qn = _symmetric(cn, en, dn, 0.0, qn1, qn2)
                    q_on[i, e] = qn
                    cf, ef, df = lane_edge_diag(off, c_off, im, i, ip, e)
                    qf = _symmetric(cf, ef, df, 0.0, qf1, qf2)
                    q_off[i, e] = qf
                    a = feedback_start(a, qn, wn, kn)
                    b = feedback_start(b, qf, wf, kf)
                on[s_on, i, e] = a
                off[s_off, i, e] = b
                acc += ti.cast((lane_abs(p) * lane_mask(e, W)).sum(), ti.f64)
            fill_ghosts(on, s_on, i, e0 == 1, e1 == E1 + 1, W, 1, REPLICATE)
            fill_ghosts(off, s_off, i, e0 == 1, e1 == E1 + 1, W, 1, REPLICATE)
            ti.atomic_add(out[0], acc)


    @ti.func
    def _lane_relax(x0: ti.template(), x: ti.template(), q: ti.template(), p, n, im, i, ip, e, w, beta, lam, mom,
                    W: ti.template()):
        """Element ``(i, e)``: buffer ``n`` of ``x`` = the update (:func:`feedback_update`) of buffer ``p``;
        returns ``|T(X) - X|`` on its frame columns."""
        c, ed, dg = lane_edge_diag(x, p, im, i, ip, e)
        new, d = feedback_update(x0[i, e], c, feedback_local(c, ed, dg, w, q[i, e]), x[n, i, e], beta, lam, mom)
        x[n, i, e] = new
        return lane_abs(d) * lane_mask(e, W)


    @ti.func
    def _lane_update_row(x0: ti.template(), x: ti.template(), q: ti.template(), p, n, i, H, w, beta, lam, mom,
                         W: ti.template()):
        """Row ``i`` of one channel update (buffer ``p`` into ``n``, :func:`_lane_relax`).

        Returns the row's ``max |T(X) - X|``."""
        E1 = ti.static((LANES + W - 1) // LANES)
        im = ti.max(i - 1, 0)
        ip = ti.min(i + 1, H - 1)
        m = ti.Vector([0.0] * LANES, dt=ti.f32)
        for e in range(1, E1 + 1):
            m = ti.max(m, _lane_relax(x0, x, q, p, n, im, i, ip, e, w, beta, lam, mom, W))
        fill_ghosts(x, n, i, 1, 1, W, 1, REPLICATE)
        return run_max(m, LANES)


    @ti.func
    def _lane_finish_row(on: ti.template(), off: ti.template(), f_on, f_off, q_on: ti.template(), q_off: ti.template(),
                         S_on: ti.template(), S_off: ti.template(), S: ti.template(), i, H, wn, wf, t_s,
                         W: ti.template()):
        """Row ``i`` of ``S_on``, ``S_off`` and ``S`` at the fixed point (channels: buffers ``f_on``/``f_off``)."""
        E1 = ti.static((LANES + W - 1) // LANES)
        im = ti.max(i - 1, 0)
        ip = ti.min(i + 1, H - 1)
        for e in range(1, E1 + 1):
            cn, en, dn = lane_edge_diag(on, f_on, im, i, ip, e)
            a = feedback_local(cn, en, dn, wn, q_on[i, e])
            cf, ef, df = lane_edge_diag(off, f_off, im, i, ip, e)
            b = feedback_local(cf, ef, df, wf, q_off[i, e])
            S_on[i, e] = a
            S_off[i, e] = b
            S[i, e] = summed_layer(a, b, t_s)
        fill_ghosts(S, 0, i, 1, 1, W, 1, REPLICATE)


    @ti.func
    def _lane_box_row(S: ti.template(), out: ti.template(), i, H, W: ti.template(), reduce: ti.template()):
        """Row ``i`` of ``out = S (*) ones/9`` (LGMD grouping, LGMD2's ``Ce``).

        Returns the row's float64 sum over the frame columns (``reduce == "sum"``) or its
        ``max |out|`` there (``"max"``).
        """
        E1 = ti.static((LANES + W - 1) // LANES)
        im = ti.max(i - 1, 0)
        ip = ti.min(i + 1, H - 1)
        acc = ti.f64(0.0)
        for e in range(1, E1 + 1):
            cs, es, ds = lane_edge_diag(S, 0, im, i, ip, e)
            b = _symmetric(cs, es, ds, 1.0 / 9.0, 1.0 / 9.0, 1.0 / 9.0)
            out[i, e] = b
            v = b * lane_mask(e, W)
            if ti.static(reduce == "max"):
                acc = ti.max(acc, ti.cast(run_max(lane_abs(v), LANES), ti.f64))
            else:
                acc += ti.cast(v.sum(), ti.f64)
        return acc


    @ti.func
    def _feedback_stage(ctx: ti.template(), i0, i1, j):
        """Update ``j`` of the feedback iteration on rows ``[i0, i1)``: buffers ``p`` (``j`` even) or ``n``
        of each channel into the other one (OFF only ``with_off``); maxes the residuals into ``rbuf[j, 0:2]``."""
        H = ctx.on0.shape[0]
        W = ti.static(ctx.W)
        lam = ctx.record[j, 0]
        mom = ctx.record[j, 1]
        src_on = ti.select(j % 2 == 0, ctx.p_on, ctx.n_on)
        dst_on = ctx.p_on + ctx.n_on - src_on
        src_off = ti.select(j % 2 == 0, ctx.p_off, ctx.n_off)
        dst_off = ctx.p_off + ctx.n_off - src_off
        m_on = 0.0
        m_off = 0.0
        for i in range(i0, i1):
            m_on = ti.max(m_on, _lane_update_row(ctx.on0, ctx.on, ctx.q_on, src_on, dst_on, i, H, ctx.wn, ctx.beta_on,
                                                 lam, mom, W))
            if ti.static(ctx.with_off):
                m_off = ti.max(m_off, _lane_update_row(ctx.off0, ctx.off, ctx.q_off, src_off, dst_off, i, H, ctx.wf,
                                                       ctx.beta_off, lam, mom, W))
        ti.atomic_max(ctx.rbuf[j, 0], m_on)
        ti.atomic_max(ctx.rbuf[j, 1], m_off)

    @ti.func
    def _feedback_finish_stage(ctx: ti.template(), i0, i1, ran):
        """``S_on``, ``S_off``, ``S`` of rows ``[i0, i1)`` at the fixed point (after ``ran`` updates)."""
        f_on = ti.select(ran % 2 == 0, ctx.p_on, ctx.n_on)  # the buffers holding the result
        f_off = ctx.p_off
        if ti.static(ctx.with_off):
            f_off = ti.select(ran % 2 == 0, ctx.p_off, ctx.n_off)
        for i in range(i0, i1):
            _lane_finish_row(ctx.on, ctx.off, f_on, f_off, ctx.q_on, ctx.q_off, ctx.S_on, ctx.S_off, ctx.S, i,
                             ctx.S.shape[0], ctx.wn, ctx.wf, ctx.t_s, ctx.W)

    @ti.func
    def _group_stage(ctx: ti.template(), i0, i1, j):
        """``G = S (*) ones/9`` on rows ``[i0, i1)``; adds their sum of ``G`` to ``msum[0]``, ``msum[1] = 1``."""
        acc = ti.f64(0.0)
        for i in range(i0, i1):
            acc += _lane_box_row(ctx.S, ctx.G, i, ctx.S.shape[0], ctx.W, "sum")
        ti.atomic_add(ctx.msum[0], acc)
        ctx.msum[1] = 1.0

    #: F-LGMD's solve: the feedback updates, then at the fixed point the layers and the grouping.
    @ti.func
    def _flgmd_controls(ctx: ti.template()):
        """F-LGMD's solve: its workers, rows, updates at most and stopping rule."""
        return ctx.nw, ctx.on0.shape[0], ctx.n, ctx.tol, ctx.grow

    FLGMD_PLAN = Plan(update=(_feedback_stage,), after=(_feedback_finish_stage, _group_stage),
                      controls=_flgmd_controls)
    flgmd_workers = workers(FLGMD_PLAN)
    FLGMDCtx = context("FLGMDCtx", "on0 off0 on off q_on q_off S_on S_off S G p_on n_on p_off n_off wn wf beta_on "
                                   "beta_off t_s record rbuf msum W with_off nw n tol grow")

    @vector_kernel
    @ti.kernel
    def flgmd_lanes_solve(
        on0: LANE2, off0: LANE2, on: LANE3, off: LANE3, q_on: LANE2,
        q_off: LANE2, S_on: LANE2, S_off: LANE2, S: LANE2, G: LANE2,
        p_on: ti.i32, n_on: ti.i32, p_off: ti.i32, n_off: ti.i32,
        wn0: ti.f32, wn1: ti.f32, wn2: ti.f32, wf0: ti.f32, wf1: ti.f32, wf2: ti.f32,
        beta_on: ti.f32, beta_off: ti.f32, t_s: ti.f32, record: ti.types.ndarray(dtype=ti.f32, ndim=2), n: ti.i32,
        tol: ti.f32, grow: ti.f32, nw: ti.i32, sync: ti.template(), rbuf: ti.template(), msum: ti.template(),
        W: ti.template(), with_off: ti.template(), out: D1,
    ):
        """Up to ``n`` feedback updates (:func:`flgmd_lanes_iterate`) in one launch, then the layers
        (:data:`FLGMD_PLAN` on the engine's scheduler).

        Update ``j`` uses ``lam, mom = record[j, 0:2]`` and reads buffers
        ``p`` (``j`` even) or ``n`` (``j`` odd) of each channel, writing the other one; OFF is
        iterated only ``with_off``. The updates stop after the first one whose residuals are
        both ``<= tol``, or one whose worst residual exceeds ``grow`` times the best of the
        launch. When the launch converged, the workers compute ``S_on``, ``S_off``, ``S`` and
        ``G`` of the result (as :func:`flgmd_lanes_finish`). In its serial tail it writes the ON
        and OFF residuals of each update to ``record[j, 2:4]`` (-1: not run,
        :class:`~cdnf_ti.kernels.common.LaunchRecord`) and ``sum G`` to ``out[0]`` (-1 when the
        launch did not converge).
        """
        wn = ti.Vector([wn0, wn1, wn2])
        wf = ti.Vector([wf0, wf1, wf2])
        msum[0] = 0.0
        msum[1] = 0.0
        ctx = ti.static(FLGMDCtx(on0, off0, on, off, q_on, q_off, S_on, S_off, S, G, p_on, n_on, p_off, n_off, wn, wf,
                                 beta_on, beta_off, t_s, record, rbuf, msum, W, with_off, nw, n, tol, grow))
        flgmd_workers(ctx)
        record_residuals(rbuf, record, 2)
        out[0] = -1.0
        if msum[1] > 0.0:  # the layers were computed (the workers have all finished here)
            out[0] = msum[0]


    @vector_kernel
    @ti.kernel
    def flgmd_lanes_finish(
        on: LANE3, off: LANE3, f_on: ti.i32, f_off: ti.i32, q_on: LANE2, q_off: LANE2,
        S_on: LANE2, S_off: LANE2, S: LANE2, G: LANE2,
        wn0: ti.f32, wn1: ti.f32, wn2: ti.f32, wf0: ti.f32, wf1: ti.f32, wf2: ti.f32, t_s: ti.f32, W: ti.template(),
        out: D1,
    ):
        """:func:`flgmd_finish` on lane fields (channels: buffers ``f_on``/``f_off``); ``out[0] = sum G``
        (set to 0 by the caller).

        For a frame whose solve launch did not converge (:func:`flgmd_lanes_solve` computes
        the layers itself when it does).
        """
        H = S.shape[0]
        wn = ti.Vector([wn0, wn1, wn2])
        wf = ti.Vector([wf0, wf1, wf2])
        for i in range(H):
            _lane_finish_row(on, off, f_on, f_off, q_on, q_off, S_on, S_off, S, i, H, wn, wf, t_s, W)
        for i in range(H):
            ti.atomic_add(out[0], _lane_box_row(S, G, i, H, W, "sum"))


    # -- LGMD1 and LGMD2 on lane fields: the layers of a frame in one launch -------------------
    # Stages on the scheduler: the delayed layers and S (:func:`_delayed_stage`); then LGMD2: Ce and
    # max |Ce|, then G and sum G. LGMD1: G and sum G (:func:`_group_stage`, as F-LGMD).
    # The stencil coefficients travel as tuples of scalars (template arguments), not as small
    # ti.Vectors: with explicit vector types quadrants 1.3.3 compiled those into a launch that
    # crashed (segmentation fault in delayed_mix's coefficients; see kernels/compat.py).


    @ti.func
    def _lane_delayed_row(on: ti.template(), off: ti.template(), c, q, X_on: ti.template(), X_off: ti.template(),
                          S: ti.template(), i, H, kn: ti.template(), an: ti.template(), kf: ti.template(),
                          af: ti.template(), model: ti.template(), sp: ti.template(), e3: ti.template(),
                          W: ti.template()):
        """Row ``i`` of the delayed layers ``X_on``/``X_off`` (:func:`delayed_mix` of ON/OFF: buffer ``c``
        now, ``q`` the frame before) and of ``S``: :func:`lgmd1_summation` (``model == "lgmd1"``;
        ``sp = (w_i_on, w_i_off, t_s)``) or :func:`lgmd2_summation` (``sp = (w_on, w_off, -)``)."""
        E1 = ti.static((LANES + W - 1) // LANES)
        im = ti.max(i - 1, 0)
        ip = ti.min(i + 1, H - 1)
        for e in range(1, E1 + 1):
            cn, en, dn = lane_edge_diag(on, c, im, i, ip, e)
            cnp, enp, dnp = lane_edge_diag(on, q, im, i, ip, e)
            x_on = delayed_mix(cn, en, dn, cnp, enp, dnp, kn[0], kn[1], kn[2], an[0], an[1], an[2])
            cf, ef, df = lane_edge_diag(off, c, im, i, ip, e)
            cfp, efp, dfp = lane_edge_diag(off, q, im, i, ip, e)
            x_off = delayed_mix(cf, ef, df, cfp, efp, dfp, kf[0], kf[1], kf[2], af[0], af[1], af[2])
            X_on[i, e] = x_on
            X_off[i, e] = x_off
            if ti.static(model == "lgmd1"):
                S[i, e] = lgmd1_summation(cn, cf, x_on, x_off, sp[0], sp[1], e3, sp[2])
            else:
                S[i, e] = lgmd2_summation(cn, cf, x_on, x_off, sp[0], sp[1], e3)
        fill_ghosts(S, 0, i, 1, 1, W, 1, REPLICATE)


    @ti.func
    def _delayed_stage(ctx: ti.template(), i0, i1, j):
        """Rows ``[i0, i1)`` of the delayed layers and of ``S`` (:func:`_lane_delayed_row`)."""
        for i in range(i0, i1):
            _lane_delayed_row(ctx.on, ctx.off, ctx.c, ctx.q, ctx.X_on, ctx.X_off, ctx.S, i, ctx.S.shape[0], ctx.kn,
                              ctx.an, ctx.kf, ctx.af, ctx.model, ctx.sp, ctx.e3, ctx.W)

    @ti.func
    def _excitation_stage(ctx: ti.template(), i0, i1, j):
        """LGMD2's ``Ce = S (*) ones/9`` on rows ``[i0, i1)``; maxes their ``max |Ce|`` into ``rbuf[0, 0]``."""
        m = 0.0
        for i in range(i0, i1):
            m = ti.max(m, ti.cast(_lane_box_row(ctx.S, ctx.Ce, i, ctx.S.shape[0], ctx.W, "max"), ti.f32))
        ti.atomic_max(ctx.rbuf[0, 0], m)

    @ti.func
    def _grouping_stage(ctx: ti.template(), i0, i1, j):
        """LGMD2's grouping ``G`` on rows ``[i0, i1)`` (:func:`lgmd2_grouping`, ``max |Ce|`` from ``rbuf[0, 0]``);
        adds their sum of ``G`` to ``msum[0]``."""
        W = ti.static(ctx.W)
        inv_omega = 1.0 / (ctx.delta_c + ti.max(ctx.rbuf[0, 0], 0.0) / ctx.c_w)
        acc = ti.f64(0.0)
        for i in range(i0, i1):
            E1 = ti.static((LANES + W - 1) // LANES)
            for e in range(1, E1 + 1):
                g = lgmd2_grouping(ctx.S[i, e], ctx.Ce[i, e], inv_omega, ctx.c_de, ctx.t_de)
                ctx.G[i, e] = g
                acc += ti.cast((g * lane_mask(e, W)).sum(), ti.f64)
        ti.atomic_add(ctx.msum[0], acc)

    #: LGMD2's layers: delayed inhibitions and S, then Ce and max |Ce|, then the grouping.
    @ti.func
    def _layers_controls(ctx: ti.template()):
        """The layers' workers and rows (no updates)."""
        return ctx.nw, ctx.S.shape[0], 0, 0.0, 0.0

    LGMD2_PLAN = Plan(after=(_delayed_stage, _excitation_stage, _grouping_stage), controls=_layers_controls)
    #: LGMD1's layers: delayed spreads and S, then the grouping.
    LGMD1_PLAN = Plan(after=(_delayed_stage, _group_stage), controls=_layers_controls)
    lgmd2_workers = workers(LGMD2_PLAN)
    lgmd1_workers = workers(LGMD1_PLAN)
    LayersCtx = context("LayersCtx", "on off c q X_on X_off S Ce G kn an kf af model sp e3 delta_c c_w c_de t_de "
                                     "rbuf msum W nw")

    @vector_kernel
    @ti.kernel
    def lgmd2_lanes_layers(
        on: LANE3, off: LANE3, c: ti.i32, q: ti.i32, I_on: LANE2, I_off: LANE2,
        S: LANE2, Ce: LANE2, G: LANE2, w_on: ti.f32, w_off: ti.f32,
        kn0: ti.f32, kn1: ti.f32, kn2: ti.f32, an0: ti.f32, an1: ti.f32, an2: ti.f32,
        kf0: ti.f32, kf1: ti.f32, kf2: ti.f32, af0: ti.f32, af1: ti.f32, af2: ti.f32,
        e_on: ti.f32, e_off: ti.f32, e_onoff: ti.f32, delta_c: ti.f32, c_w: ti.f32, c_de: ti.f32, t_de: ti.f32,
        nw: ti.i32, sync: ti.template(), rbuf: ti.template(), msum: ti.template(), W: ti.template(), out: D1,
    ):
        """:func:`lgmd2_layers` on lane fields, in one launch by persistent workers (:data:`LGMD2_PLAN`;
        channels: buffer ``c`` of ``on``/``off`` now, ``q`` the frame before).

        Writes ``out[0] = sum G``, ``out[1] = max |Ce|`` in its serial tail.
        """
        msum[0] = 0.0
        ctx = ti.static(LayersCtx(on, off, c, q, I_on, I_off, S, Ce, G, (kn0, kn1, kn2), (an0, an1, an2),
                                  (kf0, kf1, kf2), (af0, af1, af2), "lgmd2", (w_on, w_off, 0.0), (e_on, e_off, e_onoff),
                                  delta_c, c_w, c_de, t_de, rbuf, msum, W, nw))
        lgmd2_workers(ctx)
        out[0] = msum[0]
        out[1] = ti.cast(ti.max(rbuf[0, 0], 0.0), ti.f64)

    @vector_kernel
    @ti.kernel
    def lgmd1_lanes_layers(
        on: LANE3, off: LANE3, c: ti.i32, q: ti.i32, I_on: LANE2, E_off: LANE2,
        S: LANE2, G: LANE2, w_i_on: ti.f32, w_i_off: ti.f32, k1: ti.f32, k2: ti.f32, a1: ti.f32,
        a2: ti.f32, e_on: ti.f32, e_off: ti.f32, e_onoff: ti.f32, t_s: ti.f32,
        nw: ti.i32, sync: ti.template(), rbuf: ti.template(), msum: ti.template(), W: ti.template(), out: D1,
    ):
        """:func:`lgmd1_layers` on lane fields, in one launch by persistent workers (:data:`LGMD1_PLAN`;
        channels: buffer ``c`` of ``on``/``off`` now, ``q`` the frame before).

        Writes ``out[0] = sum G`` in its serial tail.
        """
        msum[0] = 0.0
        k = (0.0, k1, k2)  # centre 0
        a = (0.0, a1, a2)
        ctx = ti.static(LayersCtx(on, off, c, q, I_on, E_off, S, S, G, k, a, k, a, "lgmd1", (w_i_on, w_i_off, t_s),
                                  (e_on, e_off, e_onoff), 0.0, 0.0, 0.0, 0.0, rbuf, msum, W, nw))
        lgmd1_workers(ctx)
        out[0] = msum[0]

    return namespace(globals(), locals())
