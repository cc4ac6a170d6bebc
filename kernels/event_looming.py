"""The event-based looming detector's stages (Schubert, Knight, Philippides, Nowotny 2025; its model:
``cdnf_ti.models.event_looming``).

Three launches, run by the engine (:mod:`cdnf_ti.kernels.engine`) in either layout:

1. ``setup`` (the first bin of a run): the Gaussian ``w_pos`` of the positions ``w_x`` (-1..1 across the
   columns) and ``w_y`` (``-H/W..H/W`` down the rows).
2. ``load``: the signed event map ``X`` in {-1, 0, 1} of this bin. On an event bin ``(p_on, p_off)``: the sign
   of ``p_on - p_off``. On a frame: the project's DVS emulator with its default pixel (no mismatch, no
   refractory period, no noise), in float64: ``l = ln(g / 255 + eps)``, ``n_on = floor([l - r]^+ / C_on)``,
   ``n_off = floor([r - l]^+ / C_off)``, ``r += n_on C_on - n_off C_off``; ``X = +1`` where ``n_on >= 1``,
   ``-1`` where ``n_off >= 1``. The reference level ``r`` is a float64 kept exactly as three float32 planes,
   so the events are the float64 emulator's. A pixel whose grey lies inside the band ``(g_lo, g_hi)`` of
   its ``r`` (float32 bounds, with a margin) cannot cross: the float64 work runs for the others only.
3. ``flow``: per polarity ``q`` the separable (2 R + 1)^2 correlations (5x5) (zero padding) of ``X_q(t-1)``: row passes
   ``g (*)_x X_q``, ``x g (*)_x X_q``, then the column pass ``K_n``, ``K_x``, ``K_y``;
   ``v^q = -X_q(t) (K_x, K_y) dt / (reg + dt^2 K_n)``, ``v_r = v_x w_x + v_y w_y``; results the
   left and right sums of ``v_r w_pos``.

The kernel radius is a compile-time option (``radius``); the taps ``g`` and ``x g`` (normalised 1-D Gaussian,
``2 R + 1`` each) are the coefficient ``taps``. NumPy float64 oracle:
:class:`cdnf_ti.event_looming_reference.EventLoomingReference`.
"""

import functools
from types import SimpleNamespace

from . import engine
from .engine import Coefs, Launch, Planes, Scalars, Stage

