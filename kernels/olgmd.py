"""Taichi kernels of oLGMD (LGMD2 with contrast polarity-specific feed-forward inhibition; float32 layers).

Two launches per frame (:mod:`cdnf_ti.backends.olgmd`):

1. :func:`load` (pointwise): grey levels ``g``, ``P = g - L(t-1) + a_1 P(t-1) + a_2 P(t-2)``,
   ``P_on = [P]^+ + a1 P_on(t-1)``, ``P_off = [-P]^+ + a1 P_off(t-1)``; adds ``sum P_on`` and
   ``sum P_off`` (float64) to ``out[0:2]``.
2. :func:`layers`: the polarity-gated summation ``S``, the grouping excitation ``Ce`` (3x3 mean
   of ``S``) with ``max Ce`` in ``out[1]``, and ``G`` with ``sum G`` in ``out[0]``: three stages,
   one launch by the scheduler's persistent workers on the CPU (``LAYERS_PLAN``), three
   top-level loops of one kernel elsewhere (:func:`layers_loops`).

The per-pixel equations are ``ti.func``s written once, on scalars or vectors of columns, and
called by two paths: the generic one above on (planes, H, W) arrays, whose work items visit a
row's interior columns in runs of :data:`~cdnf_ti.kernels.common.CHUNK` and the frame's border
columns one by one, and the fast CPU path :func:`lanes_load` / :func:`lanes_layers` on lane
arrays (explicit vector types, ``LANES_PLAN``).

Borders: ``code=True`` (the authors' code) zeroes the outermost ring of ``S`` and reflects
(reflect-101) in ``Ce``; ``code=False`` replicates both. Coefficients come in one float32 array
(``coef``, slots below, filled once per backend); the frame's scalars in another (``fr``).
The NumPy float64 oracle is :mod:`cdnf_ti.olgmd_reference`.
"""

import functools
from types import SimpleNamespace

from ..taichi_runtime import vector_kernel
from . import common, compat, schedule
from .common import CHUNK, QUARTER, REFLECT, REPLICATE, context, namespace
from .schedule import Plan

