"""Wide pooling on (H, W) arrays: window sums along columns and rows, and a separable box sum.

Model-agnostic helpers for receptive fields wider than a 3x3 stencil (EMD-LPLC2's
half-plane arms pool 40x50 px). A window sum

    out(y, x) = sign * sum_{k = k0 .. k1} src(y + k, x)      (along columns)
    out(y, x) = sign * sum_{k = k0 .. k1} src(y, x + k)      (along rows)

takes zero outside the array (``k0 <= k1`` any integers: a window need not contain its
own pixel). Each line is swept once with a float64 running sum (add the sample that
enters, subtract the one that leaves), so a window costs O(1) per pixel whatever its
size, and the sum keeps float64 precision over the line (no float32 prefix sums whose
differences lose the digits of a small window beside a large total). A 2-D box sum is a
column pass then a row pass (:func:`box_sum`). NumPy check: ``tests/test_pooling.py``.

The ``ti.func``s sweep one line; a kernel calls them inside its parallel loop over lines
(one line per work item: columns for :func:`column_window`, rows for :func:`row_window`).

**Lane arrays** (the fast CPU path; explicit vector types, ``LANES`` float32 columns per element,
:func:`lane_layout`): a row of ``W`` columns is ``E1 = ceil(W / LANES)`` elements with ``G`` zero
ghost elements either side, element ``G + k`` holding columns ``k LANES .. k LANES + LANES - 1``;
columns past ``W - 1`` hold 0. Along columns (:func:`lane_column_sum`) a window is a direct sum of
rows, vectorised across the lanes. Along rows, :func:`lane_prefix` turns each element into its
inclusive in-element prefix sums, and :func:`lane_window` takes a window's sum as the difference of
two prefixes, each the in-element prefix at the window's end plus the totals of the whole elements
between it and the current one (a few local numbers, never a running total of the row, so float32
keeps the digits of a small window). Windows along rows reach at most ``(G - 1) LANES`` columns
(:func:`ghost_elements`).
"""

import functools
from types import SimpleNamespace

from ..taichi_runtime import vector_kernel
from . import common
from .common import namespace

#: Rows per work item of the lane column passes (:func:`lane_column_block`).
COLUMN_BLOCK = 8


def ghost_elements(reach: int, lanes: int) -> int:
    """Ghost elements either side of a lane row for row windows whose prefix reads (:func:`lane_window`: the
    window's end ``k1`` and the column before its start, ``k0 - 1``) lie at most ``reach`` columns away."""
    return int(reach) // lanes + 2


