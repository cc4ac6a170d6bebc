"""SDNF's stages (single field, float32 state; a documented reconstruction, ``cdnf_ti.models.sdnf``).

Two launches per frame, run by the engine (:mod:`cdnf_ti.kernels.engine`):

1. ``load``: ``g = frame * scale``, ``P = keep (g - L)``, binary input ``E = [|P| >= T_b]``; or, for an
   event bin ``(p_on, p_off)``, ``P = p_on - p_off`` and ``E = [max(p_on, p_off) >= T_b]``; result ``sum E``.
2. ``update`` (time-delayed lateral interaction: the DoG acts on the previous frame's firing rate
   ``F.before``): the separable DoG's row passes ``R1 = g1 (*)_x F``, ``R2 = g2 (*)_x F``, then
   ``u = E - h + vartheta(A g1 (*)_y R1 - B_t g2 (*)_y R2)``, ``F.now = f(u)``; result ``sum f(u)``.

The DoG's radius ``R`` is a compile-time option (the model's ``kernel_options()``); its taps ``g1``,
``g2`` (``2 R + 1`` each, unnormalised) are the coefficient ``taps``. Borders replicate. NumPy float64
oracle: :class:`cdnf_ti.baselines_reference.NumpySDNFBackend`.
"""

import functools
from types import SimpleNamespace

from . import common, engine
from .engine import Coefs, Launch, Planes, Scalars, Stage

PLANES = Planes("_L P E u activity:2 _R1 _R2")  # "_": scratch, not among the fields
#: ``A``; ``h``; theta's scale ``1 / tanh(1)``; the binary threshold ``T_b``; the rest ``-h``; ``g1``, ``g2``.
COEFS = Coefs(A=1, h=1, theta=1, t_b=1, u_rest=1, taps=0)
SCALARS = Scalars("scale keep B_t")
L, P, E, U, F, R1, R2 = PLANES
K, V = COEFS, SCALARS


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """SDNF's launches for the DSL module ``ti``: the stages below, bound to the engine."""
    tanh_rational = common.build(ti, lanes).tanh_rational

    @ti.func
    def binary_input(a: ti.template()):
        """``P`` and ``E`` from the frame or an event bin; returns ``E`` (summed)."""
        e = a.zeros()
        if ti.static(a.events):
            p_on, p_off = a.event(0), a.event(1)
            a.put(P, p_on - p_off)
            e = ti.select(ti.max(p_on, p_off) >= a.coef(K.t_b), 1.0, 0.0)
        else:
            g = a.grey() * a.value(V.scale)
            p = a.value(V.keep) * (g - a.at(L))
            a.put(L, g)
            a.put(P, p)
            e = ti.select(ti.max(p, 0.0 - p) >= a.coef(K.t_b), 1.0, 0.0)
        a.put(E, e)
        return e

    @ti.func
    def row_passes(a: ti.template()):
        """``R1``, ``R2``: the taps ``g1``, ``g2`` along the row of ``F(t-1)``."""
        R = ti.static(a.option("radius"))
        r1, r2 = a.zeros(), a.zeros()
        for d in ti.static(range(-R, R + 1)):
            v = a.at(F.before, 0, d)
            r1 += a.coef(K.taps, d + R) * v
            r2 += a.coef(K.taps, 2 * R + 1 + d + R) * v
        a.put(R1, r1)
        a.put(R2, r2)

    @ti.func
    def field(a: ti.template()):
        """``u`` and ``F.now = f(u)``; returns ``f(u)`` (summed)."""
        R = ti.static(a.option("radius"))
        b1, b2 = a.zeros(), a.zeros()
        for d in ti.static(range(-R, R + 1)):
            b1 += a.coef(K.taps, d + R) * a.at(R1, d, 0)
            b2 += a.coef(K.taps, 2 * R + 1 + d + R) * a.at(R2, d, 0)
        u = a.at(E) - a.coef(K.h) + tanh_rational(0.5 * (a.coef(K.A) * b1 - a.value(V.B_t) * b2))
        a.put(U, u)
        f = tanh_rational(ti.max(u, 0.0)) * a.coef(K.theta)
        a.put(F.now, f)
        return f

    load = Launch("load", Stage(binary_input, sums="sum_E"))
    update = Launch("update", Stage(row_passes), Stage(field, sums="sum_F", ghosts=(F.now,), halo="radius"))
    return engine.model(PLANES, COEFS, SCALARS, engine.build(ti, lanes), load, update, initial={"u": "u_rest"})
