"""LGMD_P_ON_OFF: motion and contrast vision side by side in the ON and OFF channels (Fu, Li, Peng,
*Harmonizing motion and contrast vision for robust looming detection*, Array 17:100272, 2023).

Equations as the authors' Python computes them (``Harmonizing motion and contrast vision.py`` of
``fuqinbing/harmonizing-motion-and-contrast-vision-for-looming-detection``; docs/MODELS.md,
"LGMD_P_ON_OFF"), per frame ``t`` (grey levels 0..255):

* ``P = L(t) - L(t-1)``, ``P_on = [P]^+``, ``P_off = [-P]^+`` (an event bin: ``255 p_on``, ``255 p_off``);
* ``E_x = tanh(P_x / (Mhat_x + alpha_1))``, ``Mhat_x`` the 9x9 Gaussian (sigma 5 px) of ``P_x``;
* contrast ``C_x = |K_C * E_x|``; motion ``S_x = E_x - beta K_I * E_x(t-1)``;
  ``S_x_out = [alpha S_x - alpha' C_x]^+``; ``S = S_on_out + S_off_out + S_on_out S_off_out``;
* ``Ce`` the 3x3 mean of ``S``; ``G = S Ce / (max Ce / 4 + 0.01)``, zero where ``0.5 G < 0.7``;
* ``mp = 1 / (1 + exp(-sum G / (0.1 N)))``; the alert (ours, their code has none): ``mp >= 0.9``.

The stages are ``kernels/lgmd_p_on_off.py``; the float64 oracle is
:class:`cdnf_ti.lgmd_p_on_off_reference.LGMDPOnOffReference` (the ``numpy`` backend). Their ``mp[t]``
is our output at frame ``t``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import cv2
import numpy as np

from .. import lgmd_p_on_off_reference as ref
from ..alert_rule import AlertRule
from ..errors import UserError
from ..params import ModelParams, check_params, gaussian_profile
from .base import Model, StepResult, Trace
from .reference_backend import ReferenceBackend
from .registry import register_model


@dataclass(frozen=True)
class LGMDPOnOffParams(ref.LGMDPOnOffParams, ModelParams):
    """LGMD_P_ON_OFF parameters: the constants of :class:`cdnf_ti.lgmd_p_on_off_reference.LGMDPOnOffParams`
    (the authors' names; grey levels 0..255, lengths in px) and the variant.

    Attributes
    ----------
    variant : {"code", "paper"}
        ``"code"``: the authors' Python (colour frames made grey with ``COLOR_RGB2GRAY`` on BGR; output 0
        at frame 0). ``"paper"``: ``COLOR_BGR2GRAY``, output 0.5 (the resting sigmoid) at frame 0.
    """

    variant: str = "code"

    def __post_init__(self) -> None:
        check_params("LGMDPOnOffParams", [
            (self.variant in ref.VARIANTS, f"variant must be one of {', '.join(ref.VARIANTS)}, got {self.variant!r}"),
            (int(self.gauss_size) == self.gauss_size and self.gauss_size % 2 == 1 and 1 <= self.gauss_size <= 31,
             f"gauss_size must be an odd integer in 1..31, got {self.gauss_size}"),
            (self.gauss_sigma > 0, f"gauss_sigma must be > 0, got {self.gauss_sigma}"),
            (self.alpha_1 > 0, f"alpha_1 must be > 0, got {self.alpha_1}"),
            (self.c_w > 0 and self.delta_c > 0, "c_w and delta_c must be > 0"),
            (self.sigmoid_scale > 0, f"sigmoid_scale must be > 0, got {self.sigmoid_scale}"),
        ])

    @property
    def radius(self) -> int:
        """The normalisation Gaussian's radius (px)."""
        return int(self.gauss_size) // 2


