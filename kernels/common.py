"""Shared Taichi helpers: border handling, rational tanh, work partitioning."""

from ..taichi_runtime import dsl

ti = dsl()  # taichi or quadrants: the same DSL

F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)

REPLICATE, REFLECT, ZERO = 0, 1, 2
BORDER_CODES = {"replicate": REPLICATE, "reflect": REFLECT, "zero": ZERO}

# Taichi 1.7 hands each CPU thread chunks of the outer loop; a 240-row frame
# would run on one thread if we looped over rows only. Loop over
# (row, column-block) items instead; each item visits its columns in runs
# (row_runs, below).
COLUMN_BLOCKS = 4


@ti.func
def tanh_rational(x):
    """tanh via the [13/6] rational approximation (Eigen/XLA), |err| < 4e-7 in f32."""
    xc = ti.min(ti.max(x, -7.90531110763549805), 7.90531110763549805)
    x2 = xc * xc
    p = x2 * -2.76076847742355e-16 + 2.00018790482477e-13
    p = x2 * p + -8.60467152213735e-11
    p = x2 * p + 5.12229709037114e-08
    p = x2 * p + 1.48572235717979e-05
    p = x2 * p + 6.37261928875436e-04
    p = x2 * p + 4.89352455891786e-03
    p = xc * p
    q = x2 * 1.19825839466702e-06 + 1.18534705686654e-04
    q = x2 * q + 2.26843463243900e-03
    q = x2 * q + 4.89352518554385e-03
    return p / q


@ti.func
def border_index(i, n, mode: ti.template()):
    """Map a possibly out-of-range index into [0, n) for the border mode."""
    r = i
    if ti.static(mode == REFLECT):
        r = ti.abs(i)
        if r >= n:
            r = 2 * n - 2 - r
        r = ti.min(ti.max(r, 0), n - 1)
    else:
        r = ti.min(ti.max(i, 0), n - 1)
    return r


@ti.func
def border_weight(i, n, mode: ti.template()):
    """1 inside the frame; 0 outside it for the ``zero`` border, else 1."""
    w = 1.0
    if ti.static(mode == ZERO):
        w = ti.select((i >= 0) & (i < n), 1.0, 0.0)
    return w


