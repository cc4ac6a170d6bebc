"""SDNF: a single-field dynamic neural field for looming -- a documented RECONSTRUCTION.

**RECONSTRUCTION.** The equations of the single-field DNF model (Qin et al.,
Neural Networks 2024, doi 10.1016/j.neunet.2024.106502) are not publicly
reachable. This model is built from the published mechanisms listed in
``shared/spec/BASELINES.md`` and is NOT the authors' model. Values marked
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
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from ..frames import to_grey
from ..params import THETA_SCALE
from .base import Model, StepResult
from .lgmd2 import _checks


@dataclass(frozen=True)
class SDNFParams:
    """SDNF parameters (RECONSTRUCTION; see the module docstring).

    Attributes
    ----------
    t_b : float
        Binarisation threshold on ``|P|`` (luminance in [0, 1]; 0.1, own choice).
    h : float
        Resting level (0.2, own choice = C-DNF's).
    A, B : float
        DoG amplitudes (3/2, 1/2; published).
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
    h: float = 0.2
    A: float = 1.5
    B: float = 0.5
    sigma_1: float = 1.0 / 3.0
    sigma_2: float | None = None
    radius: int | None = None
    kappa: float = 10.0
    epsilon: float = 0.006
    delta: float = 0.0
    n_persist: int = 3

    def __post_init__(self) -> None:
        if self.sigma_2 is None:
            object.__setattr__(self, "sigma_2", 3.0 * self.sigma_1)
        if self.radius is None:
            object.__setattr__(self, "radius", int(math.ceil(3.0 * self.sigma_2 - 1e-9)))
        _checks("SDNFParams", [
            (0 < self.t_b <= 1, f"t_b must be in (0, 1], got {self.t_b}"),
            (self.sigma_1 > 0 and self.sigma_2 > 0, "sigma_1 and sigma_2 must be > 0"),
            (int(self.radius) == self.radius and self.radius >= 1, f"radius must be a positive integer, got {self.radius}"),
            (self.A >= 0 and self.B >= 0, "A and B must be >= 0"),
            (self.kappa >= 0, f"kappa must be >= 0, got {self.kappa}"),
            (math.isfinite(self.h), f"h must be finite, got {self.h}"),
            (self.epsilon >= 0 and self.delta >= 0, "epsilon and delta must be >= 0"),
            (int(self.n_persist) == self.n_persist and self.n_persist >= 1,
             f"n_persist must be a positive integer, got {self.n_persist}"),
        ])

    def dog_profiles(self) -> tuple[np.ndarray, np.ndarray]:
        """1-D factors ``g_k(d) = exp(-d^2 / (2 sigma_k^2))``, ``d = -R..R`` (unnormalised)."""
        d = np.arange(-self.radius, self.radius + 1, dtype=np.float64)
        return np.exp(-(d**2) / (2.0 * self.sigma_1**2)), np.exp(-(d**2) / (2.0 * self.sigma_2**2))

    @staticmethod
    def activation(u: np.ndarray) -> np.ndarray:
        """Firing rate ``f(u) = tanh([u]+) / tanh(1)``."""
        return np.tanh(np.maximum(u, 0.0)) * THETA_SCALE

    @property
    def threshold(self) -> float:
        """Static part of the alert threshold, ``0.5 + epsilon``."""
        return 0.5 + self.epsilon

    def replace(self, **changes: Any) -> "SDNFParams":
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class TaichiSDNFBackend:
    """SDNF field state in Taichi ndarrays (float32), driven by :mod:`cdnf_ti.kernels.sdnf`."""

    name = "taichi"

    def __init__(self, params: SDNFParams, shape: tuple[int, int], arch: str = "cpu"):
        from ..taichi_runtime import ensure_taichi

        ensure_taichi(arch)
        from ..taichi_runtime import dsl

        ti = dsl()

        from ..kernels import sdnf as K
        from ..kernels.common import COLUMN_BLOCKS

        self.K = K
        self.params = params
        self.shape = tuple(shape)
        self.blocks = COLUMN_BLOCKS
        nd = lambda: ti.ndarray(ti.f32, self.shape)  # noqa: E731
        self.L, self.P, self.E, self.row1, self.row2 = nd(), nd(), nd(), nd(), nd()
        self.u = [nd(), nd()]
        self.F = [nd(), nd()]  # firing rates f(u), kept so the lateral pass reads them once
        g1, g2 = params.dog_profiles()
        self.g1 = ti.ndarray(ti.f32, g1.shape)
        self.g2 = ti.ndarray(ti.f32, g2.shape)
        self.g1.from_numpy(g1.astype(np.float32))
        self.g2.from_numpy(g2.astype(np.float32))
        self.reset()

    def reset(self) -> None:
        for a in (self.L, self.P, self.E, self.row1, self.row2):
            self.K.fill(a, 0.0)
        for a in self.u:
            self.K.fill(a, -self.params.h)
        for a in self.F:
            self.K.fill(a, 0.0)
        self.c = 0

    def load(self, grey: np.ndarray, first: bool) -> float:
        scale = 1.0 / 255.0 if grey.dtype == np.uint8 else 1.0
        n = self.K.load_binary(grey, self.L, self.P, self.E, scale, int(first), self.params.t_b, self.blocks)
        return float(n) / (self.shape[0] * self.shape[1])

    def update(self, b_t: float) -> float:
        p = self.params
        c, n = self.c, 1 - self.c
        s = self.K.field_update(self.E, self.F[c], self.row1, self.row2, self.u[n], self.F[n], self.g1, self.g2,
                                p.A, b_t, p.h, THETA_SCALE, self.blocks)
        self.c = n
        return float(s) / (self.shape[0] * self.shape[1])

    def fields(self) -> dict[str, np.ndarray]:
        return {"P": self.P.to_numpy(), "E": self.E.to_numpy(), "u": self.u[self.c].to_numpy(),
                "activity": self.F[self.c].to_numpy()}


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
    output_name = "I"
    params_type = SDNFParams
    description = "SDNF (after Qin et al. 2024): single DNF, binary input, delayed adaptive DoG -- RECONSTRUCTION"

    def __init__(self, params: SDNFParams | None = None, *, backend: str = "taichi", arch: str = "cpu",
                 fps: float = 30.0):
        super().__init__(params, backend=backend, arch=arch, fps=fps)
        self._be: Any = None
        self._t = 0
        self._prev = 0.5
        self._run = 0
        if backend == "taichi":
            from ..taichi_runtime import ensure_taichi

            ensure_taichi(arch)

    @property
    def threshold(self) -> float:
        """Static part of the (dynamic) alert threshold, ``0.5 + epsilon``."""
        return self.params.threshold

    def reset(self) -> None:
        self._t = 0
        self._prev = 0.5
        self._run = 0
        if self._be is not None:
            self._be.reset()

    #: Threshold sweep (experiments): the static alert margin epsilon.
    sweep_parameter = "epsilon (static threshold 0.5 + value)"
    sweep_values = tuple(round(0.001 * i, 3) for i in range(0, 21))

    @classmethod
    def sweep_default(cls) -> float:
        return float(cls.params_type().epsilon)

    @classmethod
    def sweep_alerts(cls, trace, values) -> list[np.ndarray]:
        """Alerts per frame at each ``epsilon``, replaying the dynamic-threshold rule on the saved output.

        The response ``I`` does not depend on ``epsilon``; the rule (``I(t) >
        max(0.5 + epsilon, I(t-1) + delta)`` on ``n_persist`` consecutive frames)
        is re-applied exactly as :meth:`step` does.
        """
        p = cls.params_type()
        out = np.asarray(trace.output, dtype=np.float64)
        result = []
        for eps in values:
            prev, run = 0.5, 0
            alerts = np.zeros(out.shape, dtype=bool)
            for t, o in enumerate(out):
                run = run + 1 if o > max(0.5 + eps, prev + p.delta) else 0
                prev = o
                alerts[t] = run >= p.n_persist
            result.append(alerts)
        return result

    def step(self, frame: np.ndarray) -> StepResult:
        p = self.params
        grey = to_grey(frame)
        if self._be is None:
            if self.backend_name == "taichi":
                self._be = TaichiSDNFBackend(p, grey.shape, self.arch)
            else:
                from ..baselines_reference import NumpySDNFBackend

                self._be = NumpySDNFBackend(p, grey.shape)
        elif grey.shape != self._be.shape:
            raise ValueError(f"frame {self._t} is {grey.shape[1]}x{grey.shape[0]} but this model runs at "
                             f"{self._be.shape[1]}x{self._be.shape[0]}; call reset() on a new model")
        t = self._t
        self._t += 1
        rho = self._be.load(grey, t == 0)
        b_t = p.B * (1.0 + p.kappa * rho)
        act = self._be.update(b_t)
        out = 1.0 / (1.0 + math.exp(-act))
        dyn = max(p.threshold, self._prev + p.delta)
        above = out > dyn
        self._run = self._run + 1 if above else 0
        self._prev = out
        alert = self._run >= p.n_persist
        diag = dict(rho=rho, B_t=b_t, activity=act, dyn_threshold=dyn, above=int(above), run=self._run)
        return StepResult(t, out, alert, True, diag)

    def fields(self) -> dict[str, np.ndarray]:
        """The field ``u``, its firing rate, the binary input ``E`` and ``P``, (H, W) each."""
        if self._be is None:
            return {}
        return self._be.fields()
