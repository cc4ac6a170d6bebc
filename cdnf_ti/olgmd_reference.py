"""Float64 NumPy reference of oLGMD (LGMD2 with contrast polarity-specific feed-forward inhibition).

Source: Gao, Liu, Wang, Fu, *A Computationally Efficient Neuronal Model for
Collision Detection with Contrast Polarity-Specific Feed-Forward Inhibition*,
Biomimetics 9(11):650, 2024, and the authors' Python
``Core_of_Source_Code/Computer_oLGMD_Python/optimized_LGMD.py`` in
``Ryannnice/Supplementary_Materials_FFI_ON_OFF`` (class ``LGMD2``, method
``LGMD``). Nothing of theirs is copied here: this is a transcription of the
computation, one frame at a time.

``variant="code"`` reproduces the authors' Python exactly (in float64 where
they use float32), quirks included; ``variant="paper"`` corrects the quirks
(:class:`OLGMDReference` lists them).

Per frame ``t`` (0-based, the ``t``-th frame read):

* grey ``L(t)``; ``P(t) = L(t) - L(t-1) + a_1 P(t-1) + a_2 P(t-2)``;
* ``P_on = [P]^+ + 0.1 P_on(t-1)``, ``P_off = [-P]^+ + 0.1 P_off(t-1)``;
* ``PM_on, PM_off``: low-passed means of ``P_on``, ``P_off`` (feed-forward
  inhibition); ``w_1 = max(1, PM_on / 6)``, ``w_2 = max(0.3, PM_off / 6)``;
* a channel is gated off (``S = 0``) while its ``PM < 1.15``; otherwise
  ``S = [E - w I]^+`` with ``I`` the 3x3 spread of the current and the
  delayed excitation (ON: centre 2, edge 0.5, diagonal 0.25, delays 15, 30,
  45 ms; OFF: 1, 0.25, 0.125, delays 60, 120, 180 ms);
* ``S = S_on + S_off``; ``Ce`` = 3x3 mean of ``S``; ``G = S Ce / (max Ce / 4 + 0.01)``,
  zeroed where ``0.5 G < 15``;
* ``k = 1 / (1 + exp(-sum G / (0.6 N)))``, reset to 0.5 when
  ``PM_on + PM_off >= 10 + 0.02 (PM_on + PM_off)(t-1)``;
* spike-frequency adaptation gives the membrane potential ``K(t) >= 0.5``;
* ``S_spike(t) = exp(4 (K(t) - 0.78))``; the alert at frame ``t`` is
  ``S_spike(t-3) + ... + S_spike(t) >= 3``.

Frame alignment with the authors' code (their alert is not causal): their
``K`` list holds ``K[0] = 0.5`` and then ``K(2), K(3), ...``, so their
``K[i]`` is this reference's ``k`` at frame ``i + 1``; their ``Col[j]`` is
this reference's ``alert`` at frame ``j + 2`` for ``j >= 3`` and at frame
``j + 3`` for ``j <= 2`` (:func:`their_col_frame`). Their last two ``Col``
entries are never set and the alert of the last frame has no ``Col`` entry.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import cv2
import numpy as np

from .errors import InputError, UserError

VARIANTS = ("code", "paper")

#: The authors' fixed frame interval (ms) in ``variant="code"`` (``self.t = 53.0``; fps is ignored).
CODE_INTERVAL_MS = 53.0

#: Spike-train window (frames) and spike-count threshold of the alert (``n_ts``, ``n_sp``).
N_TS = 4
N_SP = 3.0


@dataclass(frozen=True)
class OLGMDParams:
    """oLGMD constants as named in the authors' code (times in ms)."""

    w3: float = 1.0  #: ON bias baseline: w_1 = max(w3, PM_on / Tpm)
    w4: float = 0.3  #: OFF bias baseline: w_2 = max(w4, PM_off / Tpm)
    tpm: float = 6.0  #: PM threshold of the inhibition bias
    a1: float = 0.1  #: persistence of P_on / P_off
    t_on: tuple = (15.0, 30.0, 45.0)  #: ON delays, centre / edge / diagonal (ms)
    t_off: tuple = (60.0, 120.0, 180.0)  #: OFF delays, centre / edge / diagonal (ms)
    w_on: tuple = (2.0, 0.5, 0.25)  #: ON inhibition kernel, centre / edge / diagonal
    w_off: tuple = (1.0, 0.25, 0.125)  #: OFF inhibition kernel, centre / edge / diagonal
    tau_pm: float = 10.0  #: PM low-pass: a4 = dt / (tau_pm + dt)
    a5: float = 0.6  #: sigmoid scale: k = 1 / (1 + exp(-sum G / (N a5)))
    tau_sfa: float = 800.0  #: SFA: a6 = tau_sfa / (tau_sfa + dt)
    o1: float = 1.0  #: S = o1 S_on + o2 S_off + o3 S_on S_off
    o2: float = 1.0
    o3: float = 0.0
    th_on: float = 1.15  #: ON gate: S_on = 0 while PM_on < th_on
    th_off: float = 1.15  #: OFF gate: S_off = 0 while PM_off < th_off
    cw: float = 4.0  #: G scale: w = max(Ce) / cw + delta_c
    delta_c: float = 0.01
    cde: float = 0.5  #: G decay: G = 0 where G cde < tde
    tde: float = 15.0
    tsfa: float = 0.002  #: SFA small threshold
    aim_base: float = 10.0  #: reset k to 0.5 when AIM(t) >= aim_base + aim_slope AIM(t-1)
    aim_slope: float = 0.02
    a7: float = 4.0  #: S_spike = exp(a7 (K - t_spi))
    t_spi: float = 0.78


