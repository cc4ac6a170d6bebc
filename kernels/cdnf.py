"""C-DNF's stages (float32 fields), run by the engine (:mod:`cdnf_ti.kernels.engine`).

Per frame (:class:`cdnf_ti.models.cdnf.CDNF`):

1. ``contrast`` solve: ``load`` (the ON/OFF input: ``P = g - L``, ``P_on = [P]+``, ``P_off = [-P]+``, or an
   event bin's planes as they are; with the local start, ``u = start(P)``), then the relaxation updates of
   ``u_on``, ``u_off``: ``F(u) = P_on - h + vartheta(W_c (*) u)`` (``vartheta(a) = tanh(a / 2)``,
   ``W_c = k k^T``), and once converged the Summation input ``S = alpha_on theta([u_on]+) +
   alpha_off theta([u_off]+)`` (with the local start, ``v = start(S)``).
2. ``summation`` solve: the DoG's row passes ``R1 = g1 (*)_x v``, ``R2 = g2 (*)_x v``, then the relaxation of
   ``v``: ``F(v) = S - h + vartheta(A g1 (*)_y R1 - B g2 (*)_y R2)``; once converged ``sum theta([v]+)``.

On the lane layout the updates freeze lanes with ``|F(u) - u| <= tau`` and visit only the elements near
a change (pending spans, one group for ON+OFF and one for the Summation field). The DoG's profiles ``g1``,
``g2`` (``2 R + 1`` float32 taps each), its radius ``radius`` and ``reach = 2 radius`` (the rows the row
passes serve) are compile-time options. The NumPy float64 oracle is :mod:`cdnf_ti.reference`.
"""

import functools
from types import SimpleNamespace

from . import common, engine
from .engine import Coefs, Launch, Planes, Scalars, Span, Stage

#: ``L``: the last frame; ``P``, ``P_off``: the luminance change (frames: ``P``; an event bin: ``P_on`` in
#: ``P``, ``P_off``); ``S``: the Summation input; the fields ``u_on``, ``u_off``, ``v``; scratch: the DoG's row
#: passes, the fields' resting state, the span groups.
PLANES = Planes("L P P_off S u_on:2 u_off:2 v:2 _row1 _row2 _rest_u _rest_v _span_c _span_s")
#: ``k_c``: ``(k0, k1)`` of ``W_c = k k^T``, ``k = (k1, k0, k1)``; ``w_c``: W_c's centre, edge and diagonal
#: weights; ``h``; ``alpha_on``, ``alpha_off``; ``theta``: theta's scale ``1 / tanh(1)``; ``A``, ``B``: the
#: DoG's gains; ``local``: 1 for the local start; ``start_u``, ``start_v``: its fits
#: (:func:`cdnf_ti.solver.cdnf_local_starts`); the resting levels ``u0``, ``v0``.
COEFS = Coefs(k_c=2, w_c=3, h=1, alpha_on=1, alpha_off=1, theta=1, A=1, B=1, local=1, start_u=7, start_v=7,
              u0=1, v0=1)
