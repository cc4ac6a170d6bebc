"""Taichi kernels of the C-DNF fields (float32 state, float64 integration).

All arrays are ``ti.ndarray`` or NumPy arrays of shape (H, W), so one compiled
kernel serves every frame size. ``mode`` is a compile-time border code from
:mod:`cdnf_ti.kernels.common`.
"""

import taichi as ti

from .common import block_span, border_index, border_weight, tanh_rational

F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
F1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
VEC2 = ti.types.vector(2, ti.f32)


@ti.kernel
def load_frame(frame: ti.types.ndarray(ndim=2), L: F2, P: F2, scale: ti.f32, first: ti.i32):
    """``g = frame * scale``; ``P = g - L`` (0 when ``first``); ``L = g``."""
    for i, j in L:
        g = ti.cast(frame[i, j], ti.f32) * scale
        P[i, j] = ti.select(first != 0, 0.0, g - L[i, j])
        L[i, j] = g


@ti.kernel
def fill(x: F2, value: ti.f32):
    """Set every element of ``x`` to ``value``."""
    for i, j in x:
        x[i, j] = value


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


@ti.kernel
def contrast_iterate(
    P: F2, u_on: F2, u_off: F2, out_on: F2, out_off: F2,
    wc0: ti.f32, wc1: ti.f32, wc2: ti.f32, h: ti.f32, lam: ti.f32,
    blocks: ti.i32, mode: ti.template(),
) -> VEC2:
    """One relaxed fixed-point update of the ON and OFF fields (fused).

    ``F(u) = P_on - h + vartheta(W_c (*) u)``, ``out = u + lam (F(u) - u)``;
    returns ``(max|F(u_on) - u_on|, max|F(u_off) - u_off|)``.
    """
    H, W = P.shape[0], P.shape[1]
    r_on = 0.0
    r_off = 0.0
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        m_on = 0.0
        m_off = 0.0
        for j in range(j0, j1):
            p = P[i, j]
            s_on = _lateral_3x3(u_on, i, j, H, W, wc0, wc1, wc2, mode)
            s_off = _lateral_3x3(u_off, i, j, H, W, wc0, wc1, wc2, mode)
            d_on = ti.max(p, 0.0) - h + tanh_rational(0.5 * s_on) - u_on[i, j]
            d_off = ti.max(-p, 0.0) - h + tanh_rational(0.5 * s_off) - u_off[i, j]
            out_on[i, j] = u_on[i, j] + lam * d_on
            out_off[i, j] = u_off[i, j] + lam * d_off
            m_on = ti.max(m_on, ti.abs(d_on))
            m_off = ti.max(m_off, ti.abs(d_off))
        ti.atomic_max(r_on, m_on)
        ti.atomic_max(r_off, m_off)
    return ti.Vector([r_on, r_off])


@ti.kernel
def summation_input(u_on: F2, u_off: F2, S: F2, alpha_on: ti.f32, alpha_off: ti.f32, theta_scale: ti.f32):
    """``S = alpha_on theta([u_on]+) + alpha_off theta([u_off]+)``."""
    for i, j in S:
        a_on = tanh_rational(ti.max(u_on[i, j], 0.0)) * theta_scale
        a_off = tanh_rational(ti.max(u_off[i, j], 0.0)) * theta_scale
        S[i, j] = alpha_on * a_on + alpha_off * a_off


@ti.kernel
def summation_iterate(
    S: F2, v: F2, row1: F2, row2: F2, out: F2, g1: F1, g2: F1,
    A: ti.f32, B: ti.f32, h: ti.f32, lam: ti.f32,
    blocks: ti.i32, mode: ti.template(),
) -> ti.f32:
    """One relaxed fixed-point update of the Summation field.

    The DoG ``W_s = A g1 g1^T - B g2 g2^T`` is applied as separable passes:
    ``row1 = g1 (*)_x v``, ``row2 = g2 (*)_x v``, then
    ``W_s (*) v = A g1 (*)_y row1 - B g2 (*)_y row2`` (exact for every border
    mode). ``F(v) = S - h + vartheta(W_s (*) v)``; returns ``max|F(v) - v|``.
    """
    H, W = v.shape[0], v.shape[1]
    R = (g1.shape[0] - 1) // 2
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        for j in range(j0, j1):
            a1 = 0.0
            a2 = 0.0
            for d in range(-R, R + 1):
                jj = border_index(j + d, W, mode)
                x = border_weight(j + d, W, mode) * v[i, jj]
                a1 += g1[d + R] * x
                a2 += g2[d + R] * x
            row1[i, j] = a1
            row2[i, j] = a2
    res = 0.0
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        m = 0.0
        for j in range(j0, j1):
            b1 = 0.0
            b2 = 0.0
            for d in range(-R, R + 1):
                ii = border_index(i + d, H, mode)
                wgt = border_weight(i + d, H, mode)
                b1 += g1[d + R] * wgt * row1[ii, j]
                b2 += g2[d + R] * wgt * row2[ii, j]
            dv = S[i, j] - h + tanh_rational(0.5 * (A * b1 - B * b2)) - v[i, j]
            out[i, j] = v[i, j] + lam * dv
            m = ti.max(m, ti.abs(dv))
        ti.atomic_max(res, m)
    return res


@ti.kernel
def mean_activation(v: F2, theta_scale: ti.f32, blocks: ti.i32) -> ti.f64:
    """``mean_xy theta([v]+)``, accumulated in float64."""
    H, W = v.shape[0], v.shape[1]
    total = ti.f64(0.0)
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        acc = ti.f64(0.0)
        for j in range(j0, j1):
            acc += ti.cast(tanh_rational(ti.max(v[i, j], 0.0)) * theta_scale, ti.f64)
        ti.atomic_add(total, acc)
    return total / ti.f64(H * W)
