"""LGMD1 with ON/OFF pathways and spike frequency adaptation (Fu, Hu, Peng, Yue,
Neural Networks 106:127-143, 2018).

Equations and defaults: ``docs/EQUATIONS.md``, gathered from the same
authors' general LGMD code (``LGMDs.cs``). Differences from LGMD2
(:mod:`cdnf_ti.models.lgmd2`):

* feed-forward inhibition ``FFI(t) = a mean|P| + (1 - a) FFI(t-1)``,
  ``a = dt / (dt + 90)``; when ``FFI >= 8`` the frame is held at rest
  (``K = 0.5``, ``Kh = 0.5``, so no spike and the count resets) and the
  per-pixel layers are not computed (ON/OFF keep their previous values);
* ``S_on = ON - 0.5 I_on``, ``I_on`` the delayed 3x3 spread of ON
  (centre 0, edge 0.25, diagonal 0.125; delays 30 ms edge, 60 ms diagonal);
* ``S_off = E_off - 1.0 OFF``, ``E_off`` the same delayed spread of OFF;
* ``S = S_on + S_off`` kept only where ``S >= 30``; ``G = S (*) ones/9``;
  ``K = sigmoid(sum G / N)``;
* SFA as LGMD2 with threshold 0.005 and ``tau = 500`` ms; spikes as LGMD2
  (``T_sp = 0.78``, alert while the count ``>= 8``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..baselines_reference import NumpyLGMD1Backend
from ..params import ModelParams, check_params
from .base import StepResult
from .lgmd2 import LGMDFamily
from .registry import register_model


@dataclass(frozen=True)
class LGMD1Params(ModelParams):
    """LGMD1 parameters (defaults: docs/EQUATIONS.md / the authors' ``LGMDs.cs``).

    Attributes
    ----------
    tau_ffi : float
        FFI low-pass time constant (ms, 90).
    t_ffi : float
        FFI threshold (grey levels, 8): at or above it the frame is held at rest.
    clip, dc : float
        ON/OFF clip point (0.1 grey levels) and residue (0.1).
    k_lateral : (edge, diagonal)
        Delayed 3x3 spread weights, centre 0 ((0.25, 0.125)).
    tau_lateral : (edge, diagonal)
        Their delays (ms, (30, 60)).
    w_i_on, w_i_off : float
        ``S_on = ON - w_i_on I_on`` (0.5); ``S_off = E_off - w_i_off OFF`` (1.0).
    w_on_exc, w_off_exc, w_onoff : float
        ``S = w_on_exc S_on + w_off_exc S_off + w_onoff S_on S_off`` (1, 1, 0).
    t_s : float
        S cells below this are zeroed (grey levels, 30).
    c_sig : float
        ``K = sigmoid(sum G / (N c_sig))`` (1).
    tau_sfa, t_sfa, kh_floor : float
        SFA time constant (ms, 500), threshold (0.005) and floor (0.5).
    t_sp, c_sp : float
        Spiking threshold (0.78) and scale (4).
    n_ts : int
        Collision alert while the spike count is at least this (8).
    """

    tau_ffi: float = 90.0
    t_ffi: float = 8.0
    clip: float = 0.1
    dc: float = 0.1
    k_lateral: tuple[float, float] = (0.25, 0.125)
    tau_lateral: tuple[float, float] = (30.0, 60.0)
    w_i_on: float = 0.5
    w_i_off: float = 1.0
    w_on_exc: float = 1.0
    w_off_exc: float = 1.0
    w_onoff: float = 0.0
    t_s: float = 30.0
    c_sig: float = 1.0
    tau_sfa: float = 500.0
    t_sfa: float = 0.005
    kh_floor: float = 0.5
    t_sp: float = 0.78
    c_sp: float = 4.0
    n_ts: int = 8

    def __post_init__(self) -> None:
        check_params("LGMD1Params", lgmd1_checks(self))


def lgmd1_checks(p: LGMD1Params | Any) -> list[tuple[bool, str]]:
    """The ``(condition, message)`` checks of LGMD1's parameters (also F-LGMD's, which builds on them)."""
    return [
        (p.tau_ffi >= 0, f"tau_ffi must be >= 0 ms, got {p.tau_ffi}"),
        (p.t_ffi > 0, f"t_ffi must be > 0, got {p.t_ffi}"),
        (len(p.k_lateral) == 2 and len(p.tau_lateral) == 2,
         "k_lateral/tau_lateral must be (edge, diagonal)"),
        (all(t >= 0 for t in p.tau_lateral), "tau_lateral must be >= 0 ms"),
        (0 <= p.dc < 1, f"dc must be in [0, 1), got {p.dc}"),
        (p.c_sig > 0, f"c_sig must be > 0, got {p.c_sig}"),
        (p.tau_sfa > 0, f"tau_sfa must be > 0 ms, got {p.tau_sfa}"),
        (int(p.n_ts) == p.n_ts and p.n_ts >= 1, f"n_ts must be a positive integer, got {p.n_ts}"),
    ]








@register_model
class LGMD1(LGMDFamily):
    """LGMD1 with ON/OFF pathways and SFA (Fu et al. 2018).

    Parameters
    ----------
    params : LGMD1Params, optional
    backend : {"taichi", "numpy"}
    arch : str
    fps : float
        Input frame rate; ``dt = 1000 // fps`` ms.

    Notes
    -----
    ``output`` is ``K``; ``spike`` the collision alert (count >= 8).
    Diagnostics: ``Kh, n, count, FFI, held, sum_G``. :meth:`fields`:
    ``P, ON, OFF, I_on, E_off, S, G``.
    """

    name = "lgmd1"
    order = 3
    panels = (("ON", "ON"), ("OFF", "OFF"), ("S", "Summation S"))
    params_type = LGMD1Params
    description = "LGMD1 with ON/OFF pathways and SFA (Fu et al. 2018); equations from the authors' code"

    numpy_backend_type = NumpyLGMD1Backend
    #: The stages (``kernels/lgmd.py``).
    kernels = "lgmd:lgmd1"

    def coefficients(self) -> dict[str, Any]:
        """The stages' coefficients by name (``kernels/lgmd.py``, ``LGMD1_COEFS``)."""
        p = self.params
        return dict(clip=p.clip, dc=p.dc, k=p.k_lateral, a=self._lowpass(self.dt, p.tau_lateral),
                    w_i=(p.w_i_on, p.w_i_off), e=(p.w_on_exc, p.w_off_exc, p.w_onoff), t_s=p.t_s)

    def _step(self, t: int, grey: np.ndarray | None, loaded: Any) -> StepResult:
        p = self.params
        sum_p = self._input(t, grey, loaded)
        if t == 0 and grey is not None:  # an event bin (grey None) is a full step even at t == 0
            self._keep_channels(loaded)
            return StepResult(t, 0.5, False, True, self._diag0())
        n_cells = self._be.shape[0] * self._be.shape[1]
        self._track_pm(sum_p, n_cells, p.tau_ffi)
        held = self.pm >= p.t_ffi
        extra: dict[str, float] = self._held_diag() if held else {}
        converged = True
        if held:
            # held at rest; the per-pixel layers are not computed (ON/OFF keep their values)
            self._keep_channels(loaded)
            k, kh, sum_g = 0.5, p.kh_floor, 0.0
            self.k_prev, self.kh_prev = k, kh
        else:
            sum_g, extra, converged = self._run_layers()
            k, kh = self._membrane(sum_g, n_cells)
        n, alert = self._spikes(kh)
        diag = dict(Kh=kh, n=n, count=self.count, FFI=self.pm, held=int(held), sum_G=sum_g, **extra)
        return StepResult(t, k, alert, converged, diag)

    def _diag0(self) -> dict[str, float]:
        return dict(Kh=self.params.kh_floor, n=0, count=0, FFI=0.0, held=0, sum_G=0.0)

    def _held_diag(self) -> dict[str, float]:
        """Extra diagnostics of a held frame (none for LGMD1)."""
        return {}

    def _run_layers(self) -> tuple[float, dict[str, float], bool]:
        """Per-pixel stages of one frame: ``(sum G, extra diagnostics, converged)``."""
        if self.backend_name == "numpy":
            return self._be.layers(), {}, True
        return self._be.launch("layers")[0], {}, True
