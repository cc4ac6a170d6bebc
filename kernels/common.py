"""Shared Taichi helpers: border handling, rational tanh, lane arrays, launch records."""


import collections
import functools
from types import SimpleNamespace
from typing import Sequence

import numpy as np

from ..taichi_runtime import lanes_override, scalar_kernel
from . import compat

REPLICATE, REFLECT, ZERO = 0, 1, 2
BORDER_CODES = {"replicate": REPLICATE, "reflect": REFLECT, "zero": ZERO}

# ---------------------------------------------------------------------------
# Lane-vectorised kernels on padded lane arrays (the fast path).
#
# Taichi 1.7 on the CPU does not loop-vectorise: every ndarray/field access in a
# loop re-loads its base pointer after each store (the stores may alias the
# argument buffer), so LLVM's loop vectoriser gives up and each pixel costs a
# few scalar loads. It does SLP-vectorise straight-line code on vector-typed
# field elements. The fast path therefore stores a field as a lane array of
# LANES-float32 vectors, shape (H, NB): element (i, e) holds the LANES
# consecutive columns ``(e - 1) * LANES .. e * LANES - 1`` of row i, so column
# c lives at flat position ``LANES + c``. Element 0 and the elements past the
# last column hold "ghost" columns: the values the border mode puts outside
# the frame (replicate/reflect copies, or 0), refreshed by the thread that
# wrote the row, so the stencils read neighbours without any clamping.
# Horizontal neighbours are lane shifts of three consecutive elements.
#
# A lane array is a vector ``ti.ndarray`` (:func:`lane_array`), and the kernels that
# work on lane arrays (C-DNF's and the LGMD family's ``lanes_*``) compile with explicit
# vector types (``taichi_runtime.vector_kernel``): a lane vector stays one LLVM vector,
# which the code generator lowers to the host's widest registers, under both compilers
# (docs/PERFORMANCE.md).
#
# The lane count suits the compiler, and is 32 for both now: with explicit vector types
# every lane model ran faster at 32 lanes than at 16 under quadrants on the Zen 5 host
# (C-DNF 1.3-1.5x, LGMD1/LGMD2/F-LGMD 10-28 % at 426x240; docs/PERFORMANCE.md),
# and taichi's contrast update 1.6x faster; scalarised (rounds 7-13) quadrants had
# preferred 16. $CDNF_TI_LANES overrides it, to measure and tune the layout on another CPU.
# ---------------------------------------------------------------------------

#: Lanes per vector element of the fast path, per compiler.
LANES_BY_COMPILER = {"taichi": 32, "quadrants": 32}


def lane_count(compiler: str) -> int:
    """Lanes per vector element for ``compiler``: ``$CDNF_TI_LANES`` when set, else the measured default.

    Raises
    ------
    UserError
        ``$CDNF_TI_LANES`` is set to an unsupported count (see ``taichi_runtime.lanes_override``).
    """
    override = lanes_override()
    return LANES_BY_COMPILER[compiler] if override is None else override


MAX_STEPS = 32  # updates per launch of the solve kernels (steps_per_launch <= 32): the plain scheme's ~25
# Summation updates of a frame fit one launch, one late-waking pool thread less per frame

# -- launch records --------------------------------------------------------------------
# A solve kernel runs up to MAX_STEPS updates of a fixed point in one launch. Its
# coefficients go in, and its residuals come out, through one small NumPy array (a
# kernel argument), not through a return value: returning a vector costs ~210 us per
# launch on the CPU under taichi 1.7.4 (a NumPy argument ~12 us, zero-copy), and ~1 ms
# on a GPU, where a NumPy argument costs ~0.05-0.15 ms (copied in and out around the
# launch; docs/PERFORMANCE.md).

RECORD_COEFS = 2  # columns 0, 1 of a launch record: lam, mom


