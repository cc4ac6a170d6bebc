"""EMD-LPLC2's stages (Zhao et al. 2023): elementary motion detectors and the LPLC2 array (float32 planes).

Two launches, run by the engine (:mod:`cdnf_ti.kernels.engine`) in either layout:

1. ``store`` (the first frame): luminance ``L = frame / denom``.
2. ``frame`` (every later one):

   * ``filters``: ``F_h = b (L - L(t-1)) + b F_h(t-1)``, ``ON = [F_h - on_t]^+``, ``OFF = [off_t - F_h]^+``,
     ``F_d = a X + (1 - a) F_d(t-1)`` for X = ON, OFF;
   * ``motion``: the opponent motion of every detector pair on the (H-1, W-1) grid (ON and OFF summed):
     ``horizontal = leftward - rightward``, ``vertical = upward - downward`` (0 on the last row and column);
   * ``column_runs``, ``columns``, ``arms``: the four radial-opponent half-plane arms of every unit as separable
     window sums (a column pass, then a row pass; zero outside the grid), each kept where ``> arm_t``, and
     ``lplc2 = |their product|`` where at least ``min_arms`` of them exceed ``strong_t`` (the unit rule: arena
     ``arm_t = strong_t = 2``, ``min_arms = 4``, i.e. the plain product; real-environment ``arm_t = -2``,
     ``strong_t = 1.5``, ``min_arms = 3``); results ``active`` (units > 0), then, picked at the centre unit, its
     response ``core`` and its four arms ``left``, ``right``, ``up``, ``down``.

The pixel layout sums every window in float64. The lane layout sums in float32: a column window from sums of runs
of :data:`RUN` rows (``column_runs``) and single rows, a row window as the difference of two in-element prefix sums
(the engine's ``put_prefix`` / ``row_sum``). The window geometry (``half``, ``before``, ``after``) is compile-time
(the model's ``kernel_options()``); the row pass reads up to ``reach`` columns either side (the engine's ghosts).
The giant fibre is the model's (:class:`cdnf_ti.models.lplc2.LPLC2`). The float64 oracle:
:class:`cdnf_ti.lplc2_reference.LPLC2Reference`.
"""

import functools
from types import SimpleNamespace

from . import engine
from .engine import Coefs, Launch, Planes, Scalars, Stage

# "_": scratch, not among the fields: luminance, high-pass, delayed ON / OFF, the column passes, the runs
PLANES = Planes("_L _Fh _Fon _Foff horizontal vertical _h_band _up_cols _down_cols left right up down lplc2 "
                "_hor_end _hor_start _ver_end _ver_start")
#: High-pass ``b``, low-pass ``a``, ON / OFF thresholds; the unit rule: an arm is kept above ``arm_t``, a unit needs
#: ``min_arms`` arms above ``strong_t``; the grid (rows, columns) and its centre unit.
COEFS = Coefs(b_high=1, a_low=1, on_t=1, off_t=1, arm_t=1, strong_t=1, min_arms=1, grid=2, core=2)
#: The frame's grey scale: ``L = frame / denom``.
SCALARS = Scalars("denom")
(L, FH, FD_ON, FD_OFF, HOR, VER, H_BAND, UP_COLS, DOWN_COLS, LEFT, RIGHT, UP, DOWN, LPLC2, *RUNS) = PLANES
#: The lane layout's runs of each motion map: (the sums of RUN rows ending here, starting here).
RUNS_OF = {plane.name: (RUNS[2 * k], RUNS[2 * k + 1]) for k, plane in enumerate((HOR, VER))}
#: Rows per run of the lane layout's column pass: a window is whole runs (their sums) and single rows.
RUN = 8
K, V = COEFS, SCALARS


