"""The stages of the LGMD family on the engine core (:mod:`cdnf_ti.kernels.engine`): LGMD1, LGMD2 and
F-LGMD ONn (float32 layers), each stage written once for both layouts.

Each model declares its planes, coefficients and launch scalars by name (``LGMD1_PLANES``, ...) and has its
``build`` function (:func:`lgmd1`, :func:`lgmd2`, :func:`flgmd`; a model names it as ``kernels = "lgmd:lgmd1"``).
Per frame:

1. ``load`` (every model): photoreceptors ``L``, ``P`` (or an event bin's ``P_on``, ``P_off``) and the ON / OFF
   channels with residue; result ``sum_p`` (``sum |P|``, the PM / FFI pathway). F-LGMD's load also writes
   the drives, the frame's constant inhibition ``Q`` and the feedback iterate's start.
2. LGMD1 / LGMD2 ``layers``: the delayed 3x3 spreads or inhibitions and ``S`` (LGMD2: ``Ce``, result
   ``max_Ce``), then the grouping ``G`` (result ``sum_G``). F-LGMD ``solve``: the feedback updates (a solve
   launch, residuals of ON and OFF), then, when it converged, the layers at the fixed point (``finish``
   computes them for a solve that did not); ``solve_on`` where OFF is not iterated.

Borders replicate, as in the authors' C# code. The NumPy float64 oracle of every stage is
:mod:`cdnf_ti.baselines_reference`.
"""

import functools
from types import SimpleNamespace

from . import compat, engine
from .engine import Coefs, Launch, Planes, Scalars, Stage

# -- LGMD1 and LGMD2 on the engine (kernels/engine.py): declarations, then the stages -------------------
#: LGMD1: photoreceptors ``L``, ``P``; the ON / OFF channels (now, the frame before); the delayed spreads
#: ``I_on``, ``E_off``; the summation ``S``; the grouping ``G``.
LGMD1_PLANES = Planes("L P ON:2 OFF:2 I_on E_off S G")
#: The ON / OFF clip and residue; the spread ``k`` and its delay coefficients ``a`` (edge, diagonal; centre
#: 0); the inhibition weights ``w_i`` (on, off); the summation's weights ``e`` (on, off, onoff); ``t_s``.
LGMD1_COEFS = Coefs(clip=1, dc=1, k=2, a=2, w_i=2, e=3, t_s=1)
#: Grey scale (1 for uint8, 255 for float input and event bins); 0 on the first frame (``P = 0``), else 1.
LGMD1_SCALARS = Scalars("scale keep")
#: LGMD2: as LGMD1, with the delayed inhibitions ``I_on``, ``I_off`` and the excitation ``Ce``.
LGMD2_PLANES = Planes("L P ON:2 OFF:2 I_on I_off S Ce G")
#: The inhibition kernels ``k_*`` and delay coefficients ``a_*`` (centre, edge, diagonal) of ON and OFF.
LGMD2_COEFS = Coefs(clip=1, dc=1, k_on=3, a_on=3, k_off=3, a_off=3, e=3, delta_c=1, c_w=1, c_de=1, t_de=1)
#: ... and the adaptive inhibition weights of the frame.
LGMD2_SCALARS = Scalars("scale keep w_on w_off")


