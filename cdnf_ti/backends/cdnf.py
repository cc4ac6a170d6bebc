"""The compiled C-DNF backends: field state in the engine's arrays, driven by :mod:`cdnf_ti.kernels.cdnf`.

:class:`TaichiCDNFBackend` runs the generic kernels (GPUs, narrow frames) and
:class:`LaneTaichiCDNFBackend` the lane kernels (the fast CPU path). Both serve the
:class:`~cdnf_ti.models.cdnf.CDNF` model through :func:`make_backend`. Each keeps its state
in one stacked array (the planes of :mod:`cdnf_ti.kernels.cdnf`) and the model's
coefficients in one small float32 array, set when the backend is built (:class:`Coefficients`).
"""
from __future__ import annotations

import numpy as np

from ..kernels import cdnf as layout, common
from ..kernels.common import BORDER_CODES, LaunchRecord
from ..kernels.engine import coefficient_array
from ..kernels.schedule import MAX_WORKERS
from ..params import THETA_SCALE, CDNFParams, contrast_kernel, dog_profiles, resting_levels
from ..solver import RESTART_GROWTH, cdnf_local_starts
from ..taichi_runtime import cpu_threads, dsl, ensure_taichi, kernels, lanes
from .workspace import LaneState, event_bin

V_END = layout.V_ + 2  # the planes past the last field


class Coefficients:
    """A C-DNF backend's coefficients: one float32 ``ti.ndarray`` (slots of :mod:`cdnf_ti.kernels.cdnf`),
    filled when the backend is built and again only when one of them changes (:meth:`set`).

    Parameters
    ----------
    params : CDNFParams
    tau : float
        The freezing threshold of the lane solves.
    workers : int
        The persistent workers of a lane solve launch.
    """

    def __init__(self, params: CDNFParams, tau: float = 0.0, workers: int = 1):
        k = np.exp(-np.arange(-1, 2) ** 2 / (2.0 * params.sigma_c**2))
        k /= k.sum()  # W_c = k k^T with k the normalised 3-tap Gaussian (contrast_kernel is its outer product)
        wc = contrast_kernel(params.sigma_c)
        g1, g2 = dog_profiles(params)
        starts = cdnf_local_starts(params).astype(np.float32)
        taps = np.concatenate([g1.astype(np.float32), g2.astype(np.float32)])
        values = {"k": (k[1], k[0]), "wc": (wc[1, 1], wc[0, 1], wc[0, 0]), "h": params.h, "tau": tau,
                  "tol": params.tol, "grow": RESTART_GROWTH, "alpha_on": params.alpha_on,
                  "alpha_off": params.alpha_off, "theta": THETA_SCALE, "dog_a": params.A, "dog_b": params.B,
                  "local": int(params.start == "local"), "workers": workers, "start_u": starts[0],
                  "start_v": starts[1], "taps": taps}
        # each a float32 as a kernel's f32 argument would be
        self.values = np.array(coefficient_array(layout.COEF, values), np.float32)
        ti = dsl()
        self.array = ti.ndarray(ti.f32, self.values.shape)  # on the device once, not copied per launch
        self.array.from_numpy(self.values)

    def __getitem__(self, slot: int) -> float:
        return float(self.values[slot])

    def set(self, slot: int, value: float) -> None:
        """Change one coefficient (tests and warm-up runs: the freezing threshold, the workers, the local start)."""
        if self.values[slot] != np.float32(value):
            self.values[slot] = value
            self.array.from_numpy(self.values)


