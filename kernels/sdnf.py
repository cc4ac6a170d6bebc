"""Taichi kernels of the SDNF reconstruction (single field, float32 state).

Two launches per frame: :func:`load_binary` (binary pre-processing of the
luminance change, returning the active-pixel count) and :func:`field_update`
(time-delayed lateral interaction: the DoG acts on the previous frame's
field, so each frame is one explicit update, no iteration). The DoG is applied
as separable row/column passes with a replicate border. NumPy float64 oracle:
:class:`cdnf_ti.baselines_reference.NumpySDNFBackend`.
"""

from ..taichi_runtime import dsl
from .common import REPLICATE, block_span, dog_column_sum, dog_row_pass, fill, luminance_change, tanh_rational  # noqa: F401

ti = dsl()  # taichi or quadrants: the same DSL

F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
F1 = ti.types.ndarray(dtype=ti.f32, ndim=1)


@ti.kernel
def load_binary(frame: ti.types.ndarray(ndim=2), L: F2, P: F2, E: F2, scale: ti.f32, first: ti.i32,
                t_b: ti.f32, blocks: ti.i32) -> ti.f64:
    """``g = frame * scale`` in [0, 1]; ``P = g - L`` (0 when ``first``); ``E = [|P| >= t_b]``;
    returns ``sum E``."""
    H, W = L.shape[0], L.shape[1]
    total = ti.f64(0.0)
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        acc = ti.f64(0.0)
        for j in range(j0, j1):
            p = luminance_change(frame, L, i, j, scale, first)
            P[i, j] = p
            e = ti.select(ti.abs(p) >= t_b, 1.0, 0.0)
            E[i, j] = e
            acc += ti.cast(e, ti.f64)
        ti.atomic_add(total, acc)
    return total


@ti.func
def _act(u, theta_scale):
    """Firing rate ``f(u) = theta([u]+) = tanh([u]+) / tanh(1)``."""
    return tanh_rational(ti.max(u, 0.0)) * theta_scale


@ti.kernel
def field_update(
    E: F2, F: F2, row1: F2, row2: F2, u_new: F2, F_new: F2, g1: F1, g2: F1,
    A: ti.f32, B_t: ti.f32, h: ti.f32, theta_scale: ti.f32, blocks: ti.i32, R: ti.template(),
) -> ti.f64:
    """``u_new = E - h + vartheta(A g1g1 (*) F - B_t g2g2 (*) F)``, ``F_new = f(u_new)``;
    returns ``sum F_new``.

    ``F = f(u(t-1))`` is the previous frame's firing rate (time-delayed lateral
    interaction); ``vartheta(a) = tanh(a / 2)``; ``R``: the DoG radius (``g1``/``g2`` have ``2R + 1`` taps).
    """
    H, W = F.shape[0], F.shape[1]
    dog_row_pass(F, row1, row2, g1, g2, blocks, REPLICATE, R)
    total = ti.f64(0.0)
    for k in range(H * blocks):
        i, j0, j1 = block_span(k, W, blocks)
        acc = ti.f64(0.0)
        for j in range(j0, j1):
            v = E[i, j] - h + tanh_rational(0.5 * dog_column_sum(row1, row2, g1, g2, A, B_t, i, j, REPLICATE, R))
            u_new[i, j] = v
            f = _act(v, theta_scale)
            F_new[i, j] = f
            acc += ti.cast(f, ti.f64)
        ti.atomic_add(total, acc)
    return total