@functools.lru_cache(maxsize=None)
def _family(ti, lanes: int) -> SimpleNamespace:
    """The equations the family shares, for the DSL module ``ti``: the engine, the input stage's factory,
    the delayed 3x3 mix and the 3x3 mean."""
    E = engine.build(ti, lanes)
    lane_abs = compat.build(ti, lanes).lane_abs

    @ti.func
    def half_wave(p, on_prev, off_prev, clip, dc):
        """``ON = P [P >= clip] + dc ON(t-1)``, ``OFF = |P| [P < clip] + dc OFF(t-1)``."""
        return ti.select(p >= clip, p, 0.0) + dc * on_prev, ti.select(p < clip, lane_abs(p), 0.0) + dc * off_prev

    @ti.func
    def half_wave_on_off(p_on, p_off, on_prev, off_prev, clip, dc):
        """The channels driven by an event bin: ``ON = P_on [P_on >= clip] + dc ON(t-1)``,
        ``OFF = P_off [-P_off < clip] + dc OFF(t-1)`` (a frame's ``P_on = [P]+``, ``P_off = [-P]+``)."""
        return (ti.select(p_on >= clip, p_on, 0.0) + dc * on_prev,
                ti.select(0.0 - p_off < clip, p_off, 0.0) + dc * off_prev)

    def channels_of(pl: Planes, k: Coefs, v: Scalars, on_prev, off_prev):
        """The input stage of a model with the planes ``L``, ``P`` (``pl``), the coefficients ``clip``, ``dc``
        (``k``) and the launch scalars ``scale``, ``keep`` (``v``); ``on_prev``, ``off_prev``: the planes of the
        channels of the frame before. A ti.func of ``a`` returning ``(ON, OFF, |P|)`` (an event bin:
        ``P_on + P_off`` for ``|P|``)."""

        @ti.func
        def channels(a: ti.template()):
            """``g = floor(scale frame + 0.5)``, ``P = keep (g - L)``, ``L = g`` and the ON / OFF channels; an
            event bin drives ON by ``P_on = scale p_on`` and OFF by ``P_off = scale p_off``, ``P = P_on - P_off``."""
            on, off, drive = a.zeros(), a.zeros(), a.zeros()
            if ti.static(a.events):
                p_on = a.event(0) * a.value(v.scale)
                p_off = a.event(1) * a.value(v.scale)
                a.put(pl.P, p_on - p_off)
                on, off = half_wave_on_off(p_on, p_off, a.at(on_prev), a.at(off_prev), a.coef(k.clip), a.coef(k.dc))
                drive = p_on + p_off
            else:
                g = ti.floor(a.grey() * a.value(v.scale) + 0.5)
                p = a.value(v.keep) * (g - a.at(pl.L))
                a.put(pl.L, g)
                a.put(pl.P, p)
                on, off = half_wave(p, a.at(on_prev), a.at(off_prev), a.coef(k.clip), a.coef(k.dc))
                drive = lane_abs(p)
            return on, off, drive

        return channels

    def photoreceptors_of(pl: Planes, k: Coefs, v: Scalars):
        """LGMD1's and LGMD2's load: the channels of the frame into the pairs' ``now`` buffers from their
        ``before`` ones; returns ``|P|`` (summed, ``sum_p``)."""
        channels = channels_of(pl, k, v, pl.ON.before, pl.OFF.before)

        @ti.func
        def photoreceptors(a: ti.template()):
            on, off, drive = channels(a)
            a.put(pl.ON.now, on)
            a.put(pl.OFF.now, off)
            return drive

        return Launch("load", Stage(photoreceptors, sums="sum_p", ghosts=(pl.ON.now, pl.OFF.now)))

    @ti.func
    def delayed_mix(c, e, d, cp, ep, dp, k0, k1, k2, a0, a1, a2):
        """``sum K [a X(t) + (1 - a) X(t-1)]`` from the centre and edge / diagonal sums of ``X(t)``
        (``c, e, d``) and of ``X(t-1)`` (``cp, ep, dp``)."""
        return (k0 * (a0 * c + (1.0 - a0) * cp) + k1 * (a1 * e + (1.0 - a1) * ep)
                + k2 * (a2 * d + (1.0 - a2) * dp))

    def mean9_of(x):
        """The 3x3 mean of plane ``x``: a ti.func of ``a`` (a cell plus one argument is the widest call, 12)."""

        @ti.func
        def mean9(a: ti.template()):
            c, e, d = a.window3(x)
            return (1.0 / 9.0) * c + (1.0 / 9.0) * e + (1.0 / 9.0) * d

        return mean9

    return SimpleNamespace(E=E, lane_abs=lane_abs, channels_of=channels_of, photoreceptors_of=photoreceptors_of,
                           delayed_mix=delayed_mix, mean9_of=mean9_of)