class LaunchRecord:
    """The ``(lam, mom)`` in and the residuals out of one solve launch, as one float32 array.

    Row ``j`` of :attr:`array` (shape ``(MAX_STEPS, 2 + fields + values)``) holds update ``j``'s
    ``(lam, mom)`` in columns 0-1 and, after the launch, its residual ``max |F(u) - u|``
    per field in columns 2.. (-1: the update did not run). Row 0's last ``values`` columns
    (from :attr:`values_at`) hold the launch's own values (buffer parities, flags: small
    integers and float32 values that change at every launch), set by :meth:`start`.

    Parameters
    ----------
    fields : int
        Fields updated together (2: ON and OFF; 1: Summation).
    values : int
        The launch's values after the residual columns (0: none).
    """

    def __init__(self, fields: int, values: int = 0):
        self.fields = fields
        self.values_at = RECORD_COEFS + fields
        self.array = np.zeros((MAX_STEPS, RECORD_COEFS + fields + values), np.float32)

    def start(self, coefs: Sequence[tuple[float, float]], values: Sequence[float] = ()) -> np.ndarray:
        """Fill in the coefficients of a launch of ``len(coefs)`` updates and its ``values``; returns
        :attr:`array`."""
        if not 1 <= len(coefs) <= MAX_STEPS:
            raise ValueError(f"1..{MAX_STEPS} updates per launch, got {len(coefs)}")
        a = self.array
        if len(values) != a.shape[1] - self.values_at:
            raise ValueError(f"{a.shape[1] - self.values_at} launch values, got {len(values)}")
        a[: len(coefs), :RECORD_COEFS] = np.asarray(coefs, np.float32).reshape(-1, RECORD_COEFS)
        a[:, RECORD_COEFS:self.values_at] = -1.0
        a[0, self.values_at:] = values
        return a

    def residuals(self, count: int) -> list[tuple[float, ...]]:
        """The residuals of the updates the launch ran, of the first ``count`` (per update, per field)."""
        out = []
        for row in self.array[:count, RECORD_COEFS:self.values_at]:
            if row.min() < 0.0:
                break
            out.append(tuple(float(r) for r in row))
        return out




def unrolled_runs(n: int, run: int = 32) -> list[range]:
    """``1 .. n`` in ranges of at most ``run``: nested ``ti.static`` loops (the compilers warn on unrolling more
    than 32 iterations in one loop)."""
    return [range(d, min(d + run, n + 1)) for d in range(1, n + 1, run)]


def layout(width: int, lanes: int) -> tuple[int, int]:
    """``(E1, NB)`` of a lane array for frames ``width`` px wide: last element holding a frame
    column, elements per row (``lanes`` columns per element, a ghost element either side)."""
    e1 = (lanes + width - 1) // lanes
    return e1, e1 + 2


def context(name: str, fields: str, grid: str | None = None):
    """A named tuple type for a kernel's context: its arguments, read by name in the stages
    (``ctx.u_on``), never by position. Build one in a kernel as ``ti.static(Ctx(...))``.

    ``grid`` names the member whose last two dimensions are the frame's ``(H, W)`` (an array of
    shape (H, W) or (planes, H, W)): the context's ``grid`` property, which a row-run helper
    reads (a property, not a member: it passes nothing more to a function).
    """
    base = collections.namedtuple(name, fields)
    if grid is None:
        return base
    if grid not in base._fields:
        raise ValueError(f"{name}: grid {grid!r} is not one of its members {base._fields}")
    return type(name, (base,), {"__slots__": (), "grid": property(lambda self: getattr(self, grid))})


