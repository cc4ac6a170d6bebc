"""The engine core: a model's stages, written once, compiled for the lane layout and the pixel layout.

A model's kernel module declares its names once and writes each stage once:

* :class:`Planes` -- the state planes, by name (``"L P:2 ON:2 S"``; ``:2`` a ping-pong pair whose
  ``now`` buffer is the backend's parity). Every plane lives in one stacked float32 array.
* :class:`Coefs` -- the coefficients by name and size (``Coefs(k_on=6, a1=1)``), filled once per
  backend from the model's ``coefficients()`` by name (:func:`coefficient_array`).
* :class:`Scalars` -- the launch's scalars by name (``Scalars("scale active")``), set per launch.
* :class:`Stage` and :class:`Launch` -- a stage is a ``ti.func stage(a)`` on one *cell* ``a`` (a lane
  vector of columns, or one pixel): it reads ``a.at(PLANE, di, dj)``, writes ``a.put(PLANE, v)`` and
  returns what it reduces (declared by name: ``Stage(fn, sums="sum_G")`` or ``maxes=``).

The accessor's methods are the whole vocabulary of a stage: ``at``, ``put``, ``window3`` (centre, edge
and diagonal sums of a 3x3 window), ``coef``, ``value`` (a launch scalar), ``grey`` / ``event`` (the
input), ``result`` (an earlier stage's reduction in this launch), ``pick`` (a result set at one pixel), ``zeros``,
``put_prefix`` / ``row_sum`` (wide
windows along a row from in-element prefix sums). Borders are engine
options per plane (:func:`borders`): replicate, reflect-101 or zero outside, and the zero ring
(the outermost ring set to 0 on every write).

``build(ti, lanes).kernel(launch, lane, borders)`` compiles a launch for one layout: ``lane=True``
runs its stages on the scheduler's persistent workers over lane arrays (vectors of ``lanes``
columns with ghost columns, explicit vector types: the fast CPU path); ``lane=False`` runs one
parallel loop per stage over the pixels of (planes, H, W) arrays (GPUs, narrow frames).
"""

import functools
from types import SimpleNamespace

from ..taichi_runtime import current_arch, scalar_kernel, vector_kernel
from . import common, compat, schedule
from .common import BORDER_CODES, REFLECT, REPLICATE, ZERO, context
from .schedule import Plan

#: Reductions of one launch, at most (the engine's float64 results, one set per process).
MAX_RESULTS = 8
#: The parts of a launch that a pixel-layout kernel runs, by index (its ``part`` argument: an int, which both
#: compilers' template caches take; a string disables quadrants' cache).
PARTS = ("all", "before", "update", "after")
#: The lowest value a ``maxes`` result starts from.
LOWEST = -3.0e38
#: ``(EMPTY_LO, EMPTY_HI)``: an empty pending span (:class:`Span`).
EMPTY_LO, EMPTY_HI = 1 << 24, -1


class Plane:
    """A named plane of a model's state: ``slot`` in the stacked array; ``buffers`` 2 for a ping-pong pair,
    whose ``now`` (the backend's parity) and ``before`` buffers are :attr:`now` and :attr:`before`."""

    def __init__(self, name: str, slot: int, buffers: int = 1, side: int = 0, bit: int = 0):
        self.name, self.slot, self.buffers, self.side, self.bit = name, slot, buffers, side, bit

    @property
    def now(self) -> "Plane":
        return self if self.buffers == 1 else Plane(self.name, self.slot, 2, 0, self.bit)

    @property
    def before(self) -> "Plane":
        if self.buffers == 1:
            raise ValueError(f"plane {self.name} has one buffer")
        return Plane(self.name, self.slot, 2, 1, self.bit)


class _Names:
    """Declared names: attributes, iteration in order, ``len``."""

    def __init__(self, items: dict):
        self._items = items
        for k, v in items.items():
            setattr(self, k, v)

    def __iter__(self):
        return iter(self._items.values())

    def __len__(self):
        return len(self._items)

    def names(self) -> list[str]:
        return list(self._items)


class Planes(_Names):
    """The state planes of a model, by name: ``Planes("L P:2 S")`` (``:2``: a ping-pong pair)."""

    def __init__(self, spec: str):
        items, slot, pairs = {}, 0, 0
        for word in spec.split():
            name, _, n = word.partition(":")
            items[name] = Plane(name, slot, int(n or 1), bit=pairs)
            slot += items[name].buffers
            pairs += items[name].buffers == 2
        super().__init__(items)
        self.count = slot
        self.pairs = pairs  # the bits of the backend's parity mask (one per pair)


class Coef:
    """A named coefficient of ``size`` values at ``slot`` of the coefficient array."""

    def __init__(self, name: str, slot: int, size: int):
        self.name, self.slot, self.size = name, slot, size


class Coefs(_Names):
    """The coefficients of a model by name and size: ``Coefs(k_on=6, a1=1)``; size 0 (last only): any length."""

    def __init__(self, **sizes: int):
        items, slot = {}, 0
        for name, size in sizes.items():
            items[name] = Coef(name, slot, int(size))
            slot += int(size)
        super().__init__(items)
        self.count = max(slot, 1)


class Scalars(_Names):
    """The scalars of a model's launches by name (``Scalars("scale active")``), set per launch."""

    def __init__(self, spec: str):
        super().__init__({name: Coef(name, k, 1) for k, name in enumerate(spec.split())})
        self.count = max(len(self._items), 1)


def coefficient_array(coefs: Coefs, values: dict) -> "list[float]":
    """The coefficient array (float values, in slot order) of ``values``: one entry per declared name, a
    sequence of its size or a number. Raises ValueError on a missing, unknown or wrongly sized name."""
    unknown = sorted(set(values) - set(coefs.names()))
    missing = sorted(set(coefs.names()) - set(values))
    if unknown or missing:
        raise ValueError(f"coefficients: unknown {unknown}, missing {missing}")
    out = []
    for c in coefs:
        v = values[c.name]
        v = list(v) if hasattr(v, "__len__") else [v]
        if len(v) != c.size and not (c.size == 0 and c is list(coefs)[-1]):  # size 0, last: any length
            raise ValueError(f"coefficient {c.name}: {c.size} values, got {len(v)}")
        out += [float(x) for x in v]
    return out or [0.0]


class Span:
    """A group of fields' *pending spans* (lane layout): per row and parity of ``pair`` (the pair the group
    follows), the lane elements ``[lo, hi]`` where something changed since the group was last updated there.
    They live in element 0 of the model's scratch plane ``store`` (lanes 0-3: ``lo``, ``hi`` of parity 0,
    then of parity 1; float32, exact for any width). A frame's first state, and :meth:`reset`, mark every
    element pending."""

    def __init__(self, store: Plane, pair: Plane):
        if store.buffers != 1 or pair.buffers != 2:
            raise ValueError("a span group is kept in a plane of one buffer and follows a pair")
        self.store, self.pair = store, pair


