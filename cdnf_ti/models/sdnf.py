"""SDNF: a single-field dynamic neural field for looming -- a documented RECONSTRUCTION.

**RECONSTRUCTION.** The equations of the single-field DNF model (Qin et al.,
Neural Networks 2024, doi 10.1016/j.neunet.2024.106502) are not publicly
reachable. This model is built from the published mechanisms listed in
``docs/EQUATIONS.md`` and is NOT the authors' model. Values marked
"own choice" are ours, fixed before looking at any result and not tuned to
the C-DNF paper's Table I.

Published facts used:

* one Amari field, one neuron per pixel, luminance change as input;
* binary pre-processing of the luminance change;
* time-delayed lateral interaction: the lateral term is computed from the
  previous frame's field, so each frame is one explicit update (no iteration);
* adaptive lateral interaction regulated by the input intensity, with a DoG
  kernel ``sigma_2 = 3 sigma_1``, ``A = 3/2``, ``B = 1/2`` (as reused in
  C-DNF's Summation field: ``sigma_1 = 1/3`` px, unnormalised Gaussians);
* a dynamic activation threshold that suppresses responses to receding objects.

The reconstruction, per frame (grey ``L`` in [0, 1]):

* ``P = L(t) - L(t-1)``; binary input ``E = [|P| >= T_b]``, ``T_b = 0.1``
  (own choice); ``rho(t) = mean E`` (the input intensity);
* adaptive inhibition ``B(t) = B (1 + kappa rho(t))``, ``kappa = 10``
  (own choice: the surround inhibition grows with the fraction of the frame
  that changes);
* ``u(t) = E - h + vartheta(A g1 (*) f(u(t-1)) - B(t) g2 (*) f(u(t-1)))``,
  ``h = 0.2`` (own choice, C-DNF's value), ``vartheta(a) = tanh(a / 2)``,
  firing rate ``f(u) = theta([u]+) = tanh([u]+) / tanh(1)`` (own choice, C-DNF's
  activation); rest ``u = -h``;
* ``I(t) = sigmoid(mean f(u(t)))`` (0.5 at rest);
* dynamic threshold ``theta_d(t) = max(0.5 + epsilon, I(t-1) + delta)``
  (``epsilon = 0.006`` as C-DNF, ``delta = 0``; own choice of form): a frame
  counts only if the response exceeds the static level *and* is still rising,
  which a receding object's shrinking response never is after its onset;
* collision alert when that holds on ``n_persist = 3`` consecutive frames
  (own choice; it keeps the one-frame onset transient of any motion from
  alerting).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..alert_rule import AlertRule
from ..baselines_reference import NumpySDNFBackend
from ..params import THETA_SCALE, CDNFParams, ModelParams, check_params, dog_radius, gaussian_profile, sigmoid, theta
from .base import Model, StepResult, Trace
from .registry import register_model


@dataclass(frozen=True)
class SDNFParams(ModelParams):
    """SDNF parameters (RECONSTRUCTION; see the module docstring).

    The values shared with C-DNF take their defaults from
    :class:`~cdnf_ti.params.CDNFParams` (one source).

    Attributes
    ----------
    t_b : float
        Binarisation threshold on ``|P|`` (luminance in [0, 1]; 0.1, own choice).
    h : float
        Resting level (0.2, own choice = C-DNF's).
    A, B : float
        DoG amplitudes (3/2, 1/2; published, and reused by C-DNF's Summation field).
    sigma_1 : float
        Excitatory spread (px, 1/3, as C-DNF's Summation field).
    sigma_2 : float or None
        Inhibitory spread (px); ``None`` = ``3 sigma_1`` (published ratio).
    radius : int or None
        Kernel truncation radius (px); ``None`` = ``ceil(3 sigma_2)``.
    kappa : float
        Adaptive inhibition gain: ``B(t) = B (1 + kappa rho(t))`` (10, own choice).
    epsilon : float
        Static alert margin above 0.5 (0.006, C-DNF's).
    delta : float
        Rise required over the previous frame's output (0, own choice).
    n_persist : int
        Consecutive above-threshold frames for an alert (3, own choice).
    """

    t_b: float = 0.1
    h: float = CDNFParams.h
    A: float = CDNFParams.A
    B: float = CDNFParams.B
    sigma_1: float = CDNFParams.sigma_1
    sigma_2: float | None = None
    radius: int | None = None
    kappa: float = 10.0
    epsilon: float = CDNFParams.epsilon
    delta: float = 0.0
    n_persist: int = 3

    def __post_init__(self) -> None:
        if self.sigma_2 is None:
            object.__setattr__(self, "sigma_2", 3.0 * self.sigma_1)
        if self.radius is None:
            object.__setattr__(self, "radius", dog_radius(self.sigma_2))
        check_params("SDNFParams", [
            (0 < self.t_b <= 1, f"t_b must be in (0, 1], got {self.t_b}"),
            (self.sigma_1 > 0 and self.sigma_2 > 0, "sigma_1 and sigma_2 must be > 0"),
            (int(self.radius) == self.radius and self.radius >= 1,
             f"radius must be a positive integer, got {self.radius}"),
            (self.A >= 0 and self.B >= 0, "A and B must be >= 0"),
            (self.kappa >= 0, f"kappa must be >= 0, got {self.kappa}"),
            (math.isfinite(self.h), f"h must be finite, got {self.h}"),
            (self.epsilon >= 0 and self.delta >= 0, "epsilon and delta must be >= 0"),
            (int(self.n_persist) == self.n_persist and self.n_persist >= 1,
             f"n_persist must be a positive integer, got {self.n_persist}"),
        ])

    def dog_profiles(self) -> tuple[np.ndarray, np.ndarray]:
        """1-D factors ``g_k(d) = exp(-d^2 / (2 sigma_k^2))``, ``d = -R..R`` (unnormalised)."""
        return gaussian_profile(self.sigma_1, self.radius), gaussian_profile(self.sigma_2, self.radius)

    @staticmethod
    def activation(u: np.ndarray) -> np.ndarray:
        """Firing rate ``f(u) = theta([u]+) = tanh([u]+) / tanh(1)``."""
        return theta(np.maximum(u, 0.0))

    @property
    def threshold(self) -> float:
        """Static part of the alert threshold, ``0.5 + epsilon``."""
        return 0.5 + self.epsilon


def dynamic_threshold(p: SDNFParams, out: float, prev: float, run: int) -> tuple[float, int]:
    """The dynamic-threshold rule of one frame.

    Parameters
    ----------
    p : SDNFParams
    out, prev : float
        ``I(t)`` and ``I(t-1)``.
    run : int
        Consecutive frames above the threshold before this one.

    Returns
    -------
    theta_d : float
        ``max(0.5 + epsilon, I(t-1) + delta)``.
    run : int
        ``run + 1`` if ``I(t) > theta_d``, else 0; the alert is ``run >= n_persist``.
    """
    dyn = max(p.threshold, prev + p.delta)
    return dyn, (run + 1 if out > dyn else 0)




@register_model
class SDNF(Model):
    """Single-field DNF looming model (after Qin et al. 2024) -- a documented RECONSTRUCTION.

    See the module docstring for the equations and which values are our own.

    Parameters
    ----------
    params : SDNFParams, optional
    backend : {"taichi", "numpy"}
    arch : str
    fps : float
        Input frame rate (the reconstruction has no time constants).

    Notes
    -----
    ``output`` is ``I`` (sigmoid of the mean field activity); ``spike`` the
    alert. Diagnostics: ``rho`` (active input fraction), ``B_t``,
    ``activity`` (mean firing rate), ``dyn_threshold``, ``above``, ``run``.
    :meth:`fields`: ``P, E, u, activity``.
    """

    name = "sdnf"
    order = 1
    kernels = "sdnf"
    panels = (("E", "Binary input E"), ("u", "Field u"), ("activity", "Firing rate f(u)"))
    #: Use the fast (lane) layout where it applies; ``False``: the pixel layout (same equations).
    fast: bool = True
    output_name = "I"
    params_type = SDNFParams
    description = "SDNF (after Qin et al. 2024): single DNF, binary input, delayed adaptive DoG -- RECONSTRUCTION"

    @property
    def threshold(self) -> float:
        """Static part of the (dynamic) alert threshold, ``0.5 + epsilon``."""
        return self.params.threshold

    def alert_rule(self) -> AlertRule:
        """``I > max(0.5 + epsilon, I(t-1) + delta)`` on ``n_persist`` frames in a row: the ``run`` diagnostic
        against ``n_persist``."""
        p, name = self.params, self.output_name
        prev = f"{name}(t-1)" + (f" + {p.delta:g}" if p.delta else "")
        n = int(p.n_persist)
        return AlertRule(f"{name} > max({p.threshold:.4g}, {prev}) on {n} frames in a row",
                         "frames in a row above the dynamic threshold", "run", float(n))

    def _reset_state(self) -> None:
        self._prev = 0.5  # I(t-1)
        self._run = 0  # consecutive frames above the dynamic threshold

    #: Threshold sweep (experiments): the static alert margin epsilon.
    sweep_parameter = "epsilon (static threshold 0.5 + value)"
    sweep_values = tuple(round(0.001 * i, 3) for i in range(0, 21))

    @classmethod
    def sweep_default(cls) -> float:
        return float(cls.params_type().epsilon)

    @classmethod
    def sweep_alerts(cls, trace: Trace, values: Sequence[float]) -> list[np.ndarray]:
        """Alerts per frame at each ``epsilon``, replaying the dynamic-threshold rule on the saved output.

        The response ``I`` does not depend on ``epsilon``; the rule (``I(t) >
        max(0.5 + epsilon, I(t-1) + delta)`` on ``n_persist`` consecutive frames)
        is re-applied exactly as :meth:`step` does.
        """
        out = np.asarray(trace.output, dtype=np.float64)
        result = []
        for eps in values:
            p = cls.params_type(epsilon=float(eps))
            prev, run = 0.5, 0
            alerts = np.zeros(out.shape, dtype=bool)
            for t, o in enumerate(out):
                _, run = dynamic_threshold(p, o, prev, run)
                prev = o
                alerts[t] = run >= p.n_persist
            result.append(alerts)
        return result

    takes_events = True

    def _numpy_backend(self, shape: tuple[int, int]) -> NumpySDNFBackend:
        return NumpySDNFBackend(self.params, shape)

    def coefficients(self) -> dict:
        """The stages' coefficients by name (``kernels/sdnf.py``): ``A``, ``h``, theta's scale, ``T_b``, the
        rest ``-h`` and the DoG taps ``g1``, ``g2`` (float32)."""
        p = self.params
        g1, g2 = p.dog_profiles()
        taps = np.concatenate([g1.astype(np.float32), g2.astype(np.float32)])
        return dict(A=p.A, h=p.h, theta=THETA_SCALE, t_b=p.t_b, u_rest=-p.h, taps=taps)

    def kernel_options(self) -> dict:
        """The DoG's radius (compile-time: the taps unroll)."""
        return {"radius": int(self.params.radius)}

    def _step(self, t: int, grey: np.ndarray | None, rho: float | None) -> StepResult:
        p = self.params
        be = self._be
        n_cells = be.shape[0] * be.shape[1]
        if rho is None:  # the engine: its input stage, on the frame or event bin that load kept
            scale = 1.0 / 255.0 if grey is not None and grey.dtype == np.uint8 else 1.0
            rho = be.launch("load", scale=scale, keep=0.0 if t == 0 else 1.0)[0] / n_cells
        b_t = p.B * (1.0 + p.kappa * rho)
        if hasattr(be, "launch"):
            be.flip()  # f(u(t-1)) becomes the DoG's input
            act = be.launch("update", B_t=b_t)[0] / n_cells
        else:
            act = be.update(b_t)
        out = sigmoid(act)
        dyn, self._run = dynamic_threshold(p, out, self._prev, self._run)
        above = self._run > 0
        self._prev = out
        alert = self._run >= p.n_persist
        diag = dict(rho=rho, B_t=b_t, activity=act, dyn_threshold=dyn, above=int(above), run=self._run)
        return StepResult(t, out, alert, True, diag)