@functools.lru_cache(maxsize=None)
def lgmd1(ti, lanes: int) -> SimpleNamespace:
    """LGMD1's launches: ``load`` (result ``sum_p``) and ``layers`` (result ``sum_G``)."""
    F = _family(ti, lanes)
    pl, k = LGMD1_PLANES, LGMD1_COEFS
    mean9 = F.mean9_of(pl.S)

    @ti.func
    def summation(a: ti.template()):
        """``I_on``, ``E_off`` (the delayed spreads of ON, OFF; centre 0); ``S = e_on S_on + e_off S_off +
        e_onoff S_on S_off`` kept where ``S >= t_s``, ``S_on = ON - w_i_on I_on``, ``S_off = E_off - w_i_off OFF``.
        The coefficients are read first (float sums are ordered by where their operands are loaded)."""
        k1, k2, a1, a2 = a.coef(k.k, 0), a.coef(k.k, 1), a.coef(k.a, 0), a.coef(k.a, 1)
        e_on, e_off, e_onoff = a.coef(k.e, 0), a.coef(k.e, 1), a.coef(k.e, 2)
        w_i_on, w_i_off, t_s = a.coef(k.w_i, 0), a.coef(k.w_i, 1), a.coef(k.t_s)
        cn, en, dn = a.window3(pl.ON.now)
        cnp, enp, dnp = a.window3(pl.ON.before)
        i_on = F.delayed_mix(cn, en, dn, cnp, enp, dnp, 0.0, k1, k2, 0.0, a1, a2)
        cf, ef, df = a.window3(pl.OFF.now)
        cfp, efp, dfp = a.window3(pl.OFF.before)
        e_o = F.delayed_mix(cf, ef, df, cfp, efp, dfp, 0.0, k1, k2, 0.0, a1, a2)
        a.put(pl.I_on, i_on)
        a.put(pl.E_off, e_o)
        s_on = cn - w_i_on * i_on
        s_off = e_o - w_i_off * cf
        s = e_on * s_on + e_off * s_off + e_onoff * s_on * s_off
        a.put(pl.S, ti.select(s >= t_s, s, 0.0))

    @ti.func
    def grouping(a: ti.template()):
        """``G = S (*) ones/9``; returns it (summed)."""
        g = mean9(a)
        a.put(pl.G, g)
        return g

    layers = Launch("layers", Stage(summation, ghosts=(pl.S,)), Stage(grouping, sums="sum_G"))
    return engine.model(pl, k, LGMD1_SCALARS, F.E, F.photoreceptors_of(pl, k, LGMD1_SCALARS), layers)


@functools.lru_cache(maxsize=None)
def lgmd2(ti, lanes: int) -> SimpleNamespace:
    """LGMD2's launches: ``load`` (result ``sum_p``) and ``layers`` (results ``max_Ce``, ``sum_G``)."""
    F = _family(ti, lanes)
    pl, k, v = LGMD2_PLANES, LGMD2_COEFS, LGMD2_SCALARS
    mean9 = F.mean9_of(pl.S)

    @ti.func
    def summation(a: ti.template()):
        """``I_on``, ``I_off`` (the delayed inhibitions, centre included); ``S = e_on S_on + e_off S_off +
        e_onoff S_on S_off``, ``S_on = [ON - w_on I_on]+``, ``S_off = [OFF - w_off I_off]+``. The coefficients
        are read first (float sums are ordered by where their operands are loaded)."""
        kn0, kn1, kn2 = a.coef(k.k_on, 0), a.coef(k.k_on, 1), a.coef(k.k_on, 2)
        an0, an1, an2 = a.coef(k.a_on, 0), a.coef(k.a_on, 1), a.coef(k.a_on, 2)
        kf0, kf1, kf2 = a.coef(k.k_off, 0), a.coef(k.k_off, 1), a.coef(k.k_off, 2)
        af0, af1, af2 = a.coef(k.a_off, 0), a.coef(k.a_off, 1), a.coef(k.a_off, 2)
        e_on, e_off, e_onoff = a.coef(k.e, 0), a.coef(k.e, 1), a.coef(k.e, 2)
        w_on, w_off = a.value(v.w_on), a.value(v.w_off)
        cn, en, dn = a.window3(pl.ON.now)
        cnp, enp, dnp = a.window3(pl.ON.before)
        i_on = F.delayed_mix(cn, en, dn, cnp, enp, dnp, kn0, kn1, kn2, an0, an1, an2)
        cf, ef, df = a.window3(pl.OFF.now)
        cfp, efp, dfp = a.window3(pl.OFF.before)
        i_off = F.delayed_mix(cf, ef, df, cfp, efp, dfp, kf0, kf1, kf2, af0, af1, af2)
        a.put(pl.I_on, i_on)
        a.put(pl.I_off, i_off)
        s_on = ti.max(cn - w_on * i_on, 0.0)
        s_off = ti.max(cf - w_off * i_off, 0.0)
        a.put(pl.S, e_on * s_on + e_off * s_off + e_onoff * s_on * s_off)

    @ti.func
    def excitation(a: ti.template()):
        """``Ce = S (*) ones/9``; returns ``|Ce|`` (maxed)."""
        ce = mean9(a)
        a.put(pl.Ce, ce)
        return F.lane_abs(ce)

    @ti.func
    def grouping(a: ti.template()):
        """``G = S Ce / (delta_c + max|Ce| / c_w)``, zero unless ``c_de G >= t_de``; returns it (summed)."""
        inv_omega = 1.0 / (a.coef(k.delta_c) + ti.max(ti.cast(a.result("max_Ce"), ti.f32), 0.0) / a.coef(k.c_w))
        c_de, t_de = a.coef(k.c_de), a.coef(k.t_de)
        g = a.at(pl.S) * a.at(pl.Ce) * inv_omega
        g = ti.select(g * c_de >= t_de, g, 0.0)
        a.put(pl.G, g)
        return g

    layers = Launch("layers", Stage(summation, ghosts=(pl.S,)), Stage(excitation, maxes="max_Ce"),
                    Stage(grouping, sums="sum_G"))
    return engine.model(pl, k, v, F.E, F.photoreceptors_of(pl, k, v), layers)


