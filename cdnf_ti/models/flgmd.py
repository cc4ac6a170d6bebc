"""F-LGMD ONn: an LGMD with instantaneous negative feedback on the ON channel.

**RECONSTRUCTION.** The equations of Chang et al., "A look into feedback
neural computation upon collision selectivity" (Neural Networks 166:22-37,
2023) are not publicly reachable. This model is built from the published
mechanisms listed in ``docs/EQUATIONS.md`` and is NOT the authors'
model; every value marked "own choice" below is ours, chosen before looking
at any result and not tuned to the C-DNF paper's Table I.

Published facts used:

* an LGMD network with ON/OFF channels as LGMD1 (:mod:`cdnf_ti.models.lgmd1`):
  ON/OFF half-wave rectification with residue, delayed 3x3 lateral spread
  (centre 0, edge 0.25, diagonal 0.125; delays 30/60 ms), FFI, sum threshold
  ``T_s = 30``, grouping, ``K = sigmoid(sum G / N)``, SFA (0.005, 500 ms),
  spikes (0.78, count >= 8);
* the channel outputs are fed back *instantly* into their starting neurons,
  forming a fixed point per frame; the feedback coefficient must make the map
  a contraction (fixed-point theorem);
* "ONn" = negative feedback on the ON channel (none on OFF);
* excitation is processed with Gaussian kernels.

The reconstruction, per frame (grey levels 0..255, ``dt = 1000 // fps``):

* drives ``ON0 = P [P >= 0.1] + 0.1 ON(t-1)``, ``OFF0 = |P| [P < 0.1] + 0.1 OFF(t-1)``
  (``ON(t-1)`` the previous frame's settled channel);
* local summation of a channel ``X``:
  ``S_X(X) = [G_e (*) X - w_i sum_ij K(i,j) (a_ij X + (1 - a_ij) X(t-1))]+``,
  ``G_e`` the 3x3 normalised Gaussian with ``sigma_e = 1`` px (own choice),
  ``w_i = 0.5`` for both channels (LGMD1's ON value; for OFF an own choice:
  the OFF channel uses the same excitation/inhibition layout as ON, unlike
  LGMD1's swapped OFF layout, so that the Gaussian excitation applies to both);
* instantaneous feedback: ``X = [X0 + beta_X S_X(X)]+``, solved to ``tol``
  (:func:`cdnf_ti.solver.solve_fixed_point`: Chebyshev semi-iteration with the
  bounds of :meth:`FLGMDParams.chebyshev_bounds` by default, or the relaxed plain
  iteration with ``scheme="plain"``; the fixed point and the stopping rule are the same),
  ``beta_on = -0.5`` (own choice, negative = ONn), ``beta_off = 0``;
  contraction is guaranteed when
  ``|beta| (sum G_e + w_i sum K) < 1`` (checked: 0.5 x 1.75 = 0.875);
  the iterate starts at each pixel's local fixed point (``start="local"``, see
  :meth:`FLGMDParams.local_start_gains`) or at the drive ``X0`` (``start="drive"``);
* ``S = S_on + S_off`` at the fixed point, kept where ``>= 30``; then as LGMD1.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..baselines_reference import NumpyFLGMDBackend
from ..params import ModelParams, check_params, contrast_kernel, kernel_spectrum
from ..solver import RESTART_GROWTH, solve_fixed_point
from .lgmd1 import LGMD1, LGMD1Params, lgmd1_checks
from .lgmd2 import lowpass_coefficient
from .registry import register_model

#: Where the feedback iteration starts each frame (:attr:`FLGMDParams.start`).
FEEDBACK_STARTS = ("local", "drive")
#: Updates per solve launch at most (the engine's launch record holds 32).
UPDATES_PER_LAUNCH = 32


@dataclass(frozen=True)
class FLGMDParams(ModelParams):
    """F-LGMD ONn parameters (RECONSTRUCTION; see the module docstring).

    Attributes
    ----------
    beta_on, beta_off : float
        Instantaneous feedback coefficients of the ON and OFF channels
        (-0.5 and 0; own choices within the contraction bound).
    sigma_e : float
        Spread of the 3x3 normalised Gaussian excitation (px, 1.0; own choice).
    w_i_on, w_i_off : float
        Inhibition weights (0.5, LGMD1's ON value; OFF: own choice).
    tau_ffi, t_ffi, clip, dc, k_lateral, tau_lateral, t_s, c_sig,
    tau_sfa, t_sfa, kh_floor, t_sp, c_sp, n_ts :
        As :class:`~cdnf_ti.models.lgmd1.LGMD1Params` (defaults taken from it).
    tol : float
        Fixed-point tolerance on ``max |T(X) - X|`` (grey levels, 1e-3; own choice).
    max_iter : int
        Iteration cap per frame (100).
    damping, min_damping, stall_patience :
        Relaxation schedule of the plain scheme (and of the Chebyshev safeguard's
        fallback), see :func:`cdnf_ti.solver.solve_fixed_point`.
    scheme : {"chebyshev", "plain"}
        Iteration scheme of the feedback solve (same fixed point and stopping rule).
    start : {"local", "drive"}
        Where each frame's feedback iteration starts (same fixed point and stopping
        rule): ``"local"`` (default) at the fixed point a pixel would have if its
        neighbours shared its drive and its previous value (:meth:`local_start_gains`;
        on the shared clips 10 % fewer updates than the drive), ``"drive"`` at the
        feed-forward drive ``X0``.
    """

    beta_on: float = -0.5
    beta_off: float = 0.0
    sigma_e: float = 1.0
    w_i_on: float = LGMD1Params.w_i_on
    w_i_off: float = 0.5
    tau_ffi: float = LGMD1Params.tau_ffi
    t_ffi: float = LGMD1Params.t_ffi
    clip: float = LGMD1Params.clip
    dc: float = LGMD1Params.dc
    k_lateral: tuple[float, float] = LGMD1Params.k_lateral
    tau_lateral: tuple[float, float] = LGMD1Params.tau_lateral
    t_s: float = LGMD1Params.t_s
    c_sig: float = LGMD1Params.c_sig
    tau_sfa: float = LGMD1Params.tau_sfa
    t_sfa: float = LGMD1Params.t_sfa
    kh_floor: float = LGMD1Params.kh_floor
    t_sp: float = LGMD1Params.t_sp
    c_sp: float = LGMD1Params.c_sp
    n_ts: int = LGMD1Params.n_ts
    tol: float = 1e-3
    max_iter: int = 100
    damping: float = 1.0
    min_damping: float = 1.0 / 16.0
    stall_patience: int = 4
    scheme: str = "chebyshev"
    start: str = "local"

    def __post_init__(self) -> None:
        check_params("FLGMDParams", lgmd1_checks(self) + [
            (self.sigma_e > 0, f"sigma_e must be > 0, got {self.sigma_e}"),
            (self.w_i_on >= 0 and self.w_i_off >= 0, "w_i_on/w_i_off must be >= 0"),
            (all(k >= 0 for k in self.k_lateral), "k_lateral weights must be >= 0"),
            (self.contraction("on") < 1.0,
             f"beta_on={self.beta_on} breaks the contraction bound |beta| (1 + w_i sum K) < 1 "
             f"(got {self.contraction('on'):.3f}); the feedback fixed point is not guaranteed"),
            (self.contraction("off") < 1.0,
             f"beta_off={self.beta_off} breaks the contraction bound |beta| (1 + w_i sum K) < 1 "
             f"(got {self.contraction('off'):.3f}); the feedback fixed point is not guaranteed"),
            (self.tol > 0, f"tol must be > 0, got {self.tol}"),
            (int(self.max_iter) == self.max_iter and self.max_iter >= 1, "max_iter must be a positive integer"),
            (0 < self.min_damping <= self.damping <= 1, "need 0 < min_damping <= damping <= 1"),
            (self.scheme in ("chebyshev", "plain"), f"scheme must be 'chebyshev' or 'plain', got {self.scheme!r}"),
            (self.start in FEEDBACK_STARTS, f"start must be one of {', '.join(FEEDBACK_STARTS)}, got {self.start!r}"),
        ])

    def contraction(self, channel: str = "on") -> float:
        """Upper bound of the feedback map's Lipschitz constant (sup norm), any fps.

        ``|beta| (sum G_e + w_i sum K)`` with ``sum G_e = 1`` and the delay
        mixing coefficients bounded by 1.
        """
        beta, w = (self.beta_on, self.w_i_on) if channel == "on" else (self.beta_off, self.w_i_off)
        return abs(beta) * (1.0 + w * 4.0 * (abs(self.k_lateral[0]) + abs(self.k_lateral[1])))

    def excitation_kernel(self) -> np.ndarray:
        """The 3x3 normalised Gaussian ``G_e``, shape (3, 3)."""
        return contrast_kernel(self.sigma_e)

    def feedback_stencils(self, dt: int) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """:func:`feedback_stencil` of the ON and OFF channels at frame interval ``dt`` (ms)."""
        a = tuple(lowpass_coefficient(dt, t) for t in self.tau_lateral)
        ge = self.excitation_kernel()
        return (feedback_stencil(ge, self.k_lateral, a, self.w_i_on),
                feedback_stencil(ge, self.k_lateral, a, self.w_i_off))

    def local_start_gains(self, dt: int) -> tuple[tuple[float, float], tuple[float, float]]:
        """``(w, kappa)`` of the ON and OFF channels: the iterate starts at ``X0 + kappa [w X0 - Q]+``.

        ``w = sum W_x`` is the gain of the feedback stencil on a uniform channel. A
        pixel whose 3x3 neighbourhood shares its drive ``X0`` and its previous value
        (so ``Q`` too) has the fixed point ``X = [X0 + beta [w X - Q]+]+``: ``X = X0``
        where ``w X0 <= Q``, else ``X = (X0 - beta Q) / (1 - beta w)``, which is
        ``X0 + kappa (w X0 - Q)`` with ``kappa = beta / (1 - beta w)`` (``1 - beta w > 0``
        by the contraction bound; the start is ``>= 0``). ``kappa = 0`` (``start="drive"``
        or no feedback) starts at the drive.
        """
        gains = []
        for beta, (c, e, d) in zip((self.beta_on, self.beta_off), self.feedback_stencils(dt)):
            w = c + 4.0 * e + 4.0 * d
            gains.append((w, beta / (1.0 - beta * w) if self.start == "local" else 0.0))
        return gains[0], gains[1]

    def chebyshev_bounds(self, dt: int) -> tuple[float, float]:
        """Interval ``[a, b]`` holding the spectrum of the feedback map's Jacobian.

        ``T(X) = [X0 + beta [W_x (*) X - Q]+]+`` has the Jacobian
        ``D2 beta D1 W_x`` (``D1``, ``D2``: 0/1 masks of the active rectifiers), so its
        eigenvalues lie in the hull of ``{0} U beta [min W_x^, max W_x^]``
        (:func:`cdnf_ti.params.kernel_spectrum`), taken over the iterated channels.
        """
        lo, hi = 0.0, 0.0
        for beta, (c, e, d) in zip((self.beta_on, self.beta_off), self.feedback_stencils(dt)):
            if beta == 0.0:
                continue
            s_lo, s_hi = kernel_spectrum(np.array([[d, e, d], [e, c, e], [d, e, d]]))
            lo = min(lo, beta * s_lo, beta * s_hi)
            hi = max(hi, beta * s_lo, beta * s_hi)
        return lo, hi


def feedback_stencil(ge: np.ndarray, k_lateral: tuple[float, float], a: tuple[float, float],
                     w_i: float) -> tuple[float, float, float]:
    """The 3x3 stencil ``W_x = G_e - w_i a K`` that the feedback iteration applies to ``X``.

    ``S_X(X) = [G_e (*) X - w_i sum K (a X + (1 - a) X(t-1))]+ = [W_x (*) X - Q]+`` with
    ``Q = w_i sum K (1 - a) X(t-1)``, constant within a frame (K's centre is 0).

    Parameters
    ----------
    ge : (3, 3) ndarray
        The excitation kernel ``G_e``.
    k_lateral, a : (edge, diagonal)
        Weights of ``K`` and their delay coefficients ``a = dt / (dt + tau)``.
    w_i : float
        The channel's inhibition weight.

    Returns
    -------
    (centre, edge, diagonal) : tuple of float
    """
    return (float(ge[1, 1]), float(ge[0, 1]) - w_i * k_lateral[0] * a[0],
            float(ge[0, 0]) - w_i * k_lateral[1] * a[1])








@register_model
class FLGMDONn(LGMD1):
    """F-LGMD ONn (after Chang et al. 2023) -- a documented RECONSTRUCTION.

    See the module docstring for the equations and which parameter values
    are our own choices.

    Parameters
    ----------
    params : FLGMDParams, optional
    backend : {"taichi", "numpy"}
    arch : str
    fps : float

    Notes
    -----
    ``output`` is ``K``; ``spike`` the collision alert (count >= 8);
    ``converged`` is False when the feedback fixed point missed ``tol``.
    Diagnostics: ``Kh, n, count, FFI, held, sum_G, iterations,
    residual_on, residual_off``. :meth:`fields`: ``P, ON, OFF, S_on, S_off, S, G``.
    """

    name = "flgmd_onn"
    order = 4
    panels = (("ON", "ON"), ("OFF", "OFF"), ("S", "Summation S"))
    params_type = FLGMDParams
    description = ("F-LGMD ONn (after Chang et al. 2023): LGMD with instant negative ON feedback "
                   "solved as a fixed point -- RECONSTRUCTION")

    numpy_backend_type = NumpyFLGMDBackend
    #: The stages (``kernels/lgmd.py``): the load, the feedback solve and the layers at its fixed point.
    kernels = "lgmd:flgmd"
    #: The planes that :meth:`fields` leaves out (the solve's scratch).
    hidden = ("L", "ON0", "OFF0", "Q_on", "Q_off", "X_on", "X_off")

    def coefficients(self) -> dict[str, object]:
        """The stages' coefficients by name (``kernels/lgmd.py``, ``FLGMD_COEFS``)."""
        p, dt = self.params, self.dt
        a = self._lowpass(dt, p.tau_lateral)
        w_on, w_off = p.feedback_stencils(dt)
        start_on, start_off = p.local_start_gains(dt)
        q_on, q_off = ([w * k * (1.0 - x) for k, x in zip(p.k_lateral, a)] for w in (p.w_i_on, p.w_i_off))
        return dict(clip=p.clip, dc=p.dc, q_on=q_on, q_off=q_off, start_on=start_on, start_off=start_off,
                    w_on=w_on, w_off=w_off, beta=(p.beta_on, p.beta_off), t_s=p.t_s)

    def _keep_channels(self, loaded: object) -> None:
        """The settled channels are written only at a fixed point: a frame without one keeps them."""

    def _diag0(self) -> dict[str, float]:
        d = super()._diag0()
        d.update(iterations=0, residual_on=0.0, residual_off=0.0)
        return d

    def _held_diag(self) -> dict[str, float]:
        return dict(iterations=0, residual_on=0.0, residual_off=0.0)

    def _setup(self) -> None:
        super()._setup()
        p = self.params
        self._bounds = p.chebyshev_bounds(self.dt) if p.scheme == "chebyshev" else None
        self._launch = "" if p.beta_off != 0.0 else "_on"  # the solve's launches: OFF iterated or not

    def _run_layers(self) -> tuple[float, dict[str, float], bool]:
        p = self.params
        be = self._be
        if self.backend_name == "numpy":
            be.prepare()
            iterate, many, steps = be.feedback_iterate, None, 1
        else:
            self._sum_g = None
            iterate, many, steps = self._iterate, self._iterate_many, UPDATES_PER_LAUNCH
        rep = solve_fixed_point(iterate, 2, tol=p.tol, max_iter=p.max_iter, damping=p.damping,
                                min_damping=p.min_damping, stall_patience=p.stall_patience, bounds=self._bounds,
                                steps=steps, iterate_many=many)
        if self.backend_name == "numpy":
            sum_g = be.finish()
        else:  # a solve launch that converged computed the layers; else the finish launch does
            sum_g = self._sum_g if self._sum_g is not None else be.launch("finish")[0]
        extra = dict(iterations=max(rep.iterations), residual_on=rep.residuals[0], residual_off=rep.residuals[1])
        return sum_g, extra, rep.converged

    def _iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        """One update of the feedback solve; returns the residuals of ON and OFF before it."""
        return self._iterate_many([(lam, mom)])[0]

    def _iterate_many(self, coefs: list[tuple[float, float]]) -> list[tuple[float, float]]:
        """The updates ``coefs`` (``(lam, mom)`` each) in one solve launch, stopping after the first whose
        residuals are both ``<= tol``; that launch also computes the layers at the fixed point (``_sum_g``)."""
        p = self.params
        tol = float(np.float32(p.tol))  # the kernels' float32 tolerance
        res, (sum_g,) = self._be.solve("solve" + self._launch, coefs, len(coefs), tol, RESTART_GROWTH)
        self._sum_g = sum_g if res and max(res[-1]) <= tol else None
        return res