class TaichiCDNFBackend:
    """C-DNF field state in Taichi ndarrays (float32): one stacked array (the
    :data:`~cdnf_ti.kernels.cdnf.PLANES` planes of the frame) and the Summation field's two buffers,
    driven by the generic kernels.

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
        self.coef = Coefficients(params)
        self.x = ti.ndarray(ti.f32, (K.PLANES, *self.shape))  # L, P, S, the row passes, u_on, u_off, the rest
        self.v = [ti.ndarray(ti.f32, self.shape) for _ in range(2)]  # the Summation field's buffers
        self.rest_v = ti.ndarray(ti.f32, self.shape)
        self.c = 0  # index of the current contrast buffers
        self.s = 0  # index of the current Summation buffer
        self.events = False  # the input is an event bin (load_on_off), not a frame
        u0, v0 = resting_levels(params)
        K.fill_planes(self.x, K.U_ON, K.U_OFF + 2, u0)
        for a in self.v:
            K.fill(a, v0)

    @property
    def local(self) -> int:
        """1: the kernels set the fields' local start as they load a frame and compute a Summation input."""
        return int(self.coef[layout.LOCAL])

    @local.setter
    def local(self, value: int) -> None:
        self.coef.set(layout.LOCAL, value)

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
        K = self.K
        K.copy_plane(self.x, K.U_ON + self.c, K.REST_U)
        K.copy(self.v[self.s], self.rest_v)

    def restore_rest(self) -> None:
        K = self.K
        K.copy_plane(self.x, K.REST_U, K.U_ON + self.c)
        K.copy_plane(self.x, K.REST_U, K.U_OFF + self.c)
        K.copy(self.rest_v, self.v[self.s])

    def reset(self) -> None:
        """Back to the resting state (the :class:`~cdnf_ti.models.base.ModelBackend` contract)."""
        self.restore_rest()

    def load(self, grey: np.ndarray, first: bool) -> None:
        scale = 1.0 / 255.0 if grey.dtype == np.uint8 else 1.0
        self.events = False
        self.K.load_frame(grey, self.x, self.coef.array, scale, int(first), self.c, self.blocks)

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> None:
        """Take an event bin (H, W each, contrast in [0, 1]), one upload: the ON field's input is
        ``P_on = p_on`` and the OFF field's ``P_off = p_off`` (a pixel with both polarities in one bin
        drives both fields)."""
        self.events = True
        self.K.load_frame(event_bin(p_on, p_off), self.x, self.coef.array, 1.0, int(first), self.c, self.blocks)

    def clear_input(self) -> None:
        self.K.fill_planes(self.x, self.K.P_, self.K.P_OFF + 1, 0.0)

    def contrast_iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        return self.contrast_iterate_many([(lam, mom)])[0]

    def contrast_iterate_many(self, coefs) -> list[tuple[float, float]]:
        """Up to ``len(coefs)`` ON/OFF updates (``coefs``: ``(lam, mom)`` each; see the solver) in
        launches of :attr:`steps` ``["c"]`` (:func:`~cdnf_ti.kernels.cdnf.contrast_solve`); returns
        the residuals of the updates run."""
        def launch(rec, chunk):
            self.K.contrast_solve(self.x, self.coef.array, rec.start(chunk), self.c, len(chunk), self.blocks,
                                  self.mode, self.steps["c"], self.events)
            res = rec.residuals(len(chunk))
            self.c = (self.c + len(res)) % 2
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
        self.K.summation_input(self.x, self.v[self.s], self.coef.array, self.c)

    def summation_iterate(self, lam: float, mom: float = 0.0) -> tuple[float]:
        return self.summation_iterate_many([(lam, mom)])[0]

    def summation_iterate_many(self, coefs) -> list[tuple[float]]:
        """Up to ``len(coefs)`` Summation updates in launches of :attr:`steps` ``["s"]``
        (:func:`~cdnf_ti.kernels.cdnf.summation_solve`); as :meth:`contrast_iterate_many`."""
        def launch(rec, chunk):
            s, n = self.s, 1 - self.s
            kern = self.K.summation_solve_kernel(self.mode, int(self.params.radius_s), self.steps["s"])
            kern(self.x, self.v[s], self.v[n], self.coef.array, rec.start(chunk), len(chunk), self.blocks)
            res = rec.residuals(len(chunk))
            self.s = (self.s + len(res)) % 2
            return res

        return self._launches("s", launch, coefs)

    def mean_activation(self) -> float:
        self._total[0] = 0.0
        self.K.mean_activation(self.v[self.s], self.coef.array, self.blocks, self._total)
        return float(self._total[0]) / (self.shape[0] * self.shape[1])

    def fields(self) -> dict[str, np.ndarray]:
        K, x = self.K, self.x.to_numpy()
        return {"u_on": x[K.U_ON + self.c], "u_off": x[K.U_OFF + self.c], "v": self.v[self.s].to_numpy(),
                "P": net_input(x, self.events)}


def net_input(planes: np.ndarray, events: bool) -> np.ndarray:
    """The field ``P`` (the net luminance change) from the input planes: ``P`` (frames), or
    ``P_on - P_off`` (an event bin)."""
    p = planes[layout.P_]
    return p - planes[layout.P_OFF] if events else p


