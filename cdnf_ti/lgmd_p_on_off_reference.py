"""Float64 NumPy reference of LGMD_P_ON_OFF (motion and contrast vision in ON/OFF channels).

Source: Fu, Li, Peng, *Harmonizing motion and contrast vision for robust
looming detection*, Array 17:100272, 2023, and the authors' Python
``Harmonizing motion and contrast vision.py`` in
``fuqinbing/harmonizing-motion-and-contrast-vision-for-looming-detection``
(class ``LGMD_P_ON_OFF``, methods ``run`` and ``looming_perception``). Nothing
of theirs is copied here: this is a transcription of the computation, one
frame at a time.

Per frame ``t`` (0-based, the ``t``-th frame read; grey levels 0..255):

* ``P(t) = L(t) - L(t-1)``; ``P_on = [P]^+``, ``P_off = [-P]^+``;
* dynamic contrast normalisation: ``M = tanh(P_x / (Mhat_x + alpha_1))`` with
  ``Mhat_x`` the 9x9 Gaussian (sigma 5 px) blur of ``P_x`` (x = on, off);
* contrast: ``C = |K_C * M|``, ``K_C`` centre 1, the 8 neighbours -1/8;
* motion: ``E = M``, ``I = K_I * E(t-1)`` (``K_I`` edge 0.25, diagonal
  0.125, centre 0), ``S = E - beta I``;
* ``S_on_out = [alpha_2 S_on - alpha_3 C_on]^+`` (OFF alike with alpha_4, alpha_5);
* ``S = theta_1 S_on_out + theta_2 S_off_out + theta_3 S_on_out S_off_out``;
* grouping: ``Ce`` = 3x3 mean of ``S``; ``G = S Ce / (max Ce / C_w + delta_C)``,
  zeroed where ``C_de G < T_de``;
* membrane ``mp = 1 / (1 + exp(-sum G / (0.1 N)))``, ``N`` = pixels.

Every spatial filter is a correlation with OpenCV's default border
(reflect-101: ``dcb|abcd|cba``). Frame 0 only stores the picture.
An event bin (:meth:`LGMDPOnOffReference.step_on_off`) gives ``P_on = 255 p_on``,
``P_off = 255 p_off`` directly; every bin is a full step, bin 0 included.

The authors' code stops at ``mp``: it has no alert. The alert here is
``mp >= threshold`` (:attr:`LGMDPOnOffParams.threshold`), our choice.

Frame alignment: their ``mp[t]`` is this reference's ``mp`` at frame ``t``
(their ``mp[0] = 0``: frame 0 is never processed).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import cv2
import numpy as np

from .errors import InputError, UserError

VARIANTS = ("code", "paper")


@dataclass(frozen=True)
class LGMDPOnOffParams:
    """LGMD_P_ON_OFF constants as named in the authors' code (grey levels 0..255, lengths in px)."""

    beta: float = 0.4  #: weight of the delayed lateral inhibition, S = E - beta I
    basic_weight: float = 0.125  #: K_I cell (a, b) from the corner = basic_weight (sqrt(a^2 + b^2) + 1), centre 0
    alpha_1: float = 3.0  #: baseline of the contrast normalisation, M = tanh(P / (Mhat + alpha_1))
    alpha_2: float = 1.0  #: ON: S_on_out = [alpha_2 S_on - alpha_3 C_on]^+
    alpha_3: float = 1.0
    alpha_4: float = 1.0  #: OFF: S_off_out = [alpha_4 S_off - alpha_5 C_off]^+
    alpha_5: float = 1.0
    theta_1: float = 1.0  #: S = theta_1 S_on_out + theta_2 S_off_out + theta_3 S_on_out S_off_out
    theta_2: float = 1.0
    theta_3: float = 1.0
    gauss_size: int = 9  #: side of the normalisation Gaussian (px, odd)
    gauss_sigma: float = 5.0  #: its standard deviation (px)
    c_w: float = 4.0  #: G scale: w = max(Ce) / c_w + delta_c
    delta_c: float = 0.01
    c_de: float = 0.5  #: G = 0 where c_de G < t_de
    t_de: float = 0.7
    sigmoid_scale: float = 0.1  #: mp = 1 / (1 + exp(-sum G / (sigmoid_scale N)))
    threshold: float = 0.9  #: alert while mp >= threshold (ours: the authors' code has no alert)


@dataclass(frozen=True)
class LGMDPOnOffStep:
    """One frame's LGMD_P_ON_OFF output (scalars)."""

    mp: float  #: membrane potential in (0.5, 1); 0 (code) or 0.5 (paper) at frame 0
    alert: bool  #: mp >= threshold
    sum_g: float  #: sum of the grouped layer G
    max_ce: float  #: max of the 3x3 mean Ce


