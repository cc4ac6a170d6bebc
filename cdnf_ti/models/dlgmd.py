"""D-LGMD: an LGMD with spatially-temporally distributed presynaptic connections (Zhao, Wang, Yue et al.,
IEEE TNNLS 34, 2023).

Equations as the authors' MATLAB computes them (``D_LGMD.m`` and ``Compare with SFA/DLGMD_SFA.m`` of
``cquzjn/D-LGMD``; docs/MODELS.md, "D-LGMD"), per frame ``t`` with luminance differences
``D(t) = |L(t) - L(t-1)|`` (an event bin: ``D = p_on + p_off``):

* ``E = K_E * D(t)``, ``I = K_1 * D(t-1) + K_2 * D(t-2)`` over a radius-6 grid whose delay map gives
  the excitation (delay 0: the centre and its 4 neighbours), a delay-1 ring and a delay-2 surround;
* ``S = [E - I]^+``; ``G = S (ones(4, 4) * S)``, zero below ``T_G = min(0.3, 0.5 sum D(t-2) / 200000)``,
  clipped at 1;
* ``k = sigmoid(sum G / (0.6 n))``, ``n = 0.1625 N``; from the fifth difference on,
  ``mp = 0.8 k`` after a rise of ``k`` by 0.01 or more, else ``mp = 0.8 mp(t-1) + 0.8 (k - k(t-1))``;
  the alert ``mp >= 0.6`` is ours.

The first three frames (three differences) give no output. The float64 oracle is
:class:`cdnf_ti.dlgmd_reference.DLGMDReference` (the ``numpy`` backend).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .. import dlgmd_reference as ref
from ..alert_rule import AlertRule
from ..params import ModelParams, check_params
from .base import Model, StepResult, Trace
from .reference_backend import ReferenceBackend
from .registry import register_model

#: The largest kernel radius the compiled stages take (their row-pass planes, ``kernels/dlgmd.py``).
MAX_RADIUS = 8


@dataclass(frozen=True)
class DLGMDParams(ref.DLGMDParams, ModelParams):
    """D-LGMD parameters: the constants of :class:`cdnf_ti.dlgmd_reference.DLGMDParams` (the authors' names;
    lengths in px, luminance in [0, 1]), checked."""

    def __post_init__(self) -> None:
        check_params("DLGMDParams", [
            (self.sigma_e > 0 and self.sigma_i > 0, "sigma_e and sigma_i must be > 0 px"),
            (int(self.r) == self.r and 1 <= self.r <= MAX_RADIUS, f"r must be an integer in 1..{MAX_RADIUS}"),
            (int(self.group_side) == self.group_side and 1 <= self.group_side <= 2 * MAX_RADIUS,
             f"group_side must be an integer in 1..{2 * MAX_RADIUS}"),
            (self.k_spread > 0 and self.k_norm_per_pixel > 0, "k_spread and k_norm_per_pixel must be > 0"),
            (math.isfinite(self.threshold), f"threshold must be finite, got {self.threshold}"),
        ])


@register_model
class DLGMD(Model):
    """D-LGMD collision detector (Zhao et al. 2023): distributed excitation and delayed inhibition.

    Parameters
    ----------
    params : DLGMDParams, optional
    backend : {"taichi", "numpy"}
        The kernels (float32 layers) or the float64 reference.
    arch : str
    fps : float
        Input frame rate (unused: the model counts frames).

    Notes
    -----
    ``output`` is the membrane ``mp`` after spike-frequency adaptation; ``spike`` the alert ``mp >= 0.6``.
    Diagnostics: ``g_sum`` (their ``LGMD_OutputG``), ``s_sum``, ``ffi``, ``thresh_g``, ``k``.
    :meth:`fields`: ``D, E, I, S, G`` (the ``numpy`` backend: ``E, I, S, G``).
    """

    name = "dlgmd"
    output_name = "mp"
    params_type = DLGMDParams
    description = ("D-LGMD (Zhao et al. 2023): distributed excitation and delayed inhibition of radius 6; "
                   "equations from the authors' MATLAB")
    takes_events = True

    #: The stages (``kernels/dlgmd.py``) and the fields ``render`` shows.
    kernels = "dlgmd"
    panels = (("D", "Difference D"), ("S", "Summation S"), ("G", "Grouping G"))
    #: Use the fast (lane) layout where it applies; ``False``: the pixel layout (same equations).
    fast: bool = True

    #: Threshold sweep: the level of ``mp`` at which the alert fires (replayed from the output).
    sweep_parameter = "threshold (alert while mp >= value)"
    sweep_values = tuple(round(0.40 + 0.02 * i, 2) for i in range(21))

    @classmethod
    def sweep_default(cls) -> float:
        return float(cls.params_type().threshold)

    @classmethod
    def sweep_alerts(cls, trace: Trace, values: Sequence[float]) -> list[np.ndarray]:
        """Alerts per frame at each level (``mp`` does not depend on it; none before the fifth difference,
        where ``mp`` is 0)."""
        out = np.asarray(trace.output, dtype=np.float64)
        return [(out >= v) & (out > 0) for v in values]

    @property
    def threshold(self) -> float:
        return float(self.params.threshold)

    def alert_rule(self) -> AlertRule:
        """``mp >= threshold`` (not strict)."""
        return AlertRule(f"mp >= {self.threshold:.4g}", "mp", "mp", self.threshold)

    def _reset_state(self) -> None:
        self.recent: deque[float] = deque(maxlen=2)  # sum D of the last two differences
        self.n_diff = 0  # differences so far
        self.k_prev, self.mp = 0.5, 0.0

    def _numpy_backend(self, shape: tuple[int, int]) -> ReferenceBackend:
        """The float64 :class:`~cdnf_ti.dlgmd_reference.DLGMDReference`, stepped whole."""
        return ReferenceBackend(ref.DLGMDReference(shape[0], shape[1], self.params), shape)

    def _delay_map(self) -> tuple[np.ndarray, tuple, np.ndarray]:
        """``K_E``, the delay-0 cells (grid indices, row-major) and the delay-2 mask, each of the (2r+1)^2 grid
        of the authors' kernels (:func:`~cdnf_ti.dlgmd_reference.dlgmd_kernels`)."""
        k_e, k_1, k_2 = ref.dlgmd_kernels(self.params)
        return k_e, tuple(zip(*np.nonzero((k_1 == 0) & (k_2 == 0)))), k_2 > 0

    def _taps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(e, c e, K_E, N)``: the separable factors of ``a G(sigma_I)`` (``e(0 .. r)``, ``c e(-r .. r)``), and
        ``K_E`` and ``a G(sigma_I)`` on the delay-0 cells (in the order of :meth:`kernel_options`' ``cells``)."""
        p = self.params
        x = np.arange(-p.r, p.r + 1, dtype=np.float64)
        e = np.exp(-x * x / (2.0 * p.sigma_i ** 2))
        k_e, cells, _ = self._delay_map()
        c = p.a / (p.sigma_i * math.sqrt(2.0 * math.pi))
        near = c * np.outer(e, e)
        return e[p.r:], c * e, np.array([k_e[q] for q in cells]), np.array([near[q] for q in cells])

    def coefficients(self) -> dict[str, Any]:
        """The stages' ``taps``: ``e(0 .. r)``, ``c e(-r .. r)``, then ``K_E`` and ``N`` of the delay-0 cells."""
        return {"taps": np.concatenate(self._taps()).astype(np.float32)}

    def kernel_options(self) -> dict[str, Any]:
        """The kernels' shape (compile-time): radius, the disc's row half-widths, the delay-0 cells, the
        grouping window (MATLAB ``'same'``: ``lo = -floor((side - 1) / 2)``)."""
        p = self.params
        _, cells, far = self._delay_map()
        disc = tuple(int(np.count_nonzero(~row)) // 2 if not row.all() else -1 for row in far)
        lo = -((p.group_side - 1) // 2)
        hi = lo + p.group_side - 1
        return dict(radius=int(p.r), disc=disc, cells=tuple((int(i) - p.r, int(j) - p.r) for i, j in cells),
                    group=(lo, hi), group_halo=max(-lo, hi, 1),
                    store=tuple(w == p.r or w in disc for w in range(p.r + 1)))

    def borders(self) -> dict[str, str]:
        """Zero outside the frame for every plane read at an offset (MATLAB ``conv2(.., 'same')``)."""
        return {name: "zero" for name in ("D", "S", "_T", *(f"_R{w}" for w in range(self.params.r + 1)))}

    def _step(self, t: int, grey: np.ndarray | None, loaded: Any) -> StepResult:
        if isinstance(loaded, ref.DLGMDStep):  # the numpy backend stepped the reference
            return self._result(t, loaded)
        p, be = self.params, self._be
        differs = grey is None or t > 0  # an event bin is a difference; the first frame has none
        ffi = self.recent[0] if len(self.recent) == 2 else 0.0  # sum D(t-2)
        thresh_g = min(p.thresh_g0 * ffi * p.ffi_scale, p.thresh_g_max)
        scale = 1.0 if grey is None or grey.dtype == np.uint8 else 255.0
        sum_d, sum_s, sum_g = be.launch("frame", scale=scale, keep=float(differs), thresh_g=thresh_g)
        if differs:
            self.n_diff += 1
            self.recent.append(sum_d)
        if self.n_diff < ref.WARMUP:
            return self._result(t, ref.DLGMDStep(0.0, 0.0, 0.0, 0.0, 0.5, 0.0, False))
        k = 1.0 / (1.0 + math.exp(-sum_g / (p.k_spread * p.k_norm_per_pixel * be.shape[0] * be.shape[1])))
        if self.n_diff >= ref.SFA_START:
            dk = k - self.k_prev
            self.mp = p.sfa_gain * k if dk >= p.sfa_rise else p.sfa_gain * (self.mp + dk)
        self.k_prev = k
        alert = self.n_diff >= ref.SFA_START and self.mp >= p.threshold
        return self._result(t, ref.DLGMDStep(sum_g, sum_s, ffi, thresh_g, k, self.mp, alert))

    @staticmethod
    def _result(t: int, s: ref.DLGMDStep) -> StepResult:
        diag = dict(g_sum=s.g_sum, s_sum=s.s_sum, ffi=s.ffi, thresh_g=s.thresh_g, k=s.k)
        return StepResult(t, s.mp, bool(s.alert), True, diag)