class _LaneWorkspace(LaneState):
    """The C-DNF lane state of one backend (:class:`LaneTaichiCDNFBackend`) for frames of ``shape``,
    with the process's scratch (:class:`~cdnf_ti.backends.workspace.LaneState`)."""

    def __init__(self, shape: tuple[int, int]):
        super().__init__(shape)
        ti = dsl()
        K = kernels("cdnf")
        H, W = shape
        self.W = W
        self.e1, self.nb = K.lane_layout(W)
        #: L, P, S, the row passes and the fields (each with its two ping-pong buffers): planes of kernels/cdnf.py
        self.x = K.lane_array(K.LANE_PLANES, H=H, NB=self.nb)
        #: pending spans of the contrast group and the Summation field, per parity and row (SPAN_C, SPAN_S)
        self.pend = ti.ndarray(K.SPAN, (4, H))
        self.records = {"c": LaunchRecord(2, len(K.CONTRAST_VALUES)),  # contrast, Summation launches
                        "s": LaunchRecord(1, len(K.SUMMATION_VALUES))}
        self.total = np.zeros(1)  # sum theta([v]+) of a Summation launch or mean_activation (-1: not computed)

    def all_active(self) -> None:
        """Mark every element of both groups pending (after any change made outside the kernels)."""
        kernels("cdnf").lanes_pending_all(self.pend, self.W)

    def spans(self, group: str) -> np.ndarray:
        """The pending spans of ``group`` (``"c"``: contrast, ``"s"``: Summation): int32 (2, H, 2), per parity."""
        at = layout.SPAN_C if group == "c" else layout.SPAN_S
        return self.pend.to_numpy()[at:at + 2]

    def planes(self) -> np.ndarray:
        """Every plane's frame columns: float32 (LANE_PLANES, H, W)."""
        x = self.x.to_numpy()
        return np.stack([self.frame(p) for p in x])


