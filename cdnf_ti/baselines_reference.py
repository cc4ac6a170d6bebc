"""Plain NumPy float64 references of the comparison models' per-pixel stages.

These are the oracles the Taichi kernels in :mod:`cdnf_ti.kernels.lgmd` and
:mod:`cdnf_ti.kernels.sdnf` are tested against, and the ``backend="numpy"``
of :class:`~cdnf_ti.models.lgmd2.LGMD2`, :class:`~cdnf_ti.models.lgmd1.LGMD1`,
:class:`~cdnf_ti.models.flgmd.FLGMDONn` and :class:`~cdnf_ti.models.sdnf.SDNF`.
Every stage is written directly from the equations (3x3 sums as explicit
shifted copies with a replicate border, as in the authors' C# code), so the
reference shares no code with the kernels.

Only the per-pixel stages live here; the scalar recurrences (PM/FFI, SFA,
spike counting, dynamic threshold) are shared Python in the model classes.
"""
from __future__ import annotations

import numpy as np

from .params import vartheta
from .reference import correlate, shifted_windows


def eight_bit(grey: np.ndarray) -> np.ndarray:
    """Grey frame as uint8 grey levels: uint8 as is, float in [0, 1] as ``floor(255 x + 0.5)`` (float32).

    The LGMD family works on 8-bit grey levels, as the authors' code, which
    takes byte frames and integer luminance changes (``HighpassFilter(byte,
    byte) -> int`` in ``lgmd2OpenSource.cs`` and ``LGMDs.cs``,
    fuqinbing/LGMD2-open-source): ``P``, the ON/OFF clip (``P >= 0.1``, i.e.
    ``P >= 1``) and PM/FFI then see the same integers as theirs for any float
    input (the Taichi ``load_frame`` kernel rounds the same way).
    """
    if grey.dtype == np.uint8:
        return grey
    g = np.floor(np.asarray(grey, dtype=np.float32) * np.float32(255.0) + np.float32(0.5))
    return np.clip(g, 0, 255).astype(np.uint8)


def grey_levels(grey: np.ndarray) -> np.ndarray:
    """Grey frame as float64 grey levels in 0..255 (:func:`eight_bit`, then float64).

    Parameters
    ----------
    grey : ndarray, shape (H, W)
        uint8 (0..255) or float in [0, 1] (rounded to ``floor(255 x + 0.5)``).
    """
    return eight_bit(grey).astype(np.float64)





def kernel_3x3(centre: float, edge: float, diag: float) -> np.ndarray:
    """A symmetric 3x3 kernel from its centre, edge and diagonal weights."""
    return np.array([[diag, edge, diag], [edge, centre, edge], [diag, edge, diag]], dtype=np.float64)


def correlate3(x: np.ndarray, k: np.ndarray) -> np.ndarray:
    """``sum_ij k(i, j) x(y + i, x + j)`` over a 3x3 window, replicate border."""
    return correlate(x, k, "replicate")


