"""Float64 NumPy reference of D-LGMD (LGMD with spatially-temporally distributed presynaptic connections).

Source: Zhao, Wang, Yue et al., *Enhancing LGMD's looming selectivity for UAV
with spatial-temporal distributed presynaptic connections*, IEEE TNNLS 34,
2023, and the authors' MATLAB in ``cquzjn/D-LGMD``: ``D_LGMD.m`` (the model,
with ``DOGAnalysis.m``, ``GaussAnalysis.m``, ``gaussC.m``) and, for the membrane
and spike-frequency adaptation that ``D_LGMD.m`` leaves out,
``Compare with SFA/DLGMD_SFA.m``. Nothing of theirs is copied here: this is a
transcription of the computation, one frame at a time.

Per frame ``t`` (0-based; luminance ``L`` in [0, 1] from 8-bit grey, their
``im2single``), from ``t = 3`` on:

* ``D_k = |L(t-k+1) - L(t-k)|`` for ``k = 1, 2, 3`` (``D_1`` the newest);
* a radius-``r`` (6) grid with the delay map
  ``h(x, y) = alpha + 1 / (beta + exp(-lambda^2 (x^2 + y^2)))``: cells with
  ``h < 1`` (the centre and its 4 neighbours) have delay 0, cells with
  ``1 <= h <= 1.8999`` delay 1 frame, the rest delay 2;
* excitation ``E = K_E * D_1`` with ``K_E = [G(sigma_E) - a G(sigma_I)]^+`` on
  the delay-0 cells and 0 elsewhere, ``G(s) = exp(-d^2 / (2 s^2)) / (s sqrt(2 pi))``;
* inhibition ``I = K_1 * D_2 + K_2 * D_3`` with ``K = a G(sigma_I)`` on the
  delay-1 (``K_1``) and delay-2 (``K_2``) cells;
* ``S = [E - I]^+``; ``G = S (ones(4, 4) * S)`` (the 4x4 window of rows and
  columns ``-1 .. +2``), zeroed where below ``T_G = min(0.3, 0.5 sum(D_3) 0.001 / 200)``
  and clipped at 1 (``D_3`` the oldest difference, their ``FFI``);
* output ``sum G`` (their ``LGMD_OutputG``; ``sum S`` is their ``LGMD_OutputS``).

Convolutions are MATLAB's ``conv2(.., 'same')``: zero outside the frame (the
kernels are symmetric, so convolution and correlation agree).

Membrane and alert (``DLGMD_SFA.m``): ``k = 1 / (1 + exp(-sum G / (0.6 n)))``
with their ``n = 78000`` for 800x600 frames, taken per pixel here
(``n = 0.1625 N``); from ``t = 5``, ``mp = 0.8 k`` when ``k - k(t-1) >= 0.01``,
else ``mp = 0.8 mp(t-1) + 0.8 (k - k(t-1))``. The alert ``mp >= threshold``
is ours: neither file has one.

Frame alignment: their loop index ``i`` (1-based) reads pictures ``i .. i + 3``;
its outputs are this reference's frame ``t = i + 2``. Frames 0-2 give 0.

Event bins (:meth:`DLGMDReference.step_on_off`, ours: their code takes frames): a
bin's ON/OFF contrasts ``p_on``, ``p_off`` in [0, 1] give the difference
``D_1 = p_on + p_off`` directly, so every bin is a difference and bin ``t`` plays
frame ``t + 1``'s part (bins 0-1 give 0, the membrane starts at bin 4).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import numpy as np

from .errors import InputError, UserError
from .lgmd_p_on_off_reference import correlate_same, grey_levels
from .lplc2_reference import _window_sum

#: Frames the model needs before its first output (three differences).
WARMUP = 3
#: The first frame with a membrane potential (their SFA starts at loop index 3).
SFA_START = 5


@dataclass(frozen=True)
class DLGMDParams:
    """D-LGMD constants as named in the authors' code (lengths in px, luminance in [0, 1])."""

    sigma_e: float = 1.5  #: excitation Gaussian (px)
    sigma_i: float = 5.0  #: inhibition Gaussian (px)
    a: float = 1.5  #: inhibition gain (their ``a``), also the DoG's surround weight
    r: int = 6  #: kernel radius (px): kernels are (2r+1)^2
    alfa: float = -0.1  #: delay map h = alfa + 1 / (beta + exp(-(lamda d)^2))
    beta: float = 0.5
    lamda: float = 0.7
    h_delay1: float = 1.0  #: h < h_delay1: delay 0 (excitation)
    h_delay2: float = 1.8999  #: h > h_delay2: delay 2; between: delay 1
    group_side: int = 4  #: G = S (ones(side, side) * S), MATLAB 'same' window
    thresh_g0: float = 0.5  #: T_G = min(thresh_g_max, thresh_g0 sum(D_3) ffi_scale)
    ffi_scale: float = 0.001 / 200.0
    thresh_g_max: float = 0.3
    k_norm_per_pixel: float = 78000.0 / (800 * 600)  #: k = sigmoid(sum G / (k_spread n)), n = this N
    k_spread: float = 0.6
    sfa_gain: float = 0.8  #: mp = sfa_gain k (rise) or sfa_gain (mp(t-1) + dk)
    sfa_rise: float = 0.01  #: a rise of k at least this resets mp to sfa_gain k
    threshold: float = 0.6  #: alert while mp >= threshold (ours: the authors' code has no alert)