class LaneTaichiCDNFBackend:
    """The fast Taichi backend: state in a lane array (vector ndarray of ``LANES`` float32), kernels
    compiled with explicit vector types (:func:`~cdnf_ti.taichi_runtime.vector_kernel`).

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
        self.coef = Coefficients(params, float(params.tol) * self.freeze, min(cpu_threads(), MAX_WORKERS))
        g1, g2 = dog_profiles(params)
        taps = (tuple(float(x) for x in g1.astype(np.float32)), tuple(float(x) for x in g2.astype(np.float32)))
        # the contrast launch for frames and for event bins (compiled when first used)
        self._contrast = {e: K.lanes_contrast_kernel(self.W, self.mode, int(params.radius_s), e) for e in (False, True)}
        self.events = False  # the input is an event bin (load_on_off), not a frame
        self._summation = K.lanes_summation_kernel(*taps, self.W, self.mode)
        self._tol32 = float(np.float32(params.tol))
        self.u0, self.v0 = resting_levels(params)
        self.c = 0
        self.s = 0
        self._rest = None  # the resting state of the fields' planes, both buffers (a lane array)
        self._fresh = True
        # Results the solve kernels computed on converging: S is already the Summation input of the
        # current contrast fields; the mean activation of the current Summation field.
        self._s_ready = False
        self._mean: float | None = None
        self._frame_in: tuple[np.ndarray, float, int] | None = None  # taken by load(), not loaded yet
        # the contrast launch's frame argument when it loads none: same dtype as the frames (one compile)
        self._idle_frame = np.zeros((1, 1), np.float32)
        self._idle_bin = np.zeros((2, 1, 1), np.float32)  # the same for event bins
        with self.lock:
            self._acquire()

    # -- coefficients that tests and warm-up change --------------------------
    @property
    def tau(self) -> float:
        """The freezing threshold: updates ``|F(u) - u| <= tau`` leave a pixel as it is."""
        return self.coef[layout.TAU]

    @tau.setter
    def tau(self, value: float) -> None:
        self.coef.set(layout.TAU, value)

    @property
    def nw(self) -> int:
        """Persistent workers per solve launch."""
        return int(self.coef[layout.WORKERS])

    @nw.setter
    def nw(self, value: int) -> None:
        self.coef.set(layout.WORKERS, value)

    @property
    def local(self) -> int:
        """1: the kernels set the fields' local start as they load a frame and compute a Summation input."""
        return int(self.coef[layout.LOCAL])

    @local.setter
    def local(self, value: int) -> None:
        self.coef.set(layout.LOCAL, value)

    # -- state -------------------------------------------------------------
    def _acquire(self) -> "_LaneWorkspace":
        """This backend's arrays, set to their first state on first use."""
        ws = self.ws
        if not self._fresh:
            return ws
        self._s_ready, self._mean = False, None
        K = self.K
        K.lanes_fill_planes(ws.x, 0, K.U_ON, 0.0)  # L, P, S, the row passes
        K.lanes_fill_planes(ws.x, K.U_ON, K.V_, self.u0)
        K.lanes_fill_planes(ws.x, K.V_, V_END, self.v0)
        K.lanes_refresh_ghosts(ws.x, K.U_ON, V_END, self.W, self.mode)
        self.c = self.s = 0
        self._fresh = False
        ws.all_active()
        return ws

    # -- backend interface ---------------------------------------------------
    def save_rest(self) -> None:
        ws = self._acquire()
        self._flush_load()
        K = self.K
        x = ws.x.to_numpy()
        u, v = x[K.U_ON + self.c], x[K.V_ + self.s]
        if self._rest is None:
            self._rest = K.lane_array(V_END - K.U_ON, H=self.H, NB=ws.nb)
        self._rest.from_numpy(np.stack([u, u, u, u, v, v]))  # both buffers of each field at rest

    def restore_rest(self) -> None:
        ws = self._acquire()
        self._flush_load()
        self.K.lanes_put_planes(self._rest, ws.x, self.K.U_ON)
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
        self.events = False
        self.expect_frames(grey.dtype)

    def _flush_load(self) -> None:
        """Load the frame taken by :meth:`load` now (its fields are needed before the contrast launch)."""
        if self._frame_in is not None:
            grey, scale, first = self._frame_in
            self._frame_in = None
            ws = self.ws
            self.K.lanes_load_frame(grey, ws.x, ws.pend, self.coef.array, self.c, scale, first, self.W, self.mode)

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> None:
        """Take an event bin (H, W each, contrast in [0, 1]), one upload: the ON field's input is
        ``P_on = p_on`` and the OFF field's ``P_off = p_off`` (a pixel with both polarities in one bin
        drives both fields). As :meth:`load`, the next contrast launch loads it."""
        self._acquire()
        self._flush_load()
        self._s_ready, self._mean = False, None
        self._frame_in = (event_bin(p_on, p_off), 1.0, int(first))
        self.events = True

    def clear_input(self) -> None:
        ws = self._acquire()
        self._flush_load()
        self.K.lanes_fill_planes(ws.x, self.K.P_, self.K.P_OFF + 1, 0.0)
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
        c = self.c
        if self._frame_in is not None:
            (frame, scale, first), load = self._frame_in, 1
            self._frame_in = None
        else:
            frame, scale, first, load = self._idle_bin if self.events else self._idle_frame, 1.0, 0, 0
        rec = ws.records["c"]
        self._contrast[self.events](frame, ws.x, ws.pend, rec.start(coefs, (c, self.s, len(coefs), load, first, scale)),
                       self.coef.array)
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
        self.K.lanes_summation_input(ws.x, ws.pend, self.coef.array, self.c, self.s, self.W, self.mode,
                                     int(self.params.radius_s))

    def summation_iterate(self, lam: float, mom: float = 0.0) -> tuple[float]:
        return self.summation_iterate_many([(lam, mom)])[0]

    def summation_iterate_many(self, coefs) -> list[tuple[float]]:
        """Several Summation updates in one launch (``coefs``: ``(lam, mom)`` each).

        A launch that converges also computes the mean activation (:meth:`mean_activation`).
        """
        ws = self._acquire()
        s = self.s
        rec = ws.records["s"]
        self._summation(ws.x, ws.pend, rec.start(coefs, (s, len(coefs))), self.coef.array, ws.total)
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
        self.K.lanes_mean_activation(ws.x, self.coef.array, self.s, self.W, ws.total)
        return float(ws.total[0]) / (self.H * self.W)

    def fields(self) -> dict[str, np.ndarray]:
        ws = self._acquire()
        self._flush_load()
        K, x = self.K, ws.planes()
        return {"u_on": x[K.U_ON + self.c], "u_off": x[K.U_OFF + self.c], "v": x[K.V_ + self.s],
                "P": net_input(x, self.events)}


def make_backend(model, shape: tuple[int, int], arch: str) -> TaichiCDNFBackend | LaneTaichiCDNFBackend:
    """C-DNF's backend: the lane kernels where they apply (and ``model.fast``), else the generic ones."""
    if model.fast and LaneTaichiCDNFBackend.supports(model.params, shape, arch):
        return LaneTaichiCDNFBackend(model.params, shape, model.arch)
    return TaichiCDNFBackend(model.params, shape, model.arch)
