"""Plain NumPy float64 implementation of the C-DNF field updates.

This is the oracle the Taichi kernels are tested against, and the
``backend="numpy"`` of :class:`cdnf_ti.CDNF`. It follows ``params.py`` to the
letter: direct 2-D correlations (no separable shortcut), ``np.tanh`` in float64.
"""
from __future__ import annotations

from typing import Iterator

import numpy as np

from .params import CDNFParams, contrast_kernel, dog_kernel, resting_levels, theta, vartheta
from .solver import cdnf_local_starts, local_start

_PAD_MODE = {"replicate": "edge", "reflect": "reflect", "zero": "constant"}


def shifted_windows(x: np.ndarray, radius: int, border: str) -> Iterator[tuple[int, int, np.ndarray]]:
    """Every shift of ``x`` within ``radius``: ``(i, j, window)`` with ``window = x(y + i - r, x + j - r)``.

    The one loop behind every direct (non-separable) correlation of the NumPy
    references.

    Parameters
    ----------
    x : ndarray, shape (H, W)
    radius : int
        ``r``; ``i, j`` run over ``0..2r``.
    border : {"replicate", "reflect", "zero"}
        Values outside the frame.
    """
    h, w = x.shape
    xp = np.pad(x, radius, mode=_PAD_MODE[border])
    for i in range(2 * radius + 1):
        for j in range(2 * radius + 1):
            yield i, j, xp[i : i + h, j : j + w]