@register_model
class LGMDPOnOff(Model):
    """LGMD_P_ON_OFF collision detector (Fu, Li, Peng 2023): motion and contrast pathways in ON/OFF channels.

    Parameters
    ----------
    params : LGMDPOnOffParams, optional
    backend : {"taichi", "numpy"}
        The kernels (float32 layers) or the float64 reference.
    arch : str
    fps : float
        Input frame rate (the model has no time constants).

    Notes
    -----
    ``output`` is the membrane potential ``mp`` in (0.5, 1) (0 or 0.5 at frame 0, see ``variant``);
    ``spike`` the alert ``mp >= threshold``. Diagnostics: ``sum_G``, ``max_Ce``. :meth:`fields`:
    ``L, ON, OFF, E_on, E_off, S, Ce, G`` (the ``numpy`` backend: ``P, E_on, E_off, S_on, S_off, S, Ce, G``).
    """

    name = "lgmd_p_on_off"
    output_name = "mp"
    params_type = LGMDPOnOffParams
    description = ("LGMD_P_ON_OFF (Fu, Li, Peng 2023): motion and contrast vision in ON/OFF channels; "
                   "equations from the authors' Python")
    kernels = "lgmd_p_on_off"
    panels = (("E_on", "Normalised ON E_on"), ("E_off", "Normalised OFF E_off"), ("S", "Summation S"),
              ("G", "Grouping G"))
    #: Use the fast (lane) layout where it applies; ``False``: the pixel layout (same equations).
    fast: bool = True
    takes_events = True

    #: Threshold sweep: the level of ``mp`` at which the alert fires.
    sweep_parameter = "threshold (alert while mp >= value)"
    sweep_values = tuple(round(0.5 + 0.025 * i, 3) for i in range(21))

    @classmethod
    def sweep_default(cls) -> float:
        return float(cls.params_type().threshold)

    @classmethod
    def sweep_alerts(cls, trace: Trace, values: Sequence[float]) -> list[np.ndarray]:
        """Alerts per frame at each level (``mp`` does not depend on it)."""
        mp = np.asarray(trace.output, dtype=np.float64)
        return [mp >= v for v in values]

    @property
    def threshold(self) -> float:
        return float(self.params.threshold)

    def alert_rule(self) -> AlertRule:
        """``mp >= threshold`` (ours: the authors' code stops at ``mp``)."""
        return AlertRule(f"mp >= {self.threshold:.4g}", "mp", "mp", self.threshold)

    def _setup(self) -> None:
        self.code = self.params.variant == "code"

    def _numpy_backend(self, shape: tuple[int, int]) -> ReferenceBackend:
        """The float64 :class:`~cdnf_ti.lgmd_p_on_off_reference.LGMDPOnOffReference`, stepped whole."""
        return ReferenceBackend(ref.LGMDPOnOffReference(shape[0], shape[1], self.params.variant, self.params), shape)

    def _init_backend(self, backend: Any) -> None:
        """Frames must be at least as large as the normalisation Gaussian (its reflect border)."""
        side = max(int(self.params.gauss_size), 3)
        if min(backend.shape) < side:
            raise UserError(f"frame must be at least {side}x{side} px, "
                            f"got {backend.shape[1]}x{backend.shape[0]}")

    def coefficients(self) -> dict[str, Any]:
        """The stages' coefficients by name (``kernels/lgmd_p_on_off.py``): ``K_I`` as (centre, edge, diagonal),
        the channels' gains, ``theta``, the grouping's constants and the normalised Gaussian taps."""
        p = self.params
        k_i = ref.inhibition_kernel(p.basic_weight)
        taps = gaussian_profile(p.gauss_sigma, p.radius)
        return dict(alpha_1=p.alpha_1, beta=p.beta, k_i=(k_i[1, 1], k_i[0, 1], k_i[0, 0]),
                    gains=(p.alpha_2, p.alpha_3, p.alpha_4, p.alpha_5), theta=(p.theta_1, p.theta_2, p.theta_3),
                    c_w=p.c_w, delta_c=p.delta_c, c_de=p.c_de, t_de=p.t_de, taps=taps / taps.sum())

    def kernel_options(self) -> dict[str, int]:
        """The Gaussian's radius (compile-time: its taps unroll)."""
        return {"radius": self.params.radius}

    def borders(self) -> dict[str, str]:
        """Reflect-101 (OpenCV's default) on every plane a stage reads off its cell."""
        return {name: "reflect" for name in ("ON", "OFF", "_RON", "_ROFF", "E_on", "E_off", "S")}

    def _prepare(self, frame: np.ndarray) -> np.ndarray:
        """``variant="code"`` makes BGR uint8 frames grey with ``COLOR_RGB2GRAY``, as the authors' code."""
        f = np.asarray(frame)
        if self.code and f.ndim == 3 and f.shape[2] == 3 and f.dtype == np.uint8:
            frame = cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_RGB2GRAY)
        return super()._prepare(frame)

    def _step(self, t: int, grey: np.ndarray | None, loaded: Any) -> StepResult:
        p = self.params
        if isinstance(loaded, ref.LGMDPOnOffStep):  # the numpy backend stepped the reference
            mp, sum_g, max_ce = loaded.mp, loaded.sum_g, loaded.max_ce
        else:
            be = self._be
            be.flip()  # E(t) goes to the older buffers
            frame = grey is not None
            scale = 1.0 if frame and grey.dtype == np.uint8 else 255.0
            max_ce, sum_g = be.launch("frame", scale=scale, keep=float(t > 0 or not frame))
            mp = 1.0 / (1.0 + math.exp(-sum_g / (be.shape[0] * be.shape[1] * p.sigmoid_scale)))
            if frame and t == 0:  # frame 0 only stores its grey levels
                mp, sum_g, max_ce = (0.0 if self.code else 0.5), 0.0, 0.0
        return StepResult(t, mp, bool(mp >= p.threshold), True, dict(sum_G=sum_g, max_Ce=max_ce))