@ti.func
def block_span(k, width, blocks):
    """Row and column range [j0, j1) of work item ``k`` (row-major items)."""
    i = k // blocks
    b = k % blocks
    bw = ((width + blocks - 1) // blocks + CHUNK - 1) // CHUNK * CHUNK  # whole runs (row_runs)
    j0 = ti.min(b * bw, width)
    j1 = ti.min(j0 + bw, width)
    return i, j0, j1


# -- row runs -----------------------------------------------------------------------
# taichi 1.7 does not loop-vectorise ndarray loops (see kernels/cdnf.py), but it does
# SLP-vectorise straight-line code. A row kernel therefore visits its columns in runs:
# CHUNK consecutive columns at a time, written once as a function of vectors of n
# columns (``run_load``/``run_store``), called with n = CHUNK where the 3x3 neighbours
# are inside the frame and with n = 1 at the borders (neighbour columns clamped:
# the replicate border) and for the last columns of a segment.

CHUNK = 16
QUARTER = 4  # the shorter runs that finish a segment


@ti.func
def run_load(x: ti.template(), i, j, n: ti.template()):
    """``x[i, j .. j + n - 1]`` as a float32 vector of n values."""
    v = ti.Vector([0.0] * n, dt=ti.f32)
    for c in ti.static(range(n)):
        v[c] = ti.cast(x[i, j + c], ti.f32)
    return v


@ti.func
def run_store(x: ti.template(), i, j, v, n: ti.template()):
    """``x[i, j .. j + n - 1] = v``."""
    for c in ti.static(range(n)):
        x[i, j + c] = v[c]


@ti.func
def luminance_change(frame: ti.template(), L: ti.template(), P: ti.template(), i, j, n: ti.template(), scale, keep,
                     grey_levels: ti.template()):
    """Photoreceptors on the run ``(i, j .. j + n - 1)``: ``g = frame * scale`` (rounded to
    integer grey levels when ``grey_levels``), ``P = keep (g - L)`` (``keep = 0`` on the
    first frame), ``L = g``. Returns ``P``."""
    g = run_load(frame, i, j, n) * scale
    if ti.static(grey_levels):
        g = ti.floor(g + 0.5)
    p = keep * (g - run_load(L, i, j, n))
    run_store(L, i, j, g, n)
    run_store(P, i, j, p, n)
    return p


@ti.func
def run_sum(v, n: ti.template()):
    """Sum of the n values of ``v``, accumulated in float64."""
    s = ti.f64(0.0)
    for c in ti.static(range(n)):
        s += ti.cast(v[c], ti.f64)
    return s


@ti.func
def run_max(v, n: ti.template()):
    """Largest of the n values of ``v`` (float32)."""
    m = v[0]
    for c in ti.static(range(1, n)):
        m = ti.max(m, v[c])
    return m


@ti.func
def _combine(acc, r, reduce: ti.template()):
    """``acc + r`` (``reduce == "sum"``) or ``max(acc, r)``."""
    out = acc + r
    if ti.static(reduce == "max"):
        out = ti.max(acc, r)
    return out


@ti.func
def _single_columns(body: ti.template(), ctx: ti.template(), im, i, ip, j, stop, W, acc, reduce: ti.template()):
    """Runs of one column ``j .. stop - 1`` (neighbour columns clamped); returns ``(acc, stop)``."""
    while j < stop:
        acc = _combine(acc, body(ctx, im, i, ip, ti.max(j - 1, 0), j, ti.min(j + 1, W - 1), 1), reduce)
        j += 1
    return acc, j


@ti.func
def row_runs(body: ti.template(), ctx: ti.template(), i, j0, j1, H, W, reduce: ti.template(),
             halo: ti.template()):
    """Call ``body(ctx, im, i, ip, jm, j, jp, n)`` over the columns ``[j0, j1)`` of row ``i``.

    ``im``/``ip`` are the rows above and below, ``jm``/``jp`` the first columns of the
    left and right neighbours of the run ``j .. j + n - 1`` (clamped: replicate border).
    Runs of ``n = CHUNK`` (then ``QUARTER``) columns keep ``halo`` columns either side
    inside the frame (``halo`` >= 1: the body's horizontal reach); every other column is
    a run of one.
    Returns the ``reduce`` (``"sum"``: float64 sum; ``"max"``) of body's returns.
    """
    im = ti.min(ti.max(i - 1, 0), H - 1)
    ip = ti.min(ti.max(i + 1, 0), H - 1)
    acc, j = _single_columns(body, ctx, im, i, ip, j0, ti.min(j1, halo), W, ti.f64(0.0), reduce)
    end = ti.min(j1, W - halo)
    for n in ti.static((CHUNK, QUARTER)):
        while j + n <= end:
            acc = _combine(acc, body(ctx, im, i, ip, j - 1, j, j + 1, n), reduce)
            j += n
    acc, j = _single_columns(body, ctx, im, i, ip, j, j1, W, acc, reduce)
    return acc


@ti.func
def _dog_row_run(ctx: ti.template(), im, i, ip, jm, j, jp, n: ti.template()):
    v, row1, row2, g1, g2 = ti.static(ctx[0], ctx[1], ctx[2], ctx[3], ctx[4])
    mode, R = ti.static(ctx[5], ctx[6])
    W = v.shape[1]
    a1 = ti.Vector([0.0] * n, dt=ti.f32)
    a2 = ti.Vector([0.0] * n, dt=ti.f32)
    for d in ti.static(range(-R, R + 1)):
        x = ti.Vector([0.0] * n, dt=ti.f32)
        if ti.static(n == 1):  # a column near the border: map the tap into the frame
            x[0] = border_weight(j + d, W, mode) * v[i, border_index(j + d, W, mode)]
        else:  # a run with every tap inside the frame
            x = run_load(v, i, j + d, n)
        a1 += g1[d + R] * x
        a2 += g2[d + R] * x
    run_store(row1, i, j, a1, n)
    run_store(row2, i, j, a2, n)
    return 0.0


@ti.func
def dog_row_pass(v: ti.template(), row1: ti.template(), row2: ti.template(), g1: ti.template(),
                 g2: ti.template(), blocks, mode: ti.template(), R: ti.template()):
    """Horizontal passes of a separable DoG: ``row1 = g1 (*)_x v``, ``row2 = g2 (*)_x v``.

    ``g1``/``g2`` are 1-D profiles of length ``2R + 1`` (``R`` a compile-time radius:
    the taps unroll). Called at a kernel's top level, the loop is the kernel's
    parallel loop over (row, column-block) items.
    """
    H, W = v.shape[0], v.shape[1]
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        row_runs(_dog_row_run, (v, row1, row2, g1, g2, mode, R), i, j0, j1, H, W, "sum", ti.static(max(R, 1)))


@ti.func
def dog_column_run(row1: ti.template(), row2: ti.template(), g1: ti.template(), g2: ti.template(),
                   A, B, i, j, n: ti.template(), mode: ti.template(), R: ti.template()):
    """Vertical pass on the run ``(i, j .. j + n - 1)``: ``A g1 (*)_y row1 - B g2 (*)_y row2`` = ``W_s (*) v``
    (radius ``R``, unrolled; rows mapped by the border mode)."""
    H = row1.shape[0]
    b1 = ti.Vector([0.0] * n, dt=ti.f32)
    b2 = ti.Vector([0.0] * n, dt=ti.f32)
    for d in ti.static(range(-R, R + 1)):
        ii = border_index(i + d, H, mode)
        wgt = border_weight(i + d, H, mode)
        b1 += (g1[d + R] * wgt) * run_load(row1, ii, j, n)
        b2 += (g2[d + R] * wgt) * run_load(row2, ii, j, n)
    return A * b1 - B * b2


@ti.kernel
def fill(x: F2, value: ti.f32):
    """Set every element of ``x`` to ``value``."""
    for i, j in x:
        x[i, j] = value