@dataclass(frozen=True)
class DLGMDStep:
    """One frame's D-LGMD output (scalars); zero before frame 3."""

    g_sum: float  #: sum of G (their LGMD_OutputG)
    s_sum: float  #: sum of S (their LGMD_OutputS)
    ffi: float  #: sum of the oldest difference D_3 (their FFI)
    thresh_g: float  #: T_G
    k: float  #: sigmoid membrane (0.5 before frame 3)
    mp: float  #: membrane after SFA (0 before frame 5)
    alert: bool  #: mp >= threshold


def gauss_c(d2: np.ndarray, sigma: float) -> np.ndarray:
    """Their ``gaussC``: ``exp(-d^2 / (2 sigma^2)) / (sigma sqrt(2 pi))`` (a 1-D amplitude on a 2-D grid)."""
    return np.exp(-d2 / (2.0 * sigma * sigma)) / (sigma * np.sqrt(2.0 * np.pi))


def dlgmd_kernels(p: DLGMDParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(K_E, K_1, K_2)``: excitation (delay 0) and inhibition at delay 1 and 2 frames, each (2r+1, 2r+1)."""
    x = np.arange(-p.r, p.r + 1, dtype=np.float64)
    d2 = x[:, None] ** 2 + x[None, :] ** 2
    h = p.alfa + 1.0 / (p.beta + np.exp(-((x[:, None] * p.lamda) ** 2 + (x[None, :] * p.lamda) ** 2)))
    near, far = h < p.h_delay1, h > p.h_delay2
    mid = ~near & ~far
    dog = gauss_c(d2, p.sigma_e) - p.a * gauss_c(d2, (p.sigma_i / p.sigma_e) * p.sigma_e)
    k_e = np.where(near, np.maximum(dog, 0.0), 0.0)
    k_i = p.a * gauss_c(d2, p.sigma_i)
    return k_e, np.where(mid, k_i, 0.0), np.where(far, k_i, 0.0)


class DLGMDReference:
    """Streaming, causal D-LGMD: :meth:`step` takes one frame and returns its :class:`DLGMDStep`.

    Parameters
    ----------
    height, width : int
        Frame size in px (at least 2x2).
    params : DLGMDParams, optional

    Frames are (H, W) uint8 grey, (H, W) float grey in [0, 1] (taken as
    ``floor(255 x + 0.5)``) or (H, W, 3) uint8 BGR (``COLOR_BGR2GRAY``; their
    code takes grey pictures only). Luminance is grey / 255.
    """

    def __init__(self, height: int, width: int, params: DLGMDParams | None = None):
        if int(height) < 2 or int(width) < 2:
            raise UserError(f"frame must be at least 2x2 px, got {width}x{height}")
        self.params = p = params or DLGMDParams()
        if p.r < 1 or p.group_side < 1:
            raise UserError(f"r and group_side must be at least 1, got {p.r}, {p.group_side}")
        self.height, self.width = int(height), int(width)
        self.k_e, self.k_1, self.k_2 = dlgmd_kernels(p)
        lo = -((p.group_side - 1) // 2)  # MATLAB 'same': rows y - floor((side-1)/2) .. y + ceil((side-1)/2)
        self.group_window = (lo, lo + p.group_side - 1)
        self.reset()

    def reset(self) -> None:
        """Back to the state before the first frame."""
        self.t = 0
        self.lum: np.ndarray | None = None  # the last frame's luminance
        self.diffs: list[np.ndarray] = []  # the last three differences D, oldest first
        self.n_diff = 0  # differences so far (frame t has t, event bin t has t + 1)
        self.k_prev = 0.5
        self.mp = 0.0
        self.layers: dict[str, np.ndarray] = {}

    def step(self, frame: np.ndarray) -> DLGMDStep:
        """Advance one frame; returns this frame's output (uses no later frame)."""
        lum = grey_levels(frame, (self.height, self.width), False, f"frame {self.t}") / 255.0
        d1 = None if self.lum is None else np.abs(lum - self.lum)
        self.lum = lum
        return self._advance(d1)

    def step_on_off(self, p_on: np.ndarray, p_off: np.ndarray) -> DLGMDStep:
        """Advance one event bin (``p_on``, ``p_off``: (H, W) contrasts in [0, 1]): its difference
        ``D_1 = p_on + p_off`` (every bin is a difference, bin 0 included)."""
        d1 = np.asarray(p_on, np.float64) + np.asarray(p_off, np.float64)
        if d1.shape != (self.height, self.width):
            raise InputError(f"bin {self.t}", f"expected {self.width}x{self.height} px, got shape {d1.shape}")
        return self._advance(d1)

    def _advance(self, d1: np.ndarray | None) -> DLGMDStep:
        """One step with the newest difference ``d1`` (None: the first frame, which has none)."""
        p = self.params
        self.t += 1
        if d1 is not None:
            self.diffs = (self.diffs + [d1])[-WARMUP:]
            self.n_diff += 1
        if self.n_diff < WARMUP:
            return DLGMDStep(0.0, 0.0, 0.0, 0.0, 0.5, 0.0, False)
        d3, d2, d1 = self.diffs
        ffi = float(d3.sum())
        thresh_g = min(p.thresh_g0 * ffi * p.ffi_scale, p.thresh_g_max)
        e = correlate_same(d1, self.k_e, "constant")
        i = correlate_same(d2, self.k_1, "constant") + correlate_same(d3, self.k_2, "constant")
        s = np.maximum(e - i, 0.0)
        lo, hi = self.group_window
        g = s * _window_sum(s, lo, hi, lo, hi)
        g[g < thresh_g] = 0.0
        g = np.minimum(g, 1.0)
        g_sum = float(g.sum())
        k = 1.0 / (1.0 + np.exp(-g_sum / (p.k_spread * p.k_norm_per_pixel * self.height * self.width)))
        if self.n_diff >= SFA_START:
            dk = k - self.k_prev
            self.mp = p.sfa_gain * k if dk >= p.sfa_rise else p.sfa_gain * self.mp + p.sfa_gain * dk
        self.k_prev = k
        self.layers = {"E": e, "I": i, "S": s, "G": g}
        return DLGMDStep(g_sum, float(s.sum()), ffi, float(thresh_g), float(k), float(self.mp),
                         bool(self.n_diff >= SFA_START and self.mp >= p.threshold))

    def run(self, frames: Iterable[np.ndarray]) -> dict[str, np.ndarray]:
        """Step through ``frames`` from the current state; one array per :class:`DLGMDStep` field, shape (T,)."""
        steps = [self.step(f) for f in frames]
        return {name: np.array([getattr(s, name) for s in steps]) for name in DLGMDStep.__dataclass_fields__}