def runs(k0: int, k1: int) -> list[range]:
    """``k0 .. k1`` in ranges of at most 32 (nested ``ti.static`` loops: the compilers warn on longer ones)."""
    return [range(k, min(k + 32, k1 + 1)) for k in range(k0, k1 + 1, 32)]


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """EMD-LPLC2's launches for the DSL module ``ti``: the stages below, bound to the engine."""

    @ti.func
    def on_off(f_h, on_t, off_t):
        """ON ``= [F_h - on_t]^+`` and OFF ``= [off_t - F_h]^+``."""
        return ti.max(f_h - on_t, 0.0), ti.max(off_t - f_h, 0.0)

    @ti.func
    def store(a: ti.template()):
        """The first frame: ``L`` only."""
        a.put(L, a.grey() / a.value(V.denom))

    @ti.func
    def filters(a: ti.template()):
        """The photoreceptor high-pass ``F_h`` and the delay low-passes ``F_d`` of ON and OFF; ``L``."""
        g = a.grey() / a.value(V.denom)
        b, lp = a.coef(K.b_high), a.coef(K.a_low)
        h = b * (g - a.at(L)) + b * a.at(FH)
        on, off = on_off(h, a.coef(K.on_t), a.coef(K.off_t))
        a.put(FH, h)
        a.put(FD_ON, lp * on + (1.0 - lp) * a.at(FD_ON))
        a.put(FD_OFF, lp * off + (1.0 - lp) * a.at(FD_OFF))
        a.put(L, g)

    @ti.func
    def grid(a: ti.template()):
        """1 on the (H-1, W-1) unit grid, 0 on the frame's last row and column."""
        return a.within(0, ti.cast(a.coef(K.grid, 0), ti.i32), 0, ti.cast(a.coef(K.grid, 1), ti.i32))

    @ti.func
    def motion(a: ti.template()):
        """``horizontal = leftward - rightward``, ``vertical = upward - downward`` of the grid point here."""
        on_t, off_t = a.coef(K.on_t), a.coef(K.off_t)
        on0, off0 = on_off(a.at(FH), on_t, off_t)
        on_r, off_r = on_off(a.at(FH, 0, 1), on_t, off_t)
        on_d, off_d = on_off(a.at(FH, 1, 0), on_t, off_t)
        left = on0 * a.at(FD_ON, 0, 1) + off0 * a.at(FD_OFF, 0, 1)
        right = a.at(FD_ON) * on_r + a.at(FD_OFF) * off_r
        up = on0 * a.at(FD_ON, 1, 0) + off0 * a.at(FD_OFF, 1, 0)
        down = a.at(FD_ON) * on_d + a.at(FD_OFF) * off_d
        inside = grid(a)
        a.put(HOR, (left - right) * inside)
        a.put(VER, (up - down) * inside)

    @ti.func
    def column_window(a: ti.template(), plane: ti.template(), offsets: ti.template()):
        """``sum_k plane`` at the row ``offsets`` (a range ``k0 .. k1``) as float32, summed in float64 on the pixel
        layout; on the lane layout in float32 from whole runs of :data:`RUN` rows (:func:`column_runs`) and the rows
        left over: runs ending at or before the cell for offsets <= 0, runs starting after it for offsets > 0 (a
        run read outside the frame then lies wholly outside it: 0, as its zero border gives)."""
        s = a.zeros()
        k0, k1 = ti.static(offsets.start, offsets.stop - 1)
        if ti.static(a.lane):
            end, start = ti.static(RUNS_OF[plane.name])
            if ti.static(k0 <= 0):
                lo = ti.static(min(k1, 0))
                whole = ti.static((lo - k0 + 1) // RUN)
                for q in ti.static(range(whole)):
                    s += a.at(end, lo - q * RUN)
                for k in ti.static(range(k0, lo - whole * RUN + 1)):
                    s += a.at(plane, k)
            if ti.static(k1 > 0):
                hi = ti.static(max(k0, 1))
                whole = ti.static((k1 - hi + 1) // RUN)
                for q in ti.static(range(whole)):
                    s += a.at(start, hi + q * RUN)
                for k in ti.static(range(hi + whole * RUN, k1 + 1)):
                    s += a.at(plane, k)
        else:
            s64 = ti.f64(0.0)
            for run in ti.static(runs(k0, k1)):
                for k in ti.static(run):
                    s64 += ti.cast(a.at(plane, k), ti.f64)
            s = ti.cast(s64, ti.f32)
        return s

    @ti.func
    def column_runs(a: ti.template()):
        """The lane layout's sums of :data:`RUN` rows ending here and starting here, of the motion maps."""
        if ti.static(a.lane):
            for plane in ti.static((HOR, VER)):
                end, start = ti.static(RUNS_OF[plane.name])
                ending, starting = a.zeros(), a.zeros()
                for k in ti.static(range(RUN)):
                    ending += a.at(plane, k - RUN + 1)
                    starting += a.at(plane, k)
                a.put(end, ending)
                a.put(start, starting)

    @ti.func
    def columns(a: ti.template()):
        """The column passes: ``horizontal`` over the band rows, ``vertical`` over the half-fields above (up) and
        below (down, negated); kept for the row passes (:meth:`put_prefix`)."""
        half, before, after = ti.static(a.option("half"), a.option("before"), a.option("after"))
        a.put_prefix(H_BAND, column_window(a, HOR, ti.static(range(-before, after + 1))))
        a.put_prefix(UP_COLS, column_window(a, VER, ti.static(range(1 - half, 1))))
        a.put_prefix(DOWN_COLS, 0.0 - column_window(a, VER, ti.static(range(1, half + 1))))

    @ti.func
    def kept(arm, threshold):
        """The arm where ``> threshold``, else 0."""
        return ti.select(arm > threshold, arm, 0.0)

    @ti.func
    def arms(a: ti.template()):
        """The row passes: the four kept arms and the unit rule (``|their product|`` where at least ``min_arms`` of
        them are strong); returns whether the unit is active, picks the centre unit's response and arms."""
        half, before, after = ti.static(a.option("half"), a.option("before"), a.option("after"))
        thr, at, inside = a.coef(K.arm_t), a.coef(K.strong_t), grid(a)
        left = kept(a.row_sum(H_BAND, 1 - half, 0), thr)
        right = kept(0.0 - a.row_sum(H_BAND, 1, half), thr)
        up = kept(a.row_sum(UP_COLS, -before, after), thr)
        down = kept(a.row_sum(DOWN_COLS, -before, after), thr)
        n = (ti.select(left > at, 1.0, 0.0) + ti.select(right > at, 1.0, 0.0) + ti.select(up > at, 1.0, 0.0)
             + ti.select(down > at, 1.0, 0.0))  # the strong arms
        q = left * right * up * down
        p = ti.max(q, 0.0 - q) * ti.select(n >= a.coef(K.min_arms), inside, 0.0)  # |q| where n is enough
        cy, cx = ti.cast(a.coef(K.core, 0), ti.i32), ti.cast(a.coef(K.core, 1), ti.i32)
        a.put(LEFT, left * inside)
        a.put(RIGHT, right * inside)
        a.put(UP, up * inside)
        a.put(DOWN, down * inside)
        a.put(LPLC2, p)
        a.pick("core", p, cy, cx)
        a.pick("left", left, cy, cx)
        a.pick("right", right, cy, cx)
        a.pick("up", up, cy, cx)
        a.pick("down", down, cy, cx)
        return ti.select(p > 0.0, 1.0, 0.0)

    first = Launch("store", Stage(store))
    frame = Launch("frame", Stage(filters, ghosts=(FH, FD_ON, FD_OFF)), Stage(motion), Stage(column_runs),
                   Stage(columns), Stage(arms, sums="active", picks="core left right up down", halo="reach"))
    return engine.model(PLANES, COEFS, SCALARS, engine.build(ti, lanes), first, frame)
