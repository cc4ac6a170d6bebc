"""oLGMD: LGMD2 with contrast polarity-specific feed-forward inhibition (Gao, Liu, Wang, Fu,
Biomimetics 9(11):650, 2024).

Equations as the authors' Python computes them (``optimized_LGMD.py`` of
``Ryannnice/Supplementary_Materials_FFI_ON_OFF``; docs/MODELS.md, "oLGMD"), per frame ``t``:

* ``P = L(t) - L(t-1) + a_1 P(t-1) + a_2 P(t-2)``; ``P_on = [P]^+ + 0.1 P_on(t-1)``,
  ``P_off = [-P]^+ + 0.1 P_off(t-1)`` (the backend's :meth:`photoreceptors`);
* feed-forward inhibition: ``PM_on``, ``PM_off`` low-passed means of ``P_on``, ``P_off``;
  ``w1 = max(1, PM_on / 6)``, ``w2 = max(0.3, PM_off / 6)``; a channel is gated off while its
  ``PM < 1.15``;
* ``S = S_on + S_off``, ``S = [E - w I]^+`` with the delayed 3x3 inhibition ``I``; ``Ce`` the 3x3
  mean of ``S``; ``G = S Ce / (max Ce / 4 + 0.01)``, zero where ``0.5 G < 15`` (:meth:`layers`);
* ``k = sigmoid(sum G / (0.6 N))``, 0.5 on a global change (``AIM >= 10 + 0.02 AIM(t-1)``);
  SFA gives ``K >= 0.5``; ``S_spike = exp(4 (K - 0.78))``; the alert is
  ``S_spike(t-3) + ... + S_spike(t) >= 3``.

``variant="code"`` (default) keeps the authors' code's quirks, ``"paper"`` corrects them
(:class:`OLGMDParams`). The model is causal: the alert of frame ``t`` uses frames up to ``t``;
their ``Col[j]`` is our alert at :func:`~cdnf_ti.olgmd_reference.their_col_frame` ``(j)``.
The float64 oracle is :class:`cdnf_ti.olgmd_reference.OLGMDReference` (the ``numpy`` backend).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Sequence

import cv2
import numpy as np

from .. import olgmd_reference as ref
from ..alert_rule import AlertRule
from ..params import ModelParams, check_params
from .base import Model, StepResult, Trace
from .reference_backend import ReferenceBackend
from .registry import register_model


@dataclass(frozen=True)
class OLGMDParams(ref.OLGMDParams, ModelParams):
    """oLGMD parameters: the constants of :class:`cdnf_ti.olgmd_reference.OLGMDParams` (the authors'
    names; times in ms, grey levels 0..255) and the variant.

    Attributes
    ----------
    variant : {"code", "paper"}
        ``"code"``: the authors' Python: ``dt`` fixed at 53 ms whatever the frame rate; colour frames
        made grey with ``COLOR_RGB2GRAY`` on BGR; the first frame difference dropped; persistence
        ``a_i = 1 / (1 + e^(t - i))`` of the absolute frame ``t``; ``PM_off`` from the ON mean; PM
        smoothing of the raw previous mean; ``E(t-1) = 0`` after a gated frame; zero border on ``S``,
        reflect-101 on ``Ce``. ``"paper"``: ``dt = 1000 / fps``, ``COLOR_BGR2GRAY``, the difference
        of frames 0 and 1 used, ``a_i = 1 / (1 + e^i)``, ``PM_off`` a first-order low-pass of the OFF
        mean, ``E(t-1) = P(t-1)``, replicate borders.
    """

    variant: str = "code"

    def __post_init__(self) -> None:
        check_params("OLGMDParams", [
            (self.variant in ref.VARIANTS, f"variant must be one of {', '.join(ref.VARIANTS)}, got {self.variant!r}"),
            (all(len(x) == 3 for x in (self.t_on, self.t_off, self.w_on, self.w_off)),
             "t_on, t_off, w_on, w_off must be (centre, edge, diagonal)"),
            (all(t >= 0 for t in (*self.t_on, *self.t_off)), "delays t_on, t_off must be >= 0 ms"),
            (self.tau_pm >= 0 and self.tau_sfa > 0, "tau_pm must be >= 0 ms and tau_sfa > 0 ms"),
            (self.a5 > 0, f"a5 must be > 0, got {self.a5}"),
            (self.cw > 0 and self.delta_c > 0, "cw and delta_c must be > 0"),
            (self.tpm > 0, f"tpm must be > 0, got {self.tpm}"),
        ])


class _ReferenceBackend(ReferenceBackend):
    """The ``numpy`` backend: the float64 :class:`~cdnf_ti.olgmd_reference.OLGMDReference`, stepped whole."""

    def fields(self) -> dict[str, np.ndarray]:
        """The reference's ``S`` and ``G`` of the last frame."""
        return {"S": self.ref.s_layer, "G": self.ref.g_layer}