@dataclass(frozen=True)
class OLGMDStep:
    """One frame's oLGMD output (scalars)."""

    k: float  #: membrane potential after SFA, K(t) in [0.5, 1)
    k_raw: float  #: sigmoid membrane potential before the AIM reset (their ``Kf``)
    s_spike: float  #: exp(a7 (K - t_spi)); 0 before the model runs
    spike_sum: float  #: S_spike over the last N_TS frames, this one included
    alert: bool  #: spike_sum >= N_SP
    pm_on: float  #: low-passed ON mean (feed-forward inhibition)
    pm_off: float  #: low-passed OFF mean
    aim: float  #: PM_on + PM_off (their ``AIM``)


def their_col_frame(j: int) -> int:
    """The frame of this reference whose ``alert`` equals the authors' ``Col[j]`` (``j >= 0``)."""
    if j < 0:
        raise ValueError("j must be >= 0")
    return j + 3 if j <= 2 else j + 2


def _kernel(centre: float, edge: float, diag: float) -> np.ndarray:
    return np.array([[diag, edge, diag], [edge, centre, edge], [diag, edge, diag]], dtype=np.float64)


def _spread(x: np.ndarray, k: np.ndarray, pad: str | None) -> np.ndarray:
    """``sum_ij k(i, j) x(y + i - 1, x + j - 1)``: on the interior only (``pad=None``, shape (H-2, W-2)) or padded."""
    if pad is not None:
        x = np.pad(x, 1, mode=pad)
    h, w = x.shape[0] - 2, x.shape[1] - 2
    out = np.zeros((h, w), dtype=np.float64)
    for i in range(3):
        for j in range(3):
            out += k[i, j] * x[i : i + h, j : j + w]
    return out