PLANES = Planes("X:2 vx vy v_r _RH _RM _RL _LO _HI _NP _XP _NN _XN _WP")
#: The emulator's ``C_on``, ``C_off``, ``eps`` (each the three float32 parts of its float64 value);
#: ``ln(k / 255 + eps)`` of the grey levels ``k`` of uint8 frames (three parts each); ``dt``, ``reg``,
#: ``sigma_pos``; the taps ``g`` then ``x g``.
COEFS = Coefs(emulator=9, levels=768, dt=1, reg=1, sigma_pos=1, taps=0)
#: Grey levels of 1.0 (255 for uint8 frames, 1 for float), whether this is the first frame, the frame size
#: and the first column of the right half (``W // 2``).
SCALARS = Scalars("levels first width height half")
X, VX, VY, VR, RH, RM, RL, LO, HI, NP, XP, NN, XN, WP = PLANES
K, V = COEFS, SCALARS
#: Each polarity's row passes (``g``, ``x g``).
ROWS = ((NP, XP), (NN, XN))


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The detector's launches for the DSL module ``ti``: the stages below, bound to the engine."""
    E0 = K.emulator.slot

    @ti.func
    def radial(a: ti.template()):
        """``w_x`` (``np.linspace(-1, 1, W)`` at the cell's columns), ``w_y`` (``np.linspace(-H/W, H/W, H)`` at its
        row) and whether the columns are in the left half (1.0) or not (0.0)."""
        col = ti.cast(a.j, ti.f32) + a.zeros()
        if ti.static(a.lane):  # the columns of the lane vector
            col = ti.Vector([float(q) for q in range(lanes)], dt=ti.f32) + ti.cast((a.j - 1) * lanes, ti.f32)
        w, h = a.value(V.width), a.value(V.height)
        wy = (h / w) * (-1.0 + ti.cast(a.i, ti.f32) * (2.0 / (h - 1.0)))
        return -1.0 + col * (2.0 / (w - 1.0)), wy + a.zeros(), ti.select(col < a.value(V.half), 1.0, 0.0)

    @ti.func
    def weights(a: ti.template()):
        """The Gaussian ``w_pos = exp(-(w_x^2 + w_y^2) / (2 sigma_pos^2))``."""
        wx, wy, _ = radial(a)
        wpos = (0.0 - wx * wx - wy * wy) / (2.0 * a.coef(K.sigma_pos) * a.coef(K.sigma_pos))
        if ti.static(a.lane):  # the lane vector types have no exp: element by element
            for q in ti.static(range(lanes)):
                wpos[q] = ti.exp(wpos[q])
        else:
            wpos = ti.exp(wpos)
        a.put(WP, wpos)

    @ti.func
    def f64(high, mid, low):
        """The float64 value of three float32 parts (exact: a float64 has 53 bits, the parts 3 x 24)."""
        return (ti.cast(high, ti.f64) + ti.cast(mid, ti.f64)) + ti.cast(low, ti.f64)

    @ti.func
    def f32_parts(v):
        """The three float32 parts of the float64 ``v``, high first."""
        high = ti.cast(v, ti.f32)
        rest = v - ti.cast(high, ti.f64)
        mid = ti.cast(rest, ti.f32)
        return high, mid, ti.cast(rest - ti.cast(mid, ti.f64), ti.f32)

    @ti.func
    def coef64(coefs: ti.template(), k):
        """Coefficient ``k`` of three parts (float64); the first of the emulator's is ``E0``."""
        return f64(coefs[k], coefs[k + 1], coefs[k + 2])

    @ti.func
    def emulate_pixel(coefs: ti.template(), g, high, mid, low, first, levels, g_lo, g_hi):
        """One pixel of the emulator in float64: ``X``, the parts of the new ``r`` and the band ``(g_lo, g_hi)``."""
        c_on, c_off, eps = coef64(coefs, E0), coef64(coefs, E0 + 3), coef64(coefs, E0 + 6)
        level = ti.f64(0.0)
        if levels == 255.0:  # uint8 frames: the emulator's levels (exact)
            level = coef64(coefs, K.levels.slot + 3 * ti.cast(g, ti.i32))
        else:
            level = ti.log(ti.cast(g, ti.f64) / levels + eps)
        s, moved = ti.f32(0.0), first != 0.0
        if moved:
            high, mid, low = f32_parts(level)
        else:
            ref = f64(high, mid, low)
            n_on = ti.floor(ti.max(level - ref, 0.0) / c_on)
            n_off = ti.floor(ti.max(ref - level, 0.0) / c_off)
            s = ti.select(n_on >= 1.0, 1.0, 0.0) - ti.select(n_off >= 1.0, 1.0, 0.0)
            moved = n_on + n_off > 0.0
            high, mid, low = f32_parts(ref + n_on * c_on - n_off * c_off)
        if moved:  # the band of grey levels that cannot cross from the new r
            e_lo, e_hi = ti.exp(high - coefs[E0 + 3] + 1e-5), ti.exp(high + coefs[E0] - 1e-5)
            g_lo = (e_lo - coefs[E0 + 6]) * ti.cast(levels, ti.f32) + 1e-4 * e_lo * ti.cast(levels, ti.f32)
            g_hi = (e_hi - coefs[E0 + 6]) * ti.cast(levels, ti.f32) - 1e-4 * e_hi * ti.cast(levels, ti.f32)
        return s, high, mid, low, g_lo, g_hi

    @ti.func
    def emulate(a: ti.template()):
        """The emulator's signed map of this frame; updates ``r`` (``_RH + _RM + _RL``) and its band where a pixel
        is outside its band (the others are not read or written)."""
        g, g_lo, g_hi, first = a.grey(), a.at(LO), a.at(HI), a.value(V.first)
        levels = ti.cast(a.value(V.levels), ti.f64)
        loud = ti.select((g > g_lo) & (g < g_hi), 0.0, 1.0) + first  # first frame: every pixel
        s = a.zeros()
        if ti.static(a.lane):
            if loud.sum() > 0.0:  # float64, element by element (the lane vector types have none)
                high, mid, low = a.at(RH), a.at(RM), a.at(RL)
                for q in ti.static(range(lanes)):
                    if loud[q] > 0.0:
                        s[q], high[q], mid[q], low[q], g_lo[q], g_hi[q] = emulate_pixel(
                            a.coefs, g[q], high[q], mid[q], low[q], first, levels, g_lo[q], g_hi[q])
                for plane, v in ti.static(((RH, high), (RM, mid), (RL, low), (LO, g_lo), (HI, g_hi))):
                    a.put(plane, v)
        elif loud > 0.0:
            s, high, mid, low, g_lo, g_hi = emulate_pixel(a.coefs, g, a.at(RH), a.at(RM), a.at(RL), first, levels,
                                                          g_lo, g_hi)
            for plane, v in ti.static(((RH, high), (RM, mid), (RL, low), (LO, g_lo), (HI, g_hi))):
                a.put(plane, v)
        return s

    @ti.func
    def signed_map(a: ti.template()):
        """``X.now``: the sign of ``p_on - p_off`` of an event bin, or the emulator's map of a frame."""
        s = a.zeros()
        if ti.static(a.events):
            p_on, p_off = a.event(0), a.event(1)
            s = ti.select(p_on > p_off, 1.0, 0.0) - ti.select(p_off > p_on, 1.0, 0.0)
        else:
            s = emulate(a)
        a.put(X.now, s)

    @ti.func
    def row_passes(a: ti.template()):
        """``g (*)_x X_q(t-1)`` and ``x g (*)_x X_q(t-1)`` of each polarity (ON: ``X > 0``, OFF: ``X < 0``)."""
        R = ti.static(a.option("radius"))
        for q in ti.static(range(2)):
            n, x = a.zeros(), a.zeros()
            for d in ti.static(range(-R, R + 1)):
                v = ti.max(a.at(X.before, 0, d) * (1.0 - 2.0 * q), 0.0)
                n += a.coef(K.taps, d + R) * v
                x += a.coef(K.taps, 2 * R + 1 + d + R) * v
            a.put(ROWS[q][0], n)
            a.put(ROWS[q][1], x)

    @ti.func
    def flow(a: ti.template()):
        """``v = v^on + v^off``, ``v^q = -X_q(t) (K_x, K_y) dt / (reg + dt^2 K_n)`` from the row passes of
        ``X_q(t-1)``, and ``v_r``; returns the left and right sums of ``v_r w_pos`` (summed)."""
        R = ti.static(a.option("radius"))
        x, dt = a.at(X.now), a.coef(K.dt)
        vx, vy = a.zeros(), a.zeros()
        for q in ti.static(range(2)):
            kn, kx, ky = a.zeros(), a.zeros(), a.zeros()
            for d in ti.static(range(-R, R + 1)):
                g, n = a.coef(K.taps, d + R), a.at(ROWS[q][0], d, 0)
                kn += g * n
                ky += a.coef(K.taps, 2 * R + 1 + d + R) * n
                kx += g * a.at(ROWS[q][1], d, 0)
            scale = ti.max(x * (1.0 - 2.0 * q), 0.0) * (0.0 - dt) / (a.coef(K.reg) + dt * dt * kn)
            vx += kx * scale
            vy += ky * scale
        wx, wy, left = radial(a)
        vr = vx * wx + vy * wy
        for plane, v in ti.static(((VX, vx), (VY, vy), (VR, vr))):
            a.put(plane, v)
        return vr * a.at(WP) * left, vr * a.at(WP) * (1.0 - left)

    setup = Launch("setup", Stage(weights))
    load = Launch("load", Stage(signed_map, ghosts=(X.now,), halo="radius"))
    flow_launch = Launch("flow", Stage(row_passes), Stage(flow, sums="left right"))
    return engine.model(PLANES, COEFS, SCALARS, engine.build(ti, lanes), setup, load, flow_launch)
