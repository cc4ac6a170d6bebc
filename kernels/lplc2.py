"""Taichi kernels of EMD-LPLC2 (Zhao et al. 2023): elementary motion detectors and the LPLC2 array.

Per frame (float32 state):

* :func:`emd_step` (one launch): photoreceptor high-pass ``F_h``, ON/OFF rectification, delay low-pass
  ``F_d`` per pixel, then the opponent motion of every detector pair on the (H-1, W-1) grid:
  ``horizontal = leftward - rightward``, ``vertical = upward - downward`` (ON and OFF summed);
* :func:`lplc2_columns` and :func:`lplc2_arms` (two launches): the four radial-opponent half-plane arms of every
  LPLC2 unit as separable window sums (:mod:`cdnf_ti.kernels.pooling`), each kept where it
  exceeds the arm threshold, their product (the unit's response), the active-unit count and
  the centre unit's arms.

Two paths compute the same equations: the generic kernels on (H, W) arrays (every arch; the
pooling's running sums in float64) and the ``lanes_*`` kernels on lane arrays (the fast CPU path,
explicit vector types; :mod:`cdnf_ti.kernels.pooling`'s lane layout with ``G`` ghost elements either
side, ``coef[GHOSTS]``).

The giant fibre (a scalar LIF) is the model's (:class:`cdnf_ti.models.lplc2.LPLC2`). The float64
oracle: :class:`cdnf_ti.lplc2_reference.LPLC2Reference`.

Coefficients travel in one float64 array ``coef`` (:data:`COEF`), filled by the backend.
"""

import functools
from types import SimpleNamespace

from ..taichi_runtime import vector_kernel
from . import common, pooling
from .common import namespace

#: Slots of the coefficient array: high-pass b, low-pass a, ON and OFF thresholds, arm threshold,
#: receptive-field half side, band before/after the centre, the centre unit (row, column), the lane
#: arrays' ghost elements either side, the unit grid's columns (W - 1).
COEF = ("b_high", "a_low", "on_threshold", "off_threshold", "arm_threshold", "half_side", "band_before",
        "band_after", "core_row", "core_col", "ghosts", "grid_cols")