class Stage:
    """A stage: ``fn(a)`` on every cell, then the reductions of what it returns (``sums``/``maxes``: the
    names of its results, in the order it returns them; one kind per stage), the ghost columns of the
    planes in ``ghosts`` refreshed after each row (lane layout; ``halo`` columns). An update stage of a
    solve returns ``residuals`` (1 or 2) values instead, maxed per update (:class:`Launch`).

    A **relaxation** update (``relax``: 1 or 2 pairs) returns ``d = F(u) - u`` of each pair instead (``u``
    its ``now`` buffer at this update); the engine writes ``u + mom (u - prev) + lam d`` (``lam, mom`` the
    record's columns 0, 1; ``prev`` the ``before`` buffer, which it overwrites) and maxes ``|d|`` as the
    residuals; the solve's updates alternate the pairs' buffers. On the lane layout, lanes with
    ``|d| <= tau`` (the launch scalar ``tau``) keep ``u`` exactly, and with ``spans`` (a :class:`Span`)
    the update visits only the elements within one element and ``rows`` rows (a number or an option's
    name) of a pending span of its parity, and leaves the elements it moved as the other parity's spans;
    it refreshes the ghost columns (``halo``) of the buffers it wrote. A stage with ``spans`` and no
    ``relax`` visits the same elements and does nothing else (a pass an update reads). A stage that
    ``marks`` a span group returns whether it changed anything at the cell (``a.any(...)``): those
    elements become pending in both parities. The pixel layout visits every pixel and never freezes.

    An update that writes a pair's ``before`` buffer itself (``turns``: the pairs; an iteration that is no
    relaxation, or one that must keep its own order of operations) has its buffers alternated as a
    relaxation's are, with no freezing; it lists the ``before`` buffers in ``ghosts``.

    ``picks``: more results, each a value the stage sets at one frame pixel (``a.pick(name, value, row, column)``;
    0 where no cell sets it), after the reductions in the launch's results."""

    def __init__(self, fn, sums: str = "", maxes: str = "", ghosts=(), halo: "int | str" = 1, residuals: int = 0,
                 relax=(), spans: "Span | None" = None, rows: "int | str" = 0, marks: "Span | None" = None,
                 turns=(), picks: str = ""):
        if sums and maxes:
            raise ValueError("a stage reduces by one kind (sums or maxes)")
        self.picks = tuple(picks.split())
        if self.picks and (residuals or relax or marks is not None or spans is not None):
            raise ValueError("a stage that picks values is no update and visits every cell")
        relax, turns = tuple(relax), tuple(turns)
        residuals = len(relax) or int(residuals)
        if residuals and (sums or maxes or residuals > 2):
            raise ValueError("an update stage returns its 1 or 2 residuals only")
        if marks is not None and (sums or maxes or relax or spans is not None):
            raise ValueError("a stage that marks spans returns whether it changed the cell only")
        if any(p.buffers != 2 for p in relax + turns) or (
                spans is not None and relax and spans.pair.slot != relax[0].slot):
            raise ValueError("a relaxation updates pairs, and its spans follow its first pair")
        self.fn, self.ghosts, self.halo, self.residuals = fn, tuple(ghosts), halo, residuals
        self.relax, self.spans, self.rows, self.marks, self.turns = relax, spans, rows, marks, turns
        self.marking = marks is not None
        self.results = tuple((sums or maxes).split())
        self.kind = "max" if maxes else "sum"
        if len(self.results) > 2:
            raise ValueError("a stage returns at most two results")

    @property
    def visits(self) -> bool:
        """Whether the engine's span iterator runs the stage (lane layout)."""
        return bool(self.relax) or self.spans is not None or self.marks is not None


class Launch:
    """A launch: its stages one after another (a barrier between two), its results named by its stages.

    A solve also has ``update`` stages (at most 2): after the ``before`` stages, up to ``updates`` updates
    run while the residuals they return stay above ``tol`` and do not grow past ``grow`` times the best
    (those three are launch scalars of ``scalars``), then ``stages`` run if the solve converged. An update
    reads its index as ``a.step`` and its row of the launch record as ``a.record(k)``. The pairs its
    relaxation stages update alternate their buffers: at update ``j``, and in ``stages`` after ``j``
    updates, their ``now`` is the buffer ``j`` turns past the backend's parity."""

    def __init__(self, name: str, *stages: Stage, update=(), before=(), scalars: "Scalars | None" = None):
        self.name, self.stages = name, tuple(stages)
        self.update, self.before = tuple(update), tuple(before)
        self.fields = max((s.residuals for s in self.update), default=0)
        self.controls = None
        if self.update:
            if scalars is None or not all(hasattr(scalars, n) for n in ("updates", "tol", "grow")):
                raise ValueError(f"{name}: a solve needs the launch scalars updates, tol, grow")
            self.controls = (scalars.updates.slot, scalars.tol.slot, scalars.grow.slot)
        #: the pairs the updates alternate (bits of the backend's parity mask)
        self.alternates = tuple(sorted({p.bit for s in self.update for p in s.relax + s.turns}))
        self.tau = None
        if any(s.relax for s in self.update):
            if not hasattr(scalars, "tau"):
                raise ValueError(f"{name}: a relaxation needs the launch scalar tau")
            self.tau = scalars.tau.slot
        stages = self.before + self.stages
        self.results = tuple(r for s in stages for r in s.results + s.picks)
        if len(self.results) > MAX_RESULTS:
            raise ValueError(f"{name}: at most {MAX_RESULTS} results")
        self.kinds = tuple(kind for s in stages for kind in (s.kind,) * len(s.results) + ("pick",) * len(s.picks))
        self.starts = tuple(LOWEST if kind == "max" else 0.0 for kind in self.kinds)

    def slot(self, result: str) -> int:
        return self.results.index(result)


