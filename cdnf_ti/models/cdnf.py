"""The C-DNF model: ON/OFF contrast fields and the Summation field, per frame.

Equations and parameters: :mod:`cdnf_ti.params`. Per-pixel kernels:
:mod:`cdnf_ti.kernels.cdnf` (Taichi) or :mod:`cdnf_ti.reference` (NumPy
float64). Convergence control: :mod:`cdnf_ti.solver`.
"""
from __future__ import annotations

import threading
from typing import Sequence

import numpy as np

from ..params import THETA_SCALE, CDNFParams, contrast_kernel, dog_profiles, resting_levels, sigmoid
from ..reference import NumpyCDNFBackend
from ..solver import SolveReport, solve_fixed_point
from .base import Model, ModelBackend, StepResult, Trace
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

        ensure_taichi(arch)
        from ..taichi_runtime import dsl

        ti = dsl()

        from ..kernels import cdnf as K
        from ..kernels.common import BORDER_CODES, COLUMN_BLOCKS

        self.K = K
        self.params = params
        self.shape = tuple(shape)
        self.mode = BORDER_CODES[params.border]
        self.blocks = COLUMN_BLOCKS

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
        self.K.load_frame(grey, self.L, self.P, scale, int(first))

    def clear_input(self) -> None:
        self.K.fill(self.P, 0.0)

    def contrast_iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        c, n = self.c, 1 - self.c
        r = self.K.contrast_iterate(self.P, self.u_on[c], self.u_off[c], self.u_on[n], self.u_off[n],
                                    *self.wc, self.params.h, lam, mom, self.blocks, self.mode)
        self.c = n
        return float(r[0]), float(r[1])

    def summation_input(self) -> None:
        p = self.params
        self.K.summation_input(self.u_on[self.c], self.u_off[self.c], self.S,
                               p.alpha_on, p.alpha_off, THETA_SCALE)

    def summation_iterate(self, lam: float, mom: float = 0.0) -> tuple[float]:
        p = self.params
        s, n = self.s, 1 - self.s
        r = self.K.summation_iterate(self.S, self.v[s], self.row1, self.row2, self.v[n], self.g1, self.g2,
                                     p.A, p.B, p.h, lam, mom, self.blocks, self.mode)
        self.s = n
        return (float(r),)

    def mean_activation(self) -> float:
        return float(self.K.mean_activation(self.v[self.s], THETA_SCALE, self.blocks))

    def fields(self) -> dict[str, np.ndarray]:
        return {
            "u_on": self.u_on[self.c].to_numpy(),
            "u_off": self.u_off[self.c].to_numpy(),
            "v": self.v[self.s].to_numpy(),
            "P": self.P.to_numpy(),
        }


