"""Taichi kernels of the LGMD family: LGMD2, LGMD1 and F-LGMD (float32 layers).

Each model needs two launches per frame: :func:`load_frame` (photoreceptors and
the ON/OFF channels, pointwise, returning ``sum |P|`` for the PM/FFI pathway) and
one layer kernel whose top-level loops run one after another (local summation,
grouping); F-LGMD adds its fixed-point iteration. Every pass reads values stored
by the pass before it, so nothing is computed twice per pixel.
Sums are accumulated in float64. Borders replicate (index clamping), as in
the authors' C# code. Loops run over (row, column-block) work items
(:func:`cdnf_ti.kernels.common.block_span`).

The NumPy float64 oracle of every stage is :mod:`cdnf_ti.baselines_reference`.
"""

from ..taichi_runtime import dsl
from .common import block_span, fill  # noqa: F401 - fill is part of this module's kernel set

ti = dsl()  # taichi or quadrants: the same DSL

F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
VEC2D = ti.types.vector(2, ti.f64)


@ti.func
def _clamp(i, n):
    return ti.min(ti.max(i, 0), n - 1)


@ti.func
def _edge_diag(x: ti.template(), i, j, H, W):
    """Sums of the 4 edge and 4 diagonal neighbours of (i, j), replicate border."""
    im = _clamp(i - 1, H)
    ip = _clamp(i + 1, H)
    jm = _clamp(j - 1, W)
    jp = _clamp(j + 1, W)
    e = x[im, j] + x[ip, j] + x[i, jm] + x[i, jp]
    d = x[im, jm] + x[im, jp] + x[ip, jm] + x[ip, jp]
    return e, d


@ti.func
def _delayed(x: ti.template(), xp: ti.template(), i, j, H, W, k0, k1, k2, a0, a1, a2):
    """``sum K [a X(t) + (1 - a) X(t-1)]`` over the 3x3 window (centre k0/a0, edge k1/a1, diagonal k2/a2)."""
    e, d = _edge_diag(x, i, j, H, W)
    ep, dp = _edge_diag(xp, i, j, H, W)
    c = a0 * x[i, j] + (1.0 - a0) * xp[i, j]
    return k0 * c + k1 * (a1 * e + (1.0 - a1) * ep) + k2 * (a2 * d + (1.0 - a2) * dp)


@ti.func
def _box(x: ti.template(), i, j, H, W):
    """Mean of the 3x3 window (the grouping kernel, 1/9 ones)."""
    e, d = _edge_diag(x, i, j, H, W)
    return (x[i, j] + e + d) * (1.0 / 9.0)


@ti.func
def _group(S: ti.template(), G: ti.template(), blocks):
    """Grouping ``G = S (*) (1/9 ones 3x3)`` over the frame (a top-level parallel loop);
    returns ``sum G`` accumulated in float64."""
    H, W = S.shape[0], S.shape[1]
    total = ti.f64(0.0)
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        acc = ti.f64(0.0)
        for j in range(j0, j1):
            g = _box(S, i, j, H, W)
            G[i, j] = g
            acc += ti.cast(g, ti.f64)
        ti.atomic_add(total, acc)
    return total


@ti.func
def _gauss3(x: ti.template(), i, j, H, W, g0, g1, g2):
    e, d = _edge_diag(x, i, j, H, W)
    return g0 * x[i, j] + g1 * e + g2 * d


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
    total = ti.f64(0.0)
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        acc = ti.f64(0.0)
        for j in range(j0, j1):
            g = ti.floor(ti.cast(frame[i, j], ti.f32) * scale + 0.5)
            p = ti.select(first != 0, 0.0, g - L[i, j])
            L[i, j] = g
            P[i, j] = p
            on[i, j] = ti.select(p >= clip, p, 0.0) + dc * on_p[i, j]
            off[i, j] = ti.select(p < clip, ti.abs(p), 0.0) + dc * off_p[i, j]
            acc += ti.cast(ti.abs(p), ti.f64)
        ti.atomic_add(total, acc)
    return total


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
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        for j in range(j0, j1):
            i_on = _delayed(on, on_p, i, j, H, W, kn0, kn1, kn2, an0, an1, an2)
            i_off = _delayed(off, off_p, i, j, H, W, kf0, kf1, kf2, af0, af1, af2)
            I_on[i, j] = i_on
            I_off[i, j] = i_off
            s_on = ti.max(on[i, j] - w_on * i_on, 0.0)
            s_off = ti.max(off[i, j] - w_off * i_off, 0.0)
            S[i, j] = e_on * s_on + e_off * s_off + e_onoff * s_on * s_off
    mx = 0.0
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        m = 0.0
        for j in range(j0, j1):
            c = _box(S, i, j, H, W)
            Ce[i, j] = c
            m = ti.max(m, ti.abs(c))
        ti.atomic_max(mx, m)
    total = ti.f64(0.0)
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        inv_omega = 1.0 / (delta_c + mx / c_w)
        acc = ti.f64(0.0)
        for j in range(j0, j1):
            g = S[i, j] * Ce[i, j] * inv_omega
            g = ti.select(g * c_de >= t_de, g, 0.0)
            G[i, j] = g
            acc += ti.cast(g, ti.f64)
        ti.atomic_add(total, acc)
    return ti.Vector([total, ti.cast(mx, ti.f64)])


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
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        for j in range(j0, j1):
            i_on = _delayed(on, on_p, i, j, H, W, 0.0, k1, k2, 0.0, a1, a2)
            e_o = _delayed(off, off_p, i, j, H, W, 0.0, k1, k2, 0.0, a1, a2)
            I_on[i, j] = i_on
            E_off[i, j] = e_o
            s_on = on[i, j] - w_i_on * i_on
            s_off = e_o - w_i_off * off[i, j]
            s = e_on * s_on + e_off * s_off + e_onoff * s_on * s_off
            S[i, j] = ti.select(s >= t_s, s, 0.0)
    return _group(S, G, blocks)