# -- F-LGMD ONn: LGMD1's network with instantaneous feedback, solved per frame as a fixed point ----------
# A channel's local summation S_X(X) = [G_e (*) X - w_i sum K (a X + (1 - a) X(t-1))]+ splits into the part
# the iteration changes and the constant rest: S_X(X) = [W_x (*) X - Q]+ with W_x = G_e - w_i a K (K's centre
# is 0) and Q = w_i sum K (1 - a) X(t-1), computed with the drives by the load.
#: F-LGMD: photoreceptors; the settled channels ``ON``, ``OFF`` (the fixed point of the last computed frame);
#: the drives ``ON0``, ``OFF0``; the constant inhibitions ``Q_on``, ``Q_off``; the iterates ``X_on``, ``X_off``
#: (ping-pong pairs: an update writes ``before``, and the solve's updates alternate them); the layers at the
#: fixed point.
FLGMD_PLANES = Planes("L P ON OFF ON0 OFF0 Q_on Q_off X_on:2 X_off:2 S_on S_off S G")
#: The input stage's ``clip``, ``dc``; the edge and diagonal weights ``w_i K (1 - a)`` of ``Q`` (ON, OFF);
#: the iterate's start ``(w, kappa)`` of ON and OFF; the stencils ``W_x`` (centre, edge, diagonal) of ON and
#: OFF; the feedback gains ``beta`` (ON, OFF); the summation threshold ``t_s``.
FLGMD_COEFS = Coefs(clip=1, dc=1, q_on=2, q_off=2, start_on=2, start_off=2, w_on=3, w_off=3, beta=2, t_s=1)
#: The load's ``scale``, ``keep``; the solve's updates at most, tolerance and growth limit.
FLGMD_SCALARS = Scalars("scale keep updates tol grow")


