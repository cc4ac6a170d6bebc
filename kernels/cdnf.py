"""Taichi kernels of the C-DNF fields (float32 state, float64 integration).

Two sets of kernels compute the same equations:

* the generic kernels (``load_frame``, ``contrast_iterate``, ``summation_iterate``, ...)
  take ``ti.ndarray``/NumPy arrays of shape (H, W), so one compiled kernel serves
  every frame size; used for frames narrower than ``2 * LANES`` pixels;
* the fast kernels (``lanes_*``) work on lane-vectorised ``ti.Vector`` fields with
  ghost columns and iterate only the active tiles (see the section below and
  ``docs/PERFORMANCE.md``).

``mode`` is a compile-time border code from :mod:`cdnf_ti.kernels.common`. The
float64 NumPy reference of the same equations is :mod:`cdnf_ti.reference`.
"""

import functools

from ..taichi_runtime import dsl
from .common import (  # noqa: F401 - fill is part of this module's kernel set
    REFLECT,
    REPLICATE,
    block_span,
    border_index,
    border_weight,
    dog_column_sum,
    dog_row_pass,
    fill,
    luminance_change,
    tanh_rational,
)

ti = dsl()  # taichi or quadrants: the same DSL

F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
F1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
VEC2 = ti.types.vector(2, ti.f32)


MAX_STEPS = 8  # updates per launch of the lane kernels (CDNFParams.steps_per_launch <= 8)


@ti.func
def field_update(inp, lateral, u, prev, h, lam, mom):
    """The one statement of a C-DNF field update (scalars or lane vectors alike).

    ``F(u) = inp - h + vartheta(lateral)`` with ``vartheta(a) = tanh(a / 2)``;
    returns ``(u + mom (u - prev) + lam (F(u) - u), F(u) - u)``: plain relaxation for
    ``mom = 0``, a Chebyshev step otherwise (``prev``: the iterate before ``u``).
    """
    d = inp - h + tanh_rational(0.5 * lateral) - u
    return u + mom * (u - prev) + lam * d, d


@ti.kernel
def load_frame(frame: ti.types.ndarray(ndim=2), L: F2, P: F2, scale: ti.f32, first: ti.i32):
    """``g = frame * scale``; ``P = g - L`` (0 when ``first``); ``L = g``."""
    for i, j in L:
        P[i, j] = luminance_change(frame, L, i, j, scale, first)


@ti.kernel
def copy(src: F2, dst: F2):
    """``dst = src``."""
    for i, j in src:
        dst[i, j] = src[i, j]


@ti.func
def _lateral_3x3(u: ti.template(), i, j, H, W, wc0, wc1, wc2, mode: ti.template()):
    """``W_c (*) u`` at (i, j): wc0 centre, wc1 edge, wc2 diagonal weight."""
    im = border_index(i - 1, H, mode)
    ip = border_index(i + 1, H, mode)
    jm = border_index(j - 1, W, mode)
    jp = border_index(j + 1, W, mode)
    wim = border_weight(i - 1, H, mode)
    wip = border_weight(i + 1, H, mode)
    wjm = border_weight(j - 1, W, mode)
    wjp = border_weight(j + 1, W, mode)
    edge = wim * u[im, j] + wip * u[ip, j] + wjm * u[i, jm] + wjp * u[i, jp]
    diag = wim * (wjm * u[im, jm] + wjp * u[im, jp]) + wip * (wjm * u[ip, jm] + wjp * u[ip, jp])
    return wc0 * u[i, j] + wc1 * edge + wc2 * diag


