"""The event-based looming detector's stages (Schubert, Knight, Philippides, Nowotny 2025; its model:
``cdnf_ti.models.event_looming``).

Two launches, run by the engine (:mod:`cdnf_ti.kernels.engine`) in either layout:

1. ``setup`` (the first bin of a run): the Gaussian ``w_pos`` of the positions ``w_x`` (-1..1 across the
   columns) and ``w_y`` (``-H/W..H/W`` down the rows).
2. ``step`` (every bin), two stages:

   * the signed event map ``X`` in {-1, 0, 1} of this bin. On an event bin ``(p_on, p_off)``: the sign of
     ``p_on - p_off``. On a frame: the project's DVS emulator with its default pixel (no mismatch, no refractory
     period, no noise), in float64: ``l = ln(g / 255 + eps)``, ``n_on = floor([l - r]^+ / C_on)``,
     ``n_off = floor([r - l]^+ / C_off)``, ``r += n_on C_on - n_off C_off``; ``X = +1`` where ``n_on >= 1``,
     ``-1`` where ``n_off >= 1``. The reference level ``r`` is a float64 kept exactly as three float32 planes,
     so the events are the float64 emulator's. A pixel whose grey lies inside the band ``(g_lo, g_hi)`` of its
     ``r`` cannot cross (float32 bounds from a polynomial ``e^x``, narrowed by margins 25 times its error): the
     float64 work runs only where a cell has a pixel outside its band, on the whole lane vector as float64
     vectors without a branch (a quiet pixel gets 0 and keeps its ``r``; uint8 frames read ``l`` from the table,
     float frames take ``ln`` on the pixels outside the band only). The same stage makes the row passes of the
     last map, per polarity ``q``: ``g (*)_x X_q(t-1)``, ``x g (*)_x X_q(t-1)`` (zero padding).
   * the column passes ``K_n``, ``K_x``, ``K_y`` of the separable (2 R + 1)^2 correlations (5x5) of ``X_q(t-1)``
     for the polarity ``q`` of the pixel's own event only (the other's term is 0; a lane vector without events
     has no flow and skips them);
     ``v = -|X(t)| (K_x, K_y) dt / (reg + dt^2 K_n)``, ``v_r = v_x w_x + v_y w_y``; results the left and right
     sums of ``v_r w_pos``.

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
    def cast(v, dt: ti.template(), lane: ti.template()):
        """``v`` (a value, or a lane vector if ``lane``: lane by lane, vector casts abort both compilers) as ``dt``."""
        if ti.static(lane):
            n = ti.static(lanes)  # (quadrants' comprehensions see locals only)
            return ti.Vector([ti.cast(v[q], dt) for q in ti.static(range(n))], dt=dt)
        else:
            return ti.cast(v, dt)

    @ti.func
    def f64(high, mid, low, lane: ti.template()):
        """The float64 value of three float32 parts (exact: a float64 has 53 bits, the parts 3 x 24)."""
        return (cast(high, ti.f64, lane) + cast(mid, ti.f64, lane)) + cast(low, ti.f64, lane)

    @ti.func
    def f32_parts(v, lane: ti.template()):
        """The three float32 parts of the float64 ``v``, high first."""
        high = cast(v, ti.f32, lane)
        rest = v - cast(high, ti.f64, lane)
        mid = cast(rest, ti.f32, lane)
        return high, mid, cast(rest - cast(mid, ti.f64, lane), ti.f32, lane)

    @ti.func
    def coef64(coefs: ti.template(), k):
        """Coefficient ``k`` of three parts (float64); the first of the emulator's is ``E0``."""
        return f64(coefs[k], coefs[k + 1], coefs[k + 2], False)

    @ti.func
    def level_of(coefs: ti.template(), g, ref, levels, loud):
        """The log level ``l`` of one pixel's grey ``g`` (float64): on uint8 frames the emulator's (exact, from the
        table), on a float frame ``ln`` where ``loud`` (else ``r``: no crossing)."""
        level = ref
        if levels == 255.0:
            level = coef64(coefs, K.levels.slot + 3 * ti.cast(g, ti.i32))
        elif loud > 0.0:
            level = ti.log(ti.cast(g, ti.f64) / ti.cast(levels, ti.f64) + coef64(coefs, E0 + 6))
        return level

    @ti.func
    def exact(coefs: ti.template(), g, high, mid, low, first, levels, loud, lane: ti.template()):
        """The emulator in float64 on one pixel or a lane vector (float64 vectors): ``X`` and the three parts of the
        new ``r``. A pixel inside its band gets 0 and the same ``r``, so a quiet pixel may run it too (``loud`` 0: a
        float frame skips its ``ln``); the first frame sets ``r = l`` and no event."""
        c_on, c_off, ref = coef64(coefs, E0), coef64(coefs, E0 + 3), f64(high, mid, low, lane)
        level = ref
        if ti.static(lane):  # the levels lane by lane (the table's loads, ln)
            pixel, m = ti.static(level_of, lanes)  # (quadrants' comprehensions see locals only)
            level = ti.Vector([pixel(coefs, g[q], ref[q], levels, loud[q]) for q in ti.static(range(m))], dt=ti.f64)
        else:
            level = level_of(coefs, g, ref, levels, loud)
        ref = ti.select(first != 0.0, level, ref)
        d = level - ref  # ref - level is -d exactly: the emulator's n_on, n_off from one division
        n = cast(cast(ti.max(d, 0.0 - d) / ti.select(d > 0.0, c_on, c_off), ti.i64, lane), ti.f64, lane)  # floor
        high, mid, low = f32_parts(ref + n * ti.select(d > 0.0, c_on, 0.0 - c_off), lane)
        return cast(ti.select(n < 1.0, 0.0, ti.select(d > 0.0, 1.0, -1.0)), ti.f32, lane), high, mid, low

    @ti.func
    def exp32(x):
        """``e^x`` in float32 without libm (so the lane vectors keep it): ``p(x / 32)^32``, ``p`` the degree-7
        Taylor polynomial; relative error below 4e-6 for ``|x| <= 10`` (float32 roundings, measured; bound 2e-5),
        far inside the band's margins."""
        y = x * (1.0 / 32.0)
        p = 1.0 + y * (1.0 + y * (1.0 / 2.0) * (1.0 + y * (1.0 / 3.0) * (1.0 + y * (1.0 / 4.0) * (
            1.0 + y * (1.0 / 5.0) * (1.0 + y * (1.0 / 6.0) * (1.0 + y * (1.0 / 7.0)))))))
        for _ in ti.static(range(5)):
            p = p * p
        return p

    @ti.func
    def band(coefs: ti.template(), high, levels):
        """The band ``(g_lo, g_hi)`` of grey levels that cannot cross from ``r`` (float32 ``high`` part): the greys of
        ``r - C_off`` and ``r + C_on``, narrowed by 1e-4 in log and 1e-4 relative (conservative)."""
        e_lo, e_hi = exp32(high - coefs[E0 + 3] + 1e-4), exp32(high + coefs[E0] - 1e-4)
        return (e_lo * (1.0 + 1e-4) - coefs[E0 + 6]) * levels, (e_hi * (1.0 - 1e-4) - coefs[E0 + 6]) * levels

    @ti.func
    def emulate(a: ti.template()):
        """The emulator's signed map of this frame; updates ``r`` (``_RH + _RM + _RL``) and its band where a cell
        has a pixel outside its band (the others are not read or written)."""
        g, g_lo, g_hi, first, levels = a.grey(), a.at(LO), a.at(HI), a.value(V.first), a.value(V.levels)
        loud = ti.select((g > g_lo) & (g < g_hi), 0.0, 1.0) + first  # first frame: every pixel
        s = a.zeros()
        if a.any(loud > 0.0):
            high, mid, low = a.at(RH), a.at(RM), a.at(RL)
            s, high, mid, low = exact(a.coefs, g, high, mid, low, first, levels, loud, a.lane)
            g_lo, g_hi = band(a.coefs, high, levels)
            for plane, v in ti.static(((RH, high), (RM, mid), (RL, low), (LO, g_lo), (HI, g_hi))):
                a.put(plane, v)
        return s

    @ti.func
    def signed_map(a: ti.template()):
        """``X.now``: the sign of ``p_on - p_off`` of an event bin, or the emulator's map of a frame; and the row
        passes ``g (*)_x X_q(t-1)``, ``x g (*)_x X_q(t-1)`` of each polarity (ON: ``X > 0``, OFF: ``X < 0``)."""
        s = a.zeros()
        if ti.static(a.events):
            p_on, p_off = a.event(0), a.event(1)
            s = ti.select(p_on > p_off, 1.0, 0.0) - ti.select(p_off > p_on, 1.0, 0.0)
        else:
            s = emulate(a)
        a.put(X.now, s)
        R = ti.static(a.option("radius"))
        for q in ti.static(range(2)):
            n, x = a.zeros(), a.zeros()
            for d in ti.static(range(-R, R + 1)):
                v = ti.max(a.at(X.before, 0, d) * (1.0 - 2.0 * q), 0.0)
                n += a.coef(K.taps, d + R) * v
                x += a.coef(K.taps, 2 * R + 1 + d + R) * v
            a.put((NP, NN)[q], n)  # each polarity's row passes (g, x g)
            a.put((XP, XN)[q], x)

    @ti.func
    def flow(a: ti.template()):
        """``v = v^on + v^off``, ``v^q = -X_q(t) (K_x, K_y) dt / (reg + dt^2 K_n)`` from the row passes of
        ``X_q(t-1)``, and ``v_r``; returns the left and right sums of ``v_r w_pos`` (summed). A pixel has one
        polarity (``X(t)`` is 1, -1 or 0): the column passes take the row passes of its own (the other's term
        is 0); a cell without events has none."""
        R = ti.static(a.option("radius"))
        x, dt = a.at(X.now), a.coef(K.dt)
        vx, vy = a.zeros(), a.zeros()
        if a.any(x != 0.0):
            kn, kx, ky = a.zeros(), a.zeros(), a.zeros()
            for d in ti.static(range(-R, R + 1)):
                g, n = a.coef(K.taps, d + R), ti.select(x > 0.0, a.at(NP, d, 0), a.at(NN, d, 0))
                kn += g * n
                ky += a.coef(K.taps, 2 * R + 1 + d + R) * n
                kx += g * ti.select(x > 0.0, a.at(XP, d, 0), a.at(XN, d, 0))
            scale = x * x * (0.0 - dt) / (a.coef(K.reg) + dt * dt * kn)  # X(t)^2 = |X(t)|
            vx, vy = kx * scale, ky * scale
        wx, wy, left = radial(a)
        vr = vx * wx + vy * wy
        for plane, v in ti.static(((VX, vx), (VY, vy), (VR, vr))):
            a.put(plane, v)
        return vr * a.at(WP) * left, vr * a.at(WP) * (1.0 - left)

    setup = Launch("setup", Stage(weights))
    step = Launch("step", Stage(signed_map, ghosts=(X.now,), halo="radius"), Stage(flow, sums="left right"))
    return engine.model(PLANES, COEFS, SCALARS, engine.build(ti, lanes), setup, step)
