"""Taichi kernels of the LGMD family: LGMD2, LGMD1 and F-LGMD (float32 layers).

Each model needs two launches per frame: :func:`load_frame` (photoreceptors,
returning ``sum |P|`` for the PM/FFI pathway) and one fused layer kernel whose
top-level loops run one after another (ON/OFF + local summation, grouping).
Sums are accumulated in float64. Borders replicate (index clamping), as in
the authors' C# code. Loops run over (row, column-block) work items
(:func:`cdnf_ti.kernels.common.block_span`).

The NumPy float64 oracle of every stage is :mod:`cdnf_ti.baselines_reference`.
"""

from ..taichi_runtime import dsl
from .common import block_span, fill, luminance_change  # noqa: F401 - fill is part of this module's kernel set

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
def _chan(P: ti.template(), xp: ti.template(), r, c, clip, dc, on: ti.template()):
    """ON (``on``) or OFF cell at (r, c) computed from ``P`` and its previous value:
    ``P [P >= clip] + dc X(t-1)`` or ``|P| [P < clip] + dc X(t-1)``."""
    p = P[r, c]
    x = 0.0
    if ti.static(on):
        x = ti.select(p >= clip, p, 0.0) + dc * xp[r, c]
    else:
        x = ti.select(p < clip, ti.abs(p), 0.0) + dc * xp[r, c]
    return x