#: The solves' ``updates``, ``tol``, ``grow``, ``tau`` (the freezing threshold); the input's ``load`` (1: the
#: contrast solve loads the frame first), ``first`` (the first frame: ``P = 0``) and ``scale``.
SCALARS = Scalars("updates tol grow tau load first scale")
L, P, P_OFF, S, U_ON, U_OFF, V, ROW1, ROW2, REST_U, REST_V, SPAN_C_, SPAN_S_ = PLANES
K, X = COEFS, SCALARS
SPAN_C, SPAN_S = Span(SPAN_C_, U_ON), Span(SPAN_S_, V)
#: The slot of each field's local-start fit.
FIT = {"u_on": K.start_u.slot, "u_off": K.start_u.slot, "v": K.start_v.slot}


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """C-DNF's launches for the DSL module ``ti``: the stages below, bound to the engine."""
    C = common.build(ti, lanes)
    tanh_rational, local_start, start_coefficients = C.tanh_rational, C.local_start, C.start_coefficients

    @ti.func
    def start(a: ti.template(), field: ti.template(), inp):
        """``field = start(inp)`` (its local start) on the frame columns; whether it changed. A cell without
        input starts at the resting level without evaluating the fit."""
        cs = start_coefficients(a.coefs, ti.static(FIT[field.name]))
        new = a.zeros() + cs[0]
        if a.any(inp > 0.0):
            new = local_start(inp, cs)
        old = a.at(field)
        new = ti.select(a.frame_mask() > 0.0, new, old)
        a.put(field, new)
        return a.any(new != old)

    @ti.func
    def load(a: ti.template()):
        """The ON/OFF input (when ``load``): ``P`` (and ``P_off``) from the frame or the event bin, and the
        contrast fields' local start; returns whether anything changed (the contrast spans)."""
        changed = 0
        if a.value(X.load) != 0:
            p_on, p_off = a.zeros(), a.zeros()
            if ti.static(a.events):
                p_on, p_off = a.event(0), a.event(1)
                changed = a.any(p_on != a.at(P)) | a.any(p_off != a.at(P_OFF))
                a.put(P, p_on)
                a.put(P_OFF, p_off)
            else:
                g = a.grey() * a.value(X.scale)
                p = ti.select(a.value(X.first) != 0, 0.0, g - a.at(L))
                changed = a.any(p != a.at(P))
                a.put(P, p)
                a.put(L, g)
                p_on, p_off = ti.max(p, 0.0), ti.max(0.0 - p, 0.0)
            if a.coef(K.local) != 0:
                changed |= start(a, U_ON, p_on)
                changed |= start(a, U_OFF, p_off)
        return changed

    @ti.func
    def contrast_input(a: ti.template(), on: ti.template()):
        """``P_on = [P]+`` (``on``) or ``P_off = [-P]+``; an event bin's planes as they are."""
        inp = a.at(P)
        if ti.static(a.events and not on):
            inp = a.at(P_OFF)
        elif ti.static(not a.events and on):
            inp = ti.max(inp, 0.0)
        elif ti.static(not a.events):
            inp = ti.max(-1.0 * inp, 0.0)
        return inp

    @ti.func
    def contrast(a: ti.template()):
        """``F(u) - u`` of the ON and OFF contrast fields."""
        h = a.coef(K.h)
        d_on = contrast_input(a, True) - h + tanh_rational(0.5 * a.smooth3(U_ON, K.k_c, K.w_c)) - a.at(U_ON)
        d_off = contrast_input(a, False) - h + tanh_rational(0.5 * a.smooth3(U_OFF, K.k_c, K.w_c)) - a.at(U_OFF)
        return d_on, d_off

    @ti.func
    def summation_input(a: ti.template()):
        """``S`` of the contrast fields and the Summation field's local start; whether anything changed."""
        theta = a.coef(K.theta)
        a_on = tanh_rational(ti.max(a.at(U_ON), 0.0)) * theta
        a_off = tanh_rational(ti.max(a.at(U_OFF), 0.0)) * theta
        s = a.coef(K.alpha_on) * a_on + a.coef(K.alpha_off) * a_off
        changed = a.any(s != a.at(S))
        if a.coef(K.local) != 0:
            changed |= start(a, V, s)
        a.put(S, s)
        return changed

    @ti.func
    def row_passes(a: ti.template()):
        """``R1 = g1 (*)_x v``, ``R2 = g2 (*)_x v``."""
        a.put(ROW1, a.taps(V, "g1"))
        a.put(ROW2, a.taps(V, "g2"))

    @ti.func
    def summation(a: ti.template()):
        """``F(v) - v`` of the Summation field (the column passes of the DoG)."""
        b1, b2 = a.taps(ROW1, "g1", True), a.taps(ROW2, "g2", True)
        return a.at(S) - a.coef(K.h) + tanh_rational(0.5 * (a.coef(K.A) * b1 - a.coef(K.B) * b2)) - a.at(V)

    @ti.func
    def activation(a: ti.template()):
        """``theta([v]+)`` (summed)."""
        return tanh_rational(ti.max(a.at(V), 0.0)) * a.coef(K.theta)

    @ti.func
    def save_rest(a: ti.template()):
        a.put(REST_U, a.at(U_ON))
        a.put(REST_V, a.at(V))

    @ti.func
    def restore_contrast(a: ti.template()):
        """Both buffers of ``u_on``, ``u_off`` at rest; every contrast element pending."""
        a.put(U_ON.now, a.at(REST_U))
        a.put(U_ON.before, a.at(REST_U))
        a.put(U_OFF.now, a.at(REST_U))
        a.put(U_OFF.before, a.at(REST_U))
        return 1

    @ti.func
    def restore_summation(a: ti.template()):
        a.put(V.now, a.at(REST_V))
        a.put(V.before, a.at(REST_V))
        return 1

    pairs = (U_ON.now, U_ON.before, U_OFF.now, U_OFF.before)
    summation_input_stage = Stage(summation_input, marks=SPAN_S, ghosts=(V.now,), halo="radius")
    activation_stage = Stage(activation, sums="sum_theta")
    return engine.model(
        PLANES, COEFS, SCALARS, engine.build(ti, lanes),
        Launch("contrast", summation_input_stage, before=(Stage(load, marks=SPAN_C, ghosts=(U_ON, U_OFF)),),
               update=(Stage(contrast, relax=(U_ON, U_OFF), spans=SPAN_C, rows=1),), scalars=SCALARS),
        Launch("summation", activation_stage, scalars=SCALARS,
               update=(Stage(row_passes, spans=SPAN_S, rows="reach"),
                       Stage(summation, relax=(V,), spans=SPAN_S, rows="radius", halo="radius"))),
        Launch("load", Stage(load, marks=SPAN_C, ghosts=(U_ON, U_OFF))),
        Launch("summation_input", summation_input_stage),
        Launch("activation", activation_stage),
        Launch("save_rest", Stage(save_rest)),
        Launch("restore_rest", Stage(restore_contrast, marks=SPAN_C, ghosts=pairs),
               Stage(restore_summation, marks=SPAN_S, ghosts=(V.now, V.before), halo="radius")),
        initial={"u_on": "u0", "u_off": "u0", "v": "v0"}, spans=(SPAN_C, SPAN_S))
