"""C-DNF model description: parameters, activation functions and lateral kernels.

Everything the equations of ``docs/EQUATIONS.md`` need lives here, in NumPy,
independent of any execution backend:

* ``u_on  = P_on  - h + vartheta(W_c (*) u_on)``           (ON contrast field)
* ``u_off = P_off - h + vartheta(W_c (*) u_off)``          (OFF contrast field)
* ``v = alpha_on theta([u_on]+) + alpha_off theta([u_off]+) - h + vartheta(W_s (*) v)``
* ``I_v = sigmoid(mean theta([v]+))``, ``spike = I_v > 0.5 + epsilon``

with ``vartheta(a) = 2 / (1 + exp(-a)) - 1 = tanh(a / 2)`` and
``theta(a) = tanh(a) (e^2 + 1) / (e^2 - 1) = tanh(a) / tanh(1)``.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any, TypeVar

import numpy as np

BORDER_MODES = ("replicate", "reflect", "zero")
#: Where each frame's fixed-point iteration starts (``CDNFParams.start``).
STARTS = ("local", "previous", "rest")

P = TypeVar("P", bound="ModelParams")


def vartheta(a: np.ndarray | float) -> np.ndarray | float:
    """Lateral-interaction threshold function ``2 / (1 + exp(-a)) - 1``.

    Parameters
    ----------
    a : array_like
        Lateral input (dimensionless).

    Returns
    -------
    ndarray
        Values in (-1, 1); identical to ``tanh(a / 2)``.
    """
    return np.tanh(np.asarray(a) * 0.5)


THETA_SCALE = (math.e**2 + 1.0) / (math.e**2 - 1.0)  # == 1 / tanh(1)


def theta(a: np.ndarray | float) -> np.ndarray | float:
    """Activation ``tanh(a) (e^2 + 1) / (e^2 - 1)``, so ``theta(1) = 1``."""
    return np.tanh(np.asarray(a)) * THETA_SCALE


def sigmoid(a: float) -> float:
    """Logistic function ``1 / (1 + exp(-a))`` (float64)."""
    return 1.0 / (1.0 + math.exp(-a))


def check_params(name: str, checks: list[tuple[bool, str]]) -> None:
    """Raise ``ValueError("<name>: <message>")`` for the first failed check.

    Parameters
    ----------
    name : str
        The parameter class, named in the message (e.g. ``"CDNFParams"``).
    checks : list of (bool, str)
        ``(condition that must hold, message when it does not)``.
    """
    for ok, msg in checks:
        if not ok:
            raise ValueError(f"{name}: {msg}")


def dog_radius(sigma_2: float) -> int:
    """Default truncation radius ``ceil(3 sigma_2)`` (px) of a DoG with inhibitory spread ``sigma_2``."""
    return int(math.ceil(3.0 * sigma_2 - 1e-9))


def gaussian_profile(sigma: float, radius: int) -> np.ndarray:
    """Unnormalised 1-D Gaussian ``g(d) = exp(-d^2 / (2 sigma^2))``, ``d = -radius..radius`` (px).

    Returns
    -------
    ndarray, shape (2 radius + 1,), float64
    """
    d = np.arange(-int(radius), int(radius) + 1, dtype=np.float64)
    return np.exp(-(d**2) / (2.0 * sigma**2))


class ModelParams:
    """Shared behaviour of the models' frozen parameter dataclasses."""

    def replace(self: P, **changes: Any) -> P:
        """Return a copy with some fields changed (validated)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class CDNFParams(ModelParams):
    """Parameters of the C-DNF model (defaults from the paper, docs/EQUATIONS.md).

    Attributes
    ----------
    h : float
        Resting level of all three fields (paper: 0.2).
    alpha_on, alpha_off : float
        Weights of the ON and OFF contrast outputs in the Summation field (0.5 each).
    sigma_c : float
        Spread of the 3x3 normalised Gaussian lateral excitation ``W_c`` (px, 1.0).
    sigma_1 : float
        Excitatory spread of the Summation DoG ``W_s`` (px, 1/3).
    sigma_2 : float or None
        Inhibitory spread of ``W_s`` (px); ``None`` means ``3 * sigma_1``.
    A, B : float
        DoG amplitudes (3/2 and 1/2); ``W_s`` is not normalised.
    radius_s : int or None
        Truncation radius of ``W_s`` (px); ``None`` means ``ceil(3 * sigma_2)``.
    epsilon : float
        Alert margin: ``spike = I_v > 0.5 + epsilon`` (0.006).
    tol : float
        Fixed-point tolerance on ``max |F(u) - u|`` per field (1e-5).
    max_iter : int
        Iteration cap per field and frame (200).
    damping : float
        Initial relaxation ``lambda`` in ``u <- (1 - lambda) u + lambda F(u)`` (1.0).
    contrast_relaxation : float
        Relaxation of the ON/OFF fields' plain iteration (1.0, the paper's ``lambda = 1``;
        used by ``scheme="plain"`` and the Chebyshev safeguard's fallback).
        The contrast map's Jacobian ``0.5 sech^2(.) W_c`` has its spectrum in
        [0, 1/2] (``W_c`` is positive definite with eigenvalues <= 1), so any value
        in (0, 2) converges to the same fixed point; 4/3 is optimal for the smooth part
        of the error (factor <= 1/3 per iteration instead of 1/2: about 30% fewer contrast
        iterations from ``start="previous"``). The local start leaves mostly edge error,
        which plain steps (1.0) damp faster, so there it gains nothing.
    min_damping : float
        Smallest ``lambda`` the solver halves down to when the residual stalls.
    stall_patience : int
        Iterations without residual decrease before ``lambda`` is halved.
    scheme : {"chebyshev", "plain"}
        Iteration scheme of the three fixed-point solves (same fixed point and stopping
        rule): Chebyshev semi-iteration with bounds from the kernels' spectra (default,
        2-3x fewer iterations) or the paper's plain (damped) iteration.
    steps_per_launch : int
        Updates per kernel launch, 1..32 (the residual of each is returned; a launch
        stops updating once every field is within ``tol``, or when the residual grows).
    contrast_bounds, summation_bounds : (float, float) or None
        Spectral bounds ``[a, b]`` of the maps' Jacobians for the Chebyshev scheme;
        ``None`` (default): computed from the kernels (:func:`jacobian_bounds`).
    start : {"local", "previous", "rest"}
        Where each frame's iteration starts (all give the same fixed point, docs/EQUATIONS.md):
        ``"local"`` (default): every pixel at the stationary value its own input would
        have if all its neighbours had the same (``u = x - h + vartheta(sum(W) u)``,
        :func:`stationary_level`; ``x = P_on``/``P_off`` for the contrast fields, ``S``
        for the Summation field), which already solves the smooth part of the field
        and leaves the iteration the edges: about 10 % fewer contrast and 25-30 % fewer
        Summation updates on dashcam footage; ``"previous"``: the previous frame's
        solution; ``"rest"``: the resting state.
    border : {"replicate", "reflect", "zero"}
        Boundary handling of the lateral kernels (``replicate`` = OpenCV
        ``BORDER_REPLICATE``; ``reflect`` = ``BORDER_REFLECT_101``; ``zero`` =
        constant 0 outside the frame).
    """

    h: float = 0.2
    alpha_on: float = 0.5
    alpha_off: float = 0.5
    sigma_c: float = 1.0
    sigma_1: float = 1.0 / 3.0
    sigma_2: float | None = None
    A: float = 1.5
    B: float = 0.5
    radius_s: int | None = None
    epsilon: float = 0.006
    tol: float = 1e-5
    max_iter: int = 200
    damping: float = 1.0
    contrast_relaxation: float = 1.0
    min_damping: float = 1.0 / 64.0
    stall_patience: int = 4
    scheme: str = "chebyshev"
    steps_per_launch: int = 32
    contrast_bounds: tuple[float, float] | None = None
    summation_bounds: tuple[float, float] | None = None
    start: str = "local"
    border: str = "replicate"

    def __post_init__(self) -> None:
        if self.sigma_2 is None:
            object.__setattr__(self, "sigma_2", 3.0 * self.sigma_1)
        if self.radius_s is None:
            object.__setattr__(self, "radius_s", dog_radius(self.sigma_2))
        self.validate()

    def validate(self) -> None:
        """Raise ``ValueError`` with a clear message for an invalid value."""
        checks = [
            (self.sigma_c > 0, f"sigma_c must be > 0, got {self.sigma_c}"),
            (self.sigma_1 > 0, f"sigma_1 must be > 0, got {self.sigma_1}"),
            (self.sigma_2 > 0, f"sigma_2 must be > 0, got {self.sigma_2}"),
            (self.tol > 0, f"tol must be > 0, got {self.tol}"),
            (int(self.max_iter) == self.max_iter and self.max_iter >= 1,
             f"max_iter must be a positive integer, got {self.max_iter}"),
            (0 < self.damping <= 1, f"damping must be in (0, 1], got {self.damping}"),
            (0 < self.contrast_relaxation < 2,
             f"contrast_relaxation must be in (0, 2), got {self.contrast_relaxation}"),
            (0 < self.min_damping <= self.damping,
             f"min_damping must be in (0, damping], got {self.min_damping}"),
            (self.stall_patience >= 1, f"stall_patience must be >= 1, got {self.stall_patience}"),
            (int(self.radius_s) == self.radius_s and self.radius_s >= 1,
             f"radius_s must be a positive integer, got {self.radius_s}"),
            (self.scheme in ("chebyshev", "plain"),
             f"scheme must be 'chebyshev' or 'plain', got {self.scheme!r}"),
            (int(self.steps_per_launch) == self.steps_per_launch and 1 <= self.steps_per_launch <= 32,
             f"steps_per_launch must be an integer in 1..32, got {self.steps_per_launch}"),
            (_bounds_ok(self.contrast_bounds), f"contrast_bounds must be (a, b) with a <= b < 1, "
                                               f"got {self.contrast_bounds}"),
            (_bounds_ok(self.summation_bounds), f"summation_bounds must be (a, b) with a <= b < 1, "
                                                f"got {self.summation_bounds}"),
            (self.start in STARTS, f"start must be one of {STARTS}, got {self.start!r}"),
            (self.border in BORDER_MODES,
             f"border must be one of {BORDER_MODES}, got {self.border!r}"),
            (math.isfinite(self.h), f"h must be finite, got {self.h}"),
            (self.epsilon >= 0, f"epsilon must be >= 0, got {self.epsilon}"),
            (self.alpha_on >= 0 and self.alpha_off >= 0,
             f"alpha_on/alpha_off must be >= 0, got {self.alpha_on}/{self.alpha_off}"),
        ]
        check_params("CDNFParams", checks)

    @property
    def threshold(self) -> float:
        """Alert threshold ``I_thre = 0.5 + epsilon``."""
        return 0.5 + self.epsilon

    def chebyshev_bounds(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """``(contrast, summation)`` Jacobian bounds for the Chebyshev scheme.

        The given ``contrast_bounds``/``summation_bounds``, else :func:`jacobian_bounds`
        of ``W_c`` and ``W_s``.
        """
        c = self.contrast_bounds or jacobian_bounds(contrast_kernel(self.sigma_c))
        s = self.summation_bounds or jacobian_bounds(dog_kernel(self))
        return tuple(map(float, c)), tuple(map(float, s))


def _bounds_ok(b: Any) -> bool:
    if b is None:
        return True
    try:
        a, z = (float(x) for x in b)
    except (TypeError, ValueError):
        return False
    return math.isfinite(a) and a <= z < 1.0


def contrast_kernel(sigma_c: float) -> np.ndarray:
    """The 3x3 normalised Gaussian ``W_c`` (sums to 1), float64, shape (3, 3)."""
    d = np.arange(-1, 2, dtype=np.float64)
    g = np.exp(-(d[:, None] ** 2 + d[None, :] ** 2) / (2.0 * sigma_c**2))
    return g / g.sum()


def dog_profiles(params: CDNFParams) -> tuple[np.ndarray, np.ndarray]:
    """1-D factors of the DoG: ``W_s = A g1 g1^T - B g2 g2^T``.

    Returns
    -------
    g1, g2 : ndarray, shape (2 R + 1,)
        ``g_k(d) = exp(-d^2 / (2 sigma_k^2))`` for ``d = -R..R`` (unnormalised).
    """
    r = int(params.radius_s)
    return gaussian_profile(params.sigma_1, r), gaussian_profile(params.sigma_2, r)


def dog_kernel(params: CDNFParams) -> np.ndarray:
    """The truncated Difference-of-Gaussians ``W_s``, float64, shape (2R+1, 2R+1).

    ``W_s(dx, dy) = A exp(-(dx^2 + dy^2) / (2 sigma_1^2)) - B exp(-(dx^2 + dy^2) / (2 sigma_2^2))``
    """
    g1, g2 = dog_profiles(params)
    return params.A * np.outer(g1, g1) - params.B * np.outer(g2, g2)


def resting_level(h: float, gain: float) -> float:
    """Uniform stationary value ``u*`` of ``u = -h + vartheta(gain * u)``.

    For a uniform field with a replicate border the lateral input is
    ``gain * u`` with ``gain = sum(W)``: :func:`stationary_level` at zero input.
    """
    return float(stationary_level(0.0, h, gain))


def stationary_level(x: np.ndarray | float, h: float, gain: float) -> np.ndarray:
    """Stationary value ``u`` of ``u = x - h + vartheta(gain * u)`` for each uniform input ``x``.

    A field whose input is ``x`` everywhere (replicate border) rests there, with
    ``gain = sum(W)``; :func:`resting_level` is the case ``x = 0``. Solved by
    bisection in float64 on ``[x - h - 1, x - h + 1]``, where the root lies since
    ``|vartheta| < 1`` (for ``gain > 2`` there may be several; one is returned).

    Parameters
    ----------
    x : float or ndarray
        Uniform input (dimensionless, any shape).
    h, gain : float

    Returns
    -------
    ndarray of float64, the shape of ``x``.
    """
    x = np.asarray(x, dtype=np.float64)
    lo, hi = x - h - 1.0, x - h + 1.0
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        above = x - h + np.tanh(0.5 * gain * mid) - mid > 0.0  # the root is above mid
        lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
    return 0.5 * (lo + hi)


def resting_levels(params: CDNFParams) -> tuple[float, float]:
    """Uniform resting values ``(u*, v*)`` of the contrast fields and of the Summation field.

    ``u*`` solves ``u = -h + vartheta(u)`` (``W_c`` sums to 1); ``v*`` solves
    ``v = -h + vartheta(sum(W_s) v)`` with ``sum(W_s) = A (sum g1)^2 - B (sum g2)^2``.
    This is the starting state of every backend before its resting state is
    solved for the frame size and border (no input: ``S = 0`` since ``u* < 0``).
    """
    gain_c, gain_s = kernel_gains(params)
    return resting_level(params.h, gain_c), resting_level(params.h, gain_s)


def kernel_gains(params: CDNFParams) -> tuple[float, float]:
    """``(sum(W_c), sum(W_s))``: the lateral input per unit of a uniform field.

    ``sum(W_c) = 1`` (normalised); ``sum(W_s) = A (sum g1)^2 - B (sum g2)^2`` (about
    -1.55 at the defaults: a uniform Summation field inhibits itself).
    """
    g1, g2 = dog_profiles(params)
    return 1.0, float(params.A * g1.sum() ** 2 - params.B * g2.sum() ** 2)


def kernel_spectrum(kernel: np.ndarray, n: int = 512) -> tuple[float, float]:
    """``(min, max)`` of the Fourier transform ``W^`` of a symmetric correlation kernel.

    ``W^(w) = sum_d W(d) exp(-i w.d)`` is real for a kernel symmetric about its
    centre; it is sampled on an ``n x n`` grid of frequencies (the kernel
    zero-padded to ``n x n``, centred at the origin).
    """
    k = np.asarray(kernel, dtype=np.float64)
    r0, r1 = k.shape[0] // 2, k.shape[1] // 2
    pad = np.zeros((n, n))
    pad[: k.shape[0], : k.shape[1]] = k
    pad = np.roll(pad, (-r0, -r1), axis=(0, 1))
    spec = np.fft.fft2(pad).real
    return float(spec.min()), float(spec.max())


def jacobian_bounds(kernel: np.ndarray) -> tuple[float, float]:
    """Interval holding the spectrum of the Jacobian of ``u -> c - h + vartheta(W (*) u)``.

    The Jacobian is ``diag(0.5 sech^2(.)) W`` with ``0 < sech^2 <= 1``, so its
    eigenvalues lie in ``[min(0, 0.5 min W^), 0.5 max W^]`` (``W^``: the kernel's
    Fourier transform, :func:`kernel_spectrum`). About ``[-0.048, 0.5]`` for the
    default ``W_c`` and ``[-0.786, 0.729]`` for the default ``W_s``.
    """
    lo, hi = kernel_spectrum(kernel)
    return min(0.0, 0.5 * lo), 0.5 * hi