class Layout:
    """The compile-time choices of a launch's kernel: lane layout or not, frame width (lanes), the border
    of every plane (``modes``: slot -> (mode, ring)), the model's compile-time options (``options``:
    ``(name, value)`` pairs, e.g. a stencil's radius), the launch."""

    def __init__(self, launch: Launch, lane: bool, W: int, modes: tuple, options: tuple = (), ghosts: int = 1):
        self.launch, self.lane, self.W, self.modes, self.options = launch, lane, W, dict(modes), dict(options)
        self.ghosts = ghosts  # the lane arrays' ghost elements either side (:func:`ghost_elements`)

    def halo(self, stage: "Stage") -> int:
        """The ghost columns ``stage`` refreshes: its ``halo``, a number or the name of an option."""
        return self.options[stage.halo] if isinstance(stage.halo, str) else stage.halo

    def rows(self, stage: "Stage") -> int:
        """The rows either side of a pending span that ``stage`` visits: its ``rows``, a number or an option."""
        return self.options[stage.rows] if isinstance(stage.rows, str) else stage.rows

    def turns(self, plane: Plane) -> bool:
        """Whether ``plane`` is a pair that the launch's updates alternate."""
        return plane.buffers == 2 and plane.bit in self.launch.alternates

    def border(self, plane: Plane) -> tuple[int, bool]:
        return self.modes.get(plane.slot, (REPLICATE, False))


