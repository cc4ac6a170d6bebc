"""LGMD2 (Fu, Hu, Peng, Rind, Yue, IEEE Trans. Cybernetics 50(12):5074-5088, 2020).

Equations and defaults: ``docs/EQUATIONS.md``, gathered from the
authors' public C# supplement (``lgmd2OpenSource.cs``). Per frame, with
``dt = 1000 // fps`` ms (integer: 33 at 30 fps) and grey levels in 0..255:

1. ``P = L(t) - L(t-1)``; ``PM(t) = a PM_raw + (1 - a) PM(t-1)``,
   ``PM_raw = mean |P|``, ``a = dt / (dt + tau_PM)``;
   ``w_on = max(PM / T_pm, 1)``, ``w_off = max(PM / T_pm, 0.5)``.
2. ``ON = P [P >= 0.1] + 0.1 ON(t-1)``; ``OFF = |P| [P < 0.1] + 0.1 OFF(t-1)``.
3. ``I(x, y) = sum_ij K(i, j) [a_ij X(x+i, y+j, t) + (1 - a_ij) X(x+i, y+j, t-1)]``,
   ``a_ij = dt / (dt + tau_ij)``, centre included.
4. ``S = S_on + S_off + S_on S_off``, ``S_on = [ON - w_on I_on]+``, ``S_off = [OFF - w_off I_off]+``.
5. ``Ce = S (*) ones/9``; ``omega = 0.01 + max|Ce| / 4``; ``G = S Ce / omega``, 0 unless ``0.5 G >= 15``.
6. ``K = 1 / (1 + exp(-sum G / N))``.
7. SFA: ``Kh = a_s (Kh(t-1) + K - K(t-1))`` if ``K - K(t-1) <= 0.003`` else ``a_s K``,
   ``a_s = tau_s / (tau_s + dt)``; ``Kh = max(Kh, 0.5)``.
8. ``n(t) = floor(exp(4 (Kh - 0.78)))``; the count adds ``n`` and resets to 0 on
   any frame with ``n = 0``; collision alert while the count ``>= 8``.

Frame 0 only initialises ``L``: the state stays at zero (as the C# code's
first call sees zeros for every previous value), the output is ``K = 0.5``.

This module also holds what the LGMD family shares: the scalar recurrences
(:func:`lowpass_coefficient`, :func:`sfa_step`, :func:`spike_count`) and the
base class :class:`LGMDFamily` that runs them identically for both backends.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Sequence

import numpy as np

from ..alert_rule import AlertRule
from ..baselines_reference import NumpyLGMD2Backend
from ..params import ModelParams, check_params, sigmoid
from .base import Model, StepResult, Trace
from .registry import register_model


def frame_interval_ms(fps: float) -> int:
    """``dt = 1000 // fps`` in integer ms (33 at 30 fps), as the authors' code."""
    dt = int(1000 // fps)
    if dt < 1:
        raise ValueError(f"fps {fps} gives a frame interval below 1 ms")
    return dt


def lowpass_coefficient(dt: int, tau: float) -> float:
    """``a = dt / (dt + tau)`` of a first-order low-pass (dt, tau in ms)."""
    return dt / (dt + tau)


def sfa_step(kh_prev: float, k_prev: float, k: float, threshold: float, a_s: float, floor: float = 0.5) -> float:
    """Spike frequency adaptation of the membrane potential.

    Parameters
    ----------
    kh_prev, k_prev, k : float
        ``Kh(t-1)``, ``K(t-1)`` and ``K(t)``.
    threshold : float
        ``T_sfa``: below or at this rise of K the adaptation accumulates.
    a_s : float
        ``tau_s / (tau_s + dt)``.
    floor : float
        Lower bound of the result (0.5).

    Returns
    -------
    float
        ``Kh(t)``.
    """
    d = k - k_prev
    kh = a_s * (kh_prev + d) if d <= threshold else a_s * k
    return max(kh, floor)


def spike_count(kh: float, t_sp: float, c_sp: float) -> int:
    """``n(t) = floor(exp(c_sp (Kh - t_sp)))`` spikes in this frame."""
    return int(math.floor(math.exp(c_sp * (kh - t_sp))))


@dataclass(frozen=True)
class LGMD2Params(ModelParams):
    """LGMD2 parameters (defaults: docs/EQUATIONS.md / the authors' C# supplement).

    Attributes
    ----------
    tau_pm : float
        Time constant of the PM pathway (ms, 90).
    t_pm : float
        PM threshold of the adaptive inhibition biases (grey levels, 8).
    w_on_base, w_off_base : float
        Lower bounds of the ON/OFF inhibition biases (1 and 0.5).
    clip : float
        Clip point of the ON/OFF rectifiers (grey levels, 0.1).
    dc : float
        Residue of the previous ON/OFF value (0.1).
    k_on, k_off : (centre, edge, diagonal)
        3x3 inhibition kernels ((2, 0.5, 0.25) and (1, 0.25, 0.125)).
    tau_on, tau_off : (centre, edge, diagonal)
        Delays of the inhibitions (ms, (15, 30, 45) and (60, 120, 180)).
    w_on_exc, w_off_exc, w_onoff : float
        Weights of ``S = w_on_exc S_on + w_off_exc S_off + w_onoff S_on S_off`` (1, 1, 1).
    delta_c, c_w : float
        ``omega = delta_c + max|Ce| / c_w`` (0.01, 4).
    c_de, t_de : float
        Grouping decay: G kept where ``c_de G >= t_de`` (0.5, 15).
    c_sig : float
        ``K = sigmoid(sum G / (N c_sig))`` (1).
    tau_sfa : float
        SFA time constant (ms, 800).
    t_sfa : float
        SFA threshold on the rise of K (0.003).
    kh_floor : float
        Lower bound of the SFA output (0.5).
    t_sp, c_sp : float
        Spiking ``n = floor(exp(c_sp (Kh - t_sp)))`` (0.78, 4).
    n_ts : int
        Collision alert while the spike count is at least this (8).
    """

    tau_pm: float = 90.0
    t_pm: float = 8.0
    w_on_base: float = 1.0
    w_off_base: float = 0.5
    clip: float = 0.1
    dc: float = 0.1
    k_on: tuple[float, float, float] = (2.0, 0.5, 0.25)
    tau_on: tuple[float, float, float] = (15.0, 30.0, 45.0)
    k_off: tuple[float, float, float] = (1.0, 0.25, 0.125)
    tau_off: tuple[float, float, float] = (60.0, 120.0, 180.0)
    w_on_exc: float = 1.0
    w_off_exc: float = 1.0
    w_onoff: float = 1.0
    delta_c: float = 0.01
    c_w: float = 4.0
    c_de: float = 0.5
    t_de: float = 15.0
    c_sig: float = 1.0
    tau_sfa: float = 800.0
    t_sfa: float = 0.003
    kh_floor: float = 0.5
    t_sp: float = 0.78
    c_sp: float = 4.0
    n_ts: int = 8

    def __post_init__(self) -> None:
        check_params("LGMD2Params", [
            (self.tau_pm >= 0, f"tau_pm must be >= 0 ms, got {self.tau_pm}"),
            (self.t_pm > 0, f"t_pm must be > 0, got {self.t_pm}"),
            (len(self.k_on) == 3 and len(self.k_off) == 3, "k_on/k_off must be (centre, edge, diagonal)"),
            (len(self.tau_on) == 3 and len(self.tau_off) == 3, "tau_on/tau_off must be (centre, edge, diagonal)"),
            (all(t >= 0 for t in (*self.tau_on, *self.tau_off)), "delays tau_on/tau_off must be >= 0 ms"),
            (0 <= self.dc < 1, f"dc must be in [0, 1), got {self.dc}"),
            (self.c_w > 0 and self.delta_c > 0, "c_w and delta_c must be > 0"),
            (self.c_sig > 0, f"c_sig must be > 0, got {self.c_sig}"),
            (self.tau_sfa > 0, f"tau_sfa must be > 0 ms, got {self.tau_sfa}"),
            (int(self.n_ts) == self.n_ts and self.n_ts >= 1, f"n_ts must be a positive integer, got {self.n_ts}"),
        ])
















class LGMDFamily(Model):
    """Shared orchestration of the LGMD family (both backends).

    Subclasses supply their backends and equations (:class:`~cdnf_ti.models.base.Model`
    hooks); the family shares the frame interval ``dt``, the scalar state
    (PM/FFI, ``K``/``Kh`` history, spike count), the membrane/SFA step and the
    spike count. Inputs are grey levels 0..255 (uint8 as is; float in [0, 1]
    times 255). ``threshold`` is None: the alert is a spike count, not a level
    of ``K`` (``Kh``/``n`` are diagnostics).
    """

    output_name = "K"

    #: Threshold sweep (experiments): the spike count at which the alert fires.
    sweep_parameter = "n_ts (alert while spike count >= value)"
    sweep_values = tuple(float(v) for v in range(1, 21))

    @classmethod
    def sweep_default(cls) -> float:
        return float(cls.params_type().n_ts)

    def alert_rule(self) -> AlertRule:
        """``spike count >= n_ts``: the ``count`` diagnostic against ``n_ts``."""
        n_ts = int(self.params.n_ts)
        return AlertRule(f"spike count >= {n_ts}", "spike count", "count", float(n_ts))

    @classmethod
    def sweep_alerts(cls, trace: Trace, values: Sequence[float]) -> list[np.ndarray]:
        """Alerts per frame at each count threshold, from the saved ``count`` diagnostic.

        The spike count does not depend on the threshold, so ``count >= n_ts``
        on the saved trace is exactly what a rerun with that ``n_ts`` gives.
        """
        count = np.asarray(trace.diagnostics["count"], dtype=np.float64)
        return [count >= v for v in values]

    #: The model's NumPy reference backend, built as ``(params, shape, dt)``.
    numpy_backend_type: ClassVar[type]
    takes_events = True

    def _setup(self) -> None:
        self.dt = frame_interval_ms(self.fps)

    #: Use the fast (lane) layout where it applies; ``False``: the pixel layout (same equations).
    fast: bool = True

    def _input(self, t: int, grey: np.ndarray | None, loaded: Any) -> float:
        """``sum |P|`` of frame ``t`` (an event bin: ``sum (P_on + P_off)``): what the ``numpy`` backend's ``load``
        returned, else the kernels' ``load`` launch, which writes the frame's ON / OFF channels into the pairs'
        other buffers (:meth:`_keep_channels` drops them)."""
        if loaded is not None:
            return loaded
        self._be.flip()
        scale = 1.0 if grey is not None and grey.dtype == np.uint8 else 255.0
        return self._be.launch("load", scale=scale, keep=0.0 if t == 0 else 1.0)[0]

    def _keep_channels(self, loaded: Any) -> None:
        """A frame whose layers do not run (the first, an FFI-held one) drops its ON / OFF channels."""
        if loaded is None:
            self._be.flip()

    #: The planes that :meth:`fields` leaves out.
    hidden: tuple[str, ...] = ("L",)

    def fields(self) -> dict[str, np.ndarray]:
        """The layers (those in :attr:`hidden` aside), (H, W) each."""
        return {k: v for k, v in super().fields().items() if k not in self.hidden}

    @staticmethod
    def _lowpass(dt: int, taus: Sequence[float]) -> list[float]:
        """``a = dt / (dt + tau)`` of each delay ``tau``."""
        return [lowpass_coefficient(dt, tau) for tau in taus]

    def _numpy_backend(self, shape: tuple[int, int]) -> Any:
        return self.numpy_backend_type(self.params, shape, self.dt)

    def _reset_state(self) -> None:
        self.pm = 0.0  # PM (LGMD2) or FFI (LGMD1 family), grey levels
        self.k_prev = 0.0
        self.kh_prev = 0.0
        self.count = 0

    def _track_pm(self, sum_p: float, n_cells: int, tau: float) -> float:
        """``PM(t) = a mean|P| + (1 - a) PM(t-1)``, ``a = dt / (dt + tau)``: LGMD2's PM, LGMD1's FFI.

        Updates and returns ``self.pm`` (grey levels); ``sum_p`` is ``sum |P|`` over ``n_cells`` pixels.
        """
        a = lowpass_coefficient(self.dt, tau)
        self.pm = a * (sum_p / n_cells) + (1.0 - a) * self.pm
        return self.pm

    def _spikes(self, kh: float) -> tuple[int, bool]:
        p = self.params
        n = spike_count(kh, p.t_sp, p.c_sp)
        self.count = 0 if n == 0 else self.count + n
        return n, self.count >= p.n_ts

    def _membrane(self, sum_g: float, n_cells: int) -> tuple[float, float]:
        """``K = sigmoid(sum G / (N c_sig))`` and its SFA-adapted ``Kh``; updates the history."""
        p = self.params
        k = sigmoid(sum_g / (n_cells * p.c_sig))
        a_s = p.tau_sfa / (p.tau_sfa + self.dt)
        kh = sfa_step(self.kh_prev, self.k_prev, k, p.t_sfa, a_s, p.kh_floor)
        self.k_prev, self.kh_prev = k, kh
        return k, kh


@register_model
class LGMD2(LGMDFamily):
    """LGMD2 collision-perception network (Fu et al. 2020), selective to darker looming objects.

    Parameters
    ----------
    params : LGMD2Params, optional
    backend : {"taichi", "numpy"}
        Taichi kernels (float32 layers) or the NumPy float64 reference.
    arch : str
        Taichi architecture.
    fps : float
        Input frame rate; ``dt = 1000 // fps`` ms.

    Notes
    -----
    ``output`` is ``K`` (sigmoid membrane potential); ``spike`` is the
    collision alert (spike count >= 8). Diagnostics per frame: ``Kh``
    (after SFA), ``n`` (spikes), ``count``, ``PM``, ``w_on``, ``w_off``,
    ``sum_G``, ``max_Ce``. :meth:`fields`: ``P, ON, OFF, I_on, I_off, S, Ce, G``.
    """

    name = "lgmd2"
    order = 2
    panels = (("ON", "ON"), ("OFF", "OFF"), ("S", "Summation S"))
    params_type = LGMD2Params
    description = "LGMD2 (Fu et al. 2020): biased ON/OFF, adaptive inhibition, SFA; equations from the authors' code"

    numpy_backend_type = NumpyLGMD2Backend
    #: The stages (``kernels/lgmd.py``).
    kernels = "lgmd:lgmd2"

    def coefficients(self) -> dict[str, Any]:
        """The stages' coefficients by name (``kernels/lgmd.py``, ``LGMD2_COEFS``)."""
        p = self.params
        return dict(clip=p.clip, dc=p.dc, k_on=p.k_on, a_on=self._lowpass(self.dt, p.tau_on), k_off=p.k_off,
                    a_off=self._lowpass(self.dt, p.tau_off), e=(p.w_on_exc, p.w_off_exc, p.w_onoff),
                    delta_c=p.delta_c, c_w=p.c_w, c_de=p.c_de, t_de=p.t_de)

    def _step(self, t: int, grey: np.ndarray | None, loaded: Any) -> StepResult:
        p = self.params
        be = self._be
        sum_p = self._input(t, grey, loaded)
        if t == 0 and grey is not None:  # an event bin (grey None) is a full step even at t == 0
            self._keep_channels(loaded)
            return StepResult(t, 0.5, False, True, dict(Kh=p.kh_floor, n=0, count=0, PM=0.0,
                                                        w_on=p.w_on_base, w_off=p.w_off_base,
                                                        sum_G=0.0, max_Ce=0.0))
        n_cells = self._be.shape[0] * self._be.shape[1]
        self._track_pm(sum_p, n_cells, p.tau_pm)
        w_on = max(self.pm / p.t_pm, p.w_on_base)
        w_off = max(self.pm / p.t_pm, p.w_off_base)
        if self.backend_name == "numpy":
            sum_g, max_ce = be.layers(w_on, w_off)
        else:
            max_ce, sum_g = be.launch("layers", w_on=w_on, w_off=w_off)
        k, kh = self._membrane(sum_g, n_cells)
        n, alert = self._spikes(kh)
        diag = dict(Kh=kh, n=n, count=self.count, PM=self.pm, w_on=w_on, w_off=w_off,
                    sum_G=sum_g, max_Ce=max_ce)
        return StepResult(t, k, alert, True, diag)