def delayed_spread(x: np.ndarray, x_prev: np.ndarray, k: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Spatiotemporal 3x3 spread ``sum_ij K(i,j) [a_ij X(t) + (1 - a_ij) X(t-1)]``.

    The delay mixes the current and the previous *input* (it is not a
    recursive filter of the output).

    Parameters
    ----------
    x, x_prev : ndarray, shape (H, W)
        The channel at t and t-1.
    k, alpha : ndarray, shape (3, 3)
        Weights ``K`` and mixing coefficients ``a = dt / (dt + tau)``.
    """
    out = np.zeros_like(x, dtype=np.float64)
    now, before = shifted_windows(x, 1, "replicate"), shifted_windows(x_prev, 1, "replicate")
    for (i, j, xw), (_, _, pw) in zip(now, before):
        a = alpha[i, j]
        out += k[i, j] * (a * xw + (1.0 - a) * pw)
    return out


def half_wave_on(p: np.ndarray, on_prev: np.ndarray, clip: float, dc: float) -> np.ndarray:
    """``ON = P [P >= clip] + dc ON(t-1)``."""
    return np.where(p >= clip, p, 0.0) + dc * on_prev


def half_wave_off(p: np.ndarray, off_prev: np.ndarray, clip: float, dc: float) -> np.ndarray:
    """``OFF = |P| [P < clip] + dc OFF(t-1)``."""
    return np.where(p < clip, np.abs(p), 0.0) + dc * off_prev


class _NumpyLGMDBase:
    """Photoreceptor stage shared by the LGMD-family references."""

    name = "numpy"

    def __init__(self, shape: tuple[int, int]):
        self.shape = tuple(shape)
        self.reset()

    def reset(self) -> None:
        z = lambda: np.zeros(self.shape)  # noqa: E731
        self.L, self.P = z(), z()
        self.ON, self.OFF, self.ON_prev, self.OFF_prev = z(), z(), z(), z()
        self.drive = (self.P, self.P)  # what the ON and the OFF half-wave take: P (frames) or (P_on, -P_off)

    def load(self, grey: np.ndarray, first: bool) -> float:
        """``P = L(t) - L(t-1)`` in grey levels (0 on the first frame); returns ``sum |P|``."""
        g = grey_levels(grey)
        self.P = np.zeros(self.shape) if first else g - self.L
        self.L = g
        self.drive = (self.P, self.P)
        return float(np.abs(self.P).sum())

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> float:
        """Take an event bin (H, W each, contrast in [0, 1]): the ON channel is driven by
        ``P_on = 255 p_on``, the OFF channel by ``P_off = 255 p_off`` grey levels, through the
        half-waves of a frame (``half_wave_on(P_on)``, ``half_wave_off(-P_off)``); ``P = P_on - P_off``.
        Returns ``sum (P_on + P_off)`` (a frame's ``sum |P|``: its ``P_on = [P]+``, ``P_off = [-P]+``)."""
        p_on = 255.0 * np.asarray(p_on, np.float64)
        p_off = 255.0 * np.asarray(p_off, np.float64)
        self.P = p_on - p_off
        self.drive = (p_on, -p_off)
        return float((p_on + p_off).sum())

    def _half_waves(self, on_prev: np.ndarray, off_prev: np.ndarray, clip: float,
                    dc: float) -> tuple[np.ndarray, np.ndarray]:
        """This step's ON and OFF channels from the loaded drive (:attr:`drive`) and the previous ones."""
        return half_wave_on(self.drive[0], on_prev, clip, dc), half_wave_off(self.drive[1], off_prev, clip, dc)

    def _on_off(self, clip: float, dc: float) -> None:
        self.ON_prev, self.OFF_prev = self.ON, self.OFF
        self.ON, self.OFF = self._half_waves(self.ON_prev, self.OFF_prev, clip, dc)


class NumpyLGMD2Backend(_NumpyLGMDBase):
    """LGMD2 per-pixel layers in float64 (see :class:`cdnf_ti.models.lgmd2.LGMD2`)."""

    def __init__(self, params, shape: tuple[int, int], dt: int):
        self.params = params
        p = params
        self.k_on = kernel_3x3(*p.k_on)
        self.k_off = kernel_3x3(*p.k_off)
        self.a_on = kernel_3x3(*[dt / (dt + t) for t in p.tau_on])
        self.a_off = kernel_3x3(*[dt / (dt + t) for t in p.tau_off])
        super().__init__(shape)

    def reset(self) -> None:
        super().reset()
        z = lambda: np.zeros(self.shape)  # noqa: E731
        self.I_on, self.I_off, self.S, self.Ce, self.G = z(), z(), z(), z(), z()

    def layers(self, w_on: float, w_off: float) -> tuple[float, float]:
        """ON/OFF, delayed inhibition, S, grouping; returns ``(sum G, max |Ce|)``."""
        p = self.params
        self._on_off(p.clip, p.dc)
        self.I_on = delayed_spread(self.ON, self.ON_prev, self.k_on, self.a_on)
        self.I_off = delayed_spread(self.OFF, self.OFF_prev, self.k_off, self.a_off)
        s_on = np.maximum(self.ON - w_on * self.I_on, 0.0)
        s_off = np.maximum(self.OFF - w_off * self.I_off, 0.0)
        self.S = p.w_on_exc * s_on + p.w_off_exc * s_off + p.w_onoff * s_on * s_off
        self.Ce = correlate3(self.S, np.full((3, 3), 1.0 / 9.0))
        mx = float(np.abs(self.Ce).max())
        omega = p.delta_c + mx / p.c_w
        g = self.S * self.Ce / omega
        self.G = np.where(g * p.c_de >= p.t_de, g, 0.0)
        return float(self.G.sum()), mx

    def fields(self) -> dict[str, np.ndarray]:
        return {"P": self.P.copy(), "ON": self.ON.copy(), "OFF": self.OFF.copy(), "I_on": self.I_on.copy(),
                "I_off": self.I_off.copy(), "S": self.S.copy(), "Ce": self.Ce.copy(), "G": self.G.copy()}


class NumpyLGMD1Backend(_NumpyLGMDBase):
    """LGMD1 (ON/OFF, SFA) per-pixel layers in float64."""

    def __init__(self, params, shape: tuple[int, int], dt: int):
        self.params = params
        p = params
        self.k = kernel_3x3(0.0, *p.k_lateral)
        self.a = kernel_3x3(0.0, *[dt / (dt + t) for t in p.tau_lateral])
        super().__init__(shape)

    def reset(self) -> None:
        super().reset()
        z = lambda: np.zeros(self.shape)  # noqa: E731
        self.I_on, self.E_off, self.S, self.G = z(), z(), z(), z()

    def layers(self) -> float:
        """ON/OFF, delayed spreads, S (thresholded), G; returns ``sum G``."""
        p = self.params
        self._on_off(p.clip, p.dc)
        self.I_on = delayed_spread(self.ON, self.ON_prev, self.k, self.a)
        self.E_off = delayed_spread(self.OFF, self.OFF_prev, self.k, self.a)
        s_on = self.ON - p.w_i_on * self.I_on
        s_off = self.E_off - p.w_i_off * self.OFF
        s = p.w_on_exc * s_on + p.w_off_exc * s_off + p.w_onoff * s_on * s_off
        self.S = np.where(s >= p.t_s, s, 0.0)
        self.G = correlate3(self.S, np.full((3, 3), 1.0 / 9.0))
        return float(self.G.sum())

    def fields(self) -> dict[str, np.ndarray]:
        return {"P": self.P.copy(), "ON": self.ON.copy(), "OFF": self.OFF.copy(), "I_on": self.I_on.copy(),
                "E_off": self.E_off.copy(), "S": self.S.copy(), "G": self.G.copy()}


class NumpyFLGMDBackend(_NumpyLGMDBase):
    """F-LGMD (instantaneous ON/OFF feedback) per-pixel layers in float64.

    RECONSTRUCTION: see :class:`cdnf_ti.models.flgmd.FLGMDONn`.
    """

    def __init__(self, params, shape: tuple[int, int], dt: int):
        self.params = params
        p = params
        self.k = kernel_3x3(0.0, *p.k_lateral)
        self.a = kernel_3x3(0.0, *[dt / (dt + t) for t in p.tau_lateral])
        self.g_e = p.excitation_kernel()
        self.start_gains = p.local_start_gains(dt)
        super().__init__(shape)

    def reset(self) -> None:
        super().reset()
        z = lambda: np.zeros(self.shape)  # noqa: E731
        self.ON0, self.OFF0, self.S_on, self.S_off, self.S, self.G = z(), z(), z(), z(), z(), z()

    def prepare(self) -> None:
        """Feed-forward drives ``ON0``/``OFF0`` and the fixed-point iterate's start.

        The start is ``X0 + kappa [w X0 - Q]+`` with ``Q = w_i sum K (1 - a) X(t-1)``
        (:meth:`~cdnf_ti.models.flgmd.FLGMDParams.local_start_gains`; the drive itself
        when ``kappa = 0``).
        """
        p = self.params
        self.ON_prev, self.OFF_prev = self.ON, self.OFF
        self.ON0, self.OFF0 = self._half_waves(self.ON_prev, self.OFF_prev, p.clip, p.dc)
        starts = []
        for x0, x_prev, w_i, (w, kappa) in zip((self.ON0, self.OFF0), (self.ON_prev, self.OFF_prev),
                                               (p.w_i_on, p.w_i_off), self.start_gains):
            q = w_i * correlate3(x_prev, self.k * (1.0 - self.a))
            starts.append(x0 + kappa * np.maximum(w * x0 - q, 0.0))
        self.ON, self.OFF = starts
        self._before = (self.ON, self.OFF)  # the iterate before the current one (Chebyshev momentum)

    def _local(self, x: np.ndarray, x_prev: np.ndarray, w_i: float) -> np.ndarray:
        return np.maximum(correlate3(x, self.g_e) - w_i * delayed_spread(x, x_prev, self.k, self.a), 0.0)

    def feedback_iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        """One update ``X <- X + mom (X - X_before) + lam (T(X) - X)``, ``T(X) = [X0 + beta S_X(X)]+``."""
        p = self.params
        s_on = self._local(self.ON, self.ON_prev, p.w_i_on)
        s_off = self._local(self.OFF, self.OFF_prev, p.w_i_off)
        d_on = np.maximum(self.ON0 + p.beta_on * s_on, 0.0) - self.ON
        d_off = np.maximum(self.OFF0 + p.beta_off * s_off, 0.0) - self.OFF
        on_b, off_b = self._before
        self._before = (self.ON, self.OFF)
        self.ON = self.ON + mom * (self.ON - on_b) + lam * d_on
        self.OFF = self.OFF + mom * (self.OFF - off_b) + lam * d_off
        return float(np.abs(d_on).max()), float(np.abs(d_off).max())

    def finish(self) -> float:
        """Local summation, threshold and grouping at the fixed point; returns ``sum G``."""
        p = self.params
        self.S_on = self._local(self.ON, self.ON_prev, p.w_i_on)
        self.S_off = self._local(self.OFF, self.OFF_prev, p.w_i_off)
        s = self.S_on + self.S_off
        self.S = np.where(s >= p.t_s, s, 0.0)
        self.G = correlate3(self.S, np.full((3, 3), 1.0 / 9.0))
        return float(self.G.sum())

    def hold(self) -> None:
        """FFI-held frame: the channels keep their previous values."""

    def fields(self) -> dict[str, np.ndarray]:
        return {"P": self.P.copy(), "ON": self.ON.copy(), "OFF": self.OFF.copy(), "S_on": self.S_on.copy(),
                "S_off": self.S_off.copy(), "S": self.S.copy(), "G": self.G.copy()}


class NumpySDNFBackend:
    """SDNF single field in float64. RECONSTRUCTION: see :class:`cdnf_ti.models.sdnf.SDNF`."""

    name = "numpy"

    def __init__(self, params, shape: tuple[int, int]):
        self.params = params
        self.shape = tuple(shape)
        g1, g2 = params.dog_profiles()
        self.g1o, self.g2o = np.outer(g1, g1), np.outer(g2, g2)
        self.reset()

    def reset(self) -> None:
        z = lambda: np.zeros(self.shape)  # noqa: E731
        self.L, self.P, self.E = z(), z(), z()
        self.u = np.full(self.shape, -self.params.h)

    def load(self, grey: np.ndarray, first: bool) -> float:
        """Binary input ``E = [|P| >= T_b]``; returns the active fraction ``rho``."""
        g = grey.astype(np.float64)
        if grey.dtype == np.uint8:
            g /= 255.0
        self.P = np.zeros(self.shape) if first else g - self.L
        self.L = g
        self.E = (np.abs(self.P) >= self.params.t_b).astype(np.float64)
        return float(self.E.mean())

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> float:
        """Take an event bin (H, W each, in [0, 1]): ``E = [max(p_on, p_off) >= T_b]`` (a pixel with
        either polarity at the threshold is active; both in one bin do not cancel); ``P = p_on - p_off``
        (the photoreceptors are not used). Returns the active fraction, as :meth:`load`."""
        p_on = np.asarray(p_on, np.float64)
        p_off = np.asarray(p_off, np.float64)
        self.P = p_on - p_off
        self.E = (np.maximum(p_on, p_off) >= self.params.t_b).astype(np.float64)
        return float(self.E.mean())

    def update(self, b_t: float) -> float:
        """``u(t) = E - h + vartheta(W(t) (*) f(u(t-1)))``; returns ``mean f(u(t))``."""
        p = self.params
        f_prev = p.activation(self.u)
        lat = p.A * correlate(f_prev, self.g1o, "replicate") - b_t * correlate(f_prev, self.g2o, "replicate")
        self.u = self.E - p.h + vartheta(lat)
        return float(p.activation(self.u).mean())

    def fields(self) -> dict[str, np.ndarray]:
        return {"P": self.P.copy(), "E": self.E.copy(), "u": self.u.copy(),
                "activity": self.params.activation(self.u)}
