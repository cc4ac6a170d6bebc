"""The compiled C-DNF backends: field state in the engine's arrays, driven by :mod:`cdnf_ti.kernels.cdnf`.

:class:`TaichiCDNFBackend` runs the generic kernels (GPUs, narrow frames) and
:class:`LaneTaichiCDNFBackend` the lane kernels (the fast CPU path). Both serve the
:class:`~cdnf_ti.models.cdnf.CDNF` model through :func:`make_backend`.
"""
from __future__ import annotations

import numpy as np

from ..kernels import common
from ..kernels.common import BORDER_CODES, LaunchRecord
from ..kernels.schedule import MAX_WORKERS
from ..params import THETA_SCALE, CDNFParams, contrast_kernel, dog_profiles, resting_levels
from ..solver import RESTART_GROWTH, cdnf_local_starts
from ..taichi_runtime import cpu_threads, dsl, ensure_taichi, kernels, lanes
from .events import load_net_contrast
from .workspace import LaneState


class TaichiCDNFBackend:
    """C-DNF field state in Taichi ndarrays (float32) driven by the kernels.

    Parameters
    ----------
    params : CDNFParams
    shape : (H, W)
    arch : str
        Taichi architecture.
    """

    name = "taichi"

    def __init__(self, params: CDNFParams, shape: tuple[int, int], arch: str = "cpu"):
        arch = ensure_taichi(arch)  # the arch in use ("gpu" resolves to one)
        ti = dsl()
        K = kernels("cdnf")
        self.K = K
        self.params = params
        self.shape = tuple(shape)
        self.mode = BORDER_CODES[params.border]
        self.blocks = common.column_blocks(self.shape[1], arch)  # work items per row
        self._tol32 = float(np.float32(params.tol))
        self._records = {"c": LaunchRecord(2), "s": LaunchRecord(1)}  # contrast, Summation launches
        self.steps = self.launch_steps(arch)  # updates per launch, per group (tests may change them)
        self._total = np.zeros(1)  # the mean activation's float64 sum
        start, self.local = _local_start_args(params)
        self._start = ti.ndarray(ti.f32, start.shape)  # on the device once, not copied per launch
        self._start.from_numpy(start)

        def nd() -> "ti.Ndarray":
            return ti.ndarray(ti.f32, self.shape)

        self.L, self.P, self.S = nd(), nd(), nd()
        self.u_on, self.u_off, self.v = [nd(), nd()], [nd(), nd()], [nd(), nd()]
        self.row1, self.row2 = nd(), nd()
        self.rest_u, self.rest_v = nd(), nd()
        self.c = 0  # index of the current contrast buffers
        self.s = 0  # index of the current Summation buffer
        wc = contrast_kernel(params.sigma_c)
        self.wc = (float(wc[1, 1]), float(wc[0, 1]), float(wc[0, 0]))
        g1, g2 = dog_profiles(params)
        self.g1 = ti.ndarray(ti.f32, g1.shape)
        self.g2 = ti.ndarray(ti.f32, g2.shape)
        self.g1.from_numpy(g1.astype(np.float32))
        self.g2.from_numpy(g2.astype(np.float32))
        u0, v0 = resting_levels(params)
        for a in self.u_on + self.u_off:
            K.fill(a, u0)
        for a in self.v:
            K.fill(a, v0)

    @staticmethod
    def launch_steps(arch: str) -> dict[str, int]:
        """Updates per launch of the contrast (``"c"``) and Summation (``"s"``) solve kernels on ``arch``.

        A launch runs its updates as consecutive parallel loops, each a compiled copy of the
        update, so more updates per launch cost compile time: about 0.06 s per contrast copy
        (1.7 s for 8) but 7 s for one Summation copy, 21 s for two. A GPU runs 8 contrast
        updates per launch (Chebyshev converges in about 8), saving a launch and a read-back
        of ~0.15-0.25 ms each; on the CPU a launch costs ~30 us, so one update per launch.
        """
        return {"c": 8, "s": 1} if arch != "cpu" else {"c": 1, "s": 1}

    def save_rest(self) -> None:
        self.K.copy(self.u_on[self.c], self.rest_u)
        self.K.copy(self.v[self.s], self.rest_v)

    def restore_rest(self) -> None:
        self.K.copy(self.rest_u, self.u_on[self.c])
        self.K.copy(self.rest_u, self.u_off[self.c])
        self.K.copy(self.rest_v, self.v[self.s])

    def reset(self) -> None:
        """Back to the resting state (the :class:`~cdnf_ti.models.base.ModelBackend` contract)."""
        self.restore_rest()

    def load(self, grey: np.ndarray, first: bool) -> None:
        scale = 1.0 / 255.0 if grey.dtype == np.uint8 else 1.0
        self.K.load_frame(grey, self.L, self.P, scale, int(first), self.blocks, self.u_on[self.c],
                          self.u_off[self.c], self._start, self.local)

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> None:
        """Take an event bin (H, W each, contrast in [0, 1]): ``P = p_on - p_off``, the net signed
        contrast the kernels' ON/OFF input stage reads (a pixel with both polarities in one bin
        gets their difference); returns what :meth:`load` returns."""
        return load_net_contrast(self, p_on, p_off)

    def clear_input(self) -> None:
        self.K.fill(self.P, 0.0)

    def contrast_iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        return self.contrast_iterate_many([(lam, mom)])[0]

    def contrast_iterate_many(self, coefs) -> list[tuple[float, float]]:
        """Up to ``len(coefs)`` ON/OFF updates (``coefs``: ``(lam, mom)`` each; see the solver) in
        launches of :attr:`steps` ``["c"]`` (:func:`~cdnf_ti.kernels.cdnf.contrast_solve`); returns
        the residuals of the updates run."""
        def launch(rec, chunk):
            c, n = self.c, 1 - self.c
            self.K.contrast_solve(self.P, self.u_on[c], self.u_off[c], self.u_on[n], self.u_off[n], *self.wc,
                                  self.params.h, rec.start(chunk), len(chunk), self._tol32, RESTART_GROWTH,
                                  self.blocks, self.mode, self.steps["c"])
            res = rec.residuals(len(chunk))
            self.c = (c + len(res)) % 2
            return res

        return self._launches("c", launch, coefs)

    def _launches(self, group: str, launch, coefs) -> list[tuple[float, ...]]:
        """Run ``coefs`` in launches of ``steps[group]`` updates until one stops early or converges."""
        out: list[tuple[float, ...]] = []
        step = self.steps[group]
        for k in range(0, len(coefs), step):
            chunk = coefs[k: k + step]
            res = launch(self._records[group], chunk)
            out += res
            if len(res) < len(chunk) or max(res[-1]) <= self._tol32:
                break
        return out

    def summation_input(self) -> None:
        p = self.params
        self.K.summation_input(self.u_on[self.c], self.u_off[self.c], self.S,
                               p.alpha_on, p.alpha_off, THETA_SCALE, self.v[self.s], self._start, self.local)

    def summation_iterate(self, lam: float, mom: float = 0.0) -> tuple[float]:
        return self.summation_iterate_many([(lam, mom)])[0]

    def summation_iterate_many(self, coefs) -> list[tuple[float]]:
        """Up to ``len(coefs)`` Summation updates in launches of :attr:`steps` ``["s"]``
        (:func:`~cdnf_ti.kernels.cdnf.summation_solve`); as :meth:`contrast_iterate_many`."""
        p = self.params

        def launch(rec, chunk):
            s, n = self.s, 1 - self.s
            self.K.summation_solve(self.S, self.v[s], self.v[n], self.row1, self.row2, self.g1, self.g2,
                                   p.A, p.B, p.h, rec.start(chunk), len(chunk), self._tol32, RESTART_GROWTH,
                                   self.blocks, self.mode, int(p.radius_s), self.steps["s"])
            res = rec.residuals(len(chunk))
            self.s = (s + len(res)) % 2
            return res

        return self._launches("s", launch, coefs)

    def mean_activation(self) -> float:
        self._total[0] = 0.0
        self.K.mean_activation(self.v[self.s], THETA_SCALE, self.blocks, self._total)
        return float(self._total[0]) / (self.shape[0] * self.shape[1])

    def fields(self) -> dict[str, np.ndarray]:
        return {
            "u_on": self.u_on[self.c].to_numpy(),
            "u_off": self.u_off[self.c].to_numpy(),
            "v": self.v[self.s].to_numpy(),
            "P": self.P.to_numpy(),
        }