@ti.func
def _delayed_fused(P: ti.template(), xp: ti.template(), i, j, H, W, k0, k1, k2, a0, a1, a2, clip, dc,
                   on: ti.template()):
    """:func:`_delayed` of the ON/OFF channel, with X(t) computed on the fly from ``P``
    (so the channel update needs no pass of its own). Returns ``(spread, X(t) at (i, j))``."""
    acc = 0.0
    centre = 0.0
    for di in ti.static(range(-1, 2)):
        for dj in ti.static(range(-1, 2)):
            r = _clamp(i + di, H)
            c = _clamp(j + dj, W)
            x = _chan(P, xp, r, c, clip, dc, on)
            q = xp[r, c]
            if ti.static(di == 0 and dj == 0):
                centre = x
                acc += k0 * (a0 * x + (1.0 - a0) * q)
            elif ti.static(di == 0 or dj == 0):
                acc += k1 * (a1 * x + (1.0 - a1) * q)
            else:
                acc += k2 * (a2 * x + (1.0 - a2) * q)
    return acc, centre


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
def load_frame(frame: ti.types.ndarray(ndim=2), L: F2, P: F2, scale: ti.f32, first: ti.i32,
               blocks: ti.i32) -> ti.f64:
    """``g = floor(frame * scale + 0.5)`` (integer grey levels); ``P = g - L`` (0 when ``first``); ``L = g``.

    Returns ``sum |P|``. The rounding makes float input (``scale = 255``) the
    8-bit grey levels the authors' code works on (``HighpassFilter(byte, byte)
    -> int`` in lgmd2OpenSource.cs / LGMDs.cs, fuqinbing/LGMD2-open-source);
    uint8 input (``scale = 1``) is unchanged. NumPy reference:
    :func:`cdnf_ti.baselines_reference.eight_bit`.
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
            acc += ti.cast(ti.abs(p), ti.f64)
        ti.atomic_add(total, acc)
    return total


@ti.kernel
def lgmd2_layers(
    P: F2, on: F2, off: F2, on_p: F2, off_p: F2, I_on: F2, I_off: F2, S: F2, Ce: F2, G: F2,
    clip: ti.f32, dc: ti.f32, w_on: ti.f32, w_off: ti.f32,
    kn0: ti.f32, kn1: ti.f32, kn2: ti.f32, an0: ti.f32, an1: ti.f32, an2: ti.f32,
    kf0: ti.f32, kf1: ti.f32, kf2: ti.f32, af0: ti.f32, af1: ti.f32, af2: ti.f32,
    e_on: ti.f32, e_off: ti.f32, e_onoff: ti.f32,
    delta_c: ti.f32, c_w: ti.f32, c_de: ti.f32, t_de: ti.f32, blocks: ti.i32,
) -> VEC2D:
    """LGMD2 layers of one frame; returns ``(sum G, max |Ce|)``.

    ON/OFF with residue (computed on the fly inside the summation pass); delayed 3x3 inhibitions (centre included);
    ``S = e_on S_on + e_off S_off + e_onoff S_on S_off`` with
    ``S_on = [ON - w_on I_on]+``; ``Ce = S (*) ones/9``;
    ``G = S Ce / (delta_c + max|Ce| / c_w)``, zero unless ``c_de G >= t_de``.
    """
    H, W = P.shape[0], P.shape[1]
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        for j in range(j0, j1):
            i_on, x_on = _delayed_fused(P, on_p, i, j, H, W, kn0, kn1, kn2, an0, an1, an2, clip, dc, True)
            i_off, x_off = _delayed_fused(P, off_p, i, j, H, W, kf0, kf1, kf2, af0, af1, af2, clip, dc, False)
            on[i, j] = x_on
            off[i, j] = x_off
            I_on[i, j] = i_on
            I_off[i, j] = i_off
            s_on = ti.max(x_on - w_on * i_on, 0.0)
            s_off = ti.max(x_off - w_off * i_off, 0.0)
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
    P: F2, on: F2, off: F2, on_p: F2, off_p: F2, I_on: F2, E_off: F2, S: F2, G: F2,
    clip: ti.f32, dc: ti.f32, w_i_on: ti.f32, w_i_off: ti.f32,
    k1: ti.f32, k2: ti.f32, a1: ti.f32, a2: ti.f32,
    e_on: ti.f32, e_off: ti.f32, e_onoff: ti.f32, t_s: ti.f32, blocks: ti.i32,
) -> ti.f64:
    """LGMD1 layers of one frame; returns ``sum G``.

    ``I_on``/``E_off``: delayed 3x3 spreads (centre 0) of ON/OFF;
    ``S_on = ON - w_i_on I_on``, ``S_off = E_off - w_i_off OFF``;
    ``S = e_on S_on + e_off S_off + e_onoff S_on S_off`` kept where ``>= t_s``;
    ``G = S (*) ones/9``.
    """
    H, W = P.shape[0], P.shape[1]
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        for j in range(j0, j1):
            i_on, x_on = _delayed_fused(P, on_p, i, j, H, W, 0.0, k1, k2, 0.0, a1, a2, clip, dc, True)
            e_o, x_off = _delayed_fused(P, off_p, i, j, H, W, 0.0, k1, k2, 0.0, a1, a2, clip, dc, False)
            on[i, j] = x_on
            off[i, j] = x_off
            I_on[i, j] = i_on
            E_off[i, j] = e_o
            s_on = x_on - w_i_on * i_on
            s_off = e_o - w_i_off * x_off
            s = e_on * s_on + e_off * s_off + e_onoff * s_on * s_off
            S[i, j] = ti.select(s >= t_s, s, 0.0)
    return _group(S, G, blocks)


@ti.kernel
def flgmd_prepare(P: F2, on0: F2, off0: F2, on: F2, off: F2, on_p: F2, off_p: F2,
                  clip: ti.f32, dc: ti.f32, blocks: ti.i32):
    """Feed-forward drives ``ON0``/``OFF0`` from ``P`` and the settled previous channels
    (``on_p``/``off_p``); the iterate ``on``/``off`` starts at the drives."""
    H, W = P.shape[0], P.shape[1]
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        for j in range(j0, j1):
            p = P[i, j]
            a = ti.select(p >= clip, p, 0.0) + dc * on_p[i, j]
            b = ti.select(p < clip, ti.abs(p), 0.0) + dc * off_p[i, j]
            on0[i, j] = a
            off0[i, j] = b
            on[i, j] = a
            off[i, j] = b


@ti.func
def _flgmd_local(x: ti.template(), xp: ti.template(), i, j, H, W, g0, g1, g2, k1, k2, a1, a2, w_i):
    """``[G_e (*) X - w_i sum K (a X + (1 - a) X(t-1))]+`` (centre of K is 0)."""
    ex = _gauss3(x, i, j, H, W, g0, g1, g2)
    inh = _delayed(x, xp, i, j, H, W, 0.0, k1, k2, 0.0, a1, a2)
    return ti.max(ex - w_i * inh, 0.0)


@ti.kernel
def flgmd_iterate(
    on0: F2, off0: F2, on: F2, off: F2, on_p: F2, off_p: F2, on_n: F2, off_n: F2,
    g0: ti.f32, g1: ti.f32, g2: ti.f32, k1: ti.f32, k2: ti.f32, a1: ti.f32, a2: ti.f32,
    w_i_on: ti.f32, w_i_off: ti.f32, beta_on: ti.f32, beta_off: ti.f32, lam: ti.f32,
    blocks: ti.i32, with_off: ti.template(),
) -> ti.types.vector(2, ti.f32):
    """One relaxed fixed-point update ``X_n = X + lam (T(X) - X)``, ``T(X) = [X0 + beta S_X(X)]+``.

    Returns ``(max|T(ON) - ON|, max|T(OFF) - OFF|)``. With ``with_off`` False
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
            s_on = _flgmd_local(on, on_p, i, j, H, W, g0, g1, g2, k1, k2, a1, a2, w_i_on)
            d_on = ti.max(on0[i, j] + beta_on * s_on, 0.0) - on[i, j]
            on_n[i, j] = on[i, j] + lam * d_on
            m_on = ti.max(m_on, ti.abs(d_on))
            if ti.static(with_off):
                s_off = _flgmd_local(off, off_p, i, j, H, W, g0, g1, g2, k1, k2, a1, a2, w_i_off)
                d_off = ti.max(off0[i, j] + beta_off * s_off, 0.0) - off[i, j]
                off_n[i, j] = off[i, j] + lam * d_off
                m_off = ti.max(m_off, ti.abs(d_off))
        ti.atomic_max(r_on, m_on)
        ti.atomic_max(r_off, m_off)
    return ti.Vector([r_on, r_off])


@ti.kernel
def flgmd_finish(
    on: F2, off: F2, on_p: F2, off_p: F2, S_on: F2, S_off: F2, S: F2, G: F2,
    g0: ti.f32, g1: ti.f32, g2: ti.f32, k1: ti.f32, k2: ti.f32, a1: ti.f32, a2: ti.f32,
    w_i_on: ti.f32, w_i_off: ti.f32, t_s: ti.f32, blocks: ti.i32,
) -> ti.f64:
    """Local summation at the fixed point, ``S = S_on + S_off`` kept where ``>= t_s``,
    ``G = S (*) ones/9``; returns ``sum G``."""
    H, W = on.shape[0], on.shape[1]
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        for j in range(j0, j1):
            a = _flgmd_local(on, on_p, i, j, H, W, g0, g1, g2, k1, k2, a1, a2, w_i_on)
            b = _flgmd_local(off, off_p, i, j, H, W, g0, g1, g2, k1, k2, a1, a2, w_i_off)
            S_on[i, j] = a
            S_off[i, j] = b
            s = a + b
            S[i, j] = ti.select(s >= t_s, s, 0.0)
    return _group(S, G, blocks)