def gaussian_kernel(size: int, sigma: float) -> np.ndarray:
    """Normalised 2-D Gaussian ``g(i) g(j)``, ``g(i) ~ exp(-(i - c)^2 / (2 sigma^2))``; shape (size, size)."""
    i = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
    g = np.exp(-(i * i) / (2.0 * sigma * sigma))
    g /= g.sum()
    return np.outer(g, g)


def correlate_same(x: np.ndarray, kernel: np.ndarray, border: str) -> np.ndarray:
    """``out(y, x) = sum_ij k(i, j) x(y + i - r, x + j - r)`` for an odd (2r+1)-square kernel; shape of ``x``.

    ``border`` is a ``numpy.pad`` mode: ``"reflect"`` (OpenCV's default reflect-101),
    ``"edge"`` (replicate) or ``"constant"`` (zero, MATLAB's ``conv2(.., 'same')``
    with the kernel rotated by 180 degrees).
    """
    r = kernel.shape[0] // 2
    if kernel.shape != (2 * r + 1, 2 * r + 1):
        raise ValueError(f"kernel must be odd and square, got shape {kernel.shape}")
    xp = np.pad(x, r, mode=border)
    h, w = x.shape
    out = np.zeros((h, w), dtype=np.float64)
    for i in range(2 * r + 1):
        for j in range(2 * r + 1):
            if kernel[i, j] != 0.0:
                out += kernel[i, j] * xp[i : i + h, j : j + w]
    return out


def grey_levels(frame: np.ndarray, shape: tuple[int, int], rgb2gray: bool, where: str) -> np.ndarray:
    """Frame -> float64 grey levels 0..255, shape (H, W).

    Colour frames are (H, W, 3) uint8 BGR, converted by OpenCV (``COLOR_RGB2GRAY``
    when ``rgb2gray``, as the authors' code does on OpenCV's BGR frames, else
    ``COLOR_BGR2GRAY``); (H, W) uint8 grey is taken as is and (H, W) float grey
    in [0, 1] as ``floor(255 x + 0.5)``.
    """
    f = np.asarray(frame)
    if f.ndim == 3 and f.shape[2] == 3:
        if f.dtype != np.uint8:
            raise InputError(where, f"a colour frame must be uint8 BGR, got {f.dtype}")
        g = cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_RGB2GRAY if rgb2gray else cv2.COLOR_BGR2GRAY)
    elif f.ndim == 2 and f.dtype == np.uint8:
        g = f
    elif f.ndim == 2 and np.issubdtype(f.dtype, np.floating):
        if not np.all(np.isfinite(f)) or f.min() < 0 or f.max() > 1:
            raise InputError(where, "a float frame must be finite grey levels in [0, 1]")
        g = np.floor(f.astype(np.float64) * 255.0 + 0.5)
    else:
        raise InputError(where, f"expected an (H, W) uint8/float grey or (H, W, 3) uint8 BGR frame, "
                                f"got shape {f.shape} {f.dtype}")
    if g.shape != tuple(shape):
        raise InputError(where, f"expected {shape[1]}x{shape[0]} px, got {g.shape[1]}x{g.shape[0]}")
    return g.astype(np.float64)


def inhibition_kernel(basic_weight: float) -> np.ndarray:
    """The authors' 3x3 ``K_I``: cell (a, b) counted from the nearest corner gets
    ``basic_weight (sqrt(a^2 + b^2) + 1)``, the centre 0 (edges 2 w, diagonals w)."""
    k = np.zeros((3, 3))
    for a in range(3):
        for b in range(3):
            da, db = min(a, 2 - a), min(b, 2 - b)
            k[a, b] = basic_weight * (np.sqrt(da * da + db * db) + 1.0)
    k[1, 1] = 0.0
    return k