def _local_start_args(params: CDNFParams) -> tuple[np.ndarray, int]:
    """The kernels' local-start arguments: the coefficients (float32, (2, 7)) and the switch
    (1 when ``params.start == "local"``; the kernels then set the fields' start as they load
    a frame and compute a Summation input)."""
    return cdnf_local_starts(params).astype(np.float32), int(params.start == "local")


class _LaneWorkspace(LaneState):
    """The C-DNF lane fields of one backend (:class:`LaneTaichiCDNFBackend`) for frames of ``shape``,
    with the process's scratch (:class:`~cdnf_ti.backends.workspace.LaneState`)."""

    def __init__(self, shape: tuple[int, int]):
        super().__init__(shape)
        ti = dsl()
        K = kernels("cdnf")
        lane_array, lane_layout = K.lane_array, K.lane_layout
        H, W = shape
        self.W = W
        self.e1, self.nb = lane_layout(W)

        def lanes(*lead):
            return lane_array(*lead, H=H, NB=self.nb)

        self.L, self.P, self.S = lanes(), lanes(), lanes()
        # the fields, each with its two ping-pong buffers (leading index: the parity)
        self.u_on, self.u_off, self.v = lanes(2), lanes(2), lanes(2)
        self.row1, self.row2 = lanes(), lanes()
        # pending spans of the contrast group ("c") and the Summation field ("s"), per parity and row
        self.pend = {g: ti.ndarray(K.SPAN, (2, H)) for g in ("c", "s")}
        self.records = {"c": LaunchRecord(2), "s": LaunchRecord(1)}  # contrast, Summation launches
        self.total = np.zeros(1)  # sum theta([v]+) of a Summation launch or mean_activation (-1: not computed)

    def all_active(self) -> None:
        """Mark every element of both groups pending (after any change made outside the kernels)."""
        lanes_pending_all = kernels("cdnf").lanes_pending_all
        for pend in self.pend.values():
            lanes_pending_all(pend, self.W)


