"""The C-DNF model: ON/OFF contrast fields and the Summation field, per frame.

Equations and parameters: :mod:`cdnf_ti.params`. Per-pixel kernels:
:mod:`cdnf_ti.kernels.cdnf` (Taichi) or :mod:`cdnf_ti.reference` (NumPy
float64). Convergence control: :mod:`cdnf_ti.solver`.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..params import CDNFParams, sigmoid
from ..reference import NumpyCDNFBackend
from ..solver import SolveReport, solve_fixed_point
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
    order = 0
    panels = (("u_on", "ON field u_on"), ("u_off", "OFF field u_off"), ("v", "Summation field v"))
    output_name = "I_v"
    params_type = CDNFParams
    description = "C-DNF: ON/OFF contrast DNFs + Summation DNF (Qin et al.)"
    #: Use the lane-vectorised kernels where the frame allows (False: the generic ndarray kernels).
    fast: bool = True

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
        # Chebyshev bounds from the kernels' spectra, once per model
        self._bounds = self.params.chebyshev_bounds() if self.params.scheme == "chebyshev" else (None, None)

    @property
    def threshold(self) -> float:
        return self.params.threshold

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

    def _step(self, t: int, grey: np.ndarray | None, loaded: None) -> StepResult:
        """The equations of one frame; see :class:`StepResult`.

        Diagnostics: ``iterations_on/off/sum``, ``residual_on/off/sum`` (the plain map's
        ``max |F(u) - u|``), ``damping_sum`` (the plain relaxation in force at the end of
        the Summation solve) and ``restarts`` (Chebyshev safeguard restarts/fallbacks).
        """
        be = self._be
        if t == 0 and grey is not None:  # an event bin (grey None) is a full step even at t == 0
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
