"""Taichi kernels of the LGMD family: LGMD2, LGMD1 and F-LGMD (float32 layers).

Each model needs two launches per frame: :func:`load_frame` (photoreceptors and
the ON/OFF channels, pointwise, returning ``sum |P|`` for the PM/FFI pathway) and
one layer kernel whose top-level loops run one after another (local summation,
grouping); F-LGMD adds its fixed-point iteration. Every pass reads values stored
by the pass before it, so nothing is computed twice per pixel.
Sums are accumulated in float64. Borders replicate (index clamping), as in
the authors' C# code. Loops run over (row, column-block) work items
(:func:`cdnf_ti.kernels.common.block_span`); each item visits its columns in runs
(:func:`cdnf_ti.kernels.common.row_runs`), so the per-pixel equations below are
written once, on vectors of ``n`` consecutive columns.

The NumPy float64 oracle of every stage is :mod:`cdnf_ti.baselines_reference`.
"""

from ..taichi_runtime import dsl
from .common import block_span, fill, luminance_change, row_runs, run_load, run_max, run_store, run_sum  # noqa: F401 - fill is part of this module's kernel set

ti = dsl()  # taichi or quadrants: the same DSL

F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
VEC2D = ti.types.vector(2, ti.f64)


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
    return w0 * run_load(x, i, j, n) + w1 * e + w2 * d


@ti.func
def _delayed(x: ti.template(), xp: ti.template(), im, i, ip, jm, j, jp, n: ti.template(), k0, k1, k2, a0, a1, a2):
    """``sum K [a X(t) + (1 - a) X(t-1)]`` over the 3x3 window (centre k0/a0, edge k1/a1, diagonal k2/a2)."""
    e, d = _edge_diag(x, im, i, ip, jm, j, jp, n)
    ep, dp = _edge_diag(xp, im, i, ip, jm, j, jp, n)
    c = a0 * run_load(x, i, j, n) + (1.0 - a0) * run_load(xp, i, j, n)
    return k0 * c + k1 * (a1 * e + (1.0 - a1) * ep) + k2 * (a2 * d + (1.0 - a2) * dp)


@ti.func
def _group_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
    S, G = ti.static(ctx[0], ctx[1])
    g = _stencil(S, im, i, ip, jm, j, jp, n, 1.0 / 9.0, 1.0 / 9.0, 1.0 / 9.0)
    run_store(G, i, j, g, n)
    return run_sum(g, n)


@ti.func
def _group(S: ti.template(), G: ti.template(), blocks):
    """Grouping ``G = S (*) (1/9 ones 3x3)`` over the frame (a top-level parallel loop);
    returns ``sum G`` accumulated in float64."""
    H, W = S.shape[0], S.shape[1]
    total = ti.f64(0.0)
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        ti.atomic_add(total, row_runs(_group_run, (S, G), i, j0, j1, H, W, "sum", 1))
    return total


@ti.func
def _load_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
    frame, L, P, on, off, on_p, off_p = ti.static(ctx[0], ctx[1], ctx[2], ctx[3], ctx[4], ctx[5], ctx[6])
    scale, keep, clip, dc = ctx[7], ctx[8], ctx[9], ctx[10]
    p = luminance_change(frame, L, P, i, j, n, scale, keep, True)
    run_store(on, i, j, ti.select(p >= clip, p, 0.0) + dc * run_load(on_p, i, j, n), n)
    run_store(off, i, j, ti.select(p < clip, ti.abs(p), 0.0) + dc * run_load(off_p, i, j, n), n)
    return run_sum(ti.abs(p), n)