@ti.kernel
def contrast_iterate(
    P: F2, u_on: F2, u_off: F2, out_on: F2, out_off: F2,
    wc0: ti.f32, wc1: ti.f32, wc2: ti.f32, h: ti.f32, lam: ti.f32, mom: ti.f32,
    blocks: ti.i32, mode: ti.template(),
) -> VEC2:
    """One update of the ON and OFF fields (fused), see :func:`field_update`.

    ``F(u) = P_on - h + vartheta(W_c (*) u)``; ``out`` holds the previous iterate on
    entry and ``u + mom (u - out) + lam (F(u) - u)`` on return;
    returns ``(max|F(u_on) - u_on|, max|F(u_off) - u_off|)``.
    """
    H, W = P.shape[0], P.shape[1]
    r_on = 0.0
    r_off = 0.0
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        m_on = 0.0
        m_off = 0.0
        for j in range(j0, j1):
            p = P[i, j]
            s_on = _lateral_3x3(u_on, i, j, H, W, wc0, wc1, wc2, mode)
            s_off = _lateral_3x3(u_off, i, j, H, W, wc0, wc1, wc2, mode)
            n_on, d_on = field_update(ti.max(p, 0.0), s_on, u_on[i, j], out_on[i, j], h, lam, mom)
            n_off, d_off = field_update(ti.max(-p, 0.0), s_off, u_off[i, j], out_off[i, j], h, lam, mom)
            out_on[i, j] = n_on
            out_off[i, j] = n_off
            m_on = ti.max(m_on, ti.abs(d_on))
            m_off = ti.max(m_off, ti.abs(d_off))
        ti.atomic_max(r_on, m_on)
        ti.atomic_max(r_off, m_off)
    return ti.Vector([r_on, r_off])


@ti.kernel
def summation_input(u_on: F2, u_off: F2, S: F2, alpha_on: ti.f32, alpha_off: ti.f32, theta_scale: ti.f32):
    """``S = alpha_on theta([u_on]+) + alpha_off theta([u_off]+)``."""
    for i, j in S:
        a_on = tanh_rational(ti.max(u_on[i, j], 0.0)) * theta_scale
        a_off = tanh_rational(ti.max(u_off[i, j], 0.0)) * theta_scale
        S[i, j] = alpha_on * a_on + alpha_off * a_off


@ti.kernel
def summation_iterate(
    S: F2, v: F2, row1: F2, row2: F2, out: F2, g1: F1, g2: F1,
    A: ti.f32, B: ti.f32, h: ti.f32, lam: ti.f32, mom: ti.f32,
    blocks: ti.i32, mode: ti.template(),
) -> ti.f32:
    """One update of the Summation field (see :func:`field_update`; ``out``: previous iterate).

    The DoG ``W_s = A g1 g1^T - B g2 g2^T`` is applied as separable passes:
    ``row1 = g1 (*)_x v``, ``row2 = g2 (*)_x v``, then
    ``W_s (*) v = A g1 (*)_y row1 - B g2 (*)_y row2`` (exact for every border
    mode). ``F(v) = S - h + vartheta(W_s (*) v)``; returns ``max|F(v) - v|``.
    """
    H, W = v.shape[0], v.shape[1]
    dog_row_pass(v, row1, row2, g1, g2, blocks, mode)
    res = 0.0
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        m = 0.0
        for j in range(j0, j1):
            lateral = dog_column_sum(row1, row2, g1, g2, A, B, i, j, mode)
            nv, dv = field_update(S[i, j], lateral, v[i, j], out[i, j], h, lam, mom)
            out[i, j] = nv
            m = ti.max(m, ti.abs(dv))
        ti.atomic_max(res, m)
    return res


@ti.kernel
def mean_activation(v: F2, theta_scale: ti.f32, blocks: ti.i32) -> ti.f64:
    """``mean_xy theta([v]+)``, accumulated in float64."""
    H, W = v.shape[0], v.shape[1]
    total = ti.f64(0.0)
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        acc = ti.f64(0.0)
        for j in range(j0, j1):
            acc += ti.cast(tanh_rational(ti.max(v[i, j], 0.0)) * theta_scale, ti.f64)
        ti.atomic_add(total, acc)
    return total / ti.f64(H * W)


# ---------------------------------------------------------------------------
# Lane-vectorised kernels on padded Vector fields (the fast path).
#
# Taichi 1.7 on the CPU does not loop-vectorise: every ndarray/field access in a
# loop re-loads its base pointer after each store (the stores may alias the
# argument buffer), so LLVM's loop vectoriser gives up and each pixel costs a
# few scalar loads. It does SLP-vectorise straight-line code on vector-typed
# field elements. The fast path therefore stores a field as
# ``ti.Vector.field(LANES, f32, (H, NB))``: element (i, e) holds the LANES
# consecutive columns ``(e - 1) * LANES .. e * LANES - 1`` of row i, so column
# c lives at flat position ``LANES + c``. Element 0 and the elements past the
# last column hold "ghost" columns: the values the border mode puts outside
# the frame (replicate/reflect copies, or 0), refreshed by the thread that
# wrote the row, so the stencils read neighbours without any clamping.
# Horizontal neighbours are lane shifts of three consecutive elements.
# ---------------------------------------------------------------------------