B_HIGH, A_LOW, ON_T, OFF_T, ARM_T, HALF, BEFORE, AFTER, CORE_R, CORE_C, GHOSTS, GRID_COLS = range(len(COEF))
#: The lane kernels' stacked maps: the column passes (``bands``), their in-element prefixes, and the
#: thresholded arms with the units' responses (``maps``).
BANDS = ("h_band", "up_cols", "down_cols")
MAPS = ("left", "right", "up", "down", "lplc2")
#: Slots of a pooling launch's results ``out``: active units, the centre unit's response and its four arms.
OUT = ("active", "core", "left", "right", "up", "down")


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The kernels of this module for the DSL module ``ti`` (taichi or quadrants) and ``lanes`` float32
    columns per lane vector of the fast path: a namespace of every name below (and the module-level
    constants). Built once per (compiler, lanes), after the runtime started."""
    LANES = lanes
    C = common.build(ti, lanes)
    LANE2, LANE3 = C.LANE2, C.LANE3
    P = pooling.build(ti, lanes)
    column_window, row_window = P.column_window, P.row_window
    lane_column_block, lane_prefix, lane_window = P.lane_column_block, P.lane_prefix, P.lane_window

    F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    D1 = ti.types.ndarray(dtype=ti.f64, ndim=1)

    @ti.func
    def on_off(f_h, on_t, off_t):
        """ON ``= [F_h - on_t]^+`` and OFF ``= [off_t - F_h]^+`` of a high-passed signal (scalar or lane vector)."""
        return ti.max(f_h - on_t, 0.0), ti.max(off_t - f_h, 0.0)

    @ti.func
    def temporal_filters(f_h, fd_on, fd_off, lum, lum_prev, b, a, on_t, off_t):
        """One frame of a pixel's filters: ``F_h = b (L - L_prev) + b F_h``, then ``F_d = a X + (1 - a) F_d``
        for X = ON, OFF. Returns the new ``(F_h, F_d_on, F_d_off)``."""
        h = b * (lum - lum_prev) + b * f_h
        on, off = on_off(h, on_t, off_t)
        return h, a * on + (1.0 - a) * fd_on, a * off + (1.0 - a) * fd_off

    @ti.func
    def opponent_motion(f_h: ti.template(), fd_on: ti.template(), fd_off: ti.template(), y, x, on_t, off_t):
        """``(leftward - rightward, upward - downward)`` of grid point (y, x), ON and OFF summed."""
        on0, off0 = on_off(f_h[y, x], on_t, off_t)
        on_r, off_r = on_off(f_h[y, x + 1], on_t, off_t)
        on_d, off_d = on_off(f_h[y + 1, x], on_t, off_t)
        left = on0 * fd_on[y, x + 1] + off0 * fd_off[y, x + 1]
        right = fd_on[y, x] * on_r + fd_off[y, x] * off_r
        up = on0 * fd_on[y + 1, x] + off0 * fd_off[y + 1, x]
        down = fd_on[y, x] * on_d + fd_off[y, x] * off_d
        return left - right, up - down

    @ti.kernel
    def emd_step(frame: ti.types.ndarray(ndim=2), lum: F2, f_h: F2, fd_on: F2, fd_off: F2, horizontal: F2,
                 vertical: F2, coef: D1, denom: ti.f32, first: ti.i32):
        """Luminance ``frame / denom``; on the ``first`` frame only stored in ``lum``, else the temporal
        filters of every pixel (``f_h``, ``fd_on``, ``fd_off``, (H, W)) and the opponent motion maps
        ``horizontal``, ``vertical`` ((H-1, W-1))."""
        b, a = ti.cast(coef[B_HIGH], ti.f32), ti.cast(coef[A_LOW], ti.f32)
        on_t, off_t = ti.cast(coef[ON_T], ti.f32), ti.cast(coef[OFF_T], ti.f32)
        for y, x in lum:
            g = ti.cast(frame[y, x], ti.f32) / denom
            if first == 0:
                f_h[y, x], fd_on[y, x], fd_off[y, x] = temporal_filters(f_h[y, x], fd_on[y, x], fd_off[y, x], g,
                                                                        lum[y, x], b, a, on_t, off_t)
            lum[y, x] = g
        for y, x in horizontal:  # a top-level loop (parallel); nothing to do on the first frame
            if first == 0:
                horizontal[y, x], vertical[y, x] = opponent_motion(f_h, fd_on, fd_off, y, x, on_t, off_t)

    @ti.kernel
    def lplc2_columns(horizontal: F2, vertical: F2, h_band: F2, up_cols: F2, down_cols: F2, coef: D1):
        """The column passes of the arms: ``h_band`` = ``horizontal`` summed over the band rows
        (y - before .. y + after); ``up_cols`` = ``vertical`` over rows y - half + 1 .. y;
        ``down_cols`` = ``-vertical`` over rows y + 1 .. y + half."""
        hs = ti.cast(coef[HALF], ti.i32)
        lo, hi = -ti.cast(coef[BEFORE], ti.i32), ti.cast(coef[AFTER], ti.i32)
        for x in range(horizontal.shape[1]):
            column_window(horizontal, h_band, x, lo, hi, 1.0)
            column_window(vertical, up_cols, x, 1 - hs, 0, 1.0)
            column_window(vertical, down_cols, x, 1, hs, -1.0)

    @ti.func
    def unit_response(left, right, up, down, threshold):
        """The thresholded arms (each kept where ``> threshold``, else 0) and their product."""
        l_ = ti.select(left > threshold, left, 0.0)
        r_ = ti.select(right > threshold, right, 0.0)
        u_ = ti.select(up > threshold, up, 0.0)
        d_ = ti.select(down > threshold, down, 0.0)
        return l_, r_, u_, d_, l_ * r_ * u_ * d_

    @ti.kernel
    def lplc2_arms(h_band: F2, up_cols: F2, down_cols: F2, left: F2, right: F2, up: F2, down: F2, lplc2: F2,
                   coef: D1, out: D1):
        """The row passes: the four arms of every unit (left: ``h_band`` over columns x - half + 1 .. x; right:
        ``-h_band`` over x + 1 .. x + half; up, down: ``up_cols``, ``down_cols`` over the band columns),
        thresholded in place, and ``lplc2`` their product. Adds the active units (response > 0) to
        ``out[0]`` and writes the centre unit's response and arms to ``out[1:6]`` (set to 0 by the caller)."""
        hs = ti.cast(coef[HALF], ti.i32)
        lo, hi = -ti.cast(coef[BEFORE], ti.i32), ti.cast(coef[AFTER], ti.i32)
        thr = ti.cast(coef[ARM_T], ti.f32)
        cy, cx = ti.cast(coef[CORE_R], ti.i32), ti.cast(coef[CORE_C], ti.i32)
        for y in range(h_band.shape[0]):
            row_window(h_band, left, y, 1 - hs, 0, 1.0)
            row_window(h_band, right, y, 1, hs, -1.0)
            row_window(up_cols, up, y, lo, hi, 1.0)
            row_window(down_cols, down, y, lo, hi, 1.0)
            count = 0
            for x in range(h_band.shape[1]):
                l_, r_, u_, d_, p = unit_response(left[y, x], right[y, x], up[y, x], down[y, x], thr)
                left[y, x], right[y, x], up[y, x], down[y, x], lplc2[y, x] = l_, r_, u_, d_, p
                count += ti.select(p > 0.0, 1, 0)
                if y == cy and x == cx:
                    out[1], out[2], out[3], out[4], out[5] = p, l_, r_, u_, d_
            ti.atomic_add(out[0], ti.cast(count, ti.f64))

    # -- the lane path ---------------------------------------------------------------------------

    @ti.func
    def _lane_grey(frame: ti.template(), i, k, denom):
        """Luminance ``frame / denom`` of the columns k LANES .. of row ``i`` (past the last column: repeated)."""
        g = ti.Vector([0.0] * LANES, dt=ti.f32)
        for l in ti.static(range(LANES)):
            g[l] = ti.cast(frame[i, ti.min(k * LANES + l, frame.shape[1] - 1)], ti.f32)
        return g / denom

    @ti.func
    def _grid_mask(k, width):
        """1.0 on the lanes of the k-th element whose column is below ``width``, else 0.0."""
        m = ti.Vector([1.0] * LANES, dt=ti.f32)
        for l in ti.static(range(LANES)):
            m[l] = ti.select(k * LANES + l < width, 1.0, 0.0)
        return m

    @ti.func
    def _lane_motion(f_h: ti.template(), fd_on: ti.template(), fd_off: ti.template(), i, e, on_t, off_t):
        """:func:`opponent_motion` of the LANES grid points of element ``(i, e)``."""
        on0, off0 = on_off(f_h[i, e], on_t, off_t)
        on_d, off_d = on_off(f_h[i + 1, e], on_t, off_t)
        on_n, off_n = on_off(f_h[i, e + 1][0], on_t, off_t)  # the column after the element
        _, on_r = C.lane_neighbours(0.0, on0, on_n)
        _, off_r = C.lane_neighbours(0.0, off0, off_n)
        _, fdn_r = C.lane_neighbours(0.0, fd_on[i, e], fd_on[i, e + 1][0])
        _, fdf_r = C.lane_neighbours(0.0, fd_off[i, e], fd_off[i, e + 1][0])
        left = on0 * fdn_r + off0 * fdf_r
        right = fd_on[i, e] * on_r + fd_off[i, e] * off_r
        up = on0 * fd_on[i + 1, e] + off0 * fd_off[i + 1, e]
        down = fd_on[i, e] * on_d + fd_off[i, e] * off_d
        return left - right, up - down

    @vector_kernel
    @ti.kernel
    def lanes_emd_step(frame: ti.types.ndarray(ndim=2), lum: LANE2, f_h: LANE2, fd_on: LANE2, fd_off: LANE2,
                       horizontal: LANE2, vertical: LANE2, coef: D1, denom: ti.f32, first: ti.i32):
        """:func:`emd_step` on lane arrays: state (H, NB), motion maps (H-1, NB), zero past column W-2."""
        b, a = ti.cast(coef[B_HIGH], ti.f32), ti.cast(coef[A_LOW], ti.f32)
        on_t, off_t = ti.cast(coef[ON_T], ti.f32), ti.cast(coef[OFF_T], ti.f32)
        G = ti.cast(coef[GHOSTS], ti.i32)
        H, W = frame.shape[0], frame.shape[1]
        E1 = lum.shape[1] - 2 * G
        for n in range(H * E1):
            i, k = n // E1, n % E1
            g = _lane_grey(frame, i, k, denom)
            if first == 0:
                f_h[i, G + k], fd_on[i, G + k], fd_off[i, G + k] = temporal_filters(
                    f_h[i, G + k], fd_on[i, G + k], fd_off[i, G + k], g, lum[i, G + k], b, a, on_t, off_t)
            lum[i, G + k] = g
        for n in range((H - 1) * E1):  # a top-level loop (parallel); nothing to do on the first frame
            i, k = n // E1, n % E1
            if first == 0:
                hm, vm = _lane_motion(f_h, fd_on, fd_off, i, G + k, on_t, off_t)
                mask = _grid_mask(k, W - 1)
                horizontal[i, G + k] = hm * mask
                vertical[i, G + k] = vm * mask

    @vector_kernel
    @ti.kernel
    def lanes_columns(horizontal: LANE2, vertical: LANE2, bands: LANE3, coef: D1):
        """:func:`lplc2_columns` on lane arrays: ``bands`` = (h_band, up_cols, down_cols), (3, H-1, NB)."""
        hs = ti.cast(coef[HALF], ti.i32)
        lo, hi = -ti.cast(coef[BEFORE], ti.i32), ti.cast(coef[AFTER], ti.i32)
        G = ti.cast(coef[GHOSTS], ti.i32)
        E1 = horizontal.shape[1] - 2 * G
        H, B = horizontal.shape[0], pooling.COLUMN_BLOCK
        for n in range((H + B - 1) // B * E1):
            i0, e = n // E1 * B, G + n % E1
            i1 = ti.min(i0 + B, H)
            lane_column_block(horizontal, bands, 0, i0, i1, e, lo, hi, 1.0)
            lane_column_block(vertical, bands, 1, i0, i1, e, 1 - hs, 0, 1.0)
            lane_column_block(vertical, bands, 2, i0, i1, e, 1, hs, -1.0)

    @ti.func
    def _lane_core(out: ti.template(), k, cx, arms: ti.template()):
        """Write the centre unit's (column ``cx``) response and arms to ``out[1:6]`` if element ``k`` holds it."""
        for l in ti.static(range(LANES)):
            if k * LANES + l == cx:
                for m in ti.static(range(5)):
                    out[1 + m] = arms[(m + 4) % 5][l]

    @vector_kernel
    @ti.kernel
    def lanes_arms(bands: LANE3, prefix: LANE3, maps: LANE3, coef: D1, out: D1, half: ti.template(),
                   before: ti.template(), after: ti.template()):
        """:func:`lplc2_arms` on lane arrays: ``prefix`` the in-element prefixes of ``bands`` (3, H-1, NB),
        ``maps`` the thresholded arms and responses (left, right, up, down, lplc2; (5, H-1, NB)); the
        window geometry (``half``, ``before``, ``after``) is compiled in."""
        thr = ti.cast(coef[ARM_T], ti.f32)
        cy, cx = ti.cast(coef[CORE_R], ti.i32), ti.cast(coef[CORE_C], ti.i32)
        G = ti.cast(coef[GHOSTS], ti.i32)
        E1 = bands.shape[2] - 2 * G
        width = ti.cast(coef[GRID_COLS], ti.i32)
        for i in range(bands.shape[1]):
            for e in range(G, G + E1):
                for m in ti.static(range(3)):
                    prefix[m, i, e] = lane_prefix(bands[m, i, e])
            count = ti.f64(0.0)
            for k in range(E1):
                e = G + k
                left = lane_window(prefix, 0, i, e, 1 - half, 0)
                arms = unit_response(left, -1.0 * lane_window(prefix, 0, i, e, 1, half),
                                     lane_window(prefix, 1, i, e, -before, after),
                                     lane_window(prefix, 2, i, e, -before, after), thr)
                mask = _grid_mask(k, width)  # the units of the grid's columns
                for m in ti.static(range(5)):
                    maps[m, i, e] = arms[m] * mask
                count += ti.cast((ti.select(arms[4] > 0.0, 1.0, 0.0) * mask).sum(), ti.f64)
                if i == cy:
                    _lane_core(out, k, cx, arms)
            ti.atomic_add(out[0], count)

    return namespace(globals(), locals())
