"""Shared Taichi helpers: border handling, rational tanh, work partitioning."""

from ..taichi_runtime import dsl

ti = dsl()  # taichi or quadrants: the same DSL

F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)

REPLICATE, REFLECT, ZERO = 0, 1, 2
BORDER_CODES = {"replicate": REPLICATE, "reflect": REFLECT, "zero": ZERO}

# Taichi 1.7 hands each CPU thread chunks of the outer loop; a 240-row frame
# would run on one thread if we looped over rows only. Loop over
# (row, column-block) items instead; each item runs a serial, vectorisable
# inner loop over its columns.
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
def luminance_change(frame: ti.template(), L: ti.template(), i, j, scale, first):
    """``P = frame * scale - L`` at (i, j) (0 on the first frame); stores the new ``L``."""
    g = ti.cast(frame[i, j], ti.f32) * scale
    p = ti.select(first != 0, 0.0, g - L[i, j])
    L[i, j] = g
    return p


@ti.func
def block_span(k, width, blocks):
    """Row and column range [j0, j1) of work item ``k`` (row-major items)."""
    i = k // blocks
    b = k % blocks
    bw = (width + blocks - 1) // blocks
    j0 = ti.min(b * bw, width)
    j1 = ti.min(j0 + bw, width)
    return i, j0, j1


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
        for j in range(j0, j1):
            a1 = 0.0
            a2 = 0.0
            for d in ti.static(range(-R, R + 1)):
                x = border_weight(j + d, W, mode) * v[i, border_index(j + d, W, mode)]
                a1 += g1[d + R] * x
                a2 += g2[d + R] * x
            row1[i, j] = a1
            row2[i, j] = a2


@ti.func
def dog_column_sum(row1: ti.template(), row2: ti.template(), g1: ti.template(), g2: ti.template(),
                   A, B, i, j, mode: ti.template(), R: ti.template()):
    """Vertical pass at (i, j): ``A g1 (*)_y row1 - B g2 (*)_y row2`` = ``W_s (*) v`` (radius ``R``, unrolled)."""
    H = row1.shape[0]
    b1 = 0.0
    b2 = 0.0
    for d in ti.static(range(-R, R + 1)):
        ii = border_index(i + d, H, mode)
        wgt = border_weight(i + d, H, mode)
        b1 += g1[d + R] * wgt * row1[ii, j]
        b2 += g2[d + R] * wgt * row2[ii, j]
    return A * b1 - B * b2


@ti.kernel
def fill(x: F2, value: ti.f32):
    """Set every element of ``x`` to ``value``."""
    for i, j in x:
        x[i, j] = value
