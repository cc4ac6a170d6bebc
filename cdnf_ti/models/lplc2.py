"""EMD-LPLC2-GF: a fly-inspired looming detector (Zhao, Xi, Li, Guo, Wu et al., iScience 26(4):106337, 2023).

Equations as the authors' MATLAB computes them (``zhaojunyu01/EMD-LPLC2-GF-model``, ``code/2_...``:
``emd.m``, ``OnRect.m``, ``OffRect.m``, ``lplc2conv2.m``, ``GF.m``, ``LIF.m``; docs/MODELS.md). Per frame
``t`` (luminance ``L`` in [0, 1], ``dt = 1 / fps`` s; theirs is 10 ms):

* photoreceptor high-pass ``F_h = b (L(t) - L(t-1)) + b F_h(t-1)``, ``b = d / (d + 1)``, ``d = tau_h / dt``;
* ``ON = [F_h]^+``, ``OFF = [0.05 - F_h]^+``; delay ``F_d = a X + (1 - a) F_d(t-1)``, ``a = 1 / (tau_l / dt + 1)``;
* Hassenstein-Reichardt detectors between neighbours (ON and OFF summed) on the (H-1, W-1) grid;
* one LPLC2 unit per grid point with four radial-opponent half-plane arms (outward motion minus inward,
  a 40 x 50 px half of a 100 px receptive field each), each kept where ``> 2``; the unit's response is the
  product of its four arms (so it needs outward motion on all four sides: expansion);
* giant fibre: ``n`` = active units / 2500, ``v = (n(t) - n(t-1)) / 0.576``, input ``I = 250 n v``
  (0 while ``n(t-1) = 0``); LIF ``0.3 dV/dt = -V - 60 + 10 I`` in 20 RK4 substeps per frame, held at
  -80 mV at or below it; a substep above -50 mV is a spike and resets V to -70 mV.

``variant="real"``: the unit rule of the authors' robot and real-environment folders 5-7 (a unit counts where at
least 3 of its 4 arms exceed 1.5 and each exceeds -2; its response is ``|product|``) and folder 7's input: the
green channel of a uint8 BGR frame (else the grey frame), shrunk to a quarter as MATLAB's ``imresize(.., 0.25)``.

The per-pixel stages run on the engine (:mod:`cdnf_ti.kernels.lplc2`); the giant fibre is here. The
float64 oracle (shares no code with the engine): :class:`cdnf_ti.lplc2_reference.LPLC2Reference`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..alert_rule import AlertRule
from ..errors import UserError
from ..frames import to_grey
from ..lplc2_reference import NumpyLPLC2Backend
from ..params import ModelParams, check_params
from .base import Model, StepResult, Trace
from .registry import register_model

#: The unit rule of each variant (the kernels' coefficients): an arm is kept above ``arm_t``, a unit needs
#: ``min_arms`` arms above ``strong_t``; ``real``: ``threshold_2``, ``threshold_1`` of folders 5-7's ``lplc2conv2.m``.
REAL_RULE = dict(arm_t=-2.0, strong_t=1.5, min_arms=3)
#: ``variant="real"``: frames shrink by this factor (folder 7's ``imresize(movieData, 0.25)``).
REAL_SCALE = 0.25


@dataclass(frozen=True)
class LPLC2Params(ModelParams):
    """EMD-LPLC2-GF parameters (defaults: the authors' MATLAB; times in s, potentials in mV).

    Attributes
    ----------
    tau_h, tau_l : float
        High-pass (0.25 s) and delay low-pass (0.05 s) time constants.
    on_threshold, off_threshold : float
        ``ON = [F_h - on_threshold]^+`` (0), ``OFF = [off_threshold - F_h]^+`` (0.05).
    half_side : int
        Half side of an LPLC2 receptive field (px, 50): an arm reaches this far out from its unit.
    band_before, band_after : int
        An arm spans the centre - band_before .. centre + band_after across its direction (19, 20 px).
    arm_threshold : float
        An arm counts only where above this (2.0).
    normal_count, normal_velocity : float
        ``n`` = active units / normal_count (2500); ``v = (n(t) - n(t-1)) / normal_velocity`` (0.576).
    w : float
        Giant-fibre input gain (250).
    v_rest, v_threshold, v_reset, v_floor, v_spike : float
        LIF rest (-60), spike threshold (-50), reset (-70), floor (-80), value recorded for a spike (20).
    resistance, tau_m : float
        Membrane resistance (10) and time constant (0.3 s).
    substeps : int
        RK4 substeps per frame (20).
    variant : {"arena", "real"}
        The unit rule and input of the authors' folders: ``"arena"`` (2-4: four arms above ``arm_threshold``,
        the frame as it is) or ``"real"`` (5-7: :data:`REAL_RULE`, ``arm_threshold`` unused; folder 7's green
        channel and quarter-size frames).
    """

    tau_h: float = 0.250
    tau_l: float = 0.050
    on_threshold: float = 0.0
    off_threshold: float = 0.05
    half_side: int = 50
    band_before: int = 19
    band_after: int = 20
    arm_threshold: float = 2.0
    normal_count: float = 2500.0
    normal_velocity: float = (2116.0 - 676.0) / 2500.0
    w: float = 250.0
    v_rest: float = -60.0
    v_threshold: float = -50.0
    v_reset: float = -70.0
    v_floor: float = -80.0
    v_spike: float = 20.0
    resistance: float = 10.0
    tau_m: float = 0.30
    substeps: int = 20
    variant: str = "arena"

    def __post_init__(self) -> None:
        check_params("LPLC2Params", [
            (self.tau_h > 0 and self.tau_l > 0, f"tau_h and tau_l must be > 0 s, got {self.tau_h}, {self.tau_l}"),
            *[(int(v) == v >= 1, f"{k} must be a positive integer, got {v}")
              for k, v in (("half_side", self.half_side), ("substeps", self.substeps))],
            (all(int(b) == b and b >= 0 for b in (self.band_before, self.band_after)),
             "band_before and band_after must be integers >= 0"),
            (self.normal_count > 0 and self.normal_velocity > 0, "normal_count and normal_velocity must be > 0"),
            (self.tau_m > 0, f"tau_m must be > 0 s, got {self.tau_m}"),
            (self.v_floor < self.v_reset < self.v_threshold, "need v_floor < v_reset < v_threshold"),
            (self.variant in ("arena", "real"), f"variant must be arena or real, got {self.variant!r}"),
        ])


@register_model
class LPLC2(Model):
    """EMD-LPLC2 array with a giant-fibre LIF output (Zhao et al. 2023).

    Parameters
    ----------
    params : LPLC2Params, optional
    backend : {"taichi", "numpy"}
    arch : str
    fps : float
        Input frame rate; ``dt = 1 / fps`` s (the authors' stimuli: 100 frames/s).

    Notes
    -----
    ``output`` is the giant-fibre membrane ``V`` (mV) at the end of the frame; ``spike`` the alert (a GF
    spike in one of the frame's substeps). Diagnostics: ``spikes`` (in the frame), ``active`` (LPLC2
    units responding), ``current`` (GF input), ``core`` (the centre unit's response) and its four arms
    ``arm_left``, ``arm_right``, ``arm_up``, ``arm_down`` (the per-direction activity), ``dt`` (s, for
    the threshold sweep's replay of the GF), ``V_peak`` (the highest V of the frame's substeps, before a
    spike's reset: how close the frame came to ``v_threshold``). :meth:`fields`:
    ``horizontal``, ``vertical`` (opponent motion), ``left``, ``right``, ``up``, ``down`` (thresholded
    arms), ``lplc2`` (responses), on the (H-1, W-1) unit grid padded to (H, W) with zeros; ``variant="real"``
    runs at the shrunk size (H, W) = (ceil(H_in / 4), ceil(W_in / 4)), so its fields are that size too.
    Frame 0 only stores the picture (membrane at rest). The model has no ``threshold`` on its output:
    a substep above ``v_threshold`` spikes and resets, so the frame-end ``V`` never exceeds it.
    """

    name, order, output_name, params_type = "lplc2", 6, "V", LPLC2Params
    panels = (("horizontal", "EMD left - right"), ("vertical", "EMD up - down"), ("lplc2", "LPLC2 response"))
    #: The stages (``kernels/lplc2.py``); ``fast``: the lane layout where it applies (False: the pixel layout).
    kernels, fast = "lplc2", True
    description = "EMD-LPLC2 array with a giant-fibre LIF (Zhao et al. 2023); equations from the authors' MATLAB"

    #: Threshold sweep (:class:`~cdnf_ti.models.base.Sweepable`): the GF spike threshold.
    sweep_parameter, sweep_values = "v_threshold (GF spike threshold, mV)", tuple(float(v) for v in range(-58, -39))
    sweep_default = classmethod(lambda cls: float(cls.params_type().v_threshold))

    @classmethod
    def sweep_alerts(cls, trace: Trace, values: Sequence[float]) -> list[np.ndarray]:
        """Alerts per frame at each spike threshold: the GF replayed on the saved input ``current`` and
        frame interval ``dt`` (the LPLC2 array does not depend on the threshold), the other GF
        parameters at their defaults."""
        current, dt = trace.diagnostics["current"], trace.diagnostics["dt"]
        out = []
        for value in values:
            p = cls.params_type(v_threshold=float(value))
            v, alerts = p.v_rest, np.zeros(trace.n_frames, bool)
            for t in range(1, trace.n_frames):  # frame 0 only stores the picture
                v, spikes, _ = gf_frame(v, float(current[t]), float(dt[t]), p)
                alerts[t] = spikes > 0
            out.append(alerts)
        return out

    def alert_rule(self) -> AlertRule:
        """A giant-fibre spike: ``V > v_threshold`` in a substep, compared on ``V_peak`` (V before the reset)."""
        thr = float(self.params.v_threshold)
        return AlertRule(f"V > {thr:g} mV in a substep (a GF spike)", "V before reset", "V_peak", thr, strict=True)

    #: The frames it takes (:meth:`~cdnf_ti.models.base.Model.frame_colour`): ``"bgr"`` for ``variant="real"``
    #: (folder 7 reads the green channel), else ``"grey"``.
    frame_colour = classmethod(lambda cls, params=None: "bgr" if getattr(params, "variant", "") == "real" else "grey")

    def _numpy_backend(self, shape: tuple[int, int]) -> NumpyLPLC2Backend:
        if self.params.variant != "arena":  # the float64 real variant: LPLC2Reference(variant="real")
            raise UserError("lplc2: --backend numpy runs variant=arena only (not variant=real)")
        return NumpyLPLC2Backend(self.params, shape, self.fps)

    def _prepare(self, frame: np.ndarray) -> np.ndarray:
        """``variant="real"``: folder 7's input, the green channel of a uint8 BGR frame (else :func:`to_grey`)
        in [0, 1], shrunk by :func:`imresize_matrix` to (ceil(H / 4), ceil(W / 4)) (float32); the backend is built
        at that size. ``"arena"``: the grey frame as it is."""
        if self.params.variant == "arena":
            return super()._prepare(frame)
        f = np.asarray(frame)
        grey = f[:, :, 1] if f.ndim == 3 and f.shape[2] == 3 and f.dtype == np.uint8 else to_grey(f)
        if self._be is None:  # the backend at the shrunk size
            self._shrink = [imresize_matrix(n, REAL_SCALE) for n in grey.shape]
            self._make_backend(tuple(m.shape[0] for m in self._shrink), np.dtype(np.float32))
        rows, cols = self._shrink
        if grey.shape != (rows.shape[1], cols.shape[1]):
            raise ValueError(f"frame {self._t} is {grey.shape[1]}x{grey.shape[0]}, not {cols.shape[1]}x{rows.shape[1]}")
        return (rows @ (grey / 255.0 if grey.dtype == np.uint8 else grey) @ cols.T).astype(np.float32)

    def _taichi_backend(self, shape: tuple[int, int]):
        self.shape = tuple(shape)  # coefficients() places the unit grid and its centre unit
        return super()._taichi_backend(shape)

    def coefficients(self) -> dict[str, float | tuple[int, int]]:
        """The stages' coefficients by name: the filters' ``b = d_h / (d_h + 1)``, ``a = 1 / (d_l + 1)``
        (``d = tau / dt``), the thresholds, the variant's unit rule (arena: four arms above ``arm_threshold``,
        whose ``|product|`` is the product), the unit grid (H-1, W-1) and its centre unit."""
        p, dt = self.params, 1.0 / float(self.fps)
        d_h, d_l = p.tau_h / dt, p.tau_l / dt
        rule = REAL_RULE if p.variant == "real" else dict(arm_t=p.arm_threshold, strong_t=p.arm_threshold, min_arms=4)
        return dict(b_high=d_h / (d_h + 1.0), a_low=1.0 / (d_l + 1.0), on_t=p.on_threshold, off_t=p.off_threshold,
                    grid=(self.shape[0] - 1, self.shape[1] - 1), core=core_unit(self.shape), **rule)

    def kernel_options(self) -> dict[str, int]:
        """The arms' window geometry (px), compiled in; ``reach``: the farthest column a row window's prefix sums read
        (the column before the window and its last one)."""
        half, before, after = int(self.params.half_side), int(self.params.band_before), int(self.params.band_after)
        return dict(half=half, before=before, after=after, reach=max(half, before + 1, after))

    def borders(self) -> dict[str, str]:
        """The motion maps and their column passes count zero outside the grid."""
        return dict.fromkeys("horizontal vertical _h_band _up_cols _down_cols _hor_end _hor_start _ver_end _ver_start"
                             .split(), "zero")

    def _reset_state(self) -> None:
        self.v, self.active_prev = self.params.v_rest, None  # active_prev: the last frame's active units

    def _step(self, t: int, grey: np.ndarray, loaded: None) -> StepResult:
        engine = not isinstance(self._be, NumpyLPLC2Backend)  # the reference loaded the frame already
        scale = dict(denom=255.0 if grey.dtype == np.uint8 else 1.0)
        if t == 0:
            if engine:
                self._be.launch("store", **scale)
            return StepResult(t, self.v, False, True, self._diagnostics(0, 0, 0.0, 0.0, (0.0,) * 4, self.v))
        if engine:
            active, core, *arms = self._be.launch("frame", **scale)
            active = int(round(active))
        else:
            active, core, arms = self._be.pool()
        current = self._gf_input(active)
        self.active_prev = active
        self.v, spikes, v_peak = gf_frame(self.v, current, 1.0 / self.fps, self.params)
        return StepResult(t, self.v, spikes > 0, True, self._diagnostics(spikes, active, current, core, arms, v_peak))

    def _gf_input(self, active: int) -> float:
        """``I = w n(t) v(t)``, ``v = (n(t) - n(t-1)) / normal_velocity``; 0 while ``n(t-1) = 0`` (or unknown)."""
        p = self.params
        n = active / p.normal_count
        n_prev = n if self.active_prev is None else self.active_prev / p.normal_count
        return 0.0 if n_prev == 0 else p.w * n * (n - n_prev) / p.normal_velocity

    def _diagnostics(self, spikes: int, active: int, current: float, core: float, arms: tuple, v_peak: float) -> dict:
        return dict(spikes=spikes, active=active, current=current, core=core, dt=1.0 / self.fps, V_peak=v_peak,
                    **dict(zip(("arm_left", "arm_right", "arm_up", "arm_down"), arms)))


def imresize_matrix(n: int, scale: float) -> np.ndarray:
    """MATLAB's ``imresize`` by ``scale`` < 1 along an axis of ``n`` px as a matrix, shape (ceil(scale n), n), float64.

    Output pixel ``u`` (0-based) sits at input coordinate ``x = (u + 1/2) / scale - 1/2``; its weights are the
    antialiased bicubic kernel (Keys, a = -0.5, stretched by ``1 / scale``) at the taps
    ``floor(x - 2 / scale) + 0 .. ceil(4 / scale) + 1``, normalised to sum 1; a tap outside the axis reads
    its mirror image (half-sample symmetric: -1 -> 0, n -> n - 1)."""
    x = (np.arange(int(np.ceil(scale * n))) + 0.5) / scale - 0.5
    taps = np.floor(x - 2.0 / scale)[:, None] + np.arange(int(np.ceil(4.0 / scale)) + 2)
    d = np.abs(scale * (x[:, None] - taps))
    w = np.where(d <= 1, (1.5 * d - 2.5) * d * d + 1.0, np.where(d <= 2, ((2.5 - 0.5 * d) * d - 4.0) * d + 2.0, 0.0))
    m = taps.astype(np.int64) % (2 * n)  # the mirrored taps' columns: np.where(m < n, m, 2 n - 1 - m)
    cells = np.arange(x.size)[:, None] * n + np.where(m < n, m, 2 * n - 1 - m)
    return np.bincount(cells.ravel(), (w / w.sum(1, keepdims=True)).ravel(), x.size * n).reshape(x.size, n)


def core_unit(shape: tuple[int, int]) -> tuple[int, int]:
    """The centre unit (row, column) of the (H-1, W-1) grid: MATLAB's ``floor(end / 2)``, 0-based."""
    return max((shape[0] - 1) // 2 - 1, 0), max((shape[1] - 1) // 2 - 1, 0)


def gf_frame(v: float, current: float, dt: float, p: LPLC2Params) -> tuple[float, int, float]:
    """One frame of the giant fibre from membrane ``v`` (mV) with input ``current`` over ``dt`` s:
    ``substeps`` RK4 steps, a step ending above ``v_threshold`` spikes and resets.

    Returns ``(V at the end, spikes, V_peak)``, ``V_peak`` the highest V of the frame's substeps before
    any reset (mV; above ``v_threshold`` exactly when the frame spiked)."""
    spikes, v_peak = 0, -np.inf
    for _ in range(p.substeps):
        v = lif_substep(v, current, dt / p.substeps, p)
        v_peak = max(v_peak, v)
        if v > p.v_threshold:
            spikes, v = spikes + 1, p.v_reset
    return v, spikes, float(v_peak)


def lif_substep(v: float, current: float, h: float, p: LPLC2Params) -> float:
    """One RK4 step of length ``h`` (s) of ``tau_m dV/dt = -V + v_rest + R I``; V at or below the floor stays."""
    if v <= p.v_floor:
        return p.v_floor
    slope = lambda y: (p.v_rest + p.resistance * current - y) / p.tau_m  # noqa: E731  (dV/dt at V = y)
    k1 = slope(v)
    k2 = slope(v + k1 * h / 2)
    k3 = slope(v + k2 * h / 2)
    return v + (k1 + 2 * k2 + 2 * k3 + slope(v + k3 * h)) * h / 6