class LGMDPOnOffReference:
    """Streaming, causal LGMD_P_ON_OFF: :meth:`step` takes one frame and returns its :class:`LGMDPOnOffStep`.

    Parameters
    ----------
    height, width : int
        Frame size in px (at least 9x9: the normalisation Gaussian's reflect border needs it).
    variant : {"code", "paper"}
        ``"code"``: the authors' Python exactly (grey by ``COLOR_RGB2GRAY`` on
        OpenCV's BGR frames; ``mp = 0`` at frame 0, their unwritten array
        entry). ``"paper"``: ``COLOR_BGR2GRAY`` and ``mp = 0.5`` (the resting
        sigmoid) at frame 0. The per-pixel equations are the same.
    params : LGMDPOnOffParams, optional

    Frames are (H, W, 3) uint8 BGR, (H, W) uint8 grey, or (H, W) float grey in [0, 1].
    """

    def __init__(self, height: int, width: int, variant: str = "code", params: LGMDPOnOffParams | None = None):
        if variant not in VARIANTS:
            raise UserError(f"variant must be one of {', '.join(VARIANTS)}, got {variant!r}")
        self.params = p = params or LGMDPOnOffParams()
        side = max(p.gauss_size, 3)
        if int(height) < side or int(width) < side:
            raise UserError(f"frame must be at least {side}x{side} px, got {width}x{height}")
        if p.gauss_size < 1 or p.gauss_size % 2 == 0:
            raise UserError(f"gauss_size must be a positive odd number, got {p.gauss_size}")
        self.height, self.width = int(height), int(width)
        self.variant = variant
        self.k_gauss = gaussian_kernel(p.gauss_size, p.gauss_sigma)
        self.k_c = np.full((3, 3), -1.0 / 8.0)
        self.k_c[1, 1] = 1.0
        self.k_i = inhibition_kernel(p.basic_weight)
        self.k_g = np.full((3, 3), 1.0 / 9.0)
        self.reset()

    def reset(self) -> None:
        """Back to the state before the first frame."""
        shape = (self.height, self.width)
        self.t = 0
        self.grey_prev = np.zeros(shape)
        self.e_on_prev = np.zeros(shape)
        self.e_off_prev = np.zeros(shape)
        self.layers: dict[str, np.ndarray] = {}

    def _channel(self, p_x: np.ndarray, e_prev: np.ndarray, gain_s: float, gain_c: float):
        """One polarity: ``(E, [gain_s (E - beta K_I * E(t-1)) - gain_c |K_C * E|]^+)``, E the normalised input."""
        p = self.params
        m_hat = correlate_same(p_x, self.k_gauss, "reflect")
        e = np.tanh(p_x / (m_hat + p.alpha_1))
        c = np.abs(correlate_same(e, self.k_c, "reflect"))
        s = e - p.beta * correlate_same(e_prev, self.k_i, "reflect")
        return e, np.maximum(gain_s * s - gain_c * c, 0.0)

    def step(self, frame: np.ndarray) -> LGMDPOnOffStep:
        """Advance one frame; returns this frame's output (uses no later frame)."""
        g = grey_levels(frame, (self.height, self.width), self.variant == "code", f"frame {self.t}")
        p = self.params
        if self.t == 0:
            self.grey_prev = g
            self.t += 1
            mp0 = 0.0 if self.variant == "code" else 0.5
            return LGMDPOnOffStep(mp0, mp0 >= p.threshold, 0.0, 0.0)
        big_p = g - self.grey_prev
        self.grey_prev = g
        return self._layers(np.maximum(big_p, 0.0), np.maximum(-big_p, 0.0))

    def step_on_off(self, p_on: np.ndarray, p_off: np.ndarray) -> LGMDPOnOffStep:
        """Advance one event bin: ``P_on = 255 p_on``, ``P_off = 255 p_off`` (``p_on``, ``p_off``: (H, W)
        contrast in [0, 1]) replace the frame difference. Every bin is a full step, bin 0 included."""
        shape = (self.height, self.width)
        if np.shape(p_on) != shape or np.shape(p_off) != shape:
            raise InputError(f"bin {self.t}", f"expected two {shape[1]}x{shape[0]} planes")
        return self._layers(255.0 * np.asarray(p_on, np.float64), 255.0 * np.asarray(p_off, np.float64))

    def _layers(self, p_on: np.ndarray, p_off: np.ndarray) -> LGMDPOnOffStep:
        """The layers of one step from its ``P_on``, ``P_off`` (grey levels, (H, W)); updates the state."""
        p = self.params
        e_on, s_on = self._channel(p_on, self.e_on_prev, p.alpha_2, p.alpha_3)
        e_off, s_off = self._channel(p_off, self.e_off_prev, p.alpha_4, p.alpha_5)
        s = p.theta_1 * s_on + p.theta_2 * s_off + p.theta_3 * s_on * s_off
        ce = correlate_same(s, self.k_g, "reflect")
        max_ce = float(ce.max())
        gl = s * ce / (max_ce / p.c_w + p.delta_c)
        gl[gl * p.c_de < p.t_de] = 0.0
        sum_g = float(gl.sum())
        mp = 1.0 / (1.0 + np.exp(-sum_g / (self.height * self.width * p.sigmoid_scale)))
        self.layers = {"P": p_on - p_off, "E_on": e_on, "E_off": e_off, "S_on": s_on, "S_off": s_off, "S": s,
                       "Ce": ce, "G": gl}
        self.e_on_prev, self.e_off_prev = e_on, e_off
        self.t += 1
        return LGMDPOnOffStep(float(mp), bool(mp >= p.threshold), sum_g, max_ce)

    def run(self, frames: Iterable[np.ndarray]) -> dict[str, np.ndarray]:
        """Step through ``frames`` from the current state; one array per :class:`LGMDPOnOffStep` field, shape (T,)."""
        steps = [self.step(f) for f in frames]
        return {name: np.array([getattr(s, name) for s in steps]) for name in LGMDPOnOffStep.__dataclass_fields__}