class OLGMDReference:
    """Streaming, causal oLGMD: :meth:`step` takes one frame and returns its :class:`OLGMDStep`.

    Parameters
    ----------
    height, width : int
        Frame size in px (at least 3x3).
    variant : {"code", "paper"}
        ``"code"``: the authors' Python exactly (dt fixed at 53 ms, grey by
        ``COLOR_RGB2GRAY`` on OpenCV's BGR frames, first frame difference
        dropped, persistence weights of the absolute frame index, PM_off from
        the ON mean, PM smoothing of the raw previous mean, delayed excitation
        zero after a gated frame, zero border on S, reflect-101 border on Ce).
        ``"paper"``: the equations with those corrected (dt = 1000 / fps,
        ``COLOR_BGR2GRAY``, replicate borders).
    fps : float, optional
        Frame rate; only ``variant="paper"`` uses it (default 30).
    params : OLGMDParams, optional

    Frames are (H, W, 3) uint8 BGR (as OpenCV reads them), (H, W) uint8 grey,
    or (H, W) float grey in [0, 1] (taken as ``floor(255 x + 0.5)``).
    """

    def __init__(self, height: int, width: int, variant: str = "code", fps: float | None = None,
                 params: OLGMDParams | None = None):
        if variant not in VARIANTS:
            raise UserError(f"variant must be one of {', '.join(VARIANTS)}, got {variant!r}")
        if int(height) < 3 or int(width) < 3:
            raise UserError(f"frame must be at least 3x3 px, got {width}x{height}")
        if fps is not None and not (np.isfinite(fps) and fps > 0):
            raise UserError(f"fps must be a positive number, got {fps!r}")
        self.height, self.width = int(height), int(width)
        self.variant = variant
        self.params = params or OLGMDParams()
        self.fps = 30.0 if fps is None else float(fps)
        self.dt = CODE_INTERVAL_MS if variant == "code" else 1000.0 / self.fps
        p, dt = self.params, self.dt
        self.a4 = dt / (p.tau_pm + dt)
        self.a6 = p.tau_sfa / (p.tau_sfa + dt)
        self.k_on = _kernel(*p.w_on)
        self.k_off = _kernel(*p.w_off)
        # delay coefficient per kernel cell: a = dt / (dt + tau), centre / edge / diagonal
        self.d_on = _kernel(*(dt / (dt + tau) for tau in p.t_on))
        self.d_off = _kernel(*(dt / (dt + tau) for tau in p.t_off))
        self.reset()

    def reset(self) -> None:
        """Back to the state before the first frame."""
        shape = (self.height, self.width)
        self.t = 0
        self.grey_prev = np.zeros(shape)
        self.p1 = np.zeros(shape)  # P(t-1)
        self.p2 = np.zeros(shape)  # P(t-2)
        self.p_on = np.zeros(shape)
        self.p_off = np.zeros(shape)
        self.e_on_prev = np.zeros(shape)
        self.e_off_prev = np.zeros(shape)
        self.pm_on_prev = 0.0  # code: the raw previous mean; paper: the previous PM_on
        self.pm_off_prev = 0.0
        self.aim_prev = 0.0
        self.k1 = 0.0  # k(t-1) after the AIM reset
        self.k_pre = 0.0  # K(t-1)
        self.spikes: list[float] = [0.0] * (N_TS - 1)
        self.s_layer = np.zeros(shape)
        self.g_layer = np.zeros(shape)

    # -- input -------------------------------------------------------------------------------
    def grey(self, frame: np.ndarray) -> np.ndarray:
        """Frame -> float64 grey levels 0..255, shape (H, W); validates shape and values."""
        f = np.asarray(frame)
        where = f"frame {self.t}"
        if f.ndim == 3 and f.shape[2] == 3:
            if f.dtype != np.uint8:
                raise InputError(where, f"a colour frame must be uint8 BGR, got {f.dtype}")
            code = cv2.COLOR_RGB2GRAY if self.variant == "code" else cv2.COLOR_BGR2GRAY
            g = cv2.cvtColor(np.ascontiguousarray(f), code)
        elif f.ndim == 2:
            if f.dtype == np.uint8:
                g = f
            elif np.issubdtype(f.dtype, np.floating):
                if not np.all(np.isfinite(f)) or f.min() < 0 or f.max() > 1:
                    raise InputError(where, "a float frame must be finite grey levels in [0, 1]")
                g = np.floor(f.astype(np.float64) * 255.0 + 0.5)
            else:
                raise InputError(where, f"a grey frame must be uint8 or float in [0, 1], got {f.dtype}")
        else:
            raise InputError(where, f"expected an (H, W) grey or (H, W, 3) BGR frame, got shape {f.shape}")
        if g.shape != (self.height, self.width):
            raise InputError(where, f"expected {self.width}x{self.height} px, got {g.shape[1]}x{g.shape[0]}")
        return g.astype(np.float64)

    # -- one frame ---------------------------------------------------------------------------
    def _persistence(self) -> tuple[float, float]:
        """``(a_1, a_2)`` of ``P``: code ``1 / (1 + e^(t - i))`` (absolute frame t), paper ``1 / (1 + e^i)``."""
        if self.variant == "code":
            return 1.0 / (1.0 + np.exp(self.t - 1)), 1.0 / (1.0 + np.exp(self.t - 2))
        return 1.0 / (1.0 + np.exp(1.0)), 1.0 / (1.0 + np.exp(2.0))

    def _summation(self, e: np.ndarray, e_prev: np.ndarray, kernel: np.ndarray, delay: np.ndarray,
                   w: float) -> np.ndarray:
        """``S = [E - w sum_ij K_ij (a_ij E + (1 - a_ij) E(t-1))]^+``; code: interior only, zero border."""
        if self.variant == "code":
            s = np.zeros_like(e)
            inh = _spread(e, kernel * delay, None) + _spread(e_prev, kernel * (1.0 - delay), None)
            s[1:-1, 1:-1] = np.maximum(e[1:-1, 1:-1] - w * inh, 0.0)
            return s
        inh = _spread(e, kernel * delay, "edge") + _spread(e_prev, kernel * (1.0 - delay), "edge")
        return np.maximum(e - w * inh, 0.0)

    def step(self, frame: np.ndarray) -> OLGMDStep:
        """Advance one frame; returns this frame's output (uses no later frame)."""
        g = self.grey(frame)
        p = self.params
        t = self.t
        first = 2 if self.variant == "code" else 1  # the code drops the difference of frames 0 and 1
        if t < first:
            self.grey_prev = g
            self.t += 1
            self.spikes.append(0.0)
            return OLGMDStep(0.5, 0.5, 0.0, float(sum(self.spikes[-N_TS:])), False, 0.0, 0.0, 0.0)
        a_1, a_2 = self._persistence()
        big_p = g - self.grey_prev + a_1 * self.p1 + a_2 * self.p2
        self.p_on = np.maximum(big_p, 0.0) + p.a1 * self.p_on
        self.p_off = np.maximum(-big_p, 0.0) + p.a1 * self.p_off
        mean_on, mean_off = float(self.p_on.mean()), float(self.p_off.mean())
        if self.variant == "code":
            pm_on = self.a4 * mean_on + (1 - self.a4) * self.pm_on_prev
            pm_off = self.a4 * mean_on + (1 - self.a4) * self.pm_off_prev  # sic: the ON mean
            self.pm_on_prev, self.pm_off_prev = mean_on, mean_off  # sic: the raw means
        else:
            pm_on = self.a4 * mean_on + (1 - self.a4) * self.pm_on_prev
            pm_off = self.a4 * mean_off + (1 - self.a4) * self.pm_off_prev
            self.pm_on_prev, self.pm_off_prev = pm_on, pm_off
        w1 = max(p.w3, pm_on / p.tpm)
        w2 = max(p.w4, pm_off / p.tpm)
        aim = pm_on + pm_off

        zero = np.zeros_like(g)
        e_on = self.p_on if pm_on >= p.th_on else zero
        e_off = self.p_off if pm_off >= p.th_off else zero
        s_on = self._summation(e_on, self.e_on_prev, self.k_on, self.d_on, w1) if pm_on >= p.th_on else zero
        s_off = self._summation(e_off, self.e_off_prev, self.k_off, self.d_off, w2) if pm_off >= p.th_off else zero
        if self.variant == "code":  # their E(t-1) is zero after a gated frame
            self.e_on_prev, self.e_off_prev = e_on, e_off
        else:
            self.e_on_prev, self.e_off_prev = self.p_on, self.p_off
        s = p.o1 * s_on + p.o2 * s_off + p.o3 * s_on * s_off

        ce = _spread(s, np.full((3, 3), 1.0 / 9.0), "reflect" if self.variant == "code" else "edge")
        scale = ce.max() / p.cw + p.delta_c
        gl = s * ce / scale
        gl[gl * p.cde < p.tde] = 0.0
        self.s_layer, self.g_layer = s, gl

        n_cells = self.height * self.width
        k_raw = 1.0 / (1.0 + np.exp(-gl.sum() / (n_cells * p.a5)))
        k = 0.5 if aim >= p.aim_base + p.aim_slope * self.aim_prev else k_raw
        if k - self.k1 <= p.tsfa:
            k_cur = self.a6 * (self.k_pre + k - self.k1)
        else:
            k_cur = self.a6 * k
        k_cur = max(k_cur, 0.5)

        s_spike = float(np.exp(p.a7 * (k_cur - p.t_spi)))
        self.spikes.append(s_spike)
        del self.spikes[: len(self.spikes) - N_TS]
        spike_sum = float(sum(self.spikes))

        self.grey_prev = g
        self.p2, self.p1 = self.p1, big_p
        self.aim_prev = aim
        self.k1, self.k_pre = k, k_cur
        self.t += 1
        return OLGMDStep(float(k_cur), float(k_raw), s_spike, spike_sum, spike_sum >= N_SP,
                         float(pm_on), float(pm_off), float(aim))

    def run(self, frames: Iterable[np.ndarray]) -> dict[str, np.ndarray]:
        """Step through ``frames`` from the current state; one array per :class:`OLGMDStep` field, shape (T,)."""
        steps = [self.step(f) for f in frames]
        return {name: np.array([getattr(s, name) for s in steps]) for name in OLGMDStep.__dataclass_fields__}
