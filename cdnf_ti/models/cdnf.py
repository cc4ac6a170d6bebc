"""The C-DNF model: ON/OFF contrast fields and the Summation field, per frame.

Equations and parameters: :mod:`cdnf_ti.params`. Per-pixel stages:
:mod:`cdnf_ti.kernels.cdnf` (run by the engine's backend) or :mod:`cdnf_ti.reference` (NumPy
float64). Convergence control: :mod:`cdnf_ti.solver`, whose hooks here call the engine's solve launches.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..params import THETA_SCALE, CDNFParams, contrast_kernel, dog_profiles, resting_levels, sigmoid
from ..reference import NumpyCDNFBackend
from ..solver import RESTART_GROWTH, SolveReport, cdnf_local_starts, solve_fixed_point
from .base import Model, ModelBackend, StepResult, Trace
from .registry import register_model


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
    With the Taichi backend, frames at least two lane vectors wide run on the engine's lane layout (frozen
    lanes and pending spans: only the regions that change are iterated); set ``fast = False`` on the
    instance before its first frame to use the pixel layout (every pixel, every update).
    :meth:`fields`: ``u_on, u_off, v`` (the three fields) and ``P`` (luminance change).

    Examples
    --------
    >>> from cdnf_ti import CDNF
    >>> trace = CDNF().run(frames)          # doctest: +SKIP
    >>> trace.output, trace.spike           # I_v and alerts per frame  # doctest: +SKIP
    """

    name = "cdnf"
    order = 0
    panels = (("u_on", "ON field u_on"), ("u_off", "OFF field u_off"), ("v", "Summation field v"))
    output_name = "I_v"
    params_type = CDNFParams
    description = "C-DNF: ON/OFF contrast DNFs + Summation DNF (Qin et al.)"
    #: Use the lane layout where the frame allows (False: the pixel layout).
    fast: bool = True
    kernels = "cdnf"
    #: Lanes whose update ``|F(u) - u|`` is at most ``freeze * tol`` keep their value (lane layout), so
    #: regions at rest drop out of the iteration.
    freeze: float = 1.0 / 16.0

    takes_events = True
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
        self._pending, self._s_ready, self._mean, self._events = None, False, None, False  # the engine's hooks
        # Chebyshev bounds from the kernels' spectra, once per model
        self._bounds = self.params.chebyshev_bounds() if self.params.scheme == "chebyshev" else (None, None)

    @property
    def threshold(self) -> float:
        return self.params.threshold

    def _numpy_backend(self, shape: tuple[int, int]) -> NumpyCDNFBackend:
        return NumpyCDNFBackend(self.params, shape)

    # -- the engine: declarations by name, the solver's hooks on its solve launches ------------------------
    def coefficients(self) -> dict:
        """The stages' coefficients by name (:data:`cdnf_ti.kernels.cdnf.COEFS`), float32 as the kernels read them."""
        p = self.params
        k = np.exp(-np.arange(-1, 2) ** 2 / (2.0 * p.sigma_c**2))
        k /= k.sum()  # W_c = k k^T with k the normalised 3-tap Gaussian (contrast_kernel is its outer product)
        wc = contrast_kernel(p.sigma_c)
        starts = cdnf_local_starts(p).astype(np.float32)
        u0, v0 = resting_levels(p)
        return {"k_c": (k[1], k[0]), "w_c": (wc[1, 1], wc[0, 1], wc[0, 0]), "h": p.h, "alpha_on": p.alpha_on,
                "alpha_off": p.alpha_off, "theta": THETA_SCALE, "A": p.A, "B": p.B, "local": int(p.start == "local"),
                "start_u": starts[0], "start_v": starts[1], "u0": u0, "v0": v0}

    def kernel_options(self) -> dict:
        """The DoG's profiles (float32 taps), its radius and the rows its row passes serve (compile-time)."""
        R = int(self.params.radius_s)
        g1, g2 = (tuple(float(x) for x in g.astype(np.float32)) for g in dog_profiles(self.params))
        return {"radius": R, "reach": 2 * R, "g1": g1, "g2": g2}

    def borders(self) -> dict:
        return {name: self.params.border for name in ("u_on", "u_off", "v", "_row1", "_row2")}

    def _engine_solve(self, name: str, coefs, **values) -> tuple[list, tuple]:
        """The solve launch ``name`` over ``coefs`` (a chunk of the solver's updates): it stops after an update
        that converged or grew past ``RESTART_GROWTH`` times the best, as the solver's own rule."""
        be, tol = self._be, float(np.float32(self.params.tol))
        return be.solve(name, coefs, len(coefs), tol, RESTART_GROWTH, tau=tol * self.freeze if be.lane else 0.0,
                        **values)

    def _contrast_many(self, coefs) -> list:
        """The contrast solve's hook: loads the frame first if it is new; at convergence S is computed too."""
        load, self._pending = self._pending, None
        res, _ = self._engine_solve("contrast", coefs, **(load or {"load": 0}))
        self._s_ready = bool(res) and max(res[-1]) <= float(np.float32(self.params.tol))
        return res

    def _summation_input(self) -> None:
        if not self._s_ready:
            self._be.launch("summation_input")
        self._s_ready, self._mean = False, None

    def _summation_many(self, coefs) -> list:
        """The Summation solve's hook: at convergence the mean activation is computed too."""
        res, (total,) = self._engine_solve("summation", coefs)
        converged = bool(res) and max(res[-1]) <= float(np.float32(self.params.tol))
        self._mean = total / (self._be.shape[0] * self._be.shape[1]) if converged else None
        return res

    def _mean_activation(self) -> float:
        mean, self._mean = self._mean, None
        if mean is None:
            (total,) = self._be.launch("activation")
            mean = total / (self._be.shape[0] * self._be.shape[1])
        return mean

    def _flush_load(self) -> None:
        """Load the frame taken but not yet loaded (its fields are needed before a contrast solve)."""
        if self._pending is not None:
            self._be.launch("load", **self._pending)
            self._pending = None

    def reset(self) -> None:
        """Forget all state; the engine's backend solves its resting state again (its planes were cleared)."""
        super().reset()
        if self._be is not None and self.backend_name != "numpy":
            with self._backend_lock():
                self._init_backend(self._be)

    def fields(self) -> dict[str, np.ndarray]:
        """``u_on``, ``u_off``, ``v`` and ``P``, the net luminance change (an event bin's ``P_on - P_off``)."""
        if self._be is not None and self.backend_name != "numpy":
            with self._backend_lock():
                self._flush_load()  # a frame taken, not yet loaded
        f = super().fields()
        if "P_off" in f:  # the engine's planes
            f = {k: f[k] for k in ("u_on", "u_off", "v", "P")} | {"P": f["P"] - f["P_off"] if self._events else f["P"]}
        return f

    def _restore_rest(self) -> None:
        self._flush_load()
        self._be.launch("restore_rest")
        self._s_ready, self._mean = False, None

    def _hooks(self, be) -> tuple:
        """``(contrast, summation_input, summation, mean_activation, restore_rest)``: the numpy reference's
        one-update methods, or the engine's solve launches (``iterate_many`` hooks)."""
        if self.backend_name == "numpy":
            return (be.contrast_iterate, be.summation_input, be.summation_iterate, be.mean_activation,
                    be.restore_rest)
        return self._contrast_many, self._summation_input, self._summation_many, self._mean_activation, \
            self._restore_rest

    def _init_backend(self, be: ModelBackend) -> None:
        # The resting state for this frame size and border: the solution with no input.
        self._be, self._pending, self._s_ready, self._mean = be, None, False, None  # the hooks' backend
        self._events = False
        if self.backend_name == "numpy":
            be.clear_input()
        self._solve(be)
        if self.backend_name == "numpy":
            be.save_rest()
        else:
            be.launch("save_rest")

    def _solve(self, be) -> tuple[SolveReport, SolveReport]:
        p = self.params
        kw = dict(tol=p.tol, max_iter=p.max_iter, min_damping=p.min_damping, stall_patience=p.stall_patience,
                  steps=p.steps_per_launch)
        bc, bs = self._bounds
        contrast, summation_input, summation, _, _ = self._hooks(be)
        numpy = self.backend_name == "numpy"  # one update per call, else a launch of several

        def hook(fn):
            return {"iterate": fn, "iterate_many": None} if numpy else {"iterate": None, "iterate_many": fn}

        rc = solve_fixed_point(n_fields=2, damping=p.damping * p.contrast_relaxation, bounds=bc, **hook(contrast), **kw)
        summation_input()
        rs = solve_fixed_point(n_fields=1, damping=p.damping, bounds=bs, **hook(summation), **kw)
        return rc, rs

    def _step(self, t: int, grey: np.ndarray | None, loaded: None) -> StepResult:
        """The equations of one frame; see :class:`StepResult`.

        Diagnostics: ``iterations_on/off/sum``, ``residual_on/off/sum`` (the plain map's
        ``max |F(u) - u|``), ``damping_sum`` (the plain relaxation in force at the end of
        the Summation solve) and ``restarts`` (Chebyshev safeguard restarts/fallbacks).
        """
        be = self._be
        _, _, _, mean_activation, restore_rest = self._hooks(be)
        self._events = grey is None
        if self.backend_name != "numpy":  # the frame (or event bin) the backend took: the contrast solve loads it
            scale = 1.0 / 255.0 if grey is not None and grey.dtype == np.uint8 else 1.0
            self._pending = {"load": 1, "first": int(t == 0), "scale": scale}
        if t == 0 and grey is not None:  # an event bin (grey None) is a full step even at t == 0
            restore_rest()
            diag = dict(iterations_on=0, iterations_off=0, iterations_sum=0,
                        residual_on=0.0, residual_off=0.0, residual_sum=0.0, damping_sum=1.0, restarts=0)
            return StepResult(t, 0.5, False, True, diag)
        if self.params.start == "rest":
            restore_rest()
        rc, rs = self._solve(be)
        i_v = sigmoid(mean_activation())
        converged = rc.converged and rs.converged
        diag = dict(
            iterations_on=rc.iterations[0], iterations_off=rc.iterations[1], iterations_sum=rs.iterations[0],
            residual_on=rc.residuals[0], residual_off=rc.residuals[1], residual_sum=rs.residuals[0],
            damping_sum=rs.damping, restarts=rc.restarts + rs.restarts,
        )
        return StepResult(t, i_v, bool(i_v > self.params.threshold), converged, diag)
