"""The event-based looming detector of Schubert, Knight, Philippides and Nowotny (Neuromorphic Computing and
Engineering 5:024016, 2025).

Equations as the authors' PyTorch model computes them (``src/pytorch/looming_detector.py`` of
``FabianSchubert/Bio-Inspired-Event-Based-Looming-Object-Detection-for-Automotive-Collision-Avoidance``;
docs/MODELS.md, "Event-based looming detector"), per bin ``t`` of signed event maps ``X(t)``:

* optic flow per polarity from the maps at ``t - 1`` and ``t`` with Gaussian-derivative kernels,
  ``v^q = -X_q(t) (K_x, K_y) (*) X_q(t-1) dt / (reg + dt^2 K_n (*) X_q(t-1))``, ``v = v^on + v^off``;
* the radial projection ``v_r = v_x w_x + v_y w_y`` (the frame centre the focus of expansion);
* left / right responses ``R_l``, ``R_r``: Gaussian-weighted sums of ``v_r`` over each half;
* ``r = s_out min(R_l, R_r) sigma(a R_l - b) sigma(a R_r - b)``; output ``r - theta`` (``variant="code"``) or
  its leaky integral (``"paper"``, the GeNN model); the alert is ``output > 0``.

It is event-native: on frames it takes the events of the project's emulator (bin ``k`` = the events between
frames ``k - 1`` and ``k``; frame 0 an empty map), on an event recording its bins (the sign of ``p_on - p_off``
per pixel). The float64 oracle is :class:`cdnf_ti.event_looming_reference.EventLoomingReference` (the ``numpy``
backend).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .. import event_looming_reference as ref
from ..events.emulator import EmulatorParams, emulate
from ..params import ModelParams, check_params
from .base import Model, StepResult, Trace
from .reference_backend import ReferenceBackend
from .registry import register_model

#: The emulator's pixel on frames (the kernels model its defaults: no mismatch, refractory period or noise).
EMULATOR = EmulatorParams()


@dataclass(frozen=True)
class EventLoomingParams(ref.EventLoomingParams, ModelParams):
    """Parameters: the constants of :class:`cdnf_ti.event_looming_reference.EventLoomingParams` (lengths in
    px, times in ms; ``None``: the variant's value) and the variant.

    Attributes
    ----------
    variant : {"code", "paper"}
        ``"code"``: the PyTorch model with its untrained defaults (``dt`` 10 ms, ``s_out = a = 1.5``,
        ``b = theta = 0``, output ``r - theta``). ``"paper"``: the GeNN model (``dt`` 1 ms, its fitted
        ``s_out``, ``a``, ``b``; output the leaky integral of ``r`` with ``tau_m``).
    """

    variant: str = "code"

    def __post_init__(self) -> None:
        check_params("EventLoomingParams", [
            (self.variant in ref.VARIANTS, f"variant must be one of {', '.join(ref.VARIANTS)}, got {self.variant!r}"),
            (int(self.kern_half_size) == self.kern_half_size and 1 <= self.kern_half_size < 32,
             f"kern_half_size must be an integer in 1..31, got {self.kern_half_size}"),
            (self.sigm_kern > 0 and self.sigma_pos > 0 and self.reg > 0, "sigm_kern, sigma_pos and reg must be > 0"),
            ((self.dt is None or self.dt > 0) and self.tau_m > 0, "dt and tau_m must be > 0 ms"),
        ])

    def values(self) -> dict[str, float]:
        """``dt``, ``out_scale``, ``sigm_scale``, ``sigm_bias``: given, or the variant's."""
        return {k: float(v if getattr(self, k) is None else getattr(self, k))
                for k, v in ref.VARIANT_DEFAULTS[self.variant].items()}


def logistic(x: float) -> float:
    """``1 / (1 + e^-x)`` (float64; 0 below ``x = -700`` instead of an overflow)."""
    return 1.0 / (1.0 + math.exp(min(-x, 700.0)))


def signed_map(p_on: np.ndarray, p_off: np.ndarray) -> np.ndarray:
    """An event bin's signed map: +1 where ``p_on > p_off``, -1 where ``p_off > p_on``, else 0 (int8, (H, W))."""
    return np.sign(np.asarray(p_on, np.float64) - np.asarray(p_off, np.float64)).astype(np.int8)


def float32_parts(value: float) -> list[float]:
    """A float64 ``value`` as three float32 parts, high first, whose float64 sum is ``value`` exactly."""
    high = float(np.float32(value))
    mid = float(np.float32(value - high))
    return [high, mid, float(np.float32(value - high - mid))]


class _ReferenceBackend(ReferenceBackend):
    """The ``numpy`` backend: the float64 reference, fed by the emulator on frames (at ``fps``), stepped whole."""

    def __init__(self, reference: ref.EventLoomingReference, shape: tuple[int, int], fps: float):
        super().__init__(reference, shape)
        self.fps = fps
        self.reset()

    def reset(self) -> None:
        super().reset()
        self.frames: deque = deque()
        self.events = emulate(self._pending(), self.fps, EMULATOR)

    def _pending(self):
        while self.frames:
            yield self.frames.popleft()

    def load(self, grey: np.ndarray, first: bool) -> ref.EventLoomingStep:
        self.frames.append(grey)
        if first:  # frame 0: no events yet (the emulator reads it with frame 1)
            return self.ref.step(np.zeros(self.shape, np.int8))
        chunk = next(self.events)
        return self.ref.step(next(ref.signed_bins([chunk], self.shape, float("inf"), 0, 1)))

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> ref.EventLoomingStep:
        return self.ref.step(signed_map(p_on, p_off))


@register_model
class EventLooming(Model):
    """Event-based looming detector (Schubert et al. 2025): radial optic flow of ON/OFF events, left and right.

    Parameters
    ----------
    params : EventLoomingParams, optional
    backend : {"taichi", "numpy"}
        The kernels (float32 flow, float64 emulator) or the float64 reference.
    arch : str
    fps : float
        Input frame rate (the emulator's timestamps; the model's ``dt`` is a parameter).

    Notes
    -----
    ``output``: ``r - theta`` (code) or its leaky integral (paper); ``spike``: ``output > 0``. Diagnostics:
    ``left``, ``right`` (``R_l``, ``R_r``), ``r``. :meth:`fields`: ``X`` (signed map), ``vx``, ``vy``, ``v_r``.
    """

    name = "event_looming"
    output_name = "output"
    params_type = EventLoomingParams
    description = "event looming (Schubert et al. 2025): radial flow of ON/OFF events; the authors' PyTorch model"
    kernels = "event_looming"
    panels = (("X", "Signed events X"), ("v_r", "Radial flow v_r"))
    #: Use the fast (lane) layout where it applies; ``False``: the pixel layout (same equations).
    fast: bool = True
    takes_events = True
    #: Bins of a recording are ``dt`` long, as in their sequences (PyTorch ``DT`` 10 ms, GeNN ``DT_MS`` 1 ms).
    event_bin_ms = classmethod(lambda cls, params=None: (params or cls.params_type()).values()["dt"])

    #: The alert is ``output > 0`` (their classification ``outputs > 0``).
    threshold = 0.0
    #: Threshold sweep: the level the output must exceed.
    sweep_parameter = "alert level (output > value)"
    sweep_values = (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)

    @classmethod
    def sweep_default(cls) -> float:
        return cls.threshold

    @classmethod
    def sweep_alerts(cls, trace: Trace, values: Sequence[float]) -> list[np.ndarray]:
        """Alerts per frame at each level (the output does not depend on it)."""
        return [np.asarray(trace.output, dtype=np.float64) > v for v in values]

    def _setup(self) -> None:
        self.values = self.params.values()
        self.alpha = math.exp(-self.values["dt"] / self.params.tau_m)

    def _reset_state(self) -> None:
        self.v = 0.0  # paper: the leaky output

    def _numpy_backend(self, shape: tuple[int, int]) -> ReferenceBackend:
        reference = ref.EventLoomingReference(shape[0], shape[1], self.params.variant, self.params)
        return _ReferenceBackend(reference, shape, self.fps)

    def coefficients(self) -> dict[str, Any]:
        """The emulator's thresholds and ``eps`` and the log levels of uint8 frames (float64, as three float32 parts
        each), ``dt``, ``reg``, ``sigma_pos`` and the taps: the 1-D factors ``g`` and ``x g`` of the flow kernels
        (``K_n = g g^T``)."""
        p, e = self.params, EMULATOR
        g = ref.flow_kernels(int(p.kern_half_size), p.sigm_kern)[0].sum(axis=0)
        x = np.arange(-p.kern_half_size, p.kern_half_size + 1)
        table = np.log(np.arange(256) / 255.0 + e.log_eps)  # the emulator's levels of uint8 frames
        return dict(emulator=float32_parts(e.threshold_on) + float32_parts(e.threshold_off) + float32_parts(e.log_eps),
                    levels=[part for v in table for part in float32_parts(float(v))],
                    dt=self.values["dt"], reg=p.reg, sigma_pos=p.sigma_pos, taps=np.concatenate([g, x * g]))

    def kernel_options(self) -> dict:
        """The flow kernels' radius (compile-time: the taps unroll)."""
        return {"radius": int(self.params.kern_half_size)}

    def borders(self) -> dict[str, str]:
        """Zero padding of the correlations (PyTorch ``Conv2d``): the maps and the row passes."""
        return {name: "zero" for name in ("X", "_NP", "_XP", "_NN", "_XN")}

    def _step(self, t: int, grey: np.ndarray | None, loaded: Any) -> StepResult:
        if isinstance(loaded, ref.EventLoomingStep):  # the numpy backend stepped the reference
            return StepResult(t, loaded.output, loaded.alert, True,
                              dict(left=loaded.left, right=loaded.right, r=loaded.r))
        be = self._be
        if t == 0:
            be.launch("setup", width=float(be.shape[1]), height=float(be.shape[0]), half=float(be.shape[1] // 2))
        be.flip()  # this bin's map goes to X.now, the last one's is X.before
        levels = 255.0 if grey is not None and grey.dtype == np.uint8 else 1.0
        left, right = be.launch("step", levels=levels, first=float(grey is not None and t == 0))
        return self._output(t, left, right)

    def _output(self, t: int, left: float, right: float) -> StepResult:
        """``r`` from ``R_l``, ``R_r`` and the variant's output and alert (updates the leaky output)."""
        a, b = self.values["sigm_scale"], self.values["sigm_bias"]
        r = self.values["out_scale"] * min(left, right) * logistic(a * left - b) * logistic(a * right - b)
        if self.params.variant == "code":
            out = r - self.params.out_th
        else:
            self.v = self.alpha * self.v + (1.0 - self.alpha) * r
            out = self.v
        return StepResult(t, out, out > 0.0, True, dict(left=left, right=right, r=r))