@functools.lru_cache(maxsize=None)
def flgmd(ti, lanes: int) -> SimpleNamespace:
    """F-LGMD's launches: ``load`` (result ``sum_p``), the solve ``solve`` (update residuals of ON and OFF; when
    it converges the layers, result ``sum_G``) and ``finish`` (the layers of an unconverged solve)."""
    F = _family(ti, lanes)
    pl, k, v = FLGMD_PLANES, FLGMD_COEFS, FLGMD_SCALARS
    mean9 = F.mean9_of(pl.S)
    #: each channel's drive, constant inhibition, stencil, ``Q``'s weights, start, feedback gain (by index),
    #: settled plane and iterate
    channel = {"ON": (pl.ON0, pl.Q_on, k.w_on, k.q_on, k.start_on, 0, pl.ON, pl.X_on),
               "OFF": (pl.OFF0, pl.Q_off, k.w_off, k.q_off, k.start_off, 1, pl.OFF, pl.X_off)}

    def local_of(name: str):
        """``(X, S_X = [W_x (*) X - Q]+)`` of channel ``name``'s iterate (its ``W_x``, ``Q``): a ti.func of ``a``."""
        q, w, x = channel[name][1], channel[name][2], channel[name][7]

        @ti.func
        def local(a: ti.template()):
            c, e, d = a.window3(x)
            return c, ti.max(a.coef(w, 0) * c + a.coef(w, 1) * e + a.coef(w, 2) * d - a.at(q), 0.0)

        return local

    def inputs(name: str):
        """The drive, ``Q`` and the iterate's start of the channel ``name`` from its drive (a ti.func of
        ``(a, drive)``)."""
        x0, q, w, qk, sk, b, settled, start = channel[name]

        @ti.func
        def prepare(a: ti.template()):
            """``Q = w_i sum K (1 - a) X(t-1)`` and the start ``X0 + kappa [w X0 - Q]+`` (:meth:`local_start_gains`)
            from the drive ``X0`` just written."""
            drive = a.at(x0)
            c, e, d = a.window3(settled)
            qv = 0.0 * c + a.coef(qk, 0) * e + a.coef(qk, 1) * d
            a.put(q, qv)
            a.put(start, drive + a.coef(sk, 1) * ti.max(a.coef(sk, 0) * drive - qv, 0.0))

        return prepare

    prepare_on, prepare_off = inputs("ON"), inputs("OFF")
    channels = F.channels_of(pl, k, v, pl.ON, pl.OFF)

    @ti.func
    def load(a: ti.template()):
        """The photoreceptors, the drives, ``Q`` and the iterates' start; returns ``|P|``."""
        on, off, drive = channels(a)
        a.put(pl.ON0, on)
        a.put(pl.OFF0, off)
        prepare_on(a)
        prepare_off(a)
        return drive

    def relax_of(name: str):
        """One update of channel ``name``'s iterate (a ti.func of ``a``; returns ``|T(X) - X|``)."""
        x0, b, local, it = channel[name][0], channel[name][5], local_of(name), channel[name][7]

        @ti.func
        def relax(a: ti.template()):
            """``X_before = X + mom (X - X_before) + lam (T(X) - X)``, ``T(X) = [X0 + beta S_X(X)]+``."""
            x, s = local(a)
            d = ti.max(a.at(x0) + a.coef(k.beta, b) * s, 0.0) - x
            a.put(it.before, x + a.record(1) * (x - a.at(it.before)) + a.record(0) * d)
            return F.lane_abs(d)

        return relax

    relax_on, relax_off = relax_of("ON"), relax_of("OFF")

    def update_of(with_off: bool):
        """The update stage: ON, and OFF where ``with_off`` (else OFF is its drive: residual 0)."""

        @ti.func
        def update(a: ti.template()):
            """One update of ON (and OFF); returns their residuals."""
            r_on, r_off = relax_on(a), a.zeros()
            if ti.static(with_off):
                r_off = relax_off(a)
            return r_on, r_off

        return update

    def settle_of(name: str):
        """Channel ``name``'s fixed point in its iterate, kept as its settled value; a ti.func of ``a`` returning
        its ``S_X``."""
        local, settled = local_of(name), channel[name][6]

        @ti.func
        def settle(a: ti.template()):
            c, s = local(a)
            a.put(settled, c)
            return s

        return settle

    settle_on, settle_off = settle_of("ON"), settle_of("OFF")

    @ti.func
    def layers(a: ti.template()):
        """``S_on``, ``S_off`` and ``S = S_on + S_off`` (kept where ``>= t_s``) at the fixed point."""
        s_on, s_off = settle_on(a), settle_off(a)
        a.put(pl.S_on, s_on)
        a.put(pl.S_off, s_off)
        s = s_on + s_off
        a.put(pl.S, ti.select(s >= a.coef(k.t_s), s, 0.0))

    @ti.func
    def grouping(a: ti.template()):
        """``G = S (*) ones/9``; returns it (summed)."""
        g = mean9(a)
        a.put(pl.G, g)
        return g

    after = (Stage(layers, ghosts=(pl.S, pl.ON, pl.OFF)), Stage(grouping, sums="sum_G"))
    #: the solve iterating ON and OFF, and ``solve_on`` where OFF is its drive (no update of its own)
    both = Stage(update_of(True), residuals=2, turns=(pl.X_on, pl.X_off), ghosts=(pl.X_on.before, pl.X_off.before))
    on = Stage(update_of(False), residuals=2, turns=(pl.X_on,), ghosts=(pl.X_on.before,))
    load_launch = Launch("load", Stage(load, sums="sum_p", ghosts=(pl.X_on, pl.X_off)))
    return engine.model(pl, k, v, F.E, load_launch, Launch("solve", *after, update=(both,), scalars=v),
                        Launch("solve_on", *after, update=(on,), scalars=v), Launch("finish", *after))