# -- F-LGMD: instantaneous feedback solved as a fixed point -----------------------------
# The local summation of a channel, S_X(X) = [G_e (*) X - w_i sum K (a X + (1 - a) X(t-1))]+,
# is split once per frame into the part that the iteration changes and the part it does
# not: S_X(X) = [W_x (*) X - Q]+ with W_x = G_e - w_i a K (one 3x3 stencil, centre
# g0 since K's centre is 0) and Q = w_i sum K (1 - a) X(t-1), computed by flgmd_prepare.


@ti.func
def _flgmd_local(x: ti.template(), q: ti.template(), i, j, H, W, w0, w1, w2):
    """``S_X = [W_x (*) X - Q]+`` at (i, j)."""
    return ti.max(_gauss3(x, i, j, H, W, w0, w1, w2) - q[i, j], 0.0)


@ti.kernel
def flgmd_prepare(on0: F2, off0: F2, on: F2, off: F2, on_p: F2, off_p: F2, q_on: F2, q_off: F2,
                  k1: ti.f32, k2: ti.f32, a1: ti.f32, a2: ti.f32, w_i_on: ti.f32, w_i_off: ti.f32,
                  blocks: ti.i32):
    """The frame's constant inhibition ``Q = w_i sum K (1 - a) X(t-1)`` of both channels
    (``on_p``/``off_p``: the settled previous channels); the iterate ``on``/``off``
    starts at the drives ``on0``/``off0`` (:func:`load_frame`)."""
    H, W = on0.shape[0], on0.shape[1]
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        for j in range(j0, j1):
            e_on, d_on = _edge_diag(on_p, i, j, H, W)
            e_off, d_off = _edge_diag(off_p, i, j, H, W)
            q_on[i, j] = w_i_on * (k1 * (1.0 - a1) * e_on + k2 * (1.0 - a2) * d_on)
            q_off[i, j] = w_i_off * (k1 * (1.0 - a1) * e_off + k2 * (1.0 - a2) * d_off)
            on[i, j] = on0[i, j]
            off[i, j] = off0[i, j]


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
    (:meth:`cdnf_ti.models.flgmd.FLGMDParams.feedback_stencil`). Returns
    ``(max|T(ON) - ON|, max|T(OFF) - OFF|)``. With ``with_off`` False
    (``beta_off == 0``) the OFF channel equals its drive and is not iterated.
    """
    H, W = on.shape[0], on.shape[1]
    r_on = 0.0
    r_off = 0.0
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        m_on = 0.0
        m_off = 0.0
        for j in range(j0, j1):
            s_on = _flgmd_local(on, q_on, i, j, H, W, wn0, wn1, wn2)
            d_on = ti.max(on0[i, j] + beta_on * s_on, 0.0) - on[i, j]
            x = on[i, j]
            on_n[i, j] = x + mom * (x - on_n[i, j]) + lam * d_on
            m_on = ti.max(m_on, ti.abs(d_on))
            if ti.static(with_off):
                s_off = _flgmd_local(off, q_off, i, j, H, W, wf0, wf1, wf2)
                d_off = ti.max(off0[i, j] + beta_off * s_off, 0.0) - off[i, j]
                y = off[i, j]
                off_n[i, j] = y + mom * (y - off_n[i, j]) + lam * d_off
                m_off = ti.max(m_off, ti.abs(d_off))
        ti.atomic_max(r_on, m_on)
        ti.atomic_max(r_off, m_off)
    return ti.Vector([r_on, r_off])


@ti.kernel
def flgmd_finish(
    on: F2, off: F2, q_on: F2, q_off: F2, S_on: F2, S_off: F2, S: F2, G: F2,
    wn0: ti.f32, wn1: ti.f32, wn2: ti.f32, wf0: ti.f32, wf1: ti.f32, wf2: ti.f32,
    t_s: ti.f32, blocks: ti.i32,
) -> ti.f64:
    """Local summation at the fixed point, ``S = S_on + S_off`` kept where ``>= t_s``,
    ``G = S (*) ones/9``; returns ``sum G``."""
    H, W = on.shape[0], on.shape[1]
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        for j in range(j0, j1):
            a = _flgmd_local(on, q_on, i, j, H, W, wn0, wn1, wn2)
            b = _flgmd_local(off, q_off, i, j, H, W, wf0, wf1, wf2)
            S_on[i, j] = a
            S_off[i, j] = b
            s = a + b
            S[i, j] = ti.select(s >= t_s, s, 0.0)
    return _group(S, G, blocks)