def lane_layout(width: int, lanes: int, ghosts: int) -> tuple[int, int]:
    """``(E1, NB)``: elements holding the ``width`` columns, elements per row with ``ghosts`` either side."""
    e1 = max(1, -(-int(width) // lanes))
    return e1, e1 + 2 * ghosts


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The helpers of this module for the DSL module ``ti`` (taichi or quadrants) and ``lanes`` float32
    columns per lane vector: a namespace of every name below (and the module-level constants)."""
    LANES = lanes
    C = common.build(ti, lanes)
    LANE2 = C.LANE2
    F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)

    @ti.func
    def _tap(src: ti.template(), y, x, ok):
        """``src[y, x]`` as float64 where ``ok``, else 0 (the index clamped so the load stays inside)."""
        yc = ti.min(ti.max(y, 0), src.shape[0] - 1)
        xc = ti.min(ti.max(x, 0), src.shape[1] - 1)
        return ti.select(ok, ti.cast(src[yc, xc], ti.f64), ti.f64(0.0))

    @ti.func
    def column_window(src: ti.template(), dst: ti.template(), x, k0, k1, sign):
        """Column ``x`` of ``dst``: ``dst[y, x] = sign * sum_{k=k0..k1} src[y + k, x]`` for every row ``y``
        (rows outside ``src`` count 0). ``src``, ``dst``: (H, W) arrays; float64 running sum."""
        H = src.shape[0]
        s = ti.f64(0.0)
        for r in range(ti.max(k0, 0), ti.min(k1, H - 1) + 1):  # the window of row 0
            s += ti.cast(src[r, x], ti.f64)
        dst[0, x] = sign * s
        for y in range(1, H):
            enter, leave = y + k1, y + k0 - 1
            s += _tap(src, enter, x, (enter >= 0) & (enter < H)) - _tap(src, leave, x, (leave >= 0) & (leave < H))
            dst[y, x] = sign * s

    @ti.func
    def row_window(src: ti.template(), dst: ti.template(), y, k0, k1, sign):
        """Row ``y`` of ``dst``: ``dst[y, x] = sign * sum_{k=k0..k1} src[y, x + k]`` for every column ``x``
        (columns outside ``src`` count 0). ``src``, ``dst``: (H, W) arrays; float64 running sum."""
        W = src.shape[1]
        s = ti.f64(0.0)
        for c in range(ti.max(k0, 0), ti.min(k1, W - 1) + 1):  # the window of column 0
            s += ti.cast(src[y, c], ti.f64)
        dst[y, 0] = sign * s
        for x in range(1, W):
            enter, leave = x + k1, x + k0 - 1
            s += _tap(src, y, enter, (enter >= 0) & (enter < W)) - _tap(src, y, leave, (leave >= 0) & (leave < W))
            dst[y, x] = sign * s

    @ti.kernel
    def box_sum(src: F2, tmp: F2, dst: F2, r0: ti.i32, r1: ti.i32, c0: ti.i32, c1: ti.i32, sign: ti.f64):
        """``dst(y, x) = sign * sum src(y + r0 .. y + r1, x + c0 .. x + c1)``, zero outside; ``tmp`` (same
        shape) holds the column pass. All (H, W) float32."""
        for x in range(src.shape[1]):
            column_window(src, tmp, x, r0, r1, 1.0)
        for y in range(src.shape[0]):
            row_window(tmp, dst, y, c0, c1, sign)

    @ti.func
    def lane_column_sum(src: ti.template(), i, e, k0, k1):
        """``sum_{k=k0..k1} src[i + k, e]`` over the rows of ``src`` (a lane array; rows outside count 0)."""
        acc = ti.Vector([0.0] * LANES, dt=ti.f32)
        for r in range(ti.max(i + k0, 0), ti.min(i + k1, src.shape[0] - 1) + 1):
            acc += src[r, e]
        return acc

    @ti.func
    def lane_column_block(src: ti.template(), dst: ti.template(), p, i0, i1, e, k0, k1, scale):
        """Rows ``i0 .. i1 - 1`` of element column ``e``: ``dst[p][i, e] = scale * sum_{k=k0..k1} src[i + k, e]``
        (``dst[i, e]`` for a 2-D ``dst``). The first row is a direct sum, the next ones slide (add the row
        that enters, subtract the one that leaves): the float32 round-off of a block of ``n`` rows grows
        with ``n``, not with the column."""
        H = src.shape[0]
        acc = lane_column_sum(src, i0, e, k0, k1)
        _lane_store(dst, p, i0, e, scale * acc)
        for i in range(i0 + 1, i1):
            enter, leave = i + k1, i + k0 - 1
            if enter >= 0 and enter < H:
                acc += src[enter, e]
            if leave >= 0 and leave < H:
                acc = acc - src[leave, e]  # not `-=`: an integer op on a vector under explicit vector types
            _lane_store(dst, p, i, e, scale * acc)

    @ti.func
    def _lane_store(x: ti.template(), p, i, e, v):
        """``x[p, i, e] = v`` (``x[i, e]`` for a 2-D ``x``)."""
        if ti.static(len(x.shape) == 3):
            x[p, i, e] = v
        else:
            x[i, e] = v

    @ti.func
    def lane_prefix(v):
        """Inclusive prefix sums of a lane vector (``out[l] = v[0] + ... + v[l]``), in log2(LANES) shifts."""
        out = v
        for s in ti.static([1 << b for b in range(LANES.bit_length() - 1)]):
            shifted = ti.Vector([0.0] * LANES, dt=ti.f32)
            for l in ti.static(range(s, LANES)):
                shifted[l] = out[l - s]
            out = out + shifted
        return out

    lane_get = C.lane_get

    @ti.func
    def _between(lp: ti.template(), p, i, e, m: ti.template()):
        """Sum of the row's values from the start of element ``e`` to the start of element ``e + m``
        (negative for ``m < 0``): totals of whole elements (the last lane of their prefixes)."""
        d = ti.f32(0.0)
        for j in ti.static(range(min(m, 0), max(m, 0))):
            d += lane_get(lp, p, i, e + j)[LANES - 1]
        if ti.static(m < 0):
            d = -d
        return d

    @ti.func
    def _prefix_at(lp: ti.template(), p, i, e, k: ti.template()):
        """For each lane (column c) of element ``e``: the row's sum up to column ``c + k`` inclusive, less the
        sum before element ``e`` (``lp``: in-element prefixes, :func:`lane_prefix`)."""
        q = ti.static(k // LANES)
        r = ti.static(k - q * LANES)
        here = lane_get(lp, p, i, e + q) + _between(lp, p, i, e, q)
        out = here
        if ti.static(r > 0):
            after = lane_get(lp, p, i, e + q + 1) + _between(lp, p, i, e, q + 1)
            for l in ti.static(range(LANES)):
                if ti.static(l + r < LANES):
                    out[l] = here[l + r]
                else:
                    out[l] = after[l + r - LANES]
        return out

    @ti.func
    def lane_window(lp: ti.template(), p, i, e, k0: ti.template(), k1: ti.template()):
        """``sum_{k=k0..k1} x[i, c + k]`` for the columns ``c`` of element ``e``, from the in-element prefixes
        ``lp`` of ``x`` (:func:`lane_prefix`; columns outside the row are 0, ghosts included). ``lp`` is a
        lane array (H, NB), or a stack of them (n, H, NB) of which ``lp[p]`` is read."""
        return _prefix_at(lp, p, i, e, k1) - _prefix_at(lp, p, i, e, k0 - 1)

    @vector_kernel
    @ti.kernel
    def lane_box_sum(src: LANE2, tmp: LANE2, lp: LANE2, dst: LANE2, r0: ti.i32, r1: ti.i32, c0: ti.template(),
                     c1: ti.template(), ghosts: ti.i32):
        """:func:`box_sum` (sign 1) on lane arrays (H, NB) with ``ghosts`` ghost elements either side: ``tmp`` the
        column pass, ``lp`` its in-element prefixes, ``dst`` the result."""
        H, E1 = src.shape[0], src.shape[1] - 2 * ghosts
        for k in range((H + COLUMN_BLOCK - 1) // COLUMN_BLOCK * E1):
            i0, e = k // E1 * COLUMN_BLOCK, ghosts + k % E1
            lane_column_block(src, tmp, 0, i0, ti.min(i0 + COLUMN_BLOCK, H), e, r0, r1, 1.0)
            for i in range(i0, ti.min(i0 + COLUMN_BLOCK, H)):
                lp[i, e] = lane_prefix(tmp[i, e])
        for k in range(H * E1):
            i, e = k // E1, ghosts + k % E1
            dst[i, e] = lane_window(lp, 0, i, e, c0, c1)

    return namespace(globals(), locals())