class LaneTaichiCDNFBackend:
    """The fast Taichi backend: fields in lane arrays (vector ndarrays of ``LANES`` float32), kernels
    compiled with explicit vector types (:func:`~cdnf_ti.taichi_runtime.vector_kernel`).

    Same interface, equations, iteration schedule and residuals as
    :class:`TaichiCDNFBackend`; the kernels are in :mod:`cdnf_ti.kernels.cdnf`
    (``lanes_*``). Used when the frame is at least ``2 * LANES`` pixels wide and
    the DoG radius is below ``LANES``.

    Parameters
    ----------
    params : CDNFParams
    shape : (H, W)
    arch : str
    """

    name = "taichi"
    #: Pixels whose update ``|F(u) - u|`` is at most ``freeze * tol`` keep their value,
    #: so regions at rest drop out of the iteration (0: only exactly still pixels).
    freeze: float = 1.0 / 16.0

    @staticmethod
    def supports(params: CDNFParams, shape: tuple[int, int], arch: str = "cpu") -> bool:
        """Frames at least ``2 * LANES`` wide, DoG radius below ``LANES``, and the CPU.

        The solve kernels' persistent workers wait for each other on CPU threads; GPUs
        run the generic kernels (one parallel loop per update).
        """
        n = lanes()
        return arch == "cpu" and shape[1] >= 2 * n and shape[0] >= 2 and int(params.radius_s) < n

    def __init__(self, params: CDNFParams, shape: tuple[int, int], arch: str = "cpu"):
        ensure_taichi(arch)
        K = kernels("cdnf")
        self.K = K
        self.params = params
        self.shape = tuple(shape)
        self.H, self.W = self.shape
        self.mode = BORDER_CODES[params.border]
        self.ws = _LaneWorkspace(self.shape)  # this backend's own arrays
        self.lock = self.ws.lock  # the process's scratch: held by the model around each frame (Model.step)
        self.nw = min(cpu_threads(), MAX_WORKERS)  # persistent workers per solve launch
        self.tau = float(params.tol) * self.freeze
        # W_c = k k^T with k the normalised 3-tap Gaussian (contrast_kernel is its outer product)
        k = np.exp(-np.arange(-1, 2) ** 2 / (2.0 * params.sigma_c**2))
        k /= k.sum()
        self.k = (float(k[1]), float(k[0]))
        g1, g2 = dog_profiles(params)
        self._taps = (tuple(float(x) for x in g1.astype(np.float32)), tuple(float(x) for x in g2.astype(np.float32)))
        self._tol32 = float(np.float32(params.tol))
        self._start, self.local = _local_start_args(params)
        self.u0, self.v0 = resting_levels(params)
        self.c = 0
        self.s = 0
        self._rest: tuple[np.ndarray, np.ndarray] | None = None  # resting u and v, both parities
        self._fresh = True
        # Results the solve kernels computed on converging: S is already the Summation input of the
        # current contrast fields; the mean activation of the current Summation field.
        self._s_ready = False
        self._mean: float | None = None
        self._frame_in: tuple[np.ndarray, float, int] | None = None  # taken by load(), not loaded yet
        # the contrast launch's frame argument when it loads none: same dtype as the frames (one compile)
        self._idle_frame = np.zeros((1, 1), np.float32)
        with self.lock:
            self._acquire()

    # -- state -------------------------------------------------------------
    def _acquire(self) -> "_LaneWorkspace":
        """This backend's arrays, set to their first state on first use."""
        ws = self.ws
        if not self._fresh:
            return ws
        self._s_ready, self._mean = False, None
        K = self.K
        if self._fresh:
            for a in (ws.u_on, ws.u_off):
                a.fill(self.u0)
            ws.v.fill(self.v0)
            for a in (ws.L, ws.P, ws.S):
                a.fill(0.0)
            for a in (ws.u_on, ws.u_off, ws.v):
                K.lanes_refresh_ghosts(a, self.W, self.mode)
            self.c = self.s = 0
            self._fresh = False
            ws.all_active()
        return ws

    # -- backend interface ---------------------------------------------------
    def save_rest(self) -> None:
        ws = self._acquire()
        self._flush_load()
        u, v = ws.u_on.to_numpy()[self.c], ws.v.to_numpy()[self.s]
        self._rest = (np.stack([u, u]), np.stack([v, v]))  # both buffers at rest (built once, not per restore)

    def restore_rest(self) -> None:
        ws = self._acquire()
        self._flush_load()
        u, v = self._rest
        for f, x in ((ws.u_on, u), (ws.u_off, u), (ws.v, v)):
            f.from_numpy(x)
        self.c = self.s = 0
        ws.all_active()
        self._s_ready, self._mean = False, None

    def reset(self) -> None:
        """Back to the resting state (the :class:`~cdnf_ti.models.base.ModelBackend` contract)."""
        self.restore_rest()

    def load(self, grey: np.ndarray, first: bool) -> None:
        """Take the frame; the next contrast launch loads it (its first phase), or :meth:`_flush_load`."""
        self._acquire()
        self._flush_load()  # a frame never solved (two loads in a row) is loaded now
        scale = 1.0 / 255.0 if grey.dtype == np.uint8 else 1.0
        self._s_ready, self._mean = False, None
        self._frame_in = (grey, scale, int(first))
        self.expect_frames(grey.dtype)

    def _flush_load(self) -> None:
        """Load the frame taken by :meth:`load` now (its fields are needed before the contrast launch)."""
        if self._frame_in is not None:
            grey, scale, first = self._frame_in
            self._frame_in = None
            ws = self.ws
            self.K.lanes_load_frame(grey, ws.L, ws.P, scale, first, self.W, ws.pend["c"], self.c, ws.u_on, ws.u_off,
                                    self._start, self.local, self.mode)

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> None:
        """Take an event bin (H, W each, contrast in [0, 1]): ``P = p_on - p_off``, the net signed
        contrast the kernels' ON/OFF input stage reads (a pixel with both polarities in one bin
        gets their difference); returns what :meth:`load` returns."""
        return load_net_contrast(self, p_on, p_off)

    def clear_input(self) -> None:
        ws = self._acquire()
        self._flush_load()
        ws.P.fill(0.0)
        ws.all_active()
        self._s_ready, self._mean = False, None

    def expect_frames(self, dtype: np.dtype) -> None:
        """Frames will be of ``dtype`` (uint8 video or float): :meth:`warm_up` compiles the contrast
        launch for those (a frame of the other kind compiles its variant when it first comes)."""
        if self._idle_frame.dtype != dtype:  # the launch's frame argument when it loads none
            self._idle_frame = np.zeros((1, 1), dtype)

    def warm_up(self) -> None:
        """Compile every kernel of a frame now, not mid-run (``lam = mom = 0`` changes no value).

        The contrast launch is compiled for the frame type of :meth:`expect_frames` (default
        float32) only: each variant costs about a second of start-up even with a warm cache.
        """
        local, self.local = self.local, 0  # no local start either (compiled all the same)
        try:
            self.contrast_iterate_many([(0.0, 0.0)])
            self._s_ready = False
            self.summation_input()  # the stand-alone kernel too
            self.summation_iterate_many([(0.0, 0.0)])
        finally:
            self.local = local
        self._mean = None
        self.mean_activation()
        self._acquire().all_active()

    def contrast_iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        return self.contrast_iterate_many([(lam, mom)])[0]

    def contrast_iterate_many(self, coefs) -> list[tuple[float, float]]:
        """Several ON/OFF updates in one launch (``coefs``: ``(lam, mom)`` each); see the solver.

        The launch first loads the frame :meth:`load` took, if any; a launch that converges
        also computes the Summation input (:meth:`summation_input`).
        """
        ws = self._acquire()
        p = self.params
        c = self.c
        if self._frame_in is not None:
            (frame, scale, first), load = self._frame_in, 1
            self._frame_in = None
        else:
            frame, scale, first, load = self._idle_frame, 1.0, 0, 0
        rec = ws.records["c"]
        self.K.lanes_contrast_solve(
            frame, load, ws.L, scale, first, ws.P, ws.u_on, ws.u_off, ws.pend["c"], c, *self.k, p.h,
            rec.start(coefs), len(coefs), self.tau, self._tol32, RESTART_GROWTH, self.nw, ws.sync, ws.rbuf,
            self.W, self.mode, ws.S, ws.pend["s"], p.alpha_on, p.alpha_off, THETA_SCALE, ws.v, self.s, self._start,
            self.local, int(p.radius_s))
        res = rec.residuals(len(coefs))
        self.c = (c + len(res)) % 2
        self._s_ready = bool(res) and max(res[-1]) <= self._tol32
        self._mean = None
        return res

    def summation_input(self) -> None:
        """``S`` from the current contrast fields (already done by a contrast launch that converged)."""
        ws = self._acquire()
        self._mean = None
        if self._s_ready:
            self._s_ready = False
            return
        p = self.params
        self.K.lanes_summation_input(ws.u_on, ws.u_off, self.c, ws.S, p.alpha_on, p.alpha_off, THETA_SCALE,
                                     self.W, ws.pend["s"], ws.v, self.s, self._start, self.local, self.mode,
                                     int(p.radius_s))

    def summation_iterate(self, lam: float, mom: float = 0.0) -> tuple[float]:
        return self.summation_iterate_many([(lam, mom)])[0]

    def summation_iterate_many(self, coefs) -> list[tuple[float]]:
        """Several Summation updates in one launch (``coefs``: ``(lam, mom)`` each).

        A launch that converges also computes the mean activation (:meth:`mean_activation`).
        """
        ws = self._acquire()
        p = self.params
        s = self.s
        kern = self.K.lanes_summation_kernel(*self._taps)
        rec = ws.records["s"]
        kern(ws.S, ws.v, ws.row1, ws.row2, ws.pend["s"], s, p.A, p.B, p.h, rec.start(coefs), len(coefs),
             self.tau, self._tol32, RESTART_GROWTH, self.nw, ws.sync, ws.rbuf, self.W, self.mode, THETA_SCALE,
             ws.msum, ws.total)
        res = rec.residuals(len(coefs))
        self.s = (s + len(res)) % 2
        total = float(ws.total[0])
        self._mean = total / (self.H * self.W) if total >= 0.0 else None
        return res

    def mean_activation(self) -> float:
        """``mean_xy theta([v]+)`` (already computed by a Summation launch that converged)."""
        ws = self._acquire()
        if self._mean is not None:
            mean, self._mean = self._mean, None
            return mean
        ws.total[0] = 0.0
        self.K.lanes_mean_activation(ws.v, self.s, THETA_SCALE, self.W, ws.total)
        return float(ws.total[0]) / (self.H * self.W)

    def fields(self) -> dict[str, np.ndarray]:
        ws = self._acquire()
        self._flush_load()
        return {
            "u_on": self.ws.frame(ws.u_on.to_numpy()[self.c]),
            "u_off": self.ws.frame(ws.u_off.to_numpy()[self.c]),
            "v": self.ws.frame(ws.v.to_numpy()[self.s]),
            "P": self.ws.frame(ws.P.to_numpy()),
        }


def make_backend(model, shape: tuple[int, int], arch: str) -> TaichiCDNFBackend | LaneTaichiCDNFBackend:
    """C-DNF's backend: the lane kernels where they apply (and ``model.fast``), else the generic ones."""
    if model.fast and LaneTaichiCDNFBackend.supports(model.params, shape, arch):
        return LaneTaichiCDNFBackend(model.params, shape, model.arch)
    return TaichiCDNFBackend(model.params, shape, model.arch)
