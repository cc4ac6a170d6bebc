"""Taichi kernels of the stimulus generators: incoherent rendering, rain streaks, blur, blend.

Every kernel is deterministic for any thread count: parallel loops either
write disjoint elements, write the same value to an element (streaks), or
keep per-work-item partial sums that Python adds up in a fixed order.
NumPy float64 references of the same equations live next to their callers
(:mod:`cdnf_ti.stimuli.incoherent`, :mod:`cdnf_ti.stimuli.rain`).
"""

import functools
from types import SimpleNamespace

from . import common
from .common import REFLECT, namespace  # noqa: F401 - part of this module's interface

#: Pixel states of an incoherent stimulus (see :mod:`cdnf_ti.stimuli.incoherent`).
BACKGROUND, KEPT, DISPLACED, TARGET = 0, 1, 2, 3

# Taichi 1.7 hands each CPU thread chunks of the outer loop; a 240-row frame would run on one
# thread if a kernel looped over rows only. The kernels below loop over (row, column block) work
# items instead (:func:`block_span`).
#: Work items per row on the CPU.
COLUMN_BLOCKS = 4
#: Columns per work item on a GPU (a CPU block is rounded up to whole multiples of it).
CHUNK = 16


def column_blocks(width: int, arch: str) -> int:
    """Work items per row of the stimulus kernels for frames ``width`` px wide.

    On the CPU, :data:`COLUMN_BLOCKS` (each thread takes chunks of rows x blocks). On a
    GPU, one item per :data:`CHUNK` columns, so that a 426x240 frame is 6480 GPU threads
    rather than 960 (``block_span`` rounds a block up to whole multiples of ``CHUNK``).

    Parameters
    ----------
    width : int
        Frame width (px).
    arch : str
        The runtime's arch (``"cpu"``, ``"cuda"``, ...), as ``ensure_taichi`` returns it.
    """
    return COLUMN_BLOCKS if arch == "cpu" else max(1, -(-int(width) // CHUNK))


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The kernels of this module for the DSL module ``ti`` (taichi or quadrants) and ``lanes``
    lanes per vector element of the fast path: a namespace of every name below (and the
    module-level constants). Built once per (compiler, lanes), after the runtime started."""
    C = common.build(ti, lanes)
    border_index = C.border_index
    fill = C.fill

    F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    F1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
    D1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    I1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
    B2 = ti.types.ndarray(dtype=ti.i8, ndim=2)


    @ti.func
    def block_span(k, width, blocks):
        """Row ``i`` and column range [j0, j1) of work item ``k`` (row-major items, ``blocks`` per row)."""
        i = k // blocks
        b = k % blocks
        bw = ((width + blocks - 1) // blocks + CHUNK - 1) // CHUNK * CHUNK  # whole multiples of CHUNK
        j0 = ti.min(b * bw, width)
        j1 = ti.min(j0 + bw, width)
        return i, j0, j1

    @ti.kernel
    def incoherent_render(state: B2, out: F2, obj: ti.f32, bg: ti.f32, blocks: ti.i32):
        """``out = obj`` where ``state`` is KEPT or TARGET, else ``bg``.

        KEPT: an object pixel in place; TARGET: a background position holding a
        displaced object pixel; DISPLACED (the source of a displaced pixel) and
        BACKGROUND show the background.
        """
        H, W = state.shape[0], state.shape[1]
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            for j in range(j0, j1):
                s = state[i, j]
                out[i, j] = ti.select((s == KEPT) | (s == TARGET), obj, bg)


    @ti.kernel
    def scatter_state(idx: I1, value: ti.i8, state: B2):
        """``state.flat[idx] = value`` (indices are distinct flat row-major positions)."""
        W = state.shape[1]
        for n in range(idx.shape[0]):
            p = idx[n]
            state[p // W, p % W] = value


    @ti.kernel
    def draw_streaks(row0: I1, col0: F1, slope: F1, length: ti.i32, width: ti.i32, grey: ti.f32, layer: F2):
        """Draw one streak per droplet into ``layer`` (which holds zeros or earlier streaks).

        Droplet ``n`` covers, for ``s = 0 .. length-1``, the pixels
        ``(row0[n] + s, floor(col0[n] + s * slope[n]) + w - (width - 1) // 2)``
        for ``w = 0 .. width-1`` that lie inside the frame, set to ``grey``:
        ``length`` rows downward, ``width`` px across, at ``atan(slope)`` from
        vertical. Overlaps keep ``grey`` (max), so the order does not matter.
        """
        H, W = layer.shape[0], layer.shape[1]
        half = (width - 1) // 2
        for n in range(row0.shape[0]):
            for s in range(length):
                i = row0[n] + s
                jc = ti.cast(ti.floor(col0[n] + s * slope[n]), ti.i32)
                for w in range(width):
                    j = jc + w - half
                    if i >= 0 and i < H and j >= 0 and j < W:
                        ti.atomic_max(layer[i, j], grey)


    @ti.kernel
    def gaussian_blur(src: F2, tmp: F2, dst: F2, g: F1, blocks: ti.i32):
        """Separable blur ``dst = g (*)_y (g (*)_x src)`` with mirrored borders (OpenCV's BORDER_REFLECT_101).

        ``g`` has odd length ``2R + 1``; ``tmp`` is scratch of the frame's shape.
        """
        H, W = src.shape[0], src.shape[1]
        R = (g.shape[0] - 1) // 2
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            for j in range(j0, j1):
                a = 0.0
                for d in range(-R, R + 1):
                    a += g[d + R] * src[i, border_index(j + d, W, REFLECT)]
                tmp[i, j] = a
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            for j in range(j0, j1):
                b = 0.0
                for d in range(-R, R + 1):
                    b += g[d + R] * tmp[border_index(i + d, H, REFLECT), j]
                dst[i, j] = b


    @ti.kernel
    def rain_blend(frame: ti.types.ndarray(ndim=2), rain: F2, out: F2, scale: ti.f32, weight: ti.f32,
                   signal: D1, noise: D1, blocks: ti.i32):
        """``out = clip(frame * scale + weight * rain, 0, 1)`` plus SNR partial sums.

        For work item ``k`` (a row's column block) ``signal[k] = sum f^2`` and
        ``noise[k] = sum (out - f)^2`` over its pixels, in float64, with
        ``f = frame * scale``. Python sums the items in order (deterministic).
        """
        H, W = out.shape[0], out.shape[1]
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            s = ti.f64(0.0)
            e = ti.f64(0.0)
            for j in range(j0, j1):
                f = ti.cast(frame[i, j], ti.f32) * scale
                o = ti.min(ti.max(f + weight * rain[i, j], 0.0), 1.0)
                out[i, j] = o
                s += ti.cast(f, ti.f64) * ti.cast(f, ti.f64)
                d = ti.cast(o, ti.f64) - ti.cast(f, ti.f64)
                e += d * d
            signal[k] = s
            noise[k] = e


    @ti.kernel
    def render_box(out: F2, y0: ti.i32, y1: ti.i32, x0: ti.i32, x1: ti.i32, obj: ti.f32, bg: ti.f32,
                   blocks: ti.i32):
        """``out = obj`` on rows ``y0..y1-1`` x columns ``x0..x1-1`` (clipped to the frame), else ``bg``.

        One axis-aligned rectangle on a uniform background: the looming/receding
        square and the translating bar (:mod:`cdnf_ti.stimuli.basic`). Bounds are
        integers computed in Python, so the frame equals the NumPy reference exactly.
        """
        H, W = out.shape[0], out.shape[1]
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            inside_row = (i >= y0) & (i < y1)
            for j in range(j0, j1):
                out[i, j] = ti.select(inside_row & (j >= x0) & (j < x1), obj, bg)


    @ti.kernel
    def render_grating(out: F2, shift: ti.i32, period: ti.i32, bar: ti.i32, vertical: ti.i32, obj: ti.f32,
                       bg: ti.f32, blocks: ti.i32):
        """Square-wave grating: ``out = obj`` where ``(p - shift) mod period < bar``, else ``bg``.

        ``p`` is the column (``vertical = 1``: vertical bars drifting along x) or the
        row (``vertical = 0``). All integer arithmetic, so the frame equals the
        NumPy reference (:func:`cdnf_ti.stimuli.grating.grating_numpy`) exactly.
        """
        H, W = out.shape[0], out.shape[1]
        for k in range(H * blocks):
            i, j0, j1 = block_span(k, W, blocks)
            for j in range(j0, j1):
                p = ti.select(vertical != 0, j, i)
                q = (p - shift) % period
                q = ti.select(q < 0, q + period, q)
                out[i, j] = ti.select(q < bar, obj, bg)

    return namespace(globals(), locals())