def correlate(x: np.ndarray, kernel: np.ndarray, border: str) -> np.ndarray:
    """2-D correlation ``sum_ij K(i, j) x(y + i, x + j)`` with a border mode.

    Parameters
    ----------
    x : ndarray, shape (H, W)
        Field, float64.
    kernel : ndarray, shape (2r+1, 2r+1)
        Correlation weights.
    border : {"replicate", "reflect", "zero"}
        Values outside the frame.
    """
    out = np.zeros_like(x, dtype=np.float64)
    for i, j, window in shifted_windows(x, kernel.shape[0] // 2, border):
        out += kernel[i, j] * window
    return out


class RestingFields:
    """The cold-start state of a C-DNF backend whose fields ``u_on``, ``u_off``, ``v`` are NumPy arrays."""

    _rest: tuple[np.ndarray, np.ndarray] | None = None

    def save_rest(self) -> None:
        """Remember the current (resting) fields for cold starts."""
        self._rest = (self.u_on.copy(), self.v.copy())

    def restore_rest(self) -> None:
        """Put all fields back to the remembered resting state."""
        u, v = self._rest
        self.u_on[...] = u
        self.u_off[...] = u
        self.v[...] = v

    def reset(self) -> None:
        """Back to the resting state (the :class:`~cdnf_ti.models.base.ModelBackend` contract)."""
        self.restore_rest()


class NumpyCDNFBackend(RestingFields):
    """C-DNF field state and updates in NumPy float64.

    Parameters
    ----------
    params : CDNFParams
    shape : (H, W)
        Frame size in pixels.
    """

    name = "numpy"

    def __init__(self, params: CDNFParams, shape: tuple[int, int]):
        self.params = params
        self.shape = tuple(shape)
        self.w_c = contrast_kernel(params.sigma_c)
        self.w_s = dog_kernel(params)
        self.L = np.zeros(self.shape)
        self.P = np.zeros(self.shape)
        self.P_on = np.zeros(self.shape)  # the ON/OFF input stage: the contrast fields' inputs
        self.P_off = np.zeros(self.shape)
        u0, v0 = resting_levels(params)
        self.u_on = np.full(self.shape, u0)
        self.u_off = np.full(self.shape, u0)
        self.v = np.full(self.shape, v0)
        self.S = np.zeros(self.shape)
        self.prev_on = self.prev_off = self.prev_v = None  # previous iterates (Chebyshev momentum)
        self.start = cdnf_local_starts(params) if params.start == "local" else None  # (2, 7) or None

    # -- state -----------------------------------------------------------
    def load(self, grey: np.ndarray, first: bool) -> None:
        """Take a new frame: ``P = L(t) - L(t-1)`` (0 on the first frame); with the local start
        (``params.start == "local"``), ``u_on = start(P_on)``, ``u_off = start(P_off)``.

        ``grey`` is (H, W), uint8 (0..255) or float in [0, 1].
        """
        g = grey.astype(np.float64)
        if grey.dtype == np.uint8:
            g /= 255.0
        self.P = np.zeros(self.shape) if first else g - self.L
        self.L = g
        self._input(np.maximum(self.P, 0.0), np.maximum(-self.P, 0.0))

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> None:
        """Take an event bin (H, W each, in [0, 1]): the ON field's input is ``P_on = p_on`` and the
        OFF field's ``P_off = p_off`` (a pixel with both polarities in one bin drives both fields);
        ``P = p_on - p_off``; the photoreceptors' ``L`` is not used. With the local start,
        ``u_on = start(p_on)``, ``u_off = start(p_off)``."""
        p_on = np.asarray(p_on, np.float64)
        p_off = np.asarray(p_off, np.float64)
        self.P = p_on - p_off
        self._input(p_on, p_off)

    def _input(self, p_on: np.ndarray, p_off: np.ndarray) -> None:
        """The contrast fields' inputs ``P_on``, ``P_off``; with the local start, their starts."""
        self.P_on, self.P_off = p_on, p_off
        if self.start is not None:
            self.u_on = local_start(p_on, self.start[0])
            self.u_off = local_start(p_off, self.start[0])

    def clear_input(self) -> None:
        self.P = np.zeros(self.shape)
        self.P_on = np.zeros(self.shape)
        self.P_off = np.zeros(self.shape)

    # -- field updates ---------------------------------------------------
    def contrast_iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        """One update ``u + mom (u - u_prev) + lam (F(u) - u)`` of the ON and OFF fields.

        Returns the residuals ``max |F(u) - u|`` at the fields before the update.
        """
        p, b = self.params, self.params.border
        p_on, p_off = self.P_on, self.P_off
        f_on = p_on - p.h + vartheta(correlate(self.u_on, self.w_c, b))
        f_off = p_off - p.h + vartheta(correlate(self.u_off, self.w_c, b))
        d_on = f_on - self.u_on
        d_off = f_off - self.u_off
        self.u_on, self.prev_on = self._step(self.u_on, self.prev_on, d_on, lam, mom), self.u_on
        self.u_off, self.prev_off = self._step(self.u_off, self.prev_off, d_off, lam, mom), self.u_off
        return float(np.abs(d_on).max()), float(np.abs(d_off).max())

    @staticmethod
    def _step(u: np.ndarray, prev: np.ndarray | None, d: np.ndarray, lam: float, mom: float) -> np.ndarray:
        if mom == 0.0 or prev is None:
            return u + lam * d
        return u + mom * (u - prev) + lam * d

    def summation_input(self) -> None:
        """``S = alpha_on theta([u_on]+) + alpha_off theta([u_off]+)``; with the local start,
        ``v = start(S)``."""
        p = self.params
        self.S = p.alpha_on * theta(np.maximum(self.u_on, 0.0)) + p.alpha_off * theta(
            np.maximum(self.u_off, 0.0)
        )
        if self.start is not None:
            self.v = local_start(self.S, self.start[1])

    def summation_iterate(self, lam: float, mom: float = 0.0) -> tuple[float]:
        """One update of the Summation field (as :meth:`contrast_iterate`); returns its residual."""
        p = self.params
        f = self.S - p.h + vartheta(correlate(self.v, self.w_s, p.border))
        d = f - self.v
        self.v, self.prev_v = self._step(self.v, self.prev_v, d, lam, mom), self.v
        return (float(np.abs(d).max()),)

    def mean_activation(self) -> float:
        """``mean_xy theta([v]+)`` in float64."""
        return float(np.mean(theta(np.maximum(self.v, 0.0))))

    def fields(self) -> dict[str, np.ndarray]:
        """Copies of the three fields and the input, float64 (H, W)."""
        return {
            "u_on": self.u_on.copy(),
            "u_off": self.u_off.copy(),
            "v": self.v.copy(),
            "P": self.P.copy(),
        }
