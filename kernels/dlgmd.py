"""D-LGMD's stages (LGMD with spatially-temporally distributed presynaptic connections; float32 layers).

One launch per frame, ``frame``, run by the engine (:mod:`cdnf_ti.kernels.engine`) in either layout:

1. ``difference``: the newest luminance difference ``D = keep |g - L(t-1)| / 255`` (grey levels ``g``), or
   ``D = p_on + p_off`` of an event bin; result ``sum D``.
2. ``row_passes``: ``R_w = sum_{|dj| <= w} e(dj) D(., dj)`` for each row half-width ``w`` the kernels need
   (``e(x) = exp(-x^2 / (2 sigma_I^2))``).
3. ``layers``: the column passes give the radius-``r`` square ``F = c e (*)_y R_r`` and the delay <= 1 disc
   ``Q = c e (*)_y R_w(di)`` of the inhibition Gaussian ``a G(sigma_I)``; the delay-0 cells' taps give the
   excitation ``E = K_E * D`` and ``N`` (``a G(sigma_I)`` on them). ``X_1 = Q - N`` (the delay-1 ring),
   ``X_2 = F - Q`` (the delay-2 surround). ``I = J``, ``S = [E - I]^+``, then ``J = X_1 + X_2(t-1)``,
   so that ``I(t) = K_1 * D(t-1) + K_2 * D(t-2)``; result ``sum S``.
4. ``group_rows``, ``grouping``: ``G = S (ones * S)`` over rows and columns ``lo .. hi``, zero below
   ``thresh_g``, clipped at 1; result ``sum G``.

Compile-time options (the model's ``kernel_options()``): ``radius`` ``r``, ``store`` (whether ``R_w`` is
kept, ``w = 0 .. r``), ``disc`` (the disc's half-width of each row ``-r .. r``, -1: none), ``cells`` (the
delay-0 cells ``(di, dj)``), ``group`` (``lo, hi``) and ``group_halo``. The coefficient ``taps`` holds
``e(0 .. r)``, ``c e(-r .. r)``, ``K_E`` and ``N`` of the cells. Borders are zero (MATLAB ``conv2 'same'``).
The NumPy float64 oracle is :mod:`cdnf_ti.dlgmd_reference`.
"""

import functools
from types import SimpleNamespace

from . import engine
from .engine import Coefs, Launch, Planes, Scalars, Stage

#: The largest kernel radius: one row-pass plane ``_R0 .. _R8`` per half-width.
MAX_RADIUS = 8
PLANES = Planes("L D E I S G _J _X2 _T " + " ".join(f"_R{w}" for w in range(MAX_RADIUS + 1)))
COEFS = Coefs(taps=0)
#: Grey scale (1 for uint8, 255 for float), whether ``L(t-1)`` exists, the grouping threshold ``T_G``.
SCALARS = Scalars("scale keep thresh_g")
L, D, E, I, S, G, J, X2, T = list(PLANES)[:9]
ROWS = tuple(list(PLANES)[9:])
K, V = COEFS, SCALARS


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """D-LGMD's launch for the DSL module ``ti``: the stages below, bound to the engine."""

    @ti.func
    def difference(a: ti.template()):
        """``D`` from the frame or an event bin; returns it (summed)."""
        d = a.zeros()
        if ti.static(a.events):
            d = a.event(0) + a.event(1)
        else:
            g = ti.floor(a.grey() * a.value(V.scale) + 0.5)
            p = g - a.at(L)
            d = a.value(V.keep) * ti.max(p, 0.0 - p) * (1.0 / 255.0)
            a.put(L, g)
        a.put(D, d)
        return d

    @ti.func
    def row_passes(a: ti.template()):
        """``R_w``: the taps ``e(0 .. w)`` along the row of ``D``, summed outwards, kept where ``store``."""
        R, store = ti.static(a.option("radius"), a.option("store"))
        acc = a.coef(K.taps, 0) * a.at(D)
        if ti.static(store[0]):
            a.put(ROWS[0], acc)
        for w in ti.static(range(1, R + 1)):
            acc += a.coef(K.taps, w) * (a.at(D, 0, -w) + a.at(D, 0, w))
            if ti.static(store[w]):
                a.put(ROWS[w], acc)

    @ti.func
    def layers(a: ti.template()):
        """``E``, ``I``, ``S`` and the next frame's ``J``; returns ``S`` (summed)."""
        R, disc, cells = ti.static(a.option("radius"), a.option("disc"), a.option("cells"))
        M = ti.static(len(a.option("cells")))
        full, inner, e, near = a.zeros(), a.zeros(), a.zeros(), a.zeros()
        for q in ti.static(range(2 * R + 1)):
            c = a.coef(K.taps, R + 1 + q)
            full += c * a.at(ROWS[R], q - R, 0)
            if ti.static(disc[q] >= 0):
                inner += c * a.at(ROWS[disc[q]], q - R, 0)
        for n in ti.static(range(M)):
            v = a.at(D, cells[n][0], cells[n][1])
            e += a.coef(K.taps, 3 * R + 2 + n) * v
            near += a.coef(K.taps, 3 * R + 2 + M + n) * v
        i = a.at(J)
        s = ti.max(e - i, 0.0)
        a.put(E, e)
        a.put(I, i)
        a.put(S, s)
        a.put(J, inner - near + a.at(X2))  # X_1(t) + X_2(t-1): the next frame's I
        a.put(X2, full - inner)
        return s

    @ti.func
    def group_rows(a: ti.template()):
        """``T``: ``S`` summed over the columns ``lo .. hi``."""
        lo, hi = ti.static(a.option("group"))
        t = a.zeros()
        for dj in ti.static(range(lo, hi + 1)):
            t += a.at(S, 0, dj)
        a.put(T, t)

    @ti.func
    def grouping(a: ti.template()):
        """``G = S (sum of T over the rows lo .. hi)``, 0 below ``T_G``, at most 1; returns it (summed)."""
        lo, hi = ti.static(a.option("group"))
        t = a.zeros()
        for di in ti.static(range(lo, hi + 1)):
            t += a.at(T, di, 0)
        g = a.at(S) * t
        g = ti.min(ti.select(g < a.value(V.thresh_g), 0.0, g), 1.0)
        a.put(G, g)
        return g

    frame = Launch("frame", Stage(difference, sums="sum_D", ghosts=(D,), halo="radius"), Stage(row_passes),
                   Stage(layers, sums="sum_S", ghosts=(S,), halo="group_halo"), Stage(group_rows),
                   Stage(grouping, sums="sum_G"))
    return engine.model(PLANES, COEFS, SCALARS, engine.build(ti, lanes), frame)