#: ``coef`` slots: ON inhibition weights ``K a`` (now) and ``K (1 - a)`` (the frame before),
#: centre / edge / diagonal; the same for OFF; the ``P_on``/``P_off`` persistence; ``o1, o2, o3``;
#: ``cw, delta_c, cde, tde`` of the grouping.
C_ON, C_OFF, C_A1, C_O, C_CW, C_DC, C_CDE, C_TDE = 0, 6, 12, 13, 16, 17, 18, 19
N_COEF = 20
#: ``fr`` slots: grey scale (1 for uint8, 255 for float), whether ``P`` is computed (0 on the
#: frames before the first difference), ``a_1``, ``a_2``, ``w1``, ``w2``, ON / OFF gates
#: (1 open), weights of ON / OFF ``E(t-1)`` (0 after a closed gate in the authors' code).
F_SCALE, F_ACTIVE, F_A_1, F_A_2, F_W1, F_W2, F_GATE_ON, F_GATE_OFF, F_PREV_ON, F_PREV_OFF = range(10)
N_FRAME = 10


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The kernels of this module for the DSL module ``ti`` (taichi or quadrants) and ``lanes``
    lanes per vector element of the fast path."""
    LANES = lanes
    block = common.build(ti, lanes)
    run_max = compat.build(ti, lanes).run_max
    sched = schedule.build(ti, lanes)
    workers = sched.workers
    run_load, block_span = block.run_load, block.block_span
    rload, rstore = block.plane_load, block.plane_store  # a plane of a stacked array on a run of columns
    LANE3 = block.LANE3
    lane_edge_diag, lane_mask, fill_ghosts = block.lane_edge_diag, block.lane_mask, block.fill_ghosts

    F1 = block.COEFS
    F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    F3 = block.F3
    D1 = ti.types.ndarray(dtype=ti.f64, ndim=1)  # a launch's results, zeroed by the caller

    # -- the per-pixel equations (scalars or vectors of a run's columns) ------------------------
    @ti.func
    def luminance_change(g, l_prev, p1, p2, a_1, a_2):
        """``P(t) = L(t) - L(t-1) + a_1 P(t-1) + a_2 P(t-2)``."""
        return g - l_prev + a_1 * p1 + a_2 * p2

    @ti.func
    def polarity(p, on_prev, off_prev, a1):
        """``(P_on, P_off) = ([P]^+ + a1 P_on(t-1), [-P]^+ + a1 P_off(t-1))``."""
        return ti.max(p, 0.0) + a1 * on_prev, ti.max(0.0 - p, 0.0) + a1 * off_prev

    @ti.func
    def delayed_inhibition(now, before, k: ti.template(), base: ti.template(), prev):
        """``I = sum_ij K_ij (a_ij E + (1 - a_ij) E(t-1))`` from the centre, edge and diagonal sums of
        ``E`` (``now``) and ``E(t-1)`` (``before``); ``k[base:base + 6]`` are ``K a`` and ``K (1 - a)``;
        ``prev`` weighs ``E(t-1)``."""
        return (k[base] * now[0] + k[base + 1] * now[1] + k[base + 2] * now[2]
                + prev * (k[base + 3] * before[0] + k[base + 4] * before[1] + k[base + 5] * before[2]))

    @ti.func
    def polarity_summation(e, inh, w):
        """``S_on`` / ``S_off`` = ``[E - w I]^+``."""
        return ti.max(e - w * inh, 0.0)

    @ti.func
    def summation(s_on, s_off, k: ti.template()):
        """``S = o1 S_on + o2 S_off + o3 S_on S_off``."""
        return k[C_O] * s_on + k[C_O + 1] * s_off + k[C_O + 2] * s_on * s_off

    @ti.func
    def grouping(s, ce, inv_scale, cde, tde):
        """``G = S Ce / (max Ce / cw + delta_c)``, zero where ``cde G < tde``."""
        g = s * ce * inv_scale
        return ti.select(g * cde < tde, 0.0, g)

    # -- runs of a row ----------------------------------------------------------------------
    @ti.func
    def neighbours(x: ti.template(), k, pos, n: ti.template()):
        """Centre, edge sum and diagonal sum of plane ``k`` of ``x`` on the run at
        ``pos = (im, i, ip, jm, j, jp)`` (rows above/at/below, first columns left/at/right)."""
        im, i, ip, jm, j, jp = pos[0], pos[1], pos[2], pos[3], pos[4], pos[5]
        e = rload(x, k, im, j, n) + rload(x, k, ip, j, n) + rload(x, k, i, jm, n) + rload(x, k, i, jp, n)
        d = rload(x, k, im, jm, n) + rload(x, k, im, jp, n) + rload(x, k, ip, jm, n) + rload(x, k, ip, jp, n)
        return rload(x, k, i, j, n), e, d

    @ti.func
    def _combine(acc, r, reduce: ti.template()):
        out = acc + r
        if ti.static(reduce == "max"):
            out = ti.max(acc, r)
        return out

    @ti.func
    def _columns(body: ti.template(), ctx: ti.template(), span, reduce: ti.template(), reflect: ti.template()):
        """``body(ctx, pos, n)`` over the columns ``[j0, j1)`` of row ``i`` (``span = (i, j0, j1)``): the
        frame's border columns one by one, the others in runs of ``CHUNK``, then ``QUARTER``, then single
        columns; neighbours beyond the frame replicate (``reflect``: reflect-101). Returns the ``reduce``
        (``"sum"`` or ``"max"``) of body's float64 2-vectors."""
        H, W = ctx.chan.shape[1], ctx.chan.shape[2]
        i, j, j1 = span[0], span[1], span[2]
        im, ip = ti.max(i - 1, 0), ti.min(i + 1, H - 1)
        right = W - 1
        if ti.static(reflect):
            im, ip = ti.select(i == 0, 1, i - 1), ti.select(i == H - 1, H - 2, i + 1)
            right = W - 2
        acc = ti.Vector([0.0, 0.0], dt=ti.f64)
        if j == 0:
            acc = body(ctx, ti.Vector([im, i, ip, ti.static(1 if reflect else 0), 0, 1]), 1)
            j = 1
        end = ti.min(j1, W - 1)
        for n in ti.static((CHUNK, QUARTER)):
            while j + n <= end:
                acc = _combine(acc, body(ctx, ti.Vector([im, i, ip, j - 1, j, j + 1]), n), reduce)
                j += n
        while j < end:
            acc = _combine(acc, body(ctx, ti.Vector([im, i, ip, j - 1, j, j + 1]), 1), reduce)
            j += 1
        if (j1 == W) & (span[1] < j1):  # a block past the frame's end is empty
            acc = _combine(acc, body(ctx, ti.Vector([im, i, ip, W - 2, W - 1, right]), 1), reduce)
        return acc

    @ti.func
    def _sums(a, b, n: ti.template()):
        """Float64 sums of the run vectors ``a`` and ``b``, as a 2-vector."""
        s = ti.Vector([0.0, 0.0], dt=ti.f64)
        for q in ti.static(range(n)):
            s[0] += ti.cast(a[q], ti.f64)
            s[1] += ti.cast(b[q], ti.f64)
        return s

    # -- 1. photoreceptors and ON/OFF ---------------------------------------------------------
    LoadCtx = context("LoadCtx", "frame L P chan coef fr c")

    @ti.func
    def _load_run(ctx: ti.template(), pos, n: ti.template()):
        """One run of :func:`load`; returns ``(sum P_on, sum P_off)``."""
        fr = ti.static(ctx.fr)
        c, i, j = ctx.c, pos[1], pos[4]
        g = ti.floor(run_load(ctx.frame, i, j, n) * fr[F_SCALE] + 0.5)
        sums = ti.Vector([0.0, 0.0], dt=ti.f64)
        if fr[F_ACTIVE] > 0.0:
            p = luminance_change(g, rload(ctx.L, 0, i, j, n), rload(ctx.P, 1 - c, i, j, n),
                                 rload(ctx.P, c, i, j, n), fr[F_A_1], fr[F_A_2])
            on, off = polarity(p, rload(ctx.chan, 1 - c, i, j, n), rload(ctx.chan, 3 - c, i, j, n),
                               ctx.coef[C_A1])
            rstore(ctx.P, c, i, j, p, n)
            rstore(ctx.chan, c, i, j, on, n)
            rstore(ctx.chan, 2 + c, i, j, off, n)
            sums = _sums(on, off, n)
        rstore(ctx.L, 0, i, j, g, n)
        return sums

    @ti.kernel
    def load(frame: ti.types.ndarray(ndim=2), L: F3, P: F3, chan: F3, coef: F1, fr: F1, c: ti.i32, blocks: ti.i32,
             out: D1):
        """Photoreceptors and ON/OFF of one frame (uint8 grey, or float grey times ``fr[F_SCALE] = 255``).

        ``L`` (1, H, W): the previous grey levels; ``P`` (2, H, W): ``P(t-1)`` in plane ``1 - c``,
        ``P(t-2)`` in plane ``c`` (overwritten with ``P(t)``); ``chan`` (4, H, W): ``P_on`` in planes
        ``c`` (new) and ``1 - c`` (the frame before), ``P_off`` in ``2 + c`` and ``3 - c``. While
        ``fr[F_ACTIVE] == 0`` only ``L`` is stored. Adds ``sum P_on``, ``sum P_off`` to ``out[0:2]``.
        Work items: ``blocks`` column blocks per row (:func:`~cdnf_ti.kernels.common.column_blocks`).
        """
        for k in range(L.shape[1] * blocks):
            i, j0, j1 = block_span(k, L.shape[2], blocks)
            s = _columns(_load_run, ti.static(LoadCtx(frame, L, P, chan, coef, fr, c)), ti.Vector([i, j0, j1]),
                         "sum", False)
            ti.atomic_add(out[0], s[0])
            ti.atomic_add(out[1], s[1])

    # -- 2. summation, grouping excitation, grouping -------------------------------------------
    LayersCtx = context("LayersCtx", "chan lay coef fr c out nw code")

    @ti.func
    def _channel(chan: ti.template(), coef: ti.template(), pos, n: ti.template(), plane, base: ti.template(), w,
                 prev):
        """``[E - w I]^+`` of the channel in planes ``plane`` (now) and ``plane ^ 1`` (before; not read
        while its weight ``prev`` is 0)."""
        now = neighbours(chan, plane, pos, n)
        inh = delayed_inhibition(now, now, coef, base, 0.0)
        if prev != 0.0:
            inh = delayed_inhibition(now, neighbours(chan, plane ^ 1, pos, n), coef, base, prev)
        return polarity_summation(now[0], inh, w)

    @ti.func
    def _summation_run(ctx: ti.template(), pos, n: ti.template()):
        """One run of ``S``: gated channels, summed; zero on the outermost ring when ``ctx.code``."""
        fr = ti.static(ctx.fr)
        c = ctx.c
        s_on = ti.Vector([0.0] * n, dt=ti.f32)
        s_off = ti.Vector([0.0] * n, dt=ti.f32)
        if fr[F_GATE_ON] > 0.0:
            s_on = _channel(ctx.chan, ctx.coef, pos, n, c, C_ON, fr[F_W1], fr[F_PREV_ON])
        if fr[F_GATE_OFF] > 0.0:
            s_off = _channel(ctx.chan, ctx.coef, pos, n, 2 + c, C_OFF, fr[F_W2], fr[F_PREV_OFF])
        s = summation(s_on, s_off, ctx.coef)
        if ti.static(ctx.code):
            H, W = ctx.chan.shape[1], ctx.chan.shape[2]
            i, j = pos[1], pos[4]
            inside = (i > 0) & (i < H - 1) & (j > 0) & (j + n < W)
            s = s * ti.select(inside, 1.0, 0.0)
        rstore(ctx.lay, 0, pos[1], pos[4], s, n)
        return ti.Vector([0.0, 0.0], dt=ti.f64)

    @ti.func
    def _excitation_run(ctx: ti.template(), pos, n: ti.template()):
        """One run of ``Ce = 3x3 mean of S``; returns its maximum."""
        centre, e, d = neighbours(ctx.lay, 0, pos, n)
        ce = (centre + e + d) * (1.0 / 9.0)
        rstore(ctx.lay, 1, pos[1], pos[4], ce, n)
        return ti.Vector([ti.cast(run_max(ce, n), ti.f64), 0.0], dt=ti.f64)

    @ti.func
    def _grouping_run(ctx: ti.template(), pos, n: ti.template()):
        """One run of ``G``; returns its sum."""
        k = ti.static(ctx.coef)
        i, j = pos[1], pos[4]
        inv_scale = ti.cast(1.0 / (ctx.out[1] / k[C_CW] + k[C_DC]), ti.f32)
        g = grouping(rload(ctx.lay, 0, i, j, n), rload(ctx.lay, 1, i, j, n), inv_scale, k[C_CDE], k[C_TDE])
        rstore(ctx.lay, 2, i, j, g, n)
        total = ti.f64(0.0)
        for q in ti.static(range(n)):
            total += ti.cast(g[q], ti.f64)
        return ti.Vector([total, 0.0], dt=ti.f64)

    @ti.func
    def _summation_stage(ctx: ti.template(), i0, i1, j):
        """Rows ``[i0, i1)`` of ``S`` (plane 0 of ``lay``)."""
        for i in range(i0, i1):
            _columns(_summation_run, ctx, ti.Vector([i, 0, ctx.lay.shape[2]]), "sum", False)

    @ti.func
    def _excitation_stage(ctx: ti.template(), i0, i1, j):
        """Rows ``[i0, i1)`` of ``Ce`` (plane 1); maxes their largest into ``out[1]``."""
        m = ti.f64(0.0)
        for i in range(i0, i1):
            m = ti.max(m, _columns(_excitation_run, ctx, ti.Vector([i, 0, ctx.lay.shape[2]]), "max", ctx.code)[0])
        ti.atomic_max(ctx.out[1], m)

    @ti.func
    def _grouping_stage(ctx: ti.template(), i0, i1, j):
        """Rows ``[i0, i1)`` of ``G`` (plane 2); adds their sum to ``out[0]``."""
        s = ti.f64(0.0)
        for i in range(i0, i1):
            s += _columns(_grouping_run, ctx, ti.Vector([i, 0, ctx.lay.shape[2]]), "sum", False)[0]
        ti.atomic_add(ctx.out[0], s)

    @ti.func
    def _layers_controls(ctx: ti.template()):
        """The layers' workers and rows (no updates)."""
        return ctx.nw, ctx.lay.shape[1], 0, 0.0, 0.0

    LAYERS_PLAN = Plan(after=(_summation_stage, _excitation_stage, _grouping_stage), controls=_layers_controls)
    layers_workers = workers(LAYERS_PLAN)

    @ti.kernel
    def layers(chan: F3, lay: F3, coef: F1, fr: F1, c: ti.i32, nw: ti.i32, out: D1, code: ti.template()):
        """``S``, ``Ce``, ``G`` (planes 0, 1, 2 of ``lay``, (3, H, W)) from the channels of :func:`load`,
        in one launch of ``nw`` persistent workers. ``out`` (zeroed by the caller) receives
        ``sum G`` in ``out[0]`` and ``max Ce`` in ``out[1]``."""
        layers_workers(ti.static(LayersCtx(chan, lay, coef, fr, c, out, nw, code)))

    @ti.func
    def _block_stage(ctx: ti.template(), k, blocks, stage: ti.template()):
        """Work item ``k`` (a block of a row) of ``stage`` (``"summation"``, ``"excitation"``, ``"grouping"``)
        run as a plain parallel loop; returns the block's sum of ``G`` or maximum of ``Ce``."""
        i, j0, j1 = block_span(k, ctx.lay.shape[2], blocks)
        span = ti.Vector([i, j0, j1])
        r = ti.f64(0.0)
        if ti.static(stage == "summation"):
            _columns(_summation_run, ctx, span, "sum", False)
        elif ti.static(stage == "excitation"):
            r = _columns(_excitation_run, ctx, span, "max", ctx.code)[0]
        else:
            r = _columns(_grouping_run, ctx, span, "sum", False)[0]
        return r

    @ti.kernel
    def layers_loops(chan: F3, lay: F3, coef: F1, fr: F1, c: ti.i32, out: D1, code: ti.template(), blocks: ti.i32):
        """:func:`layers` as three top-level parallel loops over ``blocks`` column blocks per row (GPUs:
        no persistent workers)."""
        ctx = ti.static(LayersCtx(chan, lay, coef, fr, c, out, 1, code))
        for k in range(lay.shape[1] * blocks):
            _block_stage(ctx, k, blocks, "summation")
        for k in range(lay.shape[1] * blocks):
            ti.atomic_max(out[1], _block_stage(ctx, k, blocks, "excitation"))
        for k in range(lay.shape[1] * blocks):
            ti.atomic_add(out[0], _block_stage(ctx, k, blocks, "grouping"))

    # -- the fast CPU path: the same equations on lane arrays ------------------------------------
    # Lane arrays (kernels/common.py): element (k, i, e) holds the LANES columns (e - 1) * LANES ..
    # e * LANES - 1 of row i of plane k; elements 1..E1 hold the frame, the ghost columns -1 and W
    # give the border. The kernels compile with explicit vector types (``vector_kernel``) for one
    # frame width ``W``.

    @ti.func
    def _lane_grey(frame: ti.template(), i, e, scale, W: ti.template()):
        """Grey levels ``floor(frame * scale + 0.5)`` of element ``(i, e)`` (columns past W-1 repeat it)."""
        g = ti.Vector([0.0] * LANES, dt=ti.f32)
        for q in ti.static(range(LANES)):
            g[q] = ti.cast(frame[i, ti.min((e - 1) * LANES + q, W - 1)], ti.f32)
        return ti.floor(g * scale + 0.5)

    @vector_kernel
    @ti.kernel
    def lanes_load(frame: ti.types.ndarray(ndim=2), L: LANE3, P: LANE3, chan: LANE3, coef: F1, fr: F1, c: ti.i32,
                   W: ti.template(), out: D1):
        """:func:`load` on lane arrays (same planes); the channels' ghost columns replicate."""
        E1 = ti.static((LANES + W - 1) // LANES)
        for i in range(L.shape[1]):
            s_on = ti.f64(0.0)
            s_off = ti.f64(0.0)
            for e in range(1, E1 + 1):
                g = _lane_grey(frame, i, e, fr[F_SCALE], W)
                if fr[F_ACTIVE] > 0.0:
                    p = luminance_change(g, L[0, i, e], P[1 - c, i, e], P[c, i, e], fr[F_A_1], fr[F_A_2])
                    on, off = polarity(p, chan[1 - c, i, e], chan[3 - c, i, e], coef[C_A1])
                    P[c, i, e] = p
                    chan[c, i, e] = on
                    chan[2 + c, i, e] = off
                    m = lane_mask(e, W)
                    s_on += ti.cast((on * m).sum(), ti.f64)
                    s_off += ti.cast((off * m).sum(), ti.f64)
                L[0, i, e] = g
            if fr[F_ACTIVE] > 0.0:
                fill_ghosts(chan, c, i, 1, 1, W, 1, REPLICATE)
                fill_ghosts(chan, 2 + c, i, 1, 1, W, 1, REPLICATE)
            ti.atomic_add(out[0], s_on)
            ti.atomic_add(out[1], s_off)

    @ti.func
    def _lane_channel(chan: ti.template(), coef: ti.template(), plane, rows, e, base: ti.template(), w, prev):
        """:func:`_channel` on element ``e`` of the row ``rows = (im, i, ip)``."""
        now = lane_edge_diag(chan, plane, rows[0], rows[1], rows[2], e)
        inh = delayed_inhibition(now, now, coef, base, 0.0)
        if prev != 0.0:
            before = lane_edge_diag(chan, plane ^ 1, rows[0], rows[1], rows[2], e)
            inh = delayed_inhibition(now, before, coef, base, prev)
        return polarity_summation(now[0], inh, w)

    @ti.func
    def _lane_inside(i, e, H, W: ti.template()):
        """1.0 on the lanes of element ``(i, e)`` off the frame's outermost ring, else 0.0."""
        m = ti.Vector([0.0] * LANES, dt=ti.f32)
        row = (i > 0) & (i < H - 1)
        for q in ti.static(range(LANES)):
            col = (e - 1) * LANES + q
            m[q] = ti.select(row & (col >= 1) & (col <= W - 2), 1.0, 0.0)
        return m

    @ti.func
    def _lane_rows(i, H, reflect: ti.template()):
        """``(im, i, ip)``: the rows above and below ``i``, replicated or (``reflect``) reflect-101 at the border."""
        im, ip = ti.max(i - 1, 0), ti.min(i + 1, H - 1)
        if ti.static(reflect):
            im, ip = ti.select(i == 0, 1, i - 1), ti.select(i == H - 1, H - 2, i + 1)
        return ti.Vector([im, i, ip])

    @ti.func
    def _lane_summation_stage(ctx: ti.template(), i0, i1, j):
        """Rows ``[i0, i1)`` of ``S`` (plane 0), their ghost columns for ``Ce``'s border."""
        W = ti.static(ctx.W)
        fr = ti.static(ctx.fr)
        c, H = ctx.c, ctx.lay.shape[1]
        for i in range(i0, i1):
            rows = _lane_rows(i, H, False)
            for e in range(1, (LANES + W - 1) // LANES + 1):
                s_on = ti.Vector([0.0] * LANES, dt=ti.f32)
                s_off = ti.Vector([0.0] * LANES, dt=ti.f32)
                if fr[F_GATE_ON] > 0.0:
                    s_on = _lane_channel(ctx.chan, ctx.coef, c, rows, e, C_ON, fr[F_W1], fr[F_PREV_ON])
                if fr[F_GATE_OFF] > 0.0:
                    s_off = _lane_channel(ctx.chan, ctx.coef, 2 + c, rows, e, C_OFF, fr[F_W2], fr[F_PREV_OFF])
                s = summation(s_on, s_off, ctx.coef)
                if ti.static(ctx.code):
                    s = s * _lane_inside(i, e, H, W)
                ctx.lay[0, i, e] = s
            fill_ghosts(ctx.lay, 0, i, 1, 1, W, 1, ti.static(REFLECT if ctx.code else REPLICATE))

    @ti.func
    def _lane_excitation_stage(ctx: ti.template(), i0, i1, j):
        """Rows ``[i0, i1)`` of ``Ce`` (plane 1); maxes their largest into the scheduler's ``rbuf[0, 0]``."""
        W = ti.static(ctx.W)
        m = ti.f32(0.0)
        for i in range(i0, i1):
            rows = _lane_rows(i, ctx.lay.shape[1], ctx.code)
            for e in range(1, (LANES + W - 1) // LANES + 1):
                centre, edge, diag = lane_edge_diag(ctx.lay, 0, rows[0], rows[1], rows[2], e)
                ce = (centre + edge + diag) * (1.0 / 9.0)
                ctx.lay[1, i, e] = ce
                m = ti.max(m, run_max(ce * lane_mask(e, W), LANES))
        ti.atomic_max(sched.rbuf[0, 0], m)

    @ti.func
    def _lane_grouping_stage(ctx: ti.template(), i0, i1, j):
        """Rows ``[i0, i1)`` of ``G`` (plane 2); adds their sum to the scheduler's ``msum[0]``."""
        W = ti.static(ctx.W)
        k = ti.static(ctx.coef)
        inv_scale = 1.0 / (ti.max(sched.rbuf[0, 0], 0.0) / k[C_CW] + k[C_DC])
        acc = ti.f64(0.0)
        for i in range(i0, i1):
            for e in range(1, (LANES + W - 1) // LANES + 1):
                g = grouping(ctx.lay[0, i, e], ctx.lay[1, i, e], inv_scale, k[C_CDE], k[C_TDE])
                ctx.lay[2, i, e] = g
                acc += ti.cast((g * lane_mask(e, W)).sum(), ti.f64)
        ti.atomic_add(sched.msum[0], acc)

    LANES_PLAN = Plan(after=(_lane_summation_stage, _lane_excitation_stage, _lane_grouping_stage),
                      controls=_layers_controls)
    lanes_workers = workers(LANES_PLAN)
    LaneCtx = context("LaneCtx", "chan lay coef fr c nw code W")

    @vector_kernel
    @ti.kernel
    def lanes_layers(chan: LANE3, lay: LANE3, coef: F1, fr: F1, c: ti.i32, nw: ti.i32, out: D1, code: ti.template(),
                     W: ti.template()):
        """:func:`layers` on lane arrays, in one launch of ``nw`` persistent workers; writes ``out[0] = sum G``,
        ``out[1] = max Ce`` in its serial tail."""
        sched.msum[0] = 0.0
        lanes_workers(ti.static(LaneCtx(chan, lay, coef, fr, c, nw, code, W)))
        out[0] = sched.msum[0]
        out[1] = ti.cast(ti.max(sched.rbuf[0, 0], 0.0), ti.f64)

    return namespace(globals(), locals())