@register_model
class OLGMD(Model):
    """oLGMD collision detector (Gao et al. 2024), responding to darker looming objects.

    Parameters
    ----------
    params : OLGMDParams, optional
    backend : {"taichi", "numpy"}
        The kernels (float32 layers) or the float64 reference.
    arch : str
    fps : float
        Input frame rate; only ``variant="paper"`` uses it (``dt = 1000 / fps`` ms).

    Notes
    -----
    ``output`` is the membrane potential ``K`` in [0.5, 1); ``spike`` the alert. Diagnostics:
    ``k_raw`` (the sigmoid before the reset), ``s_spike``, ``spike_sum``, ``pm_on``, ``pm_off``,
    ``aim``, ``w1``, ``w2``, ``gate_on``, ``gate_off``, ``sum_G``, ``max_Ce``. :meth:`fields`:
    ``P, ON, OFF, S, Ce, G`` (the ``numpy`` backend: ``S, G``).
    """

    name = "olgmd"
    order = 5
    output_name = "K"
    params_type = OLGMDParams
    description = ("oLGMD (Gao et al. 2024): LGMD2 with polarity-specific feed-forward inhibition; "
                   "equations from the authors' Python")

    #: The stages (``kernels/olgmd.py``) and the fields ``render`` shows.
    kernels = "olgmd"
    panels = (("OFF", "OFF P_off"), ("S", "Summation S"), ("G", "Grouping G"))
    #: Use the fast (lane) layout where it applies; ``False``: the pixel layout (same equations).
    fast: bool = True

    #: Threshold sweep: the spike sum at which the alert fires (replayed from ``spike_sum``).
    sweep_parameter = "n_sp (alert while the 4-frame spike sum >= value)"
    sweep_values = tuple(float(v) / 2 for v in range(2, 17))

    @classmethod
    def sweep_default(cls) -> float:
        return ref.N_SP

    def alert_rule(self) -> AlertRule:
        """The sum of ``S_spike = exp(a7 (K - t_spi))`` over the last 4 frames ``>= 3`` (``spike_sum``)."""
        p = self.params
        return AlertRule(f"{ref.N_TS}-frame sum of exp({p.a7:g}(K - {p.t_spi:g})) >= {ref.N_SP:g}",
                         "spike_sum", "spike_sum", float(ref.N_SP))

    @classmethod
    def sweep_alerts(cls, trace: Trace, values: Sequence[float]) -> list[np.ndarray]:
        """Alerts per frame at each spike-sum threshold (the sum does not depend on it)."""
        total = np.asarray(trace.diagnostics["spike_sum"], dtype=np.float64)
        return [total >= v for v in values]

    def _setup(self) -> None:
        p = self.params
        self.code = p.variant == "code"
        self.dt = ref.CODE_INTERVAL_MS if self.code else 1000.0 / self.fps
        self.a4 = self.dt / (p.tau_pm + self.dt)
        self.a6 = p.tau_sfa / (p.tau_sfa + self.dt)
        #: the first frame whose difference is used (the authors' loop starts at t = 2)
        self.first = 2 if self.code else 1
        #: centre self-inhibition ``K_c a_c`` of ON and OFF: where ``w K_c a_c > 1`` a channel's
        #: ``[E - w I]^+`` is 0 on every pixel (``E``, ``I`` and the weights are >= 0), so it is not computed
        self.self_inhibition = tuple(k[0] * self.dt / (self.dt + tau[0]) for k, tau in ((p.w_on, p.t_on),
                                                                                           (p.w_off, p.t_off)))

    def _reset_state(self) -> None:
        self.pm_on_prev = self.pm_off_prev = 0.0  # code: the raw previous means; paper: PM(t-1)
        self.aim_prev = 0.0
        self.k1 = self.k_pre = 0.0  # k(t-1) after the reset, K(t-1)
        self.open_before = (False, False)  # the gates of the frame before
        self.spikes: deque[float] = deque([0.0] * ref.N_TS, maxlen=ref.N_TS)

    def _numpy_backend(self, shape: tuple[int, int]) -> ReferenceBackend:
        return _ReferenceBackend(ref.OLGMDReference(shape[0], shape[1], self.params.variant, self.fps, self.params),
                                 shape)

    def coefficients(self) -> dict[str, Any]:
        """The stages' coefficients by name: ON / OFF weights ``K a`` and ``K (1 - a)`` (``a = dt / (dt + tau)``),
        the channels' persistence ``a1``, ``o = (o1, o2, o3)`` and the grouping's constants."""
        p, dt = self.params, self.dt
        out = {}
        for name, weights, taus in (("k_on", p.w_on, p.t_on), ("k_off", p.w_off, p.t_off)):
            a = [dt / (dt + tau) for tau in taus]
            out[name] = [w * ai for w, ai in zip(weights, a)] + [w * (1.0 - ai) for w, ai in zip(weights, a)]
        return dict(out, a1=p.a1, o=(p.o1, p.o2, p.o3), cw=p.cw, delta_c=p.delta_c, cde=p.cde, tde=p.tde)

    def borders(self) -> dict[str, str]:
        """``code``: the outermost ring of ``S`` zero and reflect-101 around it; ``paper``: replicate."""
        return {"S": "reflect+ring"} if self.code else {}

    def _prepare(self, frame: np.ndarray) -> np.ndarray:
        """``variant="code"`` makes BGR uint8 frames grey with ``COLOR_RGB2GRAY``, as the authors' code."""
        f = np.asarray(frame)
        if self.code and f.ndim == 3 and f.shape[2] == 3 and f.dtype == np.uint8:
            frame = cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_RGB2GRAY)
        return super()._prepare(frame)

    # -- one frame ----------------------------------------------------------------------------------
    def _step(self, t: int, grey: np.ndarray | None, loaded: Any) -> StepResult:
        if isinstance(loaded, ref.OLGMDStep):  # the numpy backend stepped the reference
            return self._result(t, loaded, {})
        be = self._be
        active = t >= self.first
        if active:
            be.flip()  # this frame's P, P_on, P_off go to the older buffers
        a_1, a_2 = self._persistence(t)
        sums = be.launch("load", scale=1.0 if grey.dtype == np.uint8 else 255.0, active=float(active), a_1=a_1,
                         a_2=a_2)
        if not active:
            self.spikes.append(0.0)
            return self._result(t, ref.OLGMDStep(0.5, 0.5, 0.0, sum(self.spikes), False, 0.0, 0.0, 0.0), {})
        n_cells = be.shape[0] * be.shape[1]
        pm_on, pm_off = self._feedforward(sums[0] / n_cells, sums[1] / n_cells)
        p = self.params
        w = (max(p.w3, pm_on / p.tpm), max(p.w4, pm_off / p.tpm))
        gates = (pm_on >= p.th_on, pm_off >= p.th_off)
        before = (1.0, 1.0) if not self.code else tuple(float(g) for g in self.open_before)
        silent = tuple(wi * c > 1.0 for wi, c in zip(w, self.self_inhibition))
        max_ce, sum_g = be.launch("layers", w1=w[0], w2=w[1], gate_on=float(gates[0] and not silent[0]),
                                  gate_off=float(gates[1] and not silent[1]), prev_on=before[0], prev_off=before[1])
        self.open_before = gates
        step = self._membrane(sum_g, n_cells, pm_on, pm_off)
        extra = dict(w1=w[0], w2=w[1], gate_on=int(gates[0]), gate_off=int(gates[1]), sum_G=sum_g, max_Ce=max_ce)
        return self._result(t, step, extra)

    def _persistence(self, t: int) -> tuple[float, float]:
        """``(a_1, a_2)`` of ``P``: code ``1 / (1 + e^(t - i))`` of the frame index, paper ``1 / (1 + e^i)``."""
        if self.code:
            return 1.0 / (1.0 + math.exp(min(t - 1, 700))), 1.0 / (1.0 + math.exp(min(t - 2, 700)))
        return 1.0 / (1.0 + math.e), 1.0 / (1.0 + math.e ** 2)

    def _feedforward(self, mean_on: float, mean_off: float) -> tuple[float, float]:
        """``PM_on``, ``PM_off`` from this frame's means of ``P_on``, ``P_off`` (and the state)."""
        a4 = self.a4
        pm_on = a4 * mean_on + (1.0 - a4) * self.pm_on_prev
        if self.code:  # PM_off from the ON mean; the memory is the raw previous mean
            pm_off = a4 * mean_on + (1.0 - a4) * self.pm_off_prev
            self.pm_on_prev, self.pm_off_prev = mean_on, mean_off
        else:
            pm_off = a4 * mean_off + (1.0 - a4) * self.pm_off_prev
            self.pm_on_prev, self.pm_off_prev = pm_on, pm_off
        return pm_on, pm_off

    def _membrane(self, sum_g: float, n_cells: int, pm_on: float, pm_off: float) -> ref.OLGMDStep:
        """Sigmoid, global-change reset, SFA and spikes of this frame (updates the state)."""
        p = self.params
        aim = pm_on + pm_off
        k_raw = 1.0 / (1.0 + math.exp(-sum_g / (n_cells * p.a5)))
        k = 0.5 if aim >= p.aim_base + p.aim_slope * self.aim_prev else k_raw
        if k - self.k1 <= p.tsfa:
            k_cur = self.a6 * (self.k_pre + k - self.k1)
        else:
            k_cur = self.a6 * k
        k_cur = max(k_cur, 0.5)
        s_spike = math.exp(p.a7 * (k_cur - p.t_spi))
        self.spikes.append(s_spike)
        self.aim_prev, self.k1, self.k_pre = aim, k, k_cur
        total = sum(self.spikes)
        return ref.OLGMDStep(k_cur, k_raw, s_spike, total, total >= ref.N_SP, pm_on, pm_off, aim)

    @staticmethod
    def _result(t: int, s: ref.OLGMDStep, extra: dict[str, float]) -> StepResult:
        diag = dict(k_raw=s.k_raw, s_spike=s.s_spike, spike_sum=s.spike_sum, pm_on=s.pm_on, pm_off=s.pm_off,
                    aim=s.aim, **extra)
        return StepResult(t, s.k, bool(s.alert), True, diag)