@ti.kernel
def load_frame(frame: ti.types.ndarray(ndim=2), L: F2, P: F2, on: F2, off: F2, on_p: F2, off_p: F2,
               scale: ti.f32, first: ti.i32, clip: ti.f32, dc: ti.f32, blocks: ti.i32) -> ti.f64:
    """Photoreceptors and the ON/OFF channels of one frame; returns ``sum |P|``.

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
    total = ti.f64(0.0)
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        ti.atomic_add(total, row_runs(_load_run, (frame, L, P, on, off, on_p, off_p, scale, keep, clip, dc),
                                      i, j0, j1, H, W, "sum", 1))
    return total


@ti.func
def _lgmd2_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
    on, off, on_p, off_p, I_on, I_off, S = ti.static(ctx[0], ctx[1], ctx[2], ctx[3], ctx[4], ctx[5], ctx[6])
    kn, an, kf, af, w_on, w_off, e = ctx[7], ctx[8], ctx[9], ctx[10], ctx[11], ctx[12], ctx[13]
    i_on = _delayed(on, on_p, im, i, ip, jm, j, jp, n, kn[0], kn[1], kn[2], an[0], an[1], an[2])
    i_off = _delayed(off, off_p, im, i, ip, jm, j, jp, n, kf[0], kf[1], kf[2], af[0], af[1], af[2])
    run_store(I_on, i, j, i_on, n)
    run_store(I_off, i, j, i_off, n)
    s_on = ti.max(run_load(on, i, j, n) - w_on * i_on, 0.0)
    s_off = ti.max(run_load(off, i, j, n) - w_off * i_off, 0.0)
    run_store(S, i, j, e[0] * s_on + e[1] * s_off + e[2] * s_on * s_off, n)
    return 0.0


@ti.func
def _excitation_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
    S, Ce = ti.static(ctx[0], ctx[1])
    c = _stencil(S, im, i, ip, jm, j, jp, n, 1.0 / 9.0, 1.0 / 9.0, 1.0 / 9.0)
    run_store(Ce, i, j, c, n)
    return run_max(ti.abs(c), n)


@ti.func
def _grouping_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
    S, Ce, G = ti.static(ctx[0], ctx[1], ctx[2])
    inv_omega, c_de, t_de = ctx[3], ctx[4], ctx[5]
    g = run_load(S, i, j, n) * run_load(Ce, i, j, n) * inv_omega
    g = ti.select(g * c_de >= t_de, g, 0.0)
    run_store(G, i, j, g, n)
    return run_sum(g, n)


@ti.kernel
def lgmd2_layers(
    on: F2, off: F2, on_p: F2, off_p: F2, I_on: F2, I_off: F2, S: F2, Ce: F2, G: F2,
    w_on: ti.f32, w_off: ti.f32,
    kn0: ti.f32, kn1: ti.f32, kn2: ti.f32, an0: ti.f32, an1: ti.f32, an2: ti.f32,
    kf0: ti.f32, kf1: ti.f32, kf2: ti.f32, af0: ti.f32, af1: ti.f32, af2: ti.f32,
    e_on: ti.f32, e_off: ti.f32, e_onoff: ti.f32,
    delta_c: ti.f32, c_w: ti.f32, c_de: ti.f32, t_de: ti.f32, blocks: ti.i32,
) -> VEC2D:
    """LGMD2 layers of one frame from its ON/OFF channels (:func:`load_frame`); returns ``(sum G, max |Ce|)``.

    Delayed 3x3 inhibitions (centre included);
    ``S = e_on S_on + e_off S_off + e_onoff S_on S_off`` with
    ``S_on = [ON - w_on I_on]+``; ``Ce = S (*) ones/9``;
    ``G = S Ce / (delta_c + max|Ce| / c_w)``, zero unless ``c_de G >= t_de``.
    """
    H, W = on.shape[0], on.shape[1]
    kn = ti.Vector([kn0, kn1, kn2])
    an = ti.Vector([an0, an1, an2])
    kf = ti.Vector([kf0, kf1, kf2])
    af = ti.Vector([af0, af1, af2])
    e = ti.Vector([e_on, e_off, e_onoff])
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        row_runs(_lgmd2_run, (on, off, on_p, off_p, I_on, I_off, S, kn, an, kf, af, w_on, w_off, e),
                 i, j0, j1, H, W, "sum", 1)
    mx = 0.0
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        ti.atomic_max(mx, ti.cast(row_runs(_excitation_run, (S, Ce), i, j0, j1, H, W, "max", 1), ti.f32))
    total = ti.f64(0.0)
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        inv_omega = 1.0 / (delta_c + mx / c_w)
        ti.atomic_add(total, row_runs(_grouping_run, (S, Ce, G, inv_omega, c_de, t_de), i, j0, j1, H, W, "sum", 1))
    return ti.Vector([total, ti.cast(mx, ti.f64)])


@ti.func
def _lgmd1_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
    on, off, on_p, off_p, I_on, E_off, S = ti.static(ctx[0], ctx[1], ctx[2], ctx[3], ctx[4], ctx[5], ctx[6])
    k, a, w_i_on, w_i_off, e, t_s = ctx[7], ctx[8], ctx[9], ctx[10], ctx[11], ctx[12]
    i_on = _delayed(on, on_p, im, i, ip, jm, j, jp, n, 0.0, k[0], k[1], 0.0, a[0], a[1])
    e_o = _delayed(off, off_p, im, i, ip, jm, j, jp, n, 0.0, k[0], k[1], 0.0, a[0], a[1])
    run_store(I_on, i, j, i_on, n)
    run_store(E_off, i, j, e_o, n)
    s_on = run_load(on, i, j, n) - w_i_on * i_on
    s_off = e_o - w_i_off * run_load(off, i, j, n)
    s = e[0] * s_on + e[1] * s_off + e[2] * s_on * s_off
    run_store(S, i, j, ti.select(s >= t_s, s, 0.0), n)
    return 0.0


@ti.kernel
def lgmd1_layers(
    on: F2, off: F2, on_p: F2, off_p: F2, I_on: F2, E_off: F2, S: F2, G: F2,
    w_i_on: ti.f32, w_i_off: ti.f32, k1: ti.f32, k2: ti.f32, a1: ti.f32, a2: ti.f32,
    e_on: ti.f32, e_off: ti.f32, e_onoff: ti.f32, t_s: ti.f32, blocks: ti.i32,
) -> ti.f64:
    """LGMD1 layers of one frame from its ON/OFF channels (:func:`load_frame`); returns ``sum G``.

    ``I_on``/``E_off``: delayed 3x3 spreads (centre 0) of ON/OFF;
    ``S_on = ON - w_i_on I_on``, ``S_off = E_off - w_i_off OFF``;
    ``S = e_on S_on + e_off S_off + e_onoff S_on S_off`` kept where ``>= t_s``;
    ``G = S (*) ones/9``.
    """
    H, W = on.shape[0], on.shape[1]
    kk = ti.Vector([k1, k2])
    a = ti.Vector([a1, a2])
    e = ti.Vector([e_on, e_off, e_onoff])
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        row_runs(_lgmd1_run, (on, off, on_p, off_p, I_on, E_off, S, kk, a, w_i_on, w_i_off, e, t_s),
                 i, j0, j1, H, W, "sum", 1)
    return _group(S, G, blocks)


# -- F-LGMD: instantaneous feedback solved as a fixed point -----------------------------
# The local summation of a channel, S_X(X) = [G_e (*) X - w_i sum K (a X + (1 - a) X(t-1))]+,
# is split once per frame into the part that the iteration changes and the part it does
# not: S_X(X) = [W_x (*) X - Q]+ with W_x = G_e - w_i a K (one 3x3 stencil, centre
# g0 since K's centre is 0) and Q = w_i sum K (1 - a) X(t-1), computed by flgmd_prepare.


@ti.func
def _flgmd_local(x: ti.template(), q: ti.template(), im, i, ip, jm, j, jp, n: ti.template(), w):
    """``S_X = [W_x (*) X - Q]+`` on a run (``w``: centre, edge, diagonal of ``W_x``)."""
    return ti.max(_stencil(x, im, i, ip, jm, j, jp, n, w[0], w[1], w[2]) - run_load(q, i, j, n), 0.0)


@ti.func
def _prepare_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
    on0, off0, on, off, on_p, off_p, q_on, q_off = ti.static(ctx[0], ctx[1], ctx[2], ctx[3], ctx[4], ctx[5],
                                                             ctx[6], ctx[7])
    c_on, c_off = ctx[8], ctx[9]  # (edge, diagonal) weights w_i K (1 - a) of each channel
    run_store(q_on, i, j, _stencil(on_p, im, i, ip, jm, j, jp, n, 0.0, c_on[0], c_on[1]), n)
    run_store(q_off, i, j, _stencil(off_p, im, i, ip, jm, j, jp, n, 0.0, c_off[0], c_off[1]), n)
    run_store(on, i, j, run_load(on0, i, j, n), n)
    run_store(off, i, j, run_load(off0, i, j, n), n)
    return 0.0


@ti.kernel
def flgmd_prepare(on0: F2, off0: F2, on: F2, off: F2, on_p: F2, off_p: F2, q_on: F2, q_off: F2,
                  k1: ti.f32, k2: ti.f32, a1: ti.f32, a2: ti.f32, w_i_on: ti.f32, w_i_off: ti.f32,
                  blocks: ti.i32):
    """The frame's constant inhibition ``Q = w_i sum K (1 - a) X(t-1)`` of both channels
    (``on_p``/``off_p``: the settled previous channels); the iterate ``on``/``off``
    starts at the drives ``on0``/``off0`` (:func:`load_frame`)."""
    H, W = on0.shape[0], on0.shape[1]
    c = ti.Vector([k1 * (1.0 - a1), k2 * (1.0 - a2)])
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        row_runs(_prepare_run, (on0, off0, on, off, on_p, off_p, q_on, q_off, w_i_on * c, w_i_off * c),
                 i, j0, j1, H, W, "sum", 1)


@ti.func
def _relax_run(x0: ti.template(), x: ti.template(), q: ti.template(), x_n: ti.template(), im, i, ip, jm, j, jp,
               n: ti.template(), w, beta, lam, mom):
    """One update of a channel on a run; returns ``max |T(X) - X|`` there."""
    xc = run_load(x, i, j, n)
    d = ti.max(run_load(x0, i, j, n) + beta * _flgmd_local(x, q, im, i, ip, jm, j, jp, n, w), 0.0) - xc
    run_store(x_n, i, j, xc + mom * (xc - run_load(x_n, i, j, n)) + lam * d, n)
    return run_max(ti.abs(d), n)


@ti.func
def _iterate_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
    on0, on, q_on, on_n = ti.static(ctx[0], ctx[1], ctx[2], ctx[3])
    return _relax_run(on0, on, q_on, on_n, im, i, ip, jm, j, jp, n, ctx[4], ctx[5], ctx[6], ctx[7])


@ti.kernel
def flgmd_iterate(
    on0: F2, off0: F2, on: F2, off: F2, q_on: F2, q_off: F2, on_n: F2, off_n: F2,
    wn0: ti.f32, wn1: ti.f32, wn2: ti.f32, wf0: ti.f32, wf1: ti.f32, wf2: ti.f32,
    beta_on: ti.f32, beta_off: ti.f32, lam: ti.f32, mom: ti.f32, blocks: ti.i32, with_off: ti.template(),
) -> ti.types.vector(2, ti.f32):
    """One fixed-point update ``X_n = X + mom (X - X_n) + lam (T(X) - X)``, ``T(X) = [X0 + beta S_X(X)]+``.

    ``on_n``/``off_n`` hold the iterate before ``X`` on entry (used when ``mom != 0``:
    a Chebyshev step; ``mom = 0``: plain relaxation).
    ``wn``/``wf``: ``(centre, edge, diagonal)`` of ``W_x`` for the ON/OFF channel
    (:meth:`cdnf_ti.models.flgmd.FLGMDParams.feedback_stencils`). Returns
    ``(max|T(ON) - ON|, max|T(OFF) - OFF|)``. With ``with_off`` False
    (``beta_off == 0``) the OFF channel equals its drive and is not iterated.
    """
    H, W = on.shape[0], on.shape[1]
    wn = ti.Vector([wn0, wn1, wn2])
    wf = ti.Vector([wf0, wf1, wf2])
    r_on = 0.0
    r_off = 0.0
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        ti.atomic_max(r_on, ti.cast(row_runs(_iterate_run, (on0, on, q_on, on_n, wn, beta_on, lam, mom),
                                             i, j0, j1, H, W, "max", 1), ti.f32))
        if ti.static(with_off):
            ti.atomic_max(r_off, ti.cast(row_runs(_iterate_run, (off0, off, q_off, off_n, wf, beta_off, lam, mom),
                                                  i, j0, j1, H, W, "max", 1), ti.f32))
    return ti.Vector([r_on, r_off])


@ti.func
def _finish_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
    on, off, q_on, q_off, S_on, S_off, S = ti.static(ctx[0], ctx[1], ctx[2], ctx[3], ctx[4], ctx[5], ctx[6])
    wn, wf, t_s = ctx[7], ctx[8], ctx[9]
    a = _flgmd_local(on, q_on, im, i, ip, jm, j, jp, n, wn)
    b = _flgmd_local(off, q_off, im, i, ip, jm, j, jp, n, wf)
    run_store(S_on, i, j, a, n)
    run_store(S_off, i, j, b, n)
    s = a + b
    run_store(S, i, j, ti.select(s >= t_s, s, 0.0), n)
    return 0.0


@ti.kernel
def flgmd_finish(
    on: F2, off: F2, q_on: F2, q_off: F2, S_on: F2, S_off: F2, S: F2, G: F2,
    wn0: ti.f32, wn1: ti.f32, wn2: ti.f32, wf0: ti.f32, wf1: ti.f32, wf2: ti.f32,
    t_s: ti.f32, blocks: ti.i32,
) -> ti.f64:
    """Local summation at the fixed point, ``S = S_on + S_off`` kept where ``>= t_s``,
    ``G = S (*) ones/9``; returns ``sum G``."""
    H, W = on.shape[0], on.shape[1]
    wn = ti.Vector([wn0, wn1, wn2])
    wf = ti.Vector([wf0, wf1, wf2])
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        row_runs(_finish_run, (on, off, q_on, q_off, S_on, S_off, S, wn, wf, t_s), i, j0, j1, H, W, "sum", 1)
    return _group(S, G, blocks)
