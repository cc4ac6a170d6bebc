"""LGMD_P_ON_OFF's stages (motion and contrast vision in ON/OFF channels; float32 layers).

One launch per frame, ``frame``, run by the engine (:mod:`cdnf_ti.kernels.engine`) in either layout:

1. ``photoreceptors``: grey levels ``g``, ``P = keep (g - L)``, ``P_on = [P]^+``, ``P_off = [-P]^+``; or, for an
   event bin, ``P_on = 255 p_on``, ``P_off = 255 p_off``.
2. ``row_pass`` and ``normalisation``: ``Mhat = g (*)_y (g (*)_x P_x)``, the separable Gaussian (taps ``g``,
   radius ``R`` a compile-time option), then ``E_x = tanh(P_x / (Mhat + alpha_1))``.
3. ``summation``: ``C_x = |E_x - (edge + diagonal sum of E_x) / 8|``, ``I_x = K_I * E_x(t-1)``,
   ``S_x_out = [a (E_x - beta I_x) - b C_x]^+``, ``S = th_1 S_on_out + th_2 S_off_out + th_3 S_on_out S_off_out``.
4. ``excitation``: ``Ce`` the 3x3 mean of ``S`` (result ``max_Ce``); ``grouping``:
   ``G = S Ce / (max Ce / C_w + delta_C)``, zero where ``C_de G < T_de`` (result ``sum_G``).

Every plane read off its cell reflects (reflect-101, OpenCV's default border; the model's ``borders()``).
The NumPy float64 oracle is :mod:`cdnf_ti.lgmd_p_on_off_reference`.
"""

import functools
from types import SimpleNamespace

from . import common, engine
from .engine import Coefs, Launch, Planes, Scalars, Stage

PLANES = Planes("L ON OFF _RON _ROFF E_on:2 E_off:2 S Ce G")  # "_": scratch (the Gaussian's row passes)
#: ``alpha_1``, ``beta``, ``K_I`` (centre, edge, diagonal), the channels' gains ``(alpha_2, alpha_3, alpha_4,
#: alpha_5)``, ``theta`` (3), the grouping's constants, the Gaussian's taps ``g`` (``2 R + 1``, normalised).
COEFS = Coefs(alpha_1=1, beta=1, k_i=3, gains=4, theta=3, c_w=1, delta_c=1, c_de=1, t_de=1, taps=0)
#: Grey scale (1 for uint8, 255 for float frames and event bins), whether ``P`` is computed (0 at frame 0).
SCALARS = Scalars("scale keep")
L, ON, OFF, RON, ROFF, E_ON, E_OFF, S, Ce, G = PLANES
K, V = COEFS, SCALARS
#: Each polarity by its ``P_x``: its row pass, its ``E_x`` and the slot of its motion gain in ``gains``.
CHANNELS = {"ON": (RON, E_ON, 0), "OFF": (ROFF, E_OFF, 2)}


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """LGMD_P_ON_OFF's launch for the DSL module ``ti``: the stages below, bound to the engine."""
    C = common.build(ti, lanes)

    @ti.func
    def photoreceptors(a: ti.template()):
        """``P_on``, ``P_off`` from the frame (``L`` keeps its grey levels) or from an event bin."""
        scale = a.value(V.scale)
        if ti.static(a.events):
            a.put(ON, a.event(0) * scale)
            a.put(OFF, a.event(1) * scale)
        else:
            g = C.grey_levels(a, scale)
            p = a.value(V.keep) * (g - a.at(L))
            a.put(L, g)
            on, off = C.half_wave(p)
            a.put(ON, on)
            a.put(OFF, off)

    @ti.func
    def row_pass(a: ti.template()):
        """The Gaussian's taps along the row of ``P_on`` and ``P_off``."""
        R = ti.static(a.option("radius"))
        r_on, r_off = a.zeros(), a.zeros()
        for d in ti.static(range(-R, R + 1)):
            r_on += a.coef(K.taps, d + R) * a.at(ON, 0, d)
            r_off += a.coef(K.taps, d + R) * a.at(OFF, 0, d)
        a.put(RON, r_on)
        a.put(ROFF, r_off)

    @ti.func
    def normalised(a: ti.template(), p_x: ti.template()):
        """``E_x = tanh(P_x / (Mhat_x + alpha_1))`` of the channel of ``p_x``; ``Mhat_x``: the column pass of
        its row pass."""
        rows, e = ti.static(CHANNELS[p_x.name][:2])
        R = ti.static(a.option("radius"))
        m_hat = a.zeros()
        for d in ti.static(range(-R, R + 1)):
            m_hat += a.coef(K.taps, d + R) * a.at(rows, d, 0)
        a.put(e.now, C.tanh_rational(a.at(p_x) / (m_hat + a.coef(K.alpha_1))))

    @ti.func
    def normalisation(a: ti.template()):
        """Both channels' ``E_on``, ``E_off``."""
        normalised(a, ON)
        normalised(a, OFF)

    @ti.func
    def channel(a: ti.template(), p_x: ti.template()):
        """``S_x_out = [a (E_x - beta K_I * E_x(t-1)) - b |K_C * E_x|]^+`` of the channel of ``p_x``."""
        e, gain = ti.static(CHANNELS[p_x.name][1:])
        centre, edge, diag = a.window3(e.now)
        k_c = centre - (edge + diag) * 0.125
        contrast = ti.max(k_c, 0.0 - k_c)
        b_c, b_e, b_d = a.window3(e.before)
        inhibition = C.weighted3(a.coefs, K.k_i.slot, b_c, b_e, b_d)
        motion = centre - a.coef(K.beta) * inhibition
        return ti.max(a.coef(K.gains, gain) * motion - a.coef(K.gains, gain + 1) * contrast, 0.0)

    @ti.func
    def summation(a: ti.template()):
        """``S = theta_1 S_on_out + theta_2 S_off_out + theta_3 S_on_out S_off_out``."""
        s_on, s_off = channel(a, ON), channel(a, OFF)
        a.put(S, a.coef(K.theta, 0) * s_on + a.coef(K.theta, 1) * s_off + a.coef(K.theta, 2) * s_on * s_off)

    @ti.func
    def excitation(a: ti.template()):
        """``Ce`` = the 3x3 mean of ``S``; returns it (maxed)."""
        ce = C.mean3(a, S)
        a.put(Ce, ce)
        return ce

    @ti.func
    def grouping(a: ti.template()):
        """``G = S Ce / (max Ce / C_w + delta_C)``, zero where ``C_de G < T_de``; returns it (summed)."""
        w = ti.cast(a.result("max_Ce"), ti.f32) / a.coef(K.c_w) + a.coef(K.delta_c)
        g = a.at(S) * a.at(Ce) / w
        g = ti.select(g * a.coef(K.c_de) < a.coef(K.t_de), 0.0, g)
        a.put(G, g)
        return g

    frame = Launch("frame", Stage(photoreceptors, ghosts=(ON, OFF), halo="radius"), Stage(row_pass),
                   Stage(normalisation, ghosts=(E_ON.now, E_OFF.now)), Stage(summation, ghosts=(S,)),
                   Stage(excitation, maxes="max_Ce"), Stage(grouping, sums="sum_G"))
    return engine.model(PLANES, COEFS, SCALARS, engine.build(ti, lanes), frame)