LANES = 16
VECL = ti.types.vector(LANES, ti.f32)


def lane_layout(width: int) -> tuple[int, int]:
    """``(E1, NB)``: last element holding a frame column, elements per row."""
    e1 = (LANES + width - 1) // LANES
    return e1, e1 + 2


@ti.func
def _shift(a, b, c, s: ti.template()):
    """Lanes of ``b`` shifted by ``s`` columns (``a``/``c``: left/right neighbours)."""
    out = ti.Vector([0.0] * LANES, dt=ti.f32)
    for l in ti.static(range(LANES)):
        if ti.static(l + s < 0):
            out[l] = a[LANES + l + s]
        elif ti.static(l + s >= LANES):
            out[l] = c[l + s - LANES]
        else:
            out[l] = b[l + s]
    return out


@ti.func
def _lane_mask(e, W: ti.template()):
    """1.0 on the lanes of element ``e`` that hold frame columns, else 0.0."""
    m = ti.Vector([0.0] * LANES, dt=ti.f32)
    for l in ti.static(range(LANES)):
        m[l] = ti.select((e - 1) * LANES + l < W, 1.0, 0.0)
    return m


@ti.func
def _fill_ghosts(x: ti.template(), i, left: ti.i32, right: ti.i32, W: ti.template(), R: ti.template(),
                 mode: ti.template()):
    """Write the R ghost columns left of column 0 / right of column W-1 of row ``i``."""
    if left:
        for d in ti.static(range(1, R + 1)):
            g = LANES - d  # flat position of column -d
            val = ti.f32(0.0)
            if ti.static(mode == REFLECT):
                val = x[i, (LANES + d) // LANES][(LANES + d) % LANES]
            elif ti.static(mode == REPLICATE):
                val = x[i, 1][0]
            x[i, g // LANES][g % LANES] = val
    if right:
        for d in ti.static(range(1, R + 1)):
            g = LANES + W - 1 + d
            val = ti.f32(0.0)
            if ti.static(mode == REFLECT):
                s = LANES + W - 1 - d
                val = x[i, s // LANES][s % LANES]
            elif ti.static(mode == REPLICATE):
                s = LANES + W - 1
                val = x[i, s // LANES][s % LANES]
            x[i, g // LANES][g % LANES] = val


# -- active tiles --------------------------------------------------------------
# The frame is cut into tiles of TILE_ROWS rows x ``bs`` lane elements. Each
# field group (ON+OFF; Summation) keeps a 0/1 mark per tile ("act") and the
# compact list of marked tiles ("lst", count "cnt"). An update visits only the
# listed tiles; a pixel whose update |F(u) - u| is at most ``tau`` keeps its
# value exactly, and a tile where some pixel moved sets "chg". The next list is
# the tiles next to (3x3 tiles) a changed tile, so a tile left out has not seen
# any of its inputs change since it was last visited with every |F(u) - u| <=
# tau: its residual is still <= tau < tol. Both ping-pong buffers hold equal
# values on tiles that are left out (they were last visited without change).

TILE_ROWS = 8


def tile_blocks(e1: int, target: int = 64 // LANES) -> tuple[int, int]:
    """``(bs, nblk)``: about ``target`` lane elements per tile column, last block >= 2 elements."""
    bs = max(2, min(target, e1))
    while True:
        nblk = -(-e1 // bs)
        if nblk == 1 or e1 - (nblk - 1) * bs >= 2:
            return bs, nblk
        bs += 1


@ti.func
def _rebuild(act: ti.template(), src: ti.template(), lst: ti.template(), cnt: ti.template(),
             nbands, nblk, merge: ti.template(), go=1):
    """``act = dilate(src) (| act if merge)``; ``lst``/``cnt`` = marked tiles; ``src = 0``.

    Does nothing when ``go`` is 0 (a skipped update of a multi-step kernel).
    """
    if go != 0:
        cnt[None] = 0
    ti.loop_config(serialize=True)
    for t in range(nbands * nblk * go):
        band = t // nblk
        blk = t % nblk
        a = 0
        if ti.static(merge):
            a = act[t]
        for db in ti.static(range(-1, 2)):
            for dk in ti.static(range(-1, 2)):
                nb = band + db
                nk = blk + dk
                if 0 <= nb < nbands and 0 <= nk < nblk:
                    if src[nb * nblk + nk] != 0:
                        a = 1
        act[t] = a
        if a != 0:
            n = cnt[None]
            lst[n] = t
            cnt[None] = n + 1
    ti.loop_config(serialize=True)
    for t in range(nbands * nblk * go):
        src[t] = 0


@ti.func
def _balanced(k, n):
    """Map loop index ``k`` of :func:`_balanced_len` ``(n)`` to a work item (``-1``: none).

    Taichi 1.7 hands each CPU thread a chunk of ``max(ceil(len / 2), 512)``
    consecutive indices, so a loop over fewer than 1024 items would run on one
    thread. The loop runs over at least 1024 indices instead; the first half of
    the items sits at the start of the first chunk, the second half at the start
    of the second.
    """
    half_items = (n + 1) // 2
    half_loop = ti.max(half_items, 512)
    idx = -1
    if k < half_loop:
        if k < half_items:
            idx = k
    else:
        j = half_items + (k - half_loop)
        if j < n:
            idx = j
    return idx


@ti.func
def _balanced_len(n):
    return 2 * ti.max((n + 1) // 2, 512)


@ti.func
def _tile_row(kk, lst: ti.template(), cnt: ti.template(), nblk, bs, E1, H):
    """Work item ``kk`` of a balanced loop over the active tiles' rows.

    Returns ``(ok, t, i, blk, e0, e1)``: whether the item exists, its tile, its
    row, the tile's column and its lane elements ``[e0, e1)`` (element 0 is the
    left ghost).
    """
    k = _balanced(kk, cnt[None] * TILE_ROWS)
    t = lst[ti.max(k, 0) // TILE_ROWS]
    i = (t // nblk) * TILE_ROWS + ti.max(k, 0) % TILE_ROWS
    blk = t % nblk
    e0 = 1 + blk * bs
    e1 = ti.min(e0 + bs, E1 + 1)
    return (k >= 0) & (i < H), t, i, blk, e0, e1


@ti.kernel
def tiles_all(act: ti.template(), lst: ti.template(), cnt: ti.template()):
    """Mark every tile active."""
    n = act.shape[0]
    for t in range(n):
        act[t] = 1
        lst[t] = t
    cnt[None] = n


@ti.kernel
def lanes_load_frame(frame: ti.types.ndarray(ndim=2), L: ti.template(), P: ti.template(), scale: ti.f32,
                     first: ti.i32, W: ti.template(), bs: ti.i32, nblk: ti.i32,
                     act: ti.template(), inp: ti.template(), lst: ti.template(), cnt: ti.template()):
    """``g = frame * scale``; ``P = g - L`` (0 when ``first``); ``L = g`` (frame columns only).

    Tiles where ``P`` changed are added (with their neighbours) to the contrast tile list.
    """
    H = L.shape[0]
    E1 = (LANES + W - 1) // LANES
    for k in range(H * E1):
        i = k // E1
        e = k % E1 + 1
        g = ti.Vector([0.0] * LANES, dt=ti.f32)
        for l in ti.static(range(LANES)):
            c = ti.min((e - 1) * LANES + l, W - 1)
            g[l] = ti.cast(frame[i, c], ti.f32) * scale
        p_new = ti.select(first != 0, 0.0, g - L[i, e])
        if (p_new != P[i, e]).any():
            inp[(i // TILE_ROWS) * nblk + (e - 1) // bs] = 1
        P[i, e] = p_new
        L[i, e] = g
    _rebuild(act, inp, lst, cnt, (H + TILE_ROWS - 1) // TILE_ROWS, nblk, True)


@ti.kernel
def lanes_fill(x: ti.template(), value: ti.f32):
    """Every lane of every element (ghosts included) = ``value``."""
    for i, e in x:
        x[i, e] = ti.Vector([value] * LANES, dt=ti.f32)


@ti.func
def _neighbours(left, b, right):
    """``(b shifted right by one column, b shifted left by one column)``.

    ``left`` is the column before lane 0 and ``right`` the column after the last lane.
    """
    lo = ti.Vector([0.0] * LANES, dt=ti.f32)
    hi = ti.Vector([0.0] * LANES, dt=ti.f32)
    lo[0] = left
    hi[LANES - 1] = right
    for l in ti.static(range(1, LANES)):
        lo[l] = b[l - 1]
        hi[l - 1] = b[l]
    return lo, hi


@ti.func
def _contrast_row(P: ti.template(), u: ti.template(), out: ti.template(), sign: ti.template(), i, im, ip, wim, wip,
                  e0, e1, k0, k1, h, lam, mom, tau, W: ti.template()):
    """Update elements ``e0..e1-1`` of row ``i`` of one contrast field; returns the lane-wise max |F(u) - u|.

    ``out`` holds the previous iterate on entry (:func:`field_update`).

    ``W_c = k k^T`` is separable (``k = (k1, k0, k1)``): vertical sums
    ``c = k0 u[i] + k1 (u[i-1] + u[i+1])`` are carried along the row (one new
    element per step, only the last lane of the previous one), then
    ``W_c (*) u = k0 c + k1 (c[j-1] + c[j+1])``.
    """
    m = ti.Vector([0.0] * LANES, dt=ti.f32)
    c_left = k0 * u[i, e0 - 1][LANES - 1] + k1 * (wim * u[im, e0 - 1][LANES - 1] + wip * u[ip, e0 - 1][LANES - 1])
    c_cur = k0 * u[i, e0] + k1 * (wim * u[im, e0] + wip * u[ip, e0])
    for e in range(e0, e1):
        c_next = k0 * u[i, e + 1] + k1 * (wim * u[im, e + 1] + wip * u[ip, e + 1])
        lo, hi = _neighbours(c_left, c_cur, c_next[0])
        s = k0 * c_cur + k1 * (lo + hi)
        uc = u[i, e]
        nu, d = field_update(ti.max(sign * P[i, e], 0.0), s, uc, out[i, e], h, lam, mom)
        ad = ti.abs(d)
        out[i, e] = ti.select(ad > tau, nu, uc)
        m = ti.max(m, ad * _lane_mask(e, W))
        c_left = c_cur[LANES - 1]
        c_cur = c_next
    return m


@ti.kernel
def lanes_refresh_ghosts(x: ti.template(), W: ti.template(), mode: ti.template()):
    """Set the ghost columns of every row of ``x`` from its frame columns (border mode)."""
    for i in range(x.shape[0]):
        _fill_ghosts(x, i, 1, 1, W, LANES - 1, mode)


@functools.lru_cache(maxsize=None)
def lanes_contrast_kernel(nsteps: int):
    """The lane-vectorised ON/OFF update, ``nsteps`` updates per launch.

    Update ``j`` reads buffers ``a`` and writes ``b`` (``j`` even) or the reverse, with
    the coefficients ``coef[2j]`` (``lam``) and ``coef[2j + 1]`` (``mom``) of
    :func:`field_update`; it is skipped once update ``j - 1`` found both residuals
    ``<= tol``. Returns the residuals ``(on_0, off_0, on_1, off_1, ...)`` (0 for a
    skipped update). Pixels with ``|F(u) - u| <= tau`` keep their value; only the
    active tiles are visited.
    """

    @ti.kernel
    def lanes_contrast_iterate(
        P: ti.template(), on_a: ti.template(), off_a: ti.template(), on_b: ti.template(), off_b: ti.template(),
        k0: ti.f32, k1: ti.f32, h: ti.f32, coef: ti.types.vector(2 * nsteps, ti.f32), tau: ti.f32, tol: ti.f32,
        bs: ti.i32, nblk: ti.i32, act: ti.template(), chg: ti.template(), lst: ti.template(), cnt: ti.template(),
        rbuf: ti.template(), W: ti.template(), mode: ti.template(),
    ) -> ti.types.vector(2 * nsteps, ti.f32):
        H = P.shape[0]
        E1 = (LANES + W - 1) // LANES
        for j in ti.static(range(nsteps)):
            u_on, out_on = ti.static((on_a, on_b) if j % 2 == 0 else (on_b, on_a))
            u_off, out_off = ti.static((off_a, off_b) if j % 2 == 0 else (off_b, off_a))
            rbuf[j, 0] = 0.0
            rbuf[j, 1] = 0.0
            go = 1
            if ti.static(j > 0):
                go = ti.select(ti.max(rbuf[j - 1, 0], rbuf[j - 1, 1]) > tol, 1, 0)
            lam = coef[2 * j]
            mom = coef[2 * j + 1]
            for kk in range(_balanced_len(cnt[None] * TILE_ROWS) * go):
                ok, t, i, blk, e0, e1 = _tile_row(kk, lst, cnt, nblk, bs, E1, H)
                if ok:
                    im = border_index(i - 1, H, mode)
                    ip = border_index(i + 1, H, mode)
                    wim = ti.f32(border_weight(i - 1, H, mode))
                    wip = ti.f32(border_weight(i + 1, H, mode))
                    m_on = _contrast_row(P, u_on, out_on, 1.0, i, im, ip, wim, wip, e0, e1, k0, k1, h, lam, mom,
                                         tau, W)
                    m_off = _contrast_row(P, u_off, out_off, -1.0, i, im, ip, wim, wip, e0, e1, k0, k1, h, lam,
                                          mom, tau, W)
                    _fill_ghosts(out_on, i, blk == 0, blk == nblk - 1, W, 1, mode)
                    _fill_ghosts(out_off, i, blk == 0, blk == nblk - 1, W, 1, mode)
                    mon = m_on.max()
                    moff = m_off.max()
                    ti.atomic_max(rbuf[j, 0], mon)
                    ti.atomic_max(rbuf[j, 1], moff)
                    if ti.max(mon, moff) > tau:
                        chg[t] = 1
            _rebuild(act, chg, lst, cnt, (H + TILE_ROWS - 1) // TILE_ROWS, nblk, False, go)
        out = ti.Vector([0.0] * (2 * nsteps), dt=ti.f32)
        for j in ti.static(range(nsteps)):
            out[2 * j] = rbuf[j, 0]
            out[2 * j + 1] = rbuf[j, 1]
        return out

    return lanes_contrast_iterate


@ti.kernel
def lanes_summation_input(u_on: ti.template(), u_off: ti.template(), S: ti.template(), alpha_on: ti.f32,
                          alpha_off: ti.f32, theta_scale: ti.f32, W: ti.template(), bs: ti.i32, nblk: ti.i32,
                          act: ti.template(), inp: ti.template(), lst: ti.template(), cnt: ti.template()):
    """``S = alpha_on theta([u_on]+) + alpha_off theta([u_off]+)``; tiles where S changed join the list."""
    H = S.shape[0]
    E1 = (LANES + W - 1) // LANES
    for k in range(H * E1):
        i = k // E1
        e = k % E1 + 1
        a_on = tanh_rational(ti.max(u_on[i, e], 0.0)) * theta_scale
        a_off = tanh_rational(ti.max(u_off[i, e], 0.0)) * theta_scale
        s_new = alpha_on * a_on + alpha_off * a_off
        if (s_new != S[i, e]).any():
            inp[(i // TILE_ROWS) * nblk + (e - 1) // bs] = 1
        S[i, e] = s_new
    _rebuild(act, inp, lst, cnt, (H + TILE_ROWS - 1) // TILE_ROWS, nblk, True)


@functools.lru_cache(maxsize=None)
def lanes_summation_kernel(g1: tuple, g2: tuple, nsteps: int = 1):
    """The lane-vectorised Summation update for the DoG profiles ``g1``, ``g2``, ``nsteps`` per launch.

    The taps (``2 R + 1`` floats each, symmetric) are compiled in as constants,
    which saves their per-launch argument passing; one kernel per parameter set.
    Buffers, coefficients, skipping and residuals as in :func:`lanes_contrast_kernel`.
    """
    R = (len(g1) - 1) // 2
    G1 = tuple(float(x) for x in g1)
    G2 = tuple(float(x) for x in g2)

    @ti.kernel
    def lanes_summation_iterate(
        S: ti.template(), v_a: ti.template(), v_b: ti.template(), row1: ti.template(), row2: ti.template(),
        A: ti.f32, B: ti.f32, h: ti.f32, coef: ti.types.vector(2 * nsteps, ti.f32), tau: ti.f32, tol: ti.f32,
        bs: ti.i32, nblk: ti.i32, act: ti.template(), chg: ti.template(), lst: ti.template(), cnt: ti.template(),
        rbuf: ti.template(), W: ti.template(), mode: ti.template(),
    ) -> ti.types.vector(nsteps, ti.f32):
        """Lane-vectorised :func:`summation_iterate` on the active tiles: separable DoG, same equations."""
        H = v_a.shape[0]
        E1 = (LANES + W - 1) // LANES
        for j in ti.static(range(nsteps)):
            v, out = ti.static((v_a, v_b) if j % 2 == 0 else (v_b, v_a))
            rbuf[j, 0] = 0.0
            go = 1
            if ti.static(j > 0):
                go = ti.select(rbuf[j - 1, 0] > tol, 1, 0)
            lam = coef[2 * j]
            mom = coef[2 * j + 1]
            for kk in range(_balanced_len(cnt[None] * TILE_ROWS) * go):
                ok, t, i, blk, e0, e1 = _tile_row(kk, lst, cnt, nblk, bs, E1, H)
                if ok:
                    a = v[i, e0 - 1]
                    c = v[i, e0]
                    for e in range(e0, e1):
                        n = v[i, e + 1]
                        a1 = ti.static(G1[R]) * c
                        a2 = ti.static(G2[R]) * c
                        for d in ti.static(range(1, R + 1)):
                            pair = _shift(a, c, n, -d) + _shift(a, c, n, d)
                            a1 += ti.static(G1[R + d]) * pair
                            a2 += ti.static(G2[R + d]) * pair
                        row1[i, e] = a1
                        row2[i, e] = a2
                        a = c
                        c = n
            for kk in range(_balanced_len(cnt[None] * TILE_ROWS) * go):
                ok, t, i, blk, e0, e1 = _tile_row(kk, lst, cnt, nblk, bs, E1, H)
                if ok:
                    m = ti.Vector([0.0] * LANES, dt=ti.f32)
                    for e in range(e0, e1):
                        b1 = ti.static(G1[R]) * row1[i, e]
                        b2 = ti.static(G2[R]) * row2[i, e]
                        for d in ti.static(range(1, R + 1)):
                            iu = border_index(i - d, H, mode)
                            idn = border_index(i + d, H, mode)
                            wu = border_weight(i - d, H, mode)
                            wd = border_weight(i + d, H, mode)
                            b1 += ti.static(G1[R + d]) * (wu * row1[iu, e] + wd * row1[idn, e])
                            b2 += ti.static(G2[R + d]) * (wu * row2[iu, e] + wd * row2[idn, e])
                        vc = v[i, e]
                        nv, dv = field_update(S[i, e], A * b1 - B * b2, vc, out[i, e], h, lam, mom)
                        adv = ti.abs(dv)
                        out[i, e] = ti.select(adv > tau, nv, vc)
                        m = ti.max(m, adv * _lane_mask(e, W))
                    _fill_ghosts(out, i, blk == 0, blk == nblk - 1, W, R, mode)
                    mx = m.max()
                    ti.atomic_max(rbuf[j, 0], mx)
                    if mx > tau:
                        chg[t] = 1
            _rebuild(act, chg, lst, cnt, (H + TILE_ROWS - 1) // TILE_ROWS, nblk, False, go)
        out_r = ti.Vector([0.0] * nsteps, dt=ti.f32)
        for j in ti.static(range(nsteps)):
            out_r[j] = rbuf[j, 0]
        return out_r

    return lanes_summation_iterate


@ti.kernel
def lanes_mean_activation(v: ti.template(), theta_scale: ti.f32, W: ti.template()) -> ti.f64:
    """``mean_xy theta([v]+)`` over the frame columns, accumulated in float64."""
    H = v.shape[0]
    E1 = (LANES + W - 1) // LANES
    total = ti.f64(0.0)
    for i in range(H):
        acc = ti.f64(0.0)
        for e in range(1, E1 + 1):
            a = tanh_rational(ti.max(v[i, e], 0.0)) * theta_scale * _lane_mask(e, W)
            acc += ti.cast(a.sum(), ti.f64)
        ti.atomic_add(total, acc)
    return total / ti.f64(H * W)
