"""The one backend of the engine's models: the declared planes, the coefficients by name, the launches.

A model names its kernel module (``Model.kernels``: a module of ``kernels/``, or a ``build(ti, lanes)``
function); the module declares its planes, coefficients and launch scalars
(:mod:`cdnf_ti.kernels.engine`). :class:`Backend` allocates the planes (lane arrays on the fast CPU
path, (planes, H, W) arrays elsewhere), fills the coefficients from ``model.coefficients()`` by name,
and runs a launch with :meth:`Backend.launch`. The model's control (its ``_step``) calls the launches.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..kernels import engine
from ..kernels.common import LaunchRecord
from ..kernels.schedule import MAX_WORKERS
from ..taichi_runtime import caches_launch_arguments, cpu_threads, dsl, ensure_taichi, kernels, lanes
from .workspace import Scratch


class Backend:
    """The state of an engine model for frames of ``shape`` (H, W), and its launches.

    Parameters
    ----------
    model : Model
        Reads ``kernels`` (its kernel module), ``coefficients()`` (a dict by coefficient name),
        ``borders()`` (plane name -> border, optional), ``kernel_options()`` (compile-time values by name,
        optional: ``a.option(name)`` in a stage), ``fast`` (use the lane layout where it applies).
    shape : (H, W)
    arch : str
        ``cpu``: the lane layout for frames at least two lane vectors wide; else the pixel layout.
    """

    name = "taichi"

    def __init__(self, model: Any, shape: tuple[int, int], arch: str = "cpu"):
        arch = ensure_taichi(arch)
        ti = dsl()
        self.M = kernels(model.kernels)
        self.shape = H, W = tuple(int(s) for s in shape)
        self.lane = self.lane_layout(getattr(model, "fast", True), self.shape, arch)
        self.modes = engine.borders(self.M.planes, model.borders() if hasattr(model, "borders") else {})
        self.options = tuple(sorted(model.kernel_options().items())) if hasattr(model, "kernel_options") else ()
        n = self.M.planes.count
        #: ghost elements either side of a lane row: the stages' widest halo (:func:`engine.ghost_elements`)
        self.ghosts = engine.ghost_elements(self.M.launches.values(), dict(self.options), lanes())
        if self.lane:
            C = kernels("common")
            self.x = C.lane_array(n, H=H, NB=C.lane_layout(W)[1] + 2 * (self.ghosts - 1))
        else:
            self.x = ti.ndarray(ti.f32, (n, H, W))
        values = engine.coefficient_array(self.M.coefs, model.coefficients() if len(self.M.coefs) else {})
        self.coefs = np.asarray(values, np.float32)
        self.coef = ti.ndarray(ti.f32, len(values))
        self.coef.from_numpy(self.coefs)
        self.fr = np.zeros(self.M.scalars.count, np.float32)
        self.out = np.zeros(engine.MAX_RESULTS)
        self.record = LaunchRecord(2)  # the launches' (unused) record
        self.records: dict[str, LaunchRecord] = {}  # each solve's per-update coefficients in, residuals out
        self.nw = min(cpu_threads(), MAX_WORKERS)
        self.lock = Scratch.get().lock  # the engine's scratch is one per process (Model.step holds it)
        self.frame: np.ndarray = np.zeros((H, W), np.float32)
        self.hold_input = caches_launch_arguments()  # frames into one buffer (:meth:`_input`)
        self.reset()

    @staticmethod
    def lane_layout(fast: bool, shape: tuple[int, int], arch: str) -> bool:
        """Whether frames of ``shape`` (H, W) run on the lane layout: ``fast``, the CPU (the persistent workers
        wait for each other on CPU threads) and at least two lane vectors wide."""
        return bool(fast) and arch == "cpu" and shape[1] >= 2 * lanes()

    def reset(self) -> None:
        """Every plane to 0, or to its declared initial value; the pairs' parity to 0; every span pending."""
        self.x.fill(0.0)
        for name, coef in self.M.initial.items():
            plane = getattr(self.M.planes, name)
            value = float(self.coefs[getattr(self.M.coefs, coef).slot])
            self._fill(plane.slot, plane.slot + plane.buffers, value)
        self.parity = 0
        self.turned = 0  # the pairs a solve's odd number of updates turned (bits, Plane.bit)
        self.mark_all()

    def _fill(self, k0: int, k1: int, value: float) -> None:
        x = self.x.to_numpy()
        x[k0:k1] = value
        self.x.from_numpy(x)

    def mark_all(self) -> None:
        """Every element of every span group pending, both parities (after a change made outside the launches)."""
        if not (self.lane and self.M.spans):
            return
        x = self.x.to_numpy()
        e1 = kernels("common").lane_layout(self.shape[1])[0]
        for group in self.M.spans:
            x[group.store.slot, :, 0, :4] = (1, e1, 1, e1)
        self.x.from_numpy(x)

    def flip(self) -> None:
        """Swap the buffers of every pair: ``now`` becomes ``before``."""
        self.parity = 1 - self.parity

    @property
    def mask(self) -> int:
        """The parity of every pair, bit ``Plane.bit`` of it: the kernels' ``c``."""
        return ((1 << self.M.planes.pairs) - 1 if self.parity else 0) ^ self.turned

    def load(self, grey: np.ndarray, first: bool) -> None:
        """Keep the frame (H, W; uint8, or float in [0, 1]) as the input of the next launches (a copy in the
        backend's input buffer, :meth:`_input`, where the compiler caches launch arguments by identity)."""
        if self.hold_input:
            self._input(grey.shape, grey.dtype)[...] = grey
        else:
            self.frame = grey

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> None:
        """Keep an event bin (``p_on``, ``p_off``: (H, W) each, contrast in [0, 1]) as the input of the next
        launches: one array, the two planes stacked, (2, H, W) float32 (every model's ON/OFF input stage)."""
        buf = self._input((2, *np.shape(p_on)), np.dtype(np.float32))
        buf[0], buf[1] = p_on, p_off

    def _input(self, shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
        """The launches' input array for inputs of ``shape`` and ``dtype``: one buffer, refilled each frame.

        Under a compiler that caches launch arguments by identity
        (:func:`~cdnf_ti.taichi_runtime.caches_launch_arguments`), the same array every frame hits that cache,
        while a new one would keep an entry alive as long as the frame (a program holding its frames then pays
        full garbage collections). Elsewhere the copy costs 2-3 % of a 1 ms frame, so frames are copied only
        there (``hold_input``); event bins, stacked anyway, always are."""
        if self.frame.shape != tuple(shape) or self.frame.dtype != dtype:
            self.frame = np.empty(shape, dtype)
        return self.frame

    def _kernel(self, name: str, values: dict) -> tuple[Any, Any]:
        for k, v in values.items():
            self.fr[getattr(self.M.scalars, k).slot] = v
        launch = self.M.launches[name]
        return launch, self.M.engine.kernel(launch, self.lane, self.shape[1] if self.lane else 0, self.modes,
                                              self.options, self.ghosts if self.lane else 1)

    def _run(self, run: Any, record: LaunchRecord, *part: Any) -> None:
        if part:  # the pixel layout: the part of the launch (its index in PARTS) and the update
            part = (engine.PARTS.index(part[0]), part[1])
        run(self.x, self.coef, self.fr, self.frame, self.mask, self.nw, self.out, record.array, *part)

    def launch(self, name: str, **values: float) -> tuple[float, ...]:
        """Set the launch scalars ``values`` (by name; the others keep their last values), run the launch
        ``name`` and return its results in the order its stages declare them."""
        launch, run = self._kernel(name, values)
        self._run(run, self.record, *(() if self.lane else ("all", 0)))
        return tuple(float(v) for v in self.out[:len(launch.results)])

    def solve(self, name: str, coefs: Sequence[tuple[float, ...]], updates: int, tol: float, grow: float,
              **values: float) -> tuple[list[tuple[float, ...]], tuple[float, ...]]:
        """Run the solve launch ``name``: at most ``updates`` (<= ``len(coefs)``) updates, update ``j`` with its
        record coefficients ``coefs[j]`` (``a.record(0)``, ``a.record(1)``), stopping once every residual is
        ``<= tol`` or one grows past ``grow`` times the best. Returns the residuals of the updates run and
        the launch's results (its ``stages`` run only when the solve converged)."""
        launch, run = self._kernel(name, dict(values, updates=updates, tol=tol, grow=grow))
        record = self.records.setdefault(name, LaunchRecord(launch.fields))
        record.start(coefs)
        if self.lane:
            self._run(run, record)
        else:  # one launch per update, gated here as the scheduler gates them
            self._run(run, record, "before", 0)
            best = np.inf
            for j in range(min(updates, len(coefs))):
                self._run(run, record, "update", j)
                r = float(record.array[j, 2:2 + launch.fields].max())
                if r <= tol or r > grow * best:
                    break
                best = min(best, r)
            done = record.residuals(updates)
            if done and max(done[-1]) <= tol:  # the after stages' step: the updates run (as on the lane layout)
                self._run(run, record, "after", len(done))
        residuals = record.residuals(updates)
        if len(residuals) % 2:  # the pairs the updates alternate now hold their result in the other buffer
            self.turned ^= sum(1 << b for b in launch.alternates)
        return residuals, tuple(float(v) for v in self.out[:len(launch.results)])

    def fields(self) -> dict[str, np.ndarray]:
        """Every plane (a pair's ``now`` buffer) of the last frame, (H, W) each, by name; not the scratch
        planes (named ``_...``)."""
        x = self.x.to_numpy()
        if self.lane:
            n, (H, W) = lanes(), self.shape
            x = x.reshape(x.shape[0], H, -1)[:, :, n * self.ghosts:n * self.ghosts + W]
        return {p.name: np.ascontiguousarray(x[p.slot + ((self.mask >> p.bit) & 1 if p.buffers == 2 else 0)])
                for p in self.M.planes if not p.name.startswith("_")}