def namespace(module_globals: dict, local_vars: dict) -> SimpleNamespace:
    """The names a kernel module's ``build`` returns: its module-level constants and helpers
    (``module_globals``, dunders left out) and the kernels it defined (``local_vars``).

    Each plain ``@ti.kernel`` among them is wrapped by :func:`~cdnf_ti.taichi_runtime.scalar_kernel`
    (those made with ``vector_kernel`` already are), so every kernel of the engine compiles
    in the mode it needs whatever other threads compile at the same time.
    """
    names = {k: v for k, v in module_globals.items() if not k.startswith("__") and k != "build"}
    for k, v in local_vars.items():
        if getattr(v, "_is_wrapped_kernel", False) and not hasattr(v, "scalarize"):
            v = scalar_kernel(v)
        names[k] = v
    return SimpleNamespace(**names)


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The kernels of this module for the DSL module ``ti`` (taichi or quadrants) and ``lanes``
    lanes per vector element of the fast path: a namespace of every name below (and the
    module-level constants). Built once per (compiler, lanes), after the runtime started."""
    LANES = lanes
    X = compat.build(ti, lanes)  # the compilers' workarounds
    any_lane, lane_abs, run_max = X.any_lane, X.lane_abs, X.run_max

    F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    #: A stacked state array of the generic kernels: planes of one frame size, (planes, H, W) float32.
    F3 = ti.types.ndarray(dtype=ti.f32, ndim=3)
    #: A backend's coefficients: one small float32 array, set once per backend (each model names its slots).
    COEFS = ti.types.ndarray(dtype=ti.f32, ndim=1)


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


    # -- stage helpers: ``a`` is the engine's cell (kernels/engine.py), a lane vector or one pixel --------
    @ti.func
    def grey_levels(a: ti.template(), scale):
        """The input frame as 8-bit grey levels ``floor(scale g + 0.5)`` (``scale``: 1 for uint8, 255 for
        float frames in [0, 1])."""
        return ti.floor(a.grey() * scale + 0.5)

    @ti.func
    def half_wave(p):
        """``([P]^+, [-P]^+)``: the ON and OFF parts of a luminance change ``P``."""
        return ti.max(p, 0.0), ti.max(0.0 - p, 0.0)

    @ti.func
    def weighted3(coefs: ti.template(), at: ti.template(), centre, edge, diag):
        """``w_c centre + w_e edge + w_d diag``: a symmetric 3x3 kernel on the sums of ``a.window3``, its centre,
        edge and diagonal weights ``coefs[at .. at + 2]`` (``coefs``: the cell's coefficient array ``a.coefs``,
        ``at`` a slot: a stage's helper takes the cell and at most two more)."""
        return coefs[at] * centre + coefs[at + 1] * edge + coefs[at + 2] * diag

    @ti.func
    def mean3(a: ti.template(), plane: ti.template()):
        """The 3x3 mean of ``plane`` (its border outside the frame)."""
        centre, edge, diag = a.window3(plane)
        return (centre + edge + diag) * (1.0 / 9.0)


    @ti.func
    def start_coefficients(coef: ti.template(), at):
        """The 7 local-start coefficients ``coef[at:at + 7]`` (a row of
        :func:`cdnf_ti.solver.cdnf_local_starts`, in a backend's coefficient array) as a vector,
        read once per row of work."""
        return ti.Vector([coef[at], coef[at + 1], coef[at + 2], coef[at + 3], coef[at + 4], coef[at + 5],
                          coef[at + 6]], dt=ti.f32)


    @ti.func
    def local_start(x, c):
        """The stationary level of a uniform input ``x`` (scalar or lane vector), as fitted by
        :func:`cdnf_ti.solver.local_start_coefficients` (``c``: :func:`start_coefficients`):
        ``g0 + x q(t)``, ``x`` clipped to ``[0, x_max]``, ``t = 2 x / x_max - 1``, ``q`` cubic."""
        xc = ti.min(ti.max(x, 0.0), c[1])
        t = xc * c[2] - 1.0
        return c[0] + xc * (c[3] + t * (c[4] + t * (c[5] + t * c[6])))


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


    @ti.kernel
    def fill(x: F2, value: ti.f32):
        """Set every element of ``x`` to ``value``."""
        for i, j in x:
            x[i, j] = value


    def lane_layout(width: int) -> tuple[int, int]:
        """``(E1, NB)``: last element holding a frame column, elements per row (:func:`layout`)."""
        return layout(width, LANES)


    @ti.func
    def lane_shift(a, b, c, s: ti.template()):
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


    #: A lane array argument of an explicit-vector kernel (:func:`~cdnf_ti.taichi_runtime.vector_kernel`):
    #: a vector ndarray of ``LANES`` float32 per element, shape (H, NB) or, with its two ping-pong
    #: buffers first, (2, H, NB).
    LANE2 = ti.types.ndarray(dtype=ti.types.vector(LANES, ti.f32), ndim=2)
    LANE3 = ti.types.ndarray(dtype=ti.types.vector(LANES, ti.f32), ndim=3)


    def lane_array(*lead: int, H: int, NB: int):
        """A lane array for explicit-vector kernels: ``LANES`` float32 per element, shape
        ``(*lead, H, NB)`` (``lead``: ``2`` for a field's two ping-pong buffers)."""
        return ti.ndarray(ti.types.vector(LANES, ti.f32), (*lead, H, NB))


    @ti.func
    def lane_mask(e, W: ti.template()):
        """1.0 on the lanes of element ``e`` that hold frame columns, else 0.0 (only the last one has any)."""
        m = ti.Vector([1.0] * LANES, dt=ti.f32)
        if e == ti.static((LANES + W - 1) // LANES):
            for l in ti.static(range(LANES)):
                if ti.static((W - 1) // LANES * LANES + l >= W):
                    m[l] = 0.0
        return m


    @ti.func
    def lane_get(x: ti.template(), p, i, e):
        """Element ``(i, e)`` of buffer ``p`` of a lane field: ``x[p, i, e]``, or ``x[i, e]`` for a field of
        one buffer."""
        if ti.static(len(x.shape) == 3):
            return x[p, i, e]
        else:
            return x[i, e]


    @ti.func
    def _lane_put(x: ti.template(), p, i, e, lane: ti.template(), val):
        """Set one lane of element ``(i, e)`` of buffer ``p`` (see :func:`lane_get`)."""
        if ti.static(len(x.shape) == 3):
            x[p, i, e][lane] = val
        else:
            x[i, e][lane] = val


    @ti.func
    def fill_lane_ghosts(x: ti.template(), p, i, left: ti.i32, right: ti.i32, W: ti.template(), R: ti.template(),
                         mode: ti.template(), G: ti.template()):
        """Write the ``R`` ghost columns left of column 0 (if ``left``) / right of column W-1 (if ``right``) of row
        ``i`` of buffer ``p`` (ignored for a field of one buffer, see :func:`lane_get`), by the border ``mode``,
        for a row with ``G`` ghost elements either side (column ``c`` at flat position ``G LANES + c``),
        ``R <= G LANES``."""
        if left:
            for run in ti.static(unrolled_runs(R)):
                for d in ti.static(run):
                    g = G * LANES - d  # flat position of column -d
                    val = ti.f32(0.0)
                    if ti.static(mode == REFLECT):
                        val = lane_get(x, p, i, (G * LANES + d) // LANES)[(G * LANES + d) % LANES]
                    elif ti.static(mode == REPLICATE):
                        val = lane_get(x, p, i, G)[0]
                    _lane_put(x, p, i, g // LANES, g % LANES, val)
        if right:
            for run in ti.static(unrolled_runs(R)):
                for d in ti.static(run):
                    g = G * LANES + W - 1 + d
                    val = ti.f32(0.0)
                    if ti.static(mode == REFLECT):
                        s = G * LANES + W - 1 - d
                        val = lane_get(x, p, i, s // LANES)[s % LANES]
                    elif ti.static(mode == REPLICATE):
                        s = G * LANES + W - 1
                        val = lane_get(x, p, i, s // LANES)[s % LANES]
                    _lane_put(x, p, i, g // LANES, g % LANES, val)


    @ti.func
    def lane_edge_diag(x: ti.template(), p, im, i, ip, e):
        """``(centre, edge sum, diagonal sum)`` of the 3x3 windows of the LANES columns of element
        ``(i, e)`` of buffer ``p`` (``im``/``ip``: the rows above and below; ghosts give the border)."""
        c = lane_get(x, p, i, e)
        v = lane_get(x, p, im, e) + lane_get(x, p, ip, e)
        c_lo, c_hi = lane_neighbours(lane_get(x, p, i, e - 1)[LANES - 1], c, lane_get(x, p, i, e + 1)[0])
        v_lo, v_hi = lane_neighbours(lane_get(x, p, im, e - 1)[LANES - 1] + lane_get(x, p, ip, e - 1)[LANES - 1], v,
                                     lane_get(x, p, im, e + 1)[0] + lane_get(x, p, ip, e + 1)[0])
        return c, v + c_lo + c_hi, v_lo + v_hi


    @ti.func
    def lane_neighbours(left, b, right):
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
    def go_on(r, best, tol, grow):
        """Whether to run the next update after one with residual ``r``; the new best residual.

        Stop once ``r <= tol`` (converged) or ``r > grow * best`` (growing: the solver
        restarts the recurrence from here).
        """
        go = ti.select((r > tol) & (r <= grow * best), 1, 0)
        return go, ti.min(best, r)

    return namespace(globals(), locals())
