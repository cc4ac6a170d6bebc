"""oLGMD's stages (LGMD2 with contrast polarity-specific feed-forward inhibition; float32 layers).

Two launches per frame, run by the engine (:mod:`cdnf_ti.kernels.engine`) in either layout:

1. ``load``: grey levels ``g``, ``P = g - L(t-1) + a_1 P(t-1) + a_2 P(t-2)``, ``P_on = [P]^+ + a1 P_on(t-1)``,
   ``P_off = [-P]^+ + a1 P_off(t-1)``; results ``sum P_on``, ``sum P_off``.
2. ``layers``: the polarity-gated summation ``S``, the grouping excitation ``Ce`` (3x3 mean of ``S``,
   result ``max Ce``) and the grouping ``G`` (result ``sum G``).

Borders (the model's ``borders()``): ``variant="code"`` zeroes the outermost ring of ``S`` and reflects
(reflect-101) it in ``Ce``; ``"paper"`` replicates. The NumPy float64 oracle is
:mod:`cdnf_ti.olgmd_reference`.
"""

import functools
from types import SimpleNamespace

from . import common, engine
from .engine import Coefs, Launch, Planes, Scalars, Stage

PLANES = Planes("L P:2 ON:2 OFF:2 S Ce G")
#: ON / OFF inhibition weights ``K a`` (now) and ``K (1 - a)`` (before), each centre, edge, diagonal.
COEFS = Coefs(k_on=6, k_off=6, a1=1, o=3, cw=1, delta_c=1, cde=1, tde=1)
#: Grey scale (1 for uint8, 255 for float), whether ``P`` is computed, the persistence ``a_1``, ``a_2``,
#: the biases ``w1``, ``w2``, the ON / OFF gates (1 open) and weights of ``E(t-1)``.
SCALARS = Scalars("scale active a_1 a_2 w1 w2 gate_on gate_off prev_on prev_off")
L, P, ON, OFF, S, Ce, G = PLANES
K, V = COEFS, SCALARS
#: Each channel's weights, bias and weight of ``E(t-1)``.
CHANNELS = {"ON": (K.k_on, V.w1, V.prev_on), "OFF": (K.k_off, V.w2, V.prev_off)}


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """oLGMD's launches for the DSL module ``ti``: the stages below, bound to the engine."""
    E = engine.build(ti, lanes)
    C = common.build(ti, lanes)

    @ti.func
    def luminance_change(g, l_prev, p1, p2, a_1, a_2):
        """``P(t) = L(t) - L(t-1) + a_1 P(t-1) + a_2 P(t-2)``."""
        return g - l_prev + a_1 * p1 + a_2 * p2

    @ti.func
    def polarity(p, on_prev, off_prev, a1):
        """``(P_on, P_off) = ([P]^+ + a1 P_on(t-1), [-P]^+ + a1 P_off(t-1))``."""
        on, off = C.half_wave(p)
        return on + a1 * on_prev, off + a1 * off_prev

    @ti.func
    def photoreceptors(a: ti.template()):
        """Grey levels, ``P``, ``P_on``, ``P_off`` (while ``active``); returns ``(P_on, P_off)``."""
        g = C.grey_levels(a, a.value(V.scale))
        on, off = a.zeros(), a.zeros()
        if a.value(V.active) > 0.0:
            p = luminance_change(g, a.at(L), a.at(P.before), a.at(P.now), a.value(V.a_1), a.value(V.a_2))
            on, off = polarity(p, a.at(ON.before), a.at(OFF.before), a.coef(K.a1))
            a.put(P.now, p)
            a.put(ON.now, on)
            a.put(OFF.now, off)
        a.put(L, g)
        return on, off

    @ti.func
    def inhibition(coefs: ti.template(), k: ti.template(), now_c, now_e, now_d, b_c, b_e, b_d, prev):
        """``I = sum_ij K_ij (a_ij E + (1 - a_ij) E(t-1))`` from the centre, edge and diagonal sums of ``E``
        and ``E(t-1)`` (``coefs``: the coefficient array, ``k`` the channel's weights); ``prev`` weighs ``E(t-1)``."""
        return C.weighted3(coefs, k.slot, now_c, now_e, now_d) + prev * C.weighted3(coefs, k.slot + 3, b_c, b_e, b_d)

    @ti.func
    def channel(a: ti.template(), e: ti.template()):
        """``[E - w I]^+`` of the channel ``e`` (``E(t-1)`` not read while its weight ``prev`` is 0)."""
        k, w_at, prev_at = ti.static(CHANNELS[e.name])
        w, prev = a.value(w_at), a.value(prev_at)
        c, ed, d = a.window3(e.now)
        inh = inhibition(a.coefs, k, c, ed, d, c, ed, d, 0.0)
        if prev != 0.0:
            bc, be, bd = a.window3(e.before)
            inh = inhibition(a.coefs, k, c, ed, d, bc, be, bd, prev)
        return ti.max(c - w * inh, 0.0)

    @ti.func
    def summation(a: ti.template()):
        """``S = o1 S_on + o2 S_off + o3 S_on S_off`` of the gated channels."""
        s_on, s_off = a.zeros(), a.zeros()
        if a.value(V.gate_on) > 0.0:
            s_on = channel(a, ON)
        if a.value(V.gate_off) > 0.0:
            s_off = channel(a, OFF)
        a.put(S, a.coef(K.o, 0) * s_on + a.coef(K.o, 1) * s_off + a.coef(K.o, 2) * s_on * s_off)

    @ti.func
    def excitation(a: ti.template()):
        """``Ce`` = the 3x3 mean of ``S``; returns it (maxed)."""
        ce = C.mean3(a, S)
        a.put(Ce, ce)
        return ce

    @ti.func
    def grouping(a: ti.template()):
        """``G = S Ce / (max Ce / cw + delta_c)``, zero where ``cde G < tde``; returns it (summed)."""
        inv_scale = 1.0 / (ti.max(ti.cast(a.result("max_Ce"), ti.f32), 0.0) / a.coef(K.cw) + a.coef(K.delta_c))
        g = a.at(S) * a.at(Ce) * inv_scale
        g = ti.select(g * a.coef(K.cde) < a.coef(K.tde), 0.0, g)
        a.put(G, g)
        return g

    load = Launch("load", Stage(photoreceptors, sums="sum_on sum_off", ghosts=(ON.now, OFF.now)))
    layers = Launch("layers", Stage(summation, ghosts=(S,)), Stage(excitation, maxes="max_Ce"),
                    Stage(grouping, sums="sum_G"))
    return engine.model(PLANES, COEFS, SCALARS, E, load, layers)