def ghost_elements(launches, options: dict, lanes: int) -> int:
    """The ghost elements either side of a lane row for ``launches``: enough for the widest ``halo`` of their
    stages (a number or an option's name, in ``options``), at least 1: ``ceil(max halo / lanes)``."""
    halos = [options[s.halo] if isinstance(s.halo, str) else s.halo
             for launch in launches for s in launch.before + launch.update + launch.stages]
    return max(1, -(-max(halos, default=1) // lanes))


def borders(planes: Planes, spec: dict) -> tuple:
    """The border options ``spec`` (plane name -> ``"replicate"``, ``"reflect"`` (reflect-101), ``"zero"``,
    each optionally with ``"+ring"``: the outermost ring set to 0 on every write) as a hashable tuple."""
    out = []
    for name, mode in sorted(spec.items()):
        base, _, ring = mode.partition("+")
        if base not in BORDER_CODES or ring not in ("", "ring") or not hasattr(planes, name):
            raise ValueError(f"border of {name}: {mode!r}")
        out.append((getattr(planes, name).slot, (BORDER_CODES[base], ring == "ring")))
    return tuple(out)


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The engine for the DSL module ``ti`` and ``lanes`` lanes per vector: :func:`kernel` and the cells."""
    LANES = lanes
    C = common.build(ti, lanes)
    run_max = compat.build(ti, lanes).run_max
    sched = schedule.build(ti, lanes)
    workers = sched.workers
    res = ti.field(ti.f64, MAX_RESULTS)  # a launch's reductions
    F1 = C.COEFS
    D1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    Ctx = context("EngineCtx", "x coef fr frame c nw spec rec")
    F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)

    @ti.func
    def _index(c, plane: ti.template(), turn):
        """The slot of ``plane``: a pair's buffer by its bit of the parity mask ``c``, turned ``turn`` times."""
        k = plane.slot
        if ti.static(plane.buffers == 2):
            p = ((c >> ti.static(plane.bit)) ^ turn) & 1
            k = plane.slot + p
            if ti.static(plane.side == 1):
                k = plane.slot + 1 - p
        return k

    @ti.func
    def _turn(spec: ti.template(), plane: ti.template(), j):
        """How many times the launch's updates turned ``plane``'s buffers at update (or after) ``j``."""
        t = 0
        if ti.static(spec.turns(plane)):
            t = j
        return t

    @ti.func
    def _rows(i, H, mode: ti.template()):
        """The rows above and below ``i``, mapped by the border ``mode`` (zero: clamped, weighed by the caller)."""
        im, ip = ti.max(i - 1, 0), ti.min(i + 1, H - 1)
        if ti.static(mode == REFLECT):
            im, ip = ti.select(i == 0, 1, i - 1), ti.select(i == H - 1, H - 2, i + 1)
        return im, ip

    # -- the lane layout: element (k, i, e) holds the columns (e - G) LANES .. (e - G + 1) LANES - 1 of row i,
    # G ghost elements either side (Layout.ghosts) ------------------------------------------------------
    @ti.func
    def _lane_at(x: ti.template(), k, i, e, mode: ti.template(), di: ti.template(), dj: ti.template()):
        r = i
        if ti.static(di != 0):
            r = C.border_index(i + di, x.shape[1], mode)
        v = x[k, r, e]
        if ti.static(dj != 0 and -LANES < dj < LANES):
            v = C.lane_shift(x[k, r, e - 1], x[k, r, e], x[k, r, e + 1], dj)
        elif ti.static(dj != 0):  # a wide offset: element e + q, shifted by the rest
            q = ti.static(dj // LANES)
            v = x[k, r, e + q]
            if ti.static(dj - q * LANES != 0):
                v = C.lane_shift(x[k, r, e + q - 1], x[k, r, e + q], x[k, r, e + q + 1], dj - q * LANES)
        if ti.static(mode == ZERO and di != 0):
            v = v * C.border_weight(i + di, x.shape[1], mode)
        return v

    @ti.func
    def _lane_prefix(v):
        """Inclusive prefix sums of the lane vector ``v`` (``out[l] = v[0] + ... + v[l]``): log2(LANES) shifted adds."""
        out = v
        for s in ti.static([1 << b for b in range(LANES.bit_length() - 1)]):
            shifted = _lane_zeros()
            for q in ti.static(range(s, LANES)):
                shifted[q] = out[q - s]
            out = out + shifted
        return out

    @ti.func
    def _lane_totals(x: ti.template(), k, i, e, m: ti.template()):
        """The row's sum from the start of element ``e`` to the start of element ``e + m`` (negative for ``m < 0``):
        the totals (last lanes) of the whole elements between, read from in-element prefixes."""
        d = ti.f32(0.0)
        for q in ti.static(range(min(m, 0), max(m, 0))):
            d += x[k, i, e + q][LANES - 1]
        if ti.static(m < 0):
            d = -d
        return d

    @ti.func
    def _lane_prefix_at(x: ti.template(), k, i, e, d: ti.template()):
        """Per lane (column ``c``) of element ``e``: the row's sum up to column ``c + d`` inclusive, less its sum before
        element ``e``, from the in-element prefixes of plane ``k`` (a few local numbers, no running total)."""
        q = ti.static(d // LANES)
        r = ti.static(d - q * LANES)
        here = x[k, i, e + q] + _lane_totals(x, k, i, e, q)
        out = here
        if ti.static(r > 0):
            out = C.lane_shift(here, here, x[k, i, e + q + 1] + _lane_totals(x, k, i, e, q + 1), r)
        return out

    @ti.func
    def _pixel_row_sum(x: ti.template(), k, i, j, k0: ti.template(), k1: ti.template()):
        """``sum_{d = k0 .. k1} x[k, i, j + d]`` (0 outside the frame), summed in float64 from ``k0``, as float32."""
        s = ti.f64(0.0)
        for run in ti.static(common.unrolled_runs(k1 - k0 + 1)):
            for d in ti.static(run):
                s += ti.cast(_pixel_at(x, k, i, j, ZERO, 0, k0 - 1 + d), ti.f64)
        return ti.cast(s, ti.f32)

    @ti.func
    def _lane_window3(x: ti.template(), k, i, e, mode: ti.template()):
        im, ip = _rows(i, x.shape[1], mode)
        return C.lane_edge_diag(x, k, im, i, ip, e)

    @ti.func
    def _lane_smooth3(x: ti.template(), k, i, e, mode: ti.template(), k0, k1):
        """``W (*) x`` for ``W = k k^T``, ``k = (k1, k0, k1)``: vertical sums ``c = k0 u[i] + k1 (u[i-1] + u[i+1])``
        of the element and its neighbours' adjacent lanes, then ``k0 c + k1 (c[j-1] + c[j+1])``."""
        H = x.shape[1]
        im, ip = C.border_index(i - 1, H, mode), C.border_index(i + 1, H, mode)
        wim, wip = ti.f32(C.border_weight(i - 1, H, mode)), ti.f32(C.border_weight(i + 1, H, mode))
        c_left = k0 * x[k, i, e - 1][LANES - 1] + k1 * (wim * x[k, im, e - 1][LANES - 1]
                                                        + wip * x[k, ip, e - 1][LANES - 1])
        c_cur = k0 * x[k, i, e] + k1 * (wim * x[k, im, e] + wip * x[k, ip, e])
        c_right = k0 * x[k, i, e + 1][0] + k1 * (wim * x[k, im, e + 1][0] + wip * x[k, ip, e + 1][0])
        left, right = C.lane_neighbours(c_left, c_cur, c_right)
        return k0 * c_cur + k1 * (left + right)

    @ti.func
    def _lane_put(x: ti.template(), k, i, e, v, ring: ti.template(), spec: ti.template()):
        if ti.static(ring):
            v = v * _lane_within(i, e, 1, x.shape[1] - 1, 1, spec.W - 1, spec.ghosts)
        x[k, i, e] = v

    @ti.func
    def _lane_within(i, e, r0, r1, c0, c1, G: ti.template()):
        """1.0 on the lanes of element ``(i, e)`` in rows [r0, r1) and columns [c0, c1), else 0.0."""
        m = ti.Vector([0.0] * LANES, dt=ti.f32)
        row = (i >= r0) & (i < r1)
        for q in ti.static(range(LANES)):
            col = (e - G) * LANES + q
            m[q] = ti.select(row & (col >= c0) & (col < c1), 1.0, 0.0)
        return m

    @ti.func
    def _lane_pick(slot: ti.template(), v, i, e, r, c, G: ti.template(), W: ti.template()):
        """The result ``slot`` = the lane of ``v`` at frame pixel ``(r, c)`` if element ``(i, e)`` holds it."""
        if (i == r) & ((e - G) * LANES <= c) & (c < ti.min((e - G + 1) * LANES, W)):
            for q in ti.static(range(LANES)):
                if (e - G) * LANES + q == c:
                    res[slot] = ti.cast(v[q], ti.f64)

    @ti.func
    def _pixel_pick(slot: ti.template(), v, i, j, r, c):
        if (i == r) & (j == c):
            res[slot] = ti.cast(v, ti.f64)

    @ti.func
    def _pixel_within(i, j, r0, r1, c0, c1):
        return ti.select((i >= r0) & (i < r1) & (j >= c0) & (j < c1), 1.0, 0.0)

    @ti.func
    def _lane_input(frame: ti.template(), i, e, plane: ti.template(), spec: ti.template()):
        """The input's columns of element ``(i, e)`` (plane ``plane`` of an event bin; past W - 1: the last)."""
        W = ti.static(spec.W)
        G = ti.static(spec.ghosts)
        g = ti.Vector([0.0] * LANES, dt=ti.f32)
        for q in ti.static(range(LANES)):
            jj = ti.min((e - G) * LANES + q, W - 1)
            if ti.static(len(frame.shape) == 3):
                g[q] = ti.cast(frame[plane, i, jj], ti.f32)
            else:
                g[q] = ti.cast(frame[i, jj], ti.f32)
        return g

    @ti.func
    def _lane_zeros():
        return ti.Vector([0.0] * LANES, dt=ti.f32)

    @ti.func
    def _pixel_zeros():
        return ti.f32(0.0)

    @ti.func
    def _read(array: ti.template(), k: ti.template()):
        """``array[k]`` (a coefficient, a launch scalar, a result)."""
        return array[k]

    @ti.func
    def _read2(array: ti.template(), j, k: ti.template()):
        """``array[j, k]`` (a launch record's entry)."""
        return array[j, k]

    # -- the pixel layout: (planes, H, W) arrays, one pixel per cell ---------------------------------
    @ti.func
    def _pixel_at(x: ti.template(), k, i, j, mode: ti.template(), di: ti.template(), dj: ti.template()):
        H, W = x.shape[1], x.shape[2]
        r, s = i, j
        if ti.static(di != 0):
            r = C.border_index(i + di, H, mode)
        if ti.static(dj != 0):
            s = C.border_index(j + dj, W, mode)
        v = x[k, r, s]
        if ti.static(mode == ZERO and (di != 0 or dj != 0)):
            v = v * C.border_weight(i + di, H, mode) * C.border_weight(j + dj, W, mode)
        return v

    @ti.func
    def _pixel_window3(x: ti.template(), k, i, j, mode: ti.template()):
        """The sums of :func:`C.lane_edge_diag` as its vector code computes them (the edge sum pairwise)."""
        v = _pixel_at(x, k, i, j, mode, -1, 0) + _pixel_at(x, k, i, j, mode, 1, 0)
        edge = v + (_pixel_at(x, k, i, j, mode, 0, -1) + _pixel_at(x, k, i, j, mode, 0, 1))
        diag = (_pixel_at(x, k, i, j, mode, -1, -1) + _pixel_at(x, k, i, j, mode, 1, -1)) + (
            _pixel_at(x, k, i, j, mode, -1, 1) + _pixel_at(x, k, i, j, mode, 1, 1))
        return _pixel_at(x, k, i, j, mode, 0, 0), edge, diag

    @ti.func
    def _pixel_smooth3(x: ti.template(), k, i, j, mode: ti.template(), w0, w1, w2):
        """``W (*) x`` for a symmetric 3x3 ``W``: centre weight ``w0``, edge ``w1``, diagonal ``w2``."""
        H, W = x.shape[1], x.shape[2]
        im, ip = C.border_index(i - 1, H, mode), C.border_index(i + 1, H, mode)
        jm, jp = C.border_index(j - 1, W, mode), C.border_index(j + 1, W, mode)
        wim, wip = C.border_weight(i - 1, H, mode), C.border_weight(i + 1, H, mode)
        wjm, wjp = C.border_weight(j - 1, W, mode), C.border_weight(j + 1, W, mode)
        edge = wim * x[k, im, j] + wip * x[k, ip, j] + wjm * x[k, i, jm] + wjp * x[k, i, jp]
        diag = wim * (wjm * x[k, im, jm] + wjp * x[k, im, jp]) + wip * (wjm * x[k, ip, jm] + wjp * x[k, ip, jp])
        return w0 * x[k, i, j] + w1 * edge + w2 * diag

    @ti.func
    def _pixel_put(x: ti.template(), k, i, j, v, ring: ti.template()):
        if ti.static(ring):
            H, W = x.shape[1], x.shape[2]
            v = v * ti.select((i > 0) & (i < H - 1) & (j > 0) & (j < W - 1), 1.0, 0.0)
        x[k, i, j] = v

    @ti.func
    def _pixel_input(frame: ti.template(), i, j, plane: ti.template()):
        g = ti.f32(0.0)
        if ti.static(len(frame.shape) == 3):
            g = ti.cast(frame[plane, i, j], ti.f32)
        else:
            g = ti.cast(frame[i, j], ti.f32)
        return g

    def _dsl(method):
        """Mark an accessor method as part of the DSL: both compilers call it while they build a stage (it emits
        the stage's loads and stores) and warn about any plain Python function they call but these."""
        method._is_taichi_function = method._is_quadrants_function = False
        return method

    class Cell:
        """What a stage sees of one cell: a lane vector of columns (element ``j``) or one pixel (column
        ``j``) of row ``i``. Its methods are the stages' vocabulary (module docstring). Its members are
        the launch's arrays, the pairs' parity, the position, the first result and the update; the
        compile-time choices (:class:`Layout`) are its class's ``spec``, not a member."""

        __slots__ = ("x", "coefs", "fr", "frame", "rec", "c", "i", "j", "got", "step")
        spec: Layout
        _is_taichi_function = _is_quadrants_function = False  # made while a stage compiles (see _dsl)

        def __init__(self, ctx, i, j, got=(), step=0):
            self.x, self.coefs, self.fr, self.frame, self.rec = ctx.x, ctx.coef, ctx.fr, ctx.frame, ctx.rec
            self.c = ctx.c
            self.i, self.j, self.got = i, j, got  # got: the first result, read once per chunk of rows
            self.step = step  # the update of a solve

        @property
        def lane(self) -> bool:
            return self.spec.lane

        @property
        def events(self) -> bool:
            """Whether the launch's input is an event bin (2, H, W) of ``(p_on, p_off)``."""
            return len(self.frame.shape) == 3

        @_dsl
        def _k(self, plane):
            return _index(self.c, plane, self.step if self.spec.turns(plane) else 0)

        @_dsl
        def at(self, plane, di=0, dj=0):
            """``plane`` at row offset ``di`` and column offset ``dj`` (its border outside the frame)."""
            mode = self.spec.border(plane)[0]
            return (_lane_at if self.lane else _pixel_at)(self.x, self._k(plane), self.i, self.j, mode, di, dj)

        @_dsl
        def window3(self, plane):
            """``(centre, edge sum, diagonal sum)`` of the 3x3 window of ``plane``."""
            mode = self.spec.border(plane)[0]
            return (_lane_window3 if self.lane else _pixel_window3)(self.x, self._k(plane), self.i, self.j, mode)

        @_dsl
        def smooth3(self, plane, k, w):
            """``W (*) plane`` for a symmetric separable 3x3 ``W = k k^T`` (``k``: a coefficient ``(k0, k1)``,
            ``k = (k1, k0, k1)``; ``w``: W's centre, edge and diagonal weights): summed separably on the lane
            layout, by weights on the pixel layout (two roundings of the same sum)."""
            mode = self.spec.border(plane)[0]
            if self.lane:
                return _lane_smooth3(self.x, self._k(plane), self.i, self.j, mode, self.coef(k, 0), self.coef(k, 1))
            return _pixel_smooth3(self.x, self._k(plane), self.i, self.j, mode, self.coef(w, 0), self.coef(w, 1),
                                  self.coef(w, 2))

        @_dsl
        def taps(self, plane, name: str, vertical: bool = False):
            """``sum_d g[d] plane(offset d)``, ``d = -R .. R`` along the columns (rows if ``vertical``), for the
            symmetric taps ``g`` (``2 R + 1`` floats), the compile-time option ``name`` (constants in the code):
            the lane layout adds the centre, then the pairs ``g[d] (x[-d] + x[d])``; the pixel layout adds the
            taps in order from ``-R``."""
            g = self.spec.options[name]
            R = len(g) // 2

            def at(d):
                return self.at(plane, d, 0) if vertical else self.at(plane, 0, d)

            if self.lane:
                acc = g[R] * at(0)
                for d in range(1, R + 1):
                    acc = acc + g[R + d] * (at(-d) + at(d))
                return acc
            acc = self.zeros()
            for d in range(-R, R + 1):
                acc = acc + g[R + d] * at(d)
            return acc

        @_dsl
        def frame_mask(self):
            """1.0 on the cell's frame columns, 0.0 on a lane past the frame's last column."""
            return C.lane_mask(self.j - (self.spec.ghosts - 1), self.spec.W) if self.lane else 1.0

        @_dsl
        def put(self, plane, value):
            """Write ``value`` to ``plane`` here (0 on the outermost ring of a plane with the zero ring)."""
            ring = self.spec.border(plane)[1]
            if self.lane:
                _lane_put(self.x, self._k(plane), self.i, self.j, value, ring, self.spec)
            else:
                _pixel_put(self.x, self._k(plane), self.i, self.j, value, ring)

        @_dsl
        def put_prefix(self, plane, value):
            """Write ``value`` to ``plane`` for :meth:`row_sum`: on the lane layout as its in-element inclusive prefix
            sums (the lanes past the frame's last column as 0), on the pixel layout as it is."""
            if self.lane:
                value = _lane_prefix(value * self.frame_mask())
            self.put(plane, value)

        @_dsl
        def row_sum(self, plane, k0: int, k1: int):
            """``sum_{d = k0 .. k1} plane(column + d)`` (compile-time ``k0 <= k1``; 0 outside the frame) of a plane of
            the zero border written by :meth:`put_prefix`: on the lane layout the difference of two prefixes, each
            read from at most two elements and the totals of the elements between (float32; ``k0 - 1`` and ``k1``
            within the stage's ghost elements: give the stage ``halo >= max(1 - k0, k1)``); on the pixel layout
            the terms summed in float64."""
            if self.spec.border(plane) != (ZERO, False) or k0 > k1:
                raise ValueError(f"row_sum of {plane.name}: a plane of the zero border (no ring), k0 <= k1")
            if not self.lane:
                return _pixel_row_sum(self.x, self._k(plane), self.i, self.j, k0, k1)
            reach = max(-((k0 - 1) // LANES), k1 // LANES + (k1 % LANES > 0))  # elements read either side
            if reach > self.spec.ghosts:
                raise ValueError(f"row_sum of {plane.name} over {k0}..{k1} reads {reach} ghost elements, the launch "
                                 f"has {self.spec.ghosts}: give the stage halo >= {max(1 - k0, k1)}")
            k = self._k(plane)
            return _lane_prefix_at(self.x, k, self.i, self.j, k1) - _lane_prefix_at(self.x, k, self.i, self.j, k0 - 1)

        @_dsl
        def coef(self, c, k=0):
            """Value ``k`` of the coefficient ``c``."""
            return _read(self.coefs, c.slot + k)

        @_dsl
        def value(self, s):
            """The launch scalar ``s``."""
            return _read(self.fr, s.slot)

        @_dsl
        def option(self, name: str):
            """The model's compile-time option ``name`` (a Python value: use it in ``ti.static``)."""
            return self.spec.options[name]

        @_dsl
        def grey(self):
            """The input frame here (float32, as stored: grey levels or [0, 1])."""
            return self.event(0)

        @_dsl
        def event(self, polarity: int):
            """Plane ``polarity`` (0: ON, 1: OFF) of an event bin here."""
            if self.lane:
                return _lane_input(self.frame, self.i, self.j, polarity, self.spec)
            return _pixel_input(self.frame, self.i, self.j, polarity)

        @_dsl
        def within(self, r0, r1, c0, c1):
            """1.0 where the cell's row is in [r0, r1) and its column in [c0, c1) (frame coordinates), else 0.0
            (per lane on the lane layout): a mask of a part of the frame."""
            if self.lane:
                return _lane_within(self.i, self.j, r0, r1, c0, c1, self.spec.ghosts)
            return _pixel_within(self.i, self.j, r0, r1, c0, c1)

        @_dsl
        def record(self, k: int):
            """Column ``k`` of this update's row of the launch record (a solve's per-update coefficients)."""
            return _read2(self.rec, self.step, k)

        @_dsl
        def result(self, name: str):
            """An earlier stage's reduction ``name`` in this launch (float64)."""
            k = self.spec.launch.slot(name)
            return self.got[k] if k < len(self.got) else _read(res, k)

        @_dsl
        def pick(self, name: str, value, r, c):
            """Set the result ``name`` (one of the stage's ``picks``) to ``value`` at frame row ``r``, column ``c``:
            the cell holding that pixel writes it (float64), the others nothing."""
            if self.lane:
                _lane_pick(self.spec.launch.slot(name), value, self.i, self.j, r, c, self.spec.ghosts, self.spec.W)
            else:
                _pixel_pick(self.spec.launch.slot(name), value, self.i, self.j, r, c)

        @_dsl
        def any(self, cond):
            """Whether ``cond`` holds on any lane of the cell (a stage that marks spans returns it)."""
            return C.any_lane(cond) if self.lane else ti.select(cond, 1, 0)

        @_dsl
        def zeros(self):
            """A zero value of the cell's type."""
            return _lane_zeros() if self.lane else _pixel_zeros()

    def _cell_class(spec: Layout):
        """The cells of one kernel: :class:`Cell` with that kernel's compile-time choices."""
        return type("Cell", (Cell,), {"__slots__": (), "spec": spec})

    # -- the cell action, shared by both layouts: a stage at one cell, and what it gives the reductions --------
    @ti.func
    def _start_of(stage: ti.template()):
        """Where ``stage``'s reductions start on a chunk of rows (lane layout): its results' (float64 0, or
        :data:`LOWEST` for maxes), an update's residuals' (float32 0: a relaxation's lane maxima; else lane
        vectors, maxed lane by lane)."""
        if ti.static(len(stage.results) > 0):
            start = ti.static(0.0 if stage.kind == "sum" else LOWEST)
            return ti.f64(start), ti.f64(start)
        elif ti.static(stage.residuals > 0 and len(stage.relax) == 0):
            return _lane_zeros(), _lane_zeros()
        else:
            return ti.f32(0.0), ti.f32(0.0)

    @ti.func
    def _accumulate(stage: ti.template(), acc, v, e, W: ti.template()):
        """``acc`` with what the cell of element ``e`` (counted from 1: the lanes past ``W`` masked) gave (lane
        layout): a result reduced over its frame lanes in float64 and summed or maxed, a residual maxed."""
        out = acc
        if ti.static(len(stage.results) > 0):
            r = ti.f64(0.0)
            if ti.static(stage.kind == "max"):
                r = ti.cast(run_max(v * C.lane_mask(e, W), LANES), ti.f64)
            else:
                r = ti.cast((v * C.lane_mask(e, W)).sum(), ti.f64)
            out = _combine(acc, r, stage.kind)
        else:
            out = ti.max(acc, v)
        return out

    @ti.func
    def _combine(acc, r, kind: ti.template()):
        out = acc + r
        if ti.static(kind == "max"):
            out = ti.max(acc, r)
        return out

    @ti.func
    def _publish(slot: ti.template(), acc, kind: ti.template()):
        if ti.static(kind == "max"):
            ti.atomic_max(res[slot], acc)
        else:
            ti.atomic_add(res[slot], acc)

    # -- pending spans (lane layout): the elements a span group's stage visits, and what it leaves ------------
    @ti.func
    def _span_get(x: ti.template(), k, r, lane: ti.template()):
        return ti.cast(x[k, r, 0][lane], ti.i32)

    @ti.func
    def _visit(x: ti.template(), k, p, i, rows, E1: ti.template()):
        """Elements ``[e0, e1)`` to visit in row ``i``: one either side of the pending spans of parity ``p`` of
        rows ``i - rows .. i + rows`` (clipped) of the span plane ``k``."""
        lo, hi = EMPTY_LO, EMPTY_HI
        for r in range(ti.max(i - rows, 0), ti.min(i + rows, x.shape[1] - 1) + 1):
            lo = ti.min(lo, ti.select(p == 0, _span_get(x, k, r, 0), _span_get(x, k, r, 2)))
            hi = ti.max(hi, ti.select(p == 0, _span_get(x, k, r, 1), _span_get(x, k, r, 3)))
        return ti.max(lo - 1, 1), ti.min(hi + 1, E1) + 1

    @ti.func
    def _span_set(x: ti.template(), k, i, p, lo, hi):
        """Parity ``p``'s span of row ``i`` = ``[lo, hi]``."""
        if p == 0:
            C._lane_put(x, k, i, 0, 0, ti.cast(lo, ti.f32))
            C._lane_put(x, k, i, 0, 1, ti.cast(hi, ti.f32))
        else:
            C._lane_put(x, k, i, 0, 2, ti.cast(lo, ti.f32))
            C._lane_put(x, k, i, 0, 3, ti.cast(hi, ti.f32))

    @ti.func
    def _span_mark(x: ti.template(), k, i, lo, hi):
        """Both parities' spans of row ``i`` grow to include ``[lo, hi]``."""
        if lo <= hi:
            _span_set(x, k, i, 0, ti.min(_span_get(x, k, i, 0), lo), ti.max(_span_get(x, k, i, 1), hi))
            _span_set(x, k, i, 1, ti.min(_span_get(x, k, i, 2), lo), ti.max(_span_get(x, k, i, 3), hi))

    @ti.func
    def _settle(a: ti.template(), pair: ti.template(), d):
        """The relaxation of ``pair`` at the cell ``a`` by ``d = F(u) - u`` (see :class:`Stage`); returns ``|d|``
        (lane layout: 0 off the frame) and whether a value moved (lane layout: ``|d| > tau`` on a lane)."""
        k_u, k_prev = a._k(pair.now), a._k(pair.before)
        u, prev = a.x[k_u, a.i, a.j], a.x[k_prev, a.i, a.j]
        nx = u + a.record(1) * (u - prev) + a.record(0) * d
        ad = a.zeros()
        moved = 0
        if ti.static(a.lane):
            tau = _read(a.fr, ti.static(a.spec.launch.tau))
            ad = C.lane_abs(d) * a.frame_mask()
            a.x[k_prev, a.i, a.j] = ti.select(ad > tau, nx, u)
            moved = ti.select(run_max(ad, LANES) > tau, 1, 0)
        else:
            ad = ti.abs(d)
            a.x[k_prev, a.i, a.j] = nx
        return ad, moved

    @ti.func
    def _lane_max(v, lane: ti.template()):
        """The largest lane of ``v`` (lane layout), or ``v`` (a pixel)."""
        if ti.static(lane):
            return run_max(v, LANES)
        else:
            return v

    @ti.func
    def _cell_visit(stage: ti.template(), a: ti.template()):
        """``stage`` at the cell ``a``: what it gives its (up to two) reductions, and whether it moved or (a
        marking stage) changed anything. Those are its results as returned, an update's residuals (masked
        to the frame's lanes; a relaxation's: their lane maxima) or 0."""
        n, m = ti.static(len(stage.relax), len(stage.results))
        if ti.static(n == 1):
            ad, moved = _settle(a, stage.relax[0], stage.fn(a))
            return _lane_max(ad, a.lane), 0.0, moved
        elif ti.static(n == 2):
            d0, d1 = stage.fn(a)
            ad0, mv0 = _settle(a, stage.relax[0], d0)
            ad1, mv1 = _settle(a, stage.relax[1], d1)
            return _lane_max(ad0, a.lane), _lane_max(ad1, a.lane), mv0 | mv1
        elif ti.static(stage.marking):
            return 0.0, 0.0, stage.fn(a)
        elif ti.static(stage.residuals == 1):
            return stage.fn(a) * a.frame_mask(), 0.0, 0
        elif ti.static(stage.residuals == 2):
            q0, q1 = stage.fn(a)
            return q0 * a.frame_mask(), q1 * a.frame_mask(), 0
        elif ti.static(m == 1):
            return stage.fn(a), 0.0, 0
        elif ti.static(m == 2):
            q0, q1 = stage.fn(a)
            return q0, q1, 0
        else:
            stage.fn(a)
            return 0.0, 0.0, 0

    @ti.func
    def _deliver(spec: ti.template(), stage: ti.template(), rbuf: ti.template(), row, col: ti.template(), r0, r1):
        """Hand what ``stage`` reduced (``r0, r1``: over a chunk of rows, or at one pixel) to the launch: its
        results to the launch's (:func:`_publish`), its residuals maxed into ``rbuf[row, col]`` and
        ``rbuf[row, col + 1]`` (a lane update's residual vectors maxed over their lanes first)."""
        m, vectors = ti.static(len(stage.results), spec.lane and len(stage.relax) == 0)
        if ti.static(stage.residuals >= 1):
            ti.atomic_max(rbuf[row, col], _lane_max(r0, vectors))
        if ti.static(stage.residuals == 2):
            ti.atomic_max(rbuf[row, col + 1], _lane_max(r1, vectors))
        if ti.static(m >= 1):
            _publish(ti.static(spec.launch.slot(stage.results[0])), ti.cast(r0, ti.f64), stage.kind)
        if ti.static(m == 2):
            _publish(ti.static(spec.launch.slot(stage.results[1])), ti.cast(r1, ti.f64), stage.kind)

    # -- the row iterator (lane layout) and the pixel loop: a stage over the frame -----------------------------
    def _lane_stage(stage: Stage):
        """The scheduler's stage ``run(ctx, i0, i1, j)`` of ``stage`` on the lane layout: rows ``[i0, i1)``, each
        the cell action (:func:`_cell_visit`) element by element, then the row's ghost refresh. Compile-time
        choices of the stage: the elements (all, or with ``spans`` the visit range of a pending span), what a
        row leaves (a relaxation: the other parity's spans; ``marks``: both parities') and the ghost columns
        refreshed (of the buffers it wrote, then its ``ghosts``; on a side only when the elements reach it)."""
        group = stage.spans if stage.spans is not None else stage.marks
        grouped, visits, marks = group is not None, stage.spans is not None, stage.marking
        leaves = visits and bool(stage.relax)
        reduced = max(len(stage.results), stage.residuals)
        refreshed = tuple(q.before for q in stage.relax) + stage.ghosts
        k_span = group.store.slot if grouped else 0

        @ti.func
        def run(ctx: ti.template(), i0, i1, j):
            W, G = ti.static(ctx.spec.W, ctx.spec.ghosts)
            E1 = ti.static((LANES + W - 1) // LANES)  # the elements of a row
            p0 = _read(res, 0)  # the earlier stages' first result, final in this phase
            acc0, acc1 = _start_of(stage)
            for i in range(i0, i1):
                e0, e1, p = G, E1 + G, 0
                if ti.static(grouped):
                    p = ((ctx.c >> ti.static(group.pair.bit)) ^ _turn(ctx.spec, group.pair, j)) & 1
                    if ti.static(visits):
                        e0, e1 = _visit(ctx.x, k_span, p, i, ti.static(ctx.spec.rows(stage)), E1)
                lo, hi = EMPTY_LO, EMPTY_HI
                for e in range(e0 if ti.static(visits) else G, e1 if ti.static(visits) else E1 + G):  # static: all
                    r0, r1, moved = _cell_visit(stage, ctx.spec.cell(ctx, i, e, (p0,), j))
                    if ti.static(reduced >= 1):
                        acc0 = _accumulate(stage, acc0, r0, e - G + 1, W)
                    if ti.static(reduced == 2):
                        acc1 = _accumulate(stage, acc1, r1, e - G + 1, W)
                    if ti.static(grouped):
                        lo, hi = ti.select(moved != 0, ti.min(lo, e), lo), ti.select(moved != 0, e, hi)
                if ti.static(leaves):
                    _span_set(ctx.x, k_span, i, 1 - p, lo, hi)
                if ti.static(marks):
                    _span_mark(ctx.x, k_span, i, lo, hi)
                if e0 < e1:
                    for g in ti.static(refreshed):
                        C.fill_lane_ghosts(ctx.x, _index(ctx.c, g, _turn(ctx.spec, g, j)), i, e0 == G, e1 == E1 + G,
                                           W, ti.static(ctx.spec.halo(stage)), ti.static(ctx.spec.border(g)[0]), G)
            _deliver(ctx.spec, stage, sched.rbuf, j, 0, acc0, acc1)

        return run

    @ti.func
    def _pixel_stage(ctx: ti.template(), stage: ti.template(), step):
        """One parallel loop of ``stage`` over the pixels (the pixel layout): the cell action at each pixel, its
        results published per pixel, an update's residuals maxed into the launch record's row ``step``
        (columns 2..)."""
        for i, j in ti.ndrange(ctx.x.shape[1], ctx.x.shape[2]):
            r0, r1, _ = _cell_visit(stage, ctx.spec.cell(ctx, i, j, (), step))
            _deliver(ctx.spec, stage, ctx.rec, step, 2, r0, r1)

    @ti.func
    def _controls(ctx: ti.template()):
        return ctx.nw, ctx.x.shape[1], 0, 0.0, 0.0

    @ti.func
    def _start(spec: ti.template()):
        for k in ti.static(range(len(spec.launch.results))):
            res[k] = spec.launch.starts[k]

    @ti.func
    def _finish(spec: ti.template(), out: ti.template()):
        for k in ti.static(range(len(spec.launch.results))):
            out[k] = res[k]

    def _controls_of(launch: Launch):
        """The scheduler's controls of ``launch``: workers, rows and, for a solve, its launch scalars."""
        if launch.controls is None:
            return _controls
        n_at, tol_at, grow_at = launch.controls

        @ti.func
        def controls(ctx: ti.template()):
            fr = ti.static(ctx.fr)
            return ctx.nw, ctx.x.shape[1], ti.cast(fr[n_at], ti.i32), fr[tol_at], fr[grow_at]

        return controls

    @ti.func
    def _residuals(spec: ti.template(), rec: ti.template()):
        if ti.static(spec.launch.fields > 0):
            sched.residuals_to(rec, spec.launch.fields)

    @functools.lru_cache(maxsize=None)
    def kernel(launch: Launch, lane: bool, W: int, modes: tuple, options: tuple = (), ghosts: int = 1):
        """The kernel of ``launch`` for one layout: ``run(x, coef, fr, frame, c, nw, out, rec)`` (``x``: the
        stacked planes, lane array or (planes, H, W); ``frame``: the input, (H, W) or an event bin (2, H, W);
        ``c``: the pairs' parity; ``nw``: workers (lane layout); ``out``: the results, float64; ``rec``: the
        launch record of a solve, :class:`~cdnf_ti.kernels.common.LaunchRecord`).

        The pixel layout's kernel takes two more arguments, ``part`` (the index in :data:`PARTS` of ``"all"``,
        or ``"before"``, ``"update"``, ``"after"``: the stages it runs) and ``step`` (the update): the backend
        runs a solve's updates one launch each."""
        spec = Layout(launch, lane, W, modes, options, ghosts)
        if lane and ghosts != 1 and any(s.visits for s in launch.before + launch.update + launch.stages):
            raise ValueError(f"{launch.name}: pending spans take one ghost element either side (halo < lanes)")
        spec.cell = _cell_class(spec)
        if lane:
            run_plan = workers(Plan(before=tuple(_lane_stage(s) for s in launch.before),
                                    update=tuple(_lane_stage(s) for s in launch.update),
                                    after=tuple(_lane_stage(s) for s in launch.stages), controls=_controls_of(launch)))

            @ti.kernel
            def run_lanes(x: C.LANE3, coef: F1, fr: F1, frame: ti.types.ndarray(), c: ti.i32, nw: ti.i32,
                          out: D1, rec: F2):
                _start(spec)
                run_plan(ti.static(Ctx(x, coef, fr, frame, c, nw, spec, rec)))
                _finish(spec, out)
                _residuals(spec, rec)

            return vector_kernel(run_lanes)

        @ti.kernel
        def run_pixels(x: C.F3, coef: F1, fr: F1, frame: ti.types.ndarray(), c: ti.i32, nw: ti.i32, out: D1,
                       rec: F2, part: ti.template(), step: ti.i32):
            if ti.static(PARTS[part] in ("all", "before")):
                _start(spec)
            for s in ti.static({"all": launch.before + launch.stages, "before": launch.before,
                                "update": launch.update, "after": launch.stages}[PARTS[part]]):
                _pixel_stage(ti.static(Ctx(x, coef, fr, frame, c, nw, spec, rec)), s, step)
            _finish(spec, out)

        # on the CPU without fast-math: the stages then compute as written, as the lane layout's vector code does
        return scalar_kernel(run_pixels, fast_math=current_arch() != "cpu")

    return SimpleNamespace(ti=ti, kernel=kernel, Cell=Cell, res=res, LANES=LANES, REPLICATE=REPLICATE,
                           REFLECT=REFLECT, ZERO=ZERO)


def model(planes: Planes, coefs: Coefs, scalars: Scalars, engine_ns: SimpleNamespace, *launches: Launch,
          initial: dict | None = None, spans: tuple = ()) -> SimpleNamespace:
    """What a model's kernel module's ``build`` returns: its declarations, its launches by name, the engine
    (``engine_ns``: :func:`build`'s namespace), the planes' values at reset (``initial``: plane name ->
    a coefficient name, whose first value fills the plane; others: 0) and its span groups (``spans``:
    :class:`Span` each, every element pending at reset)."""
    return SimpleNamespace(planes=planes, coefs=coefs, scalars=scalars, engine=engine_ns,
                           launches={launch.name: launch for launch in launches}, initial=dict(initial or {}),
                           spans=tuple(spans))
