"""The C-DNF model: ON/OFF contrast fields and the Summation field, per frame.

Equations and parameters: :mod:`cdnf_ti.params`. Per-pixel kernels:
:mod:`cdnf_ti.kernels.cdnf` (Taichi) or :mod:`cdnf_ti.reference` (NumPy
float64). Convergence control: :mod:`cdnf_ti.solver`.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..params import THETA_SCALE, CDNFParams, contrast_kernel, dog_profiles, resting_levels, sigmoid
from ..reference import NumpyCDNFBackend
from ..solver import RESTART_GROWTH, SolveReport, cdnf_local_starts, solve_fixed_point
from .base import Model, ModelBackend, SharedWorkspace, StepResult, Trace
from .registry import register_model


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
        from ..taichi_runtime import ensure_taichi

        arch = ensure_taichi(arch)  # the arch in use ("gpu" resolves to one)
        from ..taichi_runtime import dsl

        ti = dsl()

        from ..kernels import cdnf as K
        from ..kernels.common import BORDER_CODES, LaunchRecord, column_blocks

        self.K = K
        self.params = params
        self.shape = tuple(shape)
        self.mode = BORDER_CODES[params.border]
        self.blocks = column_blocks(self.shape[1], arch)  # work items per row
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


class _LaneWorkspace(SharedWorkspace):
    """The C-DNF lane fields of one frame size (see :class:`~cdnf_ti.models.base.SharedWorkspace`
    and :class:`LaneTaichiCDNFBackend`)."""

    def __init__(self, shape: tuple[int, int]):
        super().__init__(shape)
        from ..taichi_runtime import dsl

        ti = dsl()

        from ..kernels.cdnf import MAX_STEPS, SPAN, lane_array, lane_layout, sync_size
        from ..kernels.common import LaunchRecord

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
        self.pend = {g: ti.ndarray(SPAN, (2, H)) for g in ("c", "s")}
        self.sync = ti.field(ti.i32, sync_size())  # phase counters of the persistent workers
        self.rbuf = ti.field(ti.f32, (MAX_STEPS, 2))  # per-update residuals of a solve launch
        self.msum = ti.field(ti.f64, 2)  # sum theta([v]+) of a converged Summation solve, and its flag
        self.records = {"c": LaunchRecord(2), "s": LaunchRecord(1)}  # contrast, Summation launches
        self.total = np.zeros(1)  # sum theta([v]+) of a Summation launch or mean_activation (-1: not computed)

    def all_active(self) -> None:
        """Mark every element of both groups pending (after any change made outside the kernels)."""
        from ..kernels.cdnf import lanes_pending_all

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
        from ..kernels.cdnf import LANES

        return arch == "cpu" and shape[1] >= 2 * LANES and shape[0] >= 2 and int(params.radius_s) < LANES

    def __init__(self, params: CDNFParams, shape: tuple[int, int], arch: str = "cpu"):
        from ..taichi_runtime import cpu_threads, ensure_taichi

        ensure_taichi(arch)
        from ..kernels import cdnf as K
        from ..kernels.common import BORDER_CODES

        self.K = K
        self.params = params
        self.shape = tuple(shape)
        self.H, self.W = self.shape
        self.mode = BORDER_CODES[params.border]
        self.ws = _LaneWorkspace.get(self.shape)
        self.lock = self.ws.lock  # held by the model around each frame (Model.step)
        self.nw = min(cpu_threads(), K.MAX_WORKERS)  # persistent workers per solve launch
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
        self._saved: dict[str, np.ndarray] | None = None
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

    # -- workspace ownership -----------------------------------------------
    _STATE = ("L", "P", "S")

    def _acquire(self) -> "_LaneWorkspace":
        ws = self.ws
        if not ws.take(self):
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
        elif self._saved is not None:
            sv = self._saved
            for name in self._STATE:
                getattr(ws, name).from_numpy(sv[name])
            for name in ("u_on", "u_off", "v"):
                getattr(ws, name).from_numpy(sv[name])
            self.c = self.s = 0
            self._saved = None
            ws.all_active()
        return ws

    def _evict(self) -> None:
        ws = self.ws
        self._flush_load()
        self._saved = {name: getattr(ws, name).to_numpy() for name in self._STATE}
        for name, k in (("u_on", self.c), ("u_off", self.c), ("v", self.s)):
            x = getattr(ws, name).to_numpy()[k]
            self._saved[name] = np.stack([x, x])  # resumes at parity 0, both buffers equal
        ws.owner = None

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


@register_model
class CDNF(Model):
    """Contrast-based Dynamic Neural Field (Qin, Fu, Peng, Yue).

    Each frame: ``P = L(t) - L(t-1)`` splits into ON/OFF contrasts; the ON and
    OFF fields and then the Summation field are solved to their stationary
    state (Chebyshev semi-iteration by default, ``CDNFParams.scheme``; the
    stopping rule is the plain map's residual); ``I_v = sigmoid(mean theta([v]+))``
    and ``spike = I_v > 0.5 + epsilon``. Frame 0 gives ``I_v = 0.5``, no spike.

    Parameters
    ----------
    params : CDNFParams, optional
    backend : {"taichi", "numpy"}
        Taichi kernels (float32 fields) or the NumPy float64 reference.
    arch : {"cpu", "cuda", "vulkan", "gpu"}
        Taichi architecture (taichi backend only).
    fps : float
        Input frame rate (unused by the equations; kept for the interface).
    compiler : {"quadrants", "taichi"} or None
        Kernel compiler (one per process, see :mod:`cdnf_ti.taichi_runtime`);
        ``None``: the one running, else the fastest installed.

    Notes
    -----
    With the Taichi backend, frames at least 32 px wide run on the lane-vectorised
    kernels with active tiles (:class:`LaneTaichiCDNFBackend`); set ``fast = False``
    on the instance before its first frame to use the generic ndarray kernels.
    :meth:`fields`: ``u_on, u_off, v`` (the three fields) and ``P`` (luminance change).

    Examples
    --------
    >>> from cdnf_ti import CDNF
    >>> trace = CDNF().run(frames)          # doctest: +SKIP
    >>> trace.output, trace.spike           # I_v and alerts per frame  # doctest: +SKIP
    """

    name = "cdnf"
    output_name = "I_v"
    params_type = CDNFParams
    description = "C-DNF: ON/OFF contrast DNFs + Summation DNF (Qin et al.)"
    #: Use the lane-vectorised kernels where the frame allows (False: the generic ndarray kernels).
    fast: bool = True

    #: Threshold sweep (:class:`~cdnf_ti.models.base.Sweepable`): epsilon from 0 to 0.02.
    sweep_parameter = "epsilon (alert I_v > 0.5 + value)"
    sweep_values = tuple(float(x) for x in np.round(np.linspace(0.0, 0.02, 21), 6))

    @classmethod
    def sweep_default(cls) -> float:
        return float(cls.params_type().epsilon)

    @classmethod
    def sweep_alerts(cls, trace: Trace, values: Sequence[float]) -> list[np.ndarray]:
        """Alerts per frame at each ``epsilon``: ``I_v`` does not depend on it, so
        ``I_v > 0.5 + epsilon`` on the saved trace is exactly what a rerun gives."""
        out = np.asarray(trace.output, dtype=np.float64)
        return [out > cls.params_type(epsilon=float(v)).threshold for v in values]

    def _setup(self) -> None:
        # Chebyshev bounds from the kernels' spectra, once per model
        self._bounds = self.params.chebyshev_bounds() if self.params.scheme == "chebyshev" else (None, None)

    @property
    def threshold(self) -> float:
        return self.params.threshold

    def _taichi_backend(self, shape: tuple[int, int]) -> TaichiCDNFBackend | LaneTaichiCDNFBackend:
        from ..taichi_runtime import ensure_taichi  # the runtime starts with the first backend

        arch = ensure_taichi(self.arch)
        if self.fast and LaneTaichiCDNFBackend.supports(self.params, shape, arch):
            return LaneTaichiCDNFBackend(self.params, shape, self.arch)
        return TaichiCDNFBackend(self.params, shape, self.arch)

    def _numpy_backend(self, shape: tuple[int, int]) -> NumpyCDNFBackend:
        return NumpyCDNFBackend(self.params, shape)

    def _init_backend(self, be: ModelBackend) -> None:
        # The resting state for this frame size and border: the solution with no input.
        be.clear_input()
        self._solve(be)
        if hasattr(be, "warm_up"):
            be.warm_up()
        be.save_rest()

    def _solve(self, be) -> tuple[SolveReport, SolveReport]:
        p = self.params
        kw = dict(tol=p.tol, max_iter=p.max_iter, min_damping=p.min_damping, stall_patience=p.stall_patience,
                  steps=p.steps_per_launch)
        bc, bs = self._bounds
        rc = solve_fixed_point(be.contrast_iterate, 2, damping=p.damping * p.contrast_relaxation, bounds=bc,
                               iterate_many=getattr(be, "contrast_iterate_many", None), **kw)
        be.summation_input()
        rs = solve_fixed_point(be.summation_iterate, 1, damping=p.damping, bounds=bs,
                               iterate_many=getattr(be, "summation_iterate_many", None), **kw)
        return rc, rs

    def _step(self, t: int, grey: np.ndarray, loaded: None) -> StepResult:
        """The equations of one frame; see :class:`StepResult`.

        Diagnostics: ``iterations_on/off/sum``, ``residual_on/off/sum`` (the plain map's
        ``max |F(u) - u|``), ``damping_sum`` (the plain relaxation in force at the end of
        the Summation solve) and ``restarts`` (Chebyshev safeguard restarts/fallbacks).
        """
        be = self._be
        if t == 0:
            be.restore_rest()
            diag = dict(iterations_on=0, iterations_off=0, iterations_sum=0,
                        residual_on=0.0, residual_off=0.0, residual_sum=0.0, damping_sum=1.0, restarts=0)
            return StepResult(t, 0.5, False, True, diag)
        if self.params.start == "rest":
            be.restore_rest()
        rc, rs = self._solve(be)
        i_v = sigmoid(be.mean_activation())
        converged = rc.converged and rs.converged
        diag = dict(
            iterations_on=rc.iterations[0], iterations_off=rc.iterations[1], iterations_sum=rs.iterations[0],
            residual_on=rc.residuals[0], residual_off=rc.residuals[1], residual_sum=rs.residuals[0],
            damping_sum=rs.damping, restarts=rc.restarts + rs.restarts,
        )
        return StepResult(t, i_v, bool(i_v > self.params.threshold), converged, diag)