class _LaneWorkspace:
    """Taichi Vector fields for one frame size, shared by the fast backends of that size.

    The lane kernels take fields as template arguments, so they are compiled once
    per field set; sharing one set per frame size keeps that to one compile per
    size. The backend that last used the workspace owns it; another backend of
    the same size first evicts the owner's state to NumPy (see
    :class:`LaneTaichiCDNFBackend`).
    """

    _pool: "dict[tuple[int, int], _LaneWorkspace]" = {}

    def __init__(self, shape: tuple[int, int]):
        from ..taichi_runtime import dsl

        ti = dsl()

        from ..kernels.cdnf import LANES, TILE_ROWS, lane_layout, tile_blocks

        H, W = shape
        self.e1, self.nb = lane_layout(W)
        self.bs, self.nblk = tile_blocks(self.e1)
        self.n_tiles = -(-H // TILE_ROWS) * self.nblk

        def vf():
            return ti.Vector.field(LANES, ti.f32, shape=(H, self.nb))

        self.L, self.P, self.S = vf(), vf(), vf()
        self.u_on, self.u_off, self.v = [vf(), vf()], [vf(), vf()], [vf(), vf()]
        self.row1, self.row2 = vf(), vf()
        # active-tile bookkeeping of the contrast group ("c") and the Summation field ("s")
        self.tiles = {}
        for g in ("c", "s"):
            self.tiles[g] = dict(act=ti.field(ti.i32, self.n_tiles), chg=ti.field(ti.i32, self.n_tiles),
                                 lst=ti.field(ti.i32, self.n_tiles), cnt=ti.field(ti.i32, ()))
        from ..kernels.cdnf import MAX_STEPS

        self.rbuf = ti.field(ti.f32, (MAX_STEPS, 2))  # per-update residuals of a multi-step launch
        self.owner = None  # weakref to the backend whose state is resident
        # One frame at a time per workspace: models of this size in other threads (a Dask worker
        # with several threads, a host program's threads) wait instead of mixing their states.
        self.lock = threading.RLock()

    def all_active(self) -> None:
        """Mark every tile of both groups active (after any change made outside the kernels)."""
        from ..kernels.cdnf import tiles_all

        for t in self.tiles.values():
            tiles_all(t["act"], t["lst"], t["cnt"])

    _pool_lock = threading.Lock()

    @classmethod
    def get(cls, shape: tuple[int, int]) -> "_LaneWorkspace":
        with cls._pool_lock:
            ws = cls._pool.get(shape)
            if ws is None:
                ws = cls._pool[shape] = cls(shape)
            return ws


class LaneTaichiCDNFBackend:
    """The fast Taichi backend: fields in lane-vectorised Vector fields (float32).

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
    #: so tiles at rest drop out of the iteration (0: only exactly still pixels).
    freeze: float = 1.0 / 16.0

    @staticmethod
    def supports(params: CDNFParams, shape: tuple[int, int]) -> bool:
        from ..kernels.cdnf import LANES

        return shape[1] >= 2 * LANES and shape[0] >= 2 and int(params.radius_s) < LANES

    def __init__(self, params: CDNFParams, shape: tuple[int, int], arch: str = "cpu"):
        import weakref

        from ..taichi_runtime import ensure_taichi

        ensure_taichi(arch)
        from ..kernels import cdnf as K
        from ..kernels.common import BORDER_CODES
        from ..taichi_runtime import dsl

        self.ti = dsl()
        self.K = K
        self.params = params
        self.shape = tuple(shape)
        self.H, self.W = self.shape
        self.mode = BORDER_CODES[params.border]
        self.ws = _LaneWorkspace.get(self.shape)
        self.lock = self.ws.lock  # held by the model around each frame (Model.step)
        self.bs, self.nblk = self.ws.bs, self.ws.nblk
        self.tau = float(params.tol) * self.freeze
        self._ref = weakref.ref(self)
        # W_c = k k^T with k the normalised 3-tap Gaussian (contrast_kernel is its outer product)
        k = np.exp(-np.arange(-1, 2) ** 2 / (2.0 * params.sigma_c**2))
        k /= k.sum()
        self.k = (float(k[1]), float(k[0]))
        g1, g2 = dog_profiles(params)
        self._taps = (tuple(float(x) for x in g1.astype(np.float32)), tuple(float(x) for x in g2.astype(np.float32)))
        self._tol32 = float(np.float32(params.tol))
        self.u0, self.v0 = resting_levels(params)
        self.c = 0
        self.s = 0
        self._saved: dict[str, np.ndarray] | None = None
        self._rest: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._fresh = True
        with self.lock:
            self._acquire()

    # -- workspace ownership -----------------------------------------------
    _STATE = ("L", "P", "S")

    def _acquire(self) -> "_LaneWorkspace":
        ws = self.ws
        owner = ws.owner() if ws.owner is not None else None
        if owner is self:
            return ws
        if owner is not None:
            owner._evict()
        ws.owner = self._ref
        K = self.K
        if self._fresh:
            for a in ws.u_on + ws.u_off:
                K.lanes_fill(a, self.u0)
            for a in ws.v:
                K.lanes_fill(a, self.v0)
            for a in (ws.L, ws.P, ws.S):
                K.lanes_fill(a, 0.0)
            for a in ws.u_on + ws.u_off + ws.v:
                K.lanes_refresh_ghosts(a, self.W, self.mode)
            self.c = self.s = 0
            self._fresh = False
            ws.all_active()
        elif self._saved is not None:
            sv = self._saved
            for name in self._STATE:
                getattr(ws, name).from_numpy(sv[name])
            ws.u_on[0].from_numpy(sv["u_on"])
            ws.u_off[0].from_numpy(sv["u_off"])
            ws.v[0].from_numpy(sv["v"])
            self.c = self.s = 0
            self._saved = None
            ws.all_active()
        return ws

    def _evict(self) -> None:
        ws = self.ws
        self._saved = {name: getattr(ws, name).to_numpy() for name in self._STATE}
        self._saved["u_on"] = ws.u_on[self.c].to_numpy()
        self._saved["u_off"] = ws.u_off[self.c].to_numpy()
        self._saved["v"] = ws.v[self.s].to_numpy()
        ws.owner = None

    # -- backend interface ---------------------------------------------------
    def save_rest(self) -> None:
        ws = self._acquire()
        self._rest = (ws.u_on[self.c].to_numpy(), ws.u_off[self.c].to_numpy(), ws.v[self.s].to_numpy())

    def restore_rest(self) -> None:
        ws = self._acquire()
        u, _, v = self._rest
        ws.u_on[self.c].from_numpy(u)
        ws.u_off[self.c].from_numpy(u)
        ws.v[self.s].from_numpy(v)
        ws.all_active()

    def reset(self) -> None:
        """Back to the resting state (the :class:`~cdnf_ti.models.base.ModelBackend` contract)."""
        self.restore_rest()

    def load(self, grey: np.ndarray, first: bool) -> None:
        ws = self._acquire()
        scale = 1.0 / 255.0 if grey.dtype == np.uint8 else 1.0
        t = ws.tiles["c"]
        self.K.lanes_load_frame(grey, ws.L, ws.P, scale, int(first), self.W, self.bs, self.nblk,
                                t["act"], t["chg"], t["lst"], t["cnt"])

    def clear_input(self) -> None:
        ws = self._acquire()
        self.K.lanes_fill(ws.P, 0.0)
        ws.all_active()

    def warm_up(self, steps: int) -> None:
        """Compile the multi-step kernels for both buffer parities now, not mid-run.

        The kernels take the ping-pong buffers as template arguments, so each order is a
        separate compilation. Updates with ``lam = mom = 0`` leave every value as it is.
        """
        for n in sorted({1, steps}):
            for _ in range(2):
                self.contrast_iterate_many([(0.0, 0.0)] * n)
                self.summation_input()  # also takes the contrast buffers by parity
                self.summation_iterate_many([(0.0, 0.0)] * n)
                self.mean_activation()
        self._acquire().all_active()

    def _done(self, res: list[tuple[float, ...]]) -> list[tuple[float, ...]]:
        """The updates a multi-step launch performed: up to the first with every residual <= tol."""
        for j, r in enumerate(res):
            if max(r) <= self._tol32:
                return res[: j + 1]
        return res

    def contrast_iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        return self.contrast_iterate_many([(lam, mom)])[0]

    def contrast_iterate_many(self, coefs) -> list[tuple[float, float]]:
        """Several ON/OFF updates in one launch (``coefs``: ``(lam, mom)`` each); see the solver."""
        ws = self._acquire()
        c = self.c
        t = ws.tiles["c"]
        kern = self.K.lanes_contrast_kernel(len(coefs))
        flat = [float(x) for cm in coefs for x in cm]
        r = kern(ws.P, ws.u_on[c], ws.u_off[c], ws.u_on[1 - c], ws.u_off[1 - c], *self.k, self.params.h,
                 self.ti.Vector(flat), self.tau, self._tol32, self.bs, self.nblk,
                 t["act"], t["chg"], t["lst"], t["cnt"], ws.rbuf, self.W, self.mode)
        res = self._done([(float(r[2 * j]), float(r[2 * j + 1])) for j in range(len(coefs))])
        self.c = (c + len(res)) % 2
        return res

    def summation_input(self) -> None:
        ws = self._acquire()
        p = self.params
        t = ws.tiles["s"]
        self.K.lanes_summation_input(ws.u_on[self.c], ws.u_off[self.c], ws.S, p.alpha_on, p.alpha_off,
                                     THETA_SCALE, self.W, self.bs, self.nblk, t["act"], t["chg"], t["lst"], t["cnt"])

    def summation_iterate(self, lam: float, mom: float = 0.0) -> tuple[float]:
        return self.summation_iterate_many([(lam, mom)])[0]

    def summation_iterate_many(self, coefs) -> list[tuple[float]]:
        """Several Summation updates in one launch (``coefs``: ``(lam, mom)`` each)."""
        ws = self._acquire()
        p = self.params
        s = self.s
        t = ws.tiles["s"]
        kern = self.K.lanes_summation_kernel(*self._taps, len(coefs))
        flat = [float(x) for cm in coefs for x in cm]
        r = kern(ws.S, ws.v[s], ws.v[1 - s], ws.row1, ws.row2, p.A, p.B, p.h, self.ti.Vector(flat), self.tau,
                 self._tol32, self.bs, self.nblk, t["act"], t["chg"], t["lst"], t["cnt"], ws.rbuf, self.W, self.mode)
        res = self._done([(float(r[j]),) for j in range(len(coefs))])
        self.s = (s + len(res)) % 2
        return res

    def mean_activation(self) -> float:
        ws = self._acquire()
        return float(self.K.lanes_mean_activation(ws.v[self.s], THETA_SCALE, self.W))

    def _frame(self, x: np.ndarray) -> np.ndarray:
        from ..kernels.cdnf import LANES

        return np.ascontiguousarray(x.reshape(self.H, -1)[:, LANES:LANES + self.W])

    def fields(self) -> dict[str, np.ndarray]:
        ws = self._acquire()
        return {
            "u_on": self._frame(ws.u_on[self.c].to_numpy()),
            "u_off": self._frame(ws.u_off[self.c].to_numpy()),
            "v": self._frame(ws.v[self.s].to_numpy()),
            "P": self._frame(ws.P.to_numpy()),
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
        if self.fast and LaneTaichiCDNFBackend.supports(self.params, shape):
            return LaneTaichiCDNFBackend(self.params, shape, self.arch)
        return TaichiCDNFBackend(self.params, shape, self.arch)

    def _numpy_backend(self, shape: tuple[int, int]) -> NumpyCDNFBackend:
        return NumpyCDNFBackend(self.params, shape)

    def _init_backend(self, be: ModelBackend) -> None:
        # The resting state for this frame size and border: the solution with no input.
        be.clear_input()
        self._solve(be)
        if hasattr(be, "warm_up"):
            be.warm_up(self.params.steps_per_launch)
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
        if not self.params.warm_start:
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
