"""Float64 NumPy reference of the EMD-LPLC2-GF looming detector.

Source: Zhao, Xi, Li, Guo, Wu et al., *A fly inspired solution to looming
detection for collision avoidance*, iScience 2023, and the authors' MATLAB in
``zhaojunyu01/EMD-LPLC2-GF-model`` (``code/2_Response-Characteristics-LPLC2-
Arrays-And-GF-Unit-To-Looming``: ``emd.m``, ``OnRect.m``, ``OffRect.m``,
``lplc2conv2.m``, ``loom.m``, ``GF.m``, ``LIF.m``; the same files are in
folders 3 and 4). Nothing of theirs is copied: this is a transcription of the
computation, one frame at a time.

Per frame ``t`` (luminance ``L`` in [0, 1], time step ``dt = 1 / fps``, their 10 ms):

* photoreceptor high-pass ``F_h(t) = b (L(t) - L(t-1)) + b F_h(t-1)``,
  ``b = (tau_H / dt) / (tau_H / dt + 1)`` (``tau_H`` = 250 ms);
* ON ``= [F_h]^+``, OFF ``= [0.05 - F_h]^+`` (their OFF threshold 0.05);
* delay low-pass ``F_d(t) = a X(t) + (1 - a) F_d(t-1)``, ``a = 1 / (tau_L / dt + 1)``
  (``tau_L`` = 50 ms), for X = ON and OFF;
* Hassenstein-Reichardt half-detectors between neighbours, ON and OFF summed:
  rightward ``F_d(y, x) X(y, x+1)``, leftward ``X(y, x) F_d(y, x+1)``,
  downward ``F_d(y, x) X(y+1, x)``, upward ``X(y, x) F_d(y+1, x)``; shape (H-1, W-1);
* LPLC2 unit at every (y, x), four arms (radial-opponent half-plane pooling of
  a 100-px receptive field): left arm = sum of (leftward - rightward) over
  rows y-19..y+20, columns x-49..x; right arm = (rightward - leftward) over
  columns x+1..x+50; up arm = (upward - downward) over rows y-49..y, columns
  x-19..x+20; down arm = (downward - upward) over rows y+1..y+50 (zero
  outside the frame; this is MATLAB's ``conv2(.., 'same')`` with their
  even-sized kernels);
* each arm is zeroed unless > 2.0; LPLC2 = product of the four arms;
* GF input ``I(t) = w n(t) v(t)`` with ``n = (active LPLC2 units) / 2500``
  and ``v = (n(t) - n(t-1)) / 0.576`` (zero while ``n(t-1) = 0``);
* GF membrane: ``tau dV/dt = -V + L + R I`` (``tau`` 0.3 s, ``L`` -60 mV,
  ``R`` 10), 20 fourth-order Runge-Kutta substeps per frame, V clamped at
  -80 mV; a substep with ``V > -50`` mV is a spike (recorded as +20 mV) and
  resets V to -70 mV. The alert is a spike.

``variant="real"``: the rule of the authors' robot and real-environment folders
(``code/5_...``, ``code/6_...``, ``code/7_Real-Environment-Test-About-Animals``,
whose ``lplc2conv2.m`` is the same in all three): a unit counts when at least 3
of its 4 arms exceed 1.5 and none is at or below -2 (nor exactly 0); its
response is ``|product of the four arms|``. As folder 7's ``loom.m``, that
variant takes the green channel of a colour frame (``B(:,:,2) / 255``) and
shrinks it to a quarter with MATLAB's ``imresize(.., 0.25)`` (bicubic with
antialiasing, :func:`matlab_imresize`) before the EMD; ``height, width`` are
the frame's size before the shrink. ``variant="arena"`` (default) is the rule
above, folders 2-4.

Frame alignment: their loop index ``i`` (1-based) processes pictures ``i``
and ``i + 1``; its outputs (``nums(i)``, ``I(i)``, the membrane samples
``v(20 (i-1) + 2 .. 20 i + 1)``) are this reference's frame ``i`` (0-based).
Frame 0 only stores the picture (membrane at rest, no spike).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import numpy as np

from .errors import InputError, UserError

#: The authors' time step (s): their stimuli are 100 frames/s.
AUTHORS_DT = 0.01

#: Unit rules: ``arena`` (folders 2-4 of the authors' code), ``real`` (folders 5-7).
VARIANTS = ("arena", "real")
#: ``variant="real"``: an arm is strong above this ...
REAL_ARM_THRESHOLD = 1.5
#: ... a unit needs at least this many strong arms ...
REAL_MIN_ARMS = 3
#: ... and every arm above this floor (their ``threshold_2``).
REAL_ARM_FLOOR = -2.0
#: ``variant="real"``: frames are shrunk by this factor (folder 7's ``imresize(movieData, 0.25)``).
REAL_SCALE = 0.25


@dataclass(frozen=True)
class LPLC2Params:
    """EMD-LPLC2-GF constants as in the authors' MATLAB (times in s, potentials in mV)."""

    tau_h: float = 0.250  #: high-pass time constant
    tau_l: float = 0.050  #: delay low-pass time constant
    on_threshold: float = 0.0  #: ON = [F_h - on_threshold]^+
    off_threshold: float = 0.05  #: OFF = [off_threshold - F_h]^+
    half_side: int = 50  #: LPLC2 receptive field half side (their side = 100)
    band_before: int = 19  #: a half-plane arm spans centre - band_before .. centre + band_after across
    band_after: int = 20
    arm_threshold: float = 2.0  #: an arm counts only where > arm_threshold
    normal_count: float = 2500.0  #: n = active units / normal_count
    normal_velocity: float = (2116.0 - 676.0) / 2500.0  #: v = (n(t) - n(t-1)) / normal_velocity
    w: float = 250.0  #: GF input gain
    v_rest: float = -60.0
    v_threshold: float = -50.0
    v_reset: float = -70.0
    v_floor: float = -80.0
    v_spike: float = 20.0  #: value recorded for a spike substep
    resistance: float = 10.0
    tau_m: float = 0.30
    substeps: int = 20


@dataclass(frozen=True)
class LPLC2Step:
    """One frame's EMD-LPLC2-GF output."""

    v: float  #: GF membrane at the end of the frame (mV, after any reset)
    spikes: int  #: GF spikes in the frame's substeps
    alert: bool  #: spikes > 0
    active: int  #: LPLC2 units with a non-zero response (their ``nums``)
    current: float  #: GF input I
    core: float  #: LPLC2 response of the centre unit (their ``LPLC2_core``)
    arms: tuple  #: the centre unit's four thresholded arms (left, right, up, down)
    trace: tuple  #: the frame's membrane samples, one per substep (+20 mV for a spike)


def _cubic(x: np.ndarray) -> np.ndarray:
    """MATLAB's bicubic kernel (Keys, a = -0.5)."""
    ax = np.abs(x)
    return ((1.5 * ax**3 - 2.5 * ax**2 + 1.0) * (ax <= 1)
            + (-0.5 * ax**3 + 2.5 * ax**2 - 4.0 * ax + 2.0) * ((ax > 1) & (ax <= 2)))


def _resize_matrix(n_in: int, scale: float) -> np.ndarray:
    """The (ceil(scale n_in), n_in) weights of MATLAB's ``imresize`` along one axis (bicubic, antialiased
    when shrinking, mirrored border)."""
    n_out = int(np.ceil(scale * n_in))
    width = 4.0 / scale if scale < 1 else 4.0
    u = np.arange(1, n_out + 1) / scale + 0.5 * (1.0 - 1.0 / scale)  # output centres on the input axis (1-based)
    left = np.floor(u - width / 2.0)
    ind = left[:, None] + np.arange(int(np.ceil(width)) + 2)[None, :]
    wts = scale * _cubic(scale * (u[:, None] - ind)) if scale < 1 else _cubic(u[:, None] - ind)
    wts /= wts.sum(axis=1, keepdims=True)
    mirror = np.concatenate([np.arange(n_in), np.arange(n_in)[::-1]])
    idx = mirror[(ind.astype(np.int64) - 1) % (2 * n_in)]
    out = np.zeros((n_out, n_in))
    np.add.at(out, (np.repeat(np.arange(n_out), ind.shape[1]), idx.ravel()), wts.ravel())
    return out


def matlab_imresize(img: np.ndarray, scale: float) -> np.ndarray:
    """MATLAB's ``imresize(img, scale)`` of a float (H, W) image: bicubic, antialiased when shrinking,
    output ``ceil(scale H) x ceil(scale W)``; rows first, then columns; no clipping."""
    return _resize_matrix(img.shape[0], scale) @ img @ _resize_matrix(img.shape[1], scale).T


def _window_sum(x: np.ndarray, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    """``out(y, x) = sum x(y + r0 .. y + r1, x + c0 .. x + c1)``, zero outside; same shape as x."""
    h, w = x.shape
    pr, pc = max(-r0, r1, 0) + 1, max(-c0, c1, 0) + 1
    xp = np.zeros((h + 2 * pr, w + 2 * pc))
    xp[pr : pr + h, pc : pc + w] = x
    ii = np.zeros((xp.shape[0] + 1, xp.shape[1] + 1))
    ii[1:, 1:] = xp.cumsum(0).cumsum(1)
    y0, y1 = pr + r0, pr + r1 + 1
    x0, x1 = pc + c0, pc + c1 + 1
    return (ii[y1 : y1 + h, x1 : x1 + w] - ii[y0 : y0 + h, x1 : x1 + w]
            - ii[y1 : y1 + h, x0 : x0 + w] + ii[y0 : y0 + h, x0 : x0 + w])


class LPLC2Reference:
    """Streaming, causal EMD-LPLC2-GF: :meth:`step` takes one frame and returns its :class:`LPLC2Step`.

    Parameters
    ----------
    height, width : int
        Frame size in px (at least 2x2); the LPLC2 array is (H-1, W-1).
    fps : float
        Frame rate; ``dt = 1 / fps`` sets the filters and the GF integration
        (the authors' 100 frames/s by default).
    params : LPLC2Params, optional

    variant : {"arena", "real"}
        The unit rule (module docstring): ``"arena"`` (default) the authors'
        folders 2-4, ``"real"`` their robot and real-environment folders 5-7,
        with folder 7's green channel and quarter-size frames.

    Frames are (H, W) float luminance in [0, 1] or uint8 (divided by 255);
    ``variant="real"`` also takes (H, W, 3) uint8 BGR frames (their green channel).
    The LPLC2 array is (h-1, w-1) with ``(h, w)`` the frame size, after the
    shrink in ``variant="real"`` (``ceil(H / 4), ceil(W / 4)``).
    """

    def __init__(self, height: int, width: int, fps: float = 1.0 / AUTHORS_DT, params: LPLC2Params | None = None,
                 variant: str = "arena"):
        if variant not in VARIANTS:
            raise UserError(f"variant must be one of {', '.join(VARIANTS)}, got {variant!r}")
        self.variant = variant
        self.input_shape = (int(height), int(width))
        if variant == "real":
            height, width = (int(np.ceil(REAL_SCALE * int(n))) for n in (height, width))
        if int(height) < 2 or int(width) < 2:
            raise UserError(f"frame must be at least 2x2 px, got {width}x{height}")
        if not (np.isfinite(fps) and fps > 0):
            raise UserError(f"fps must be a positive number, got {fps!r}")
        self.height, self.width = int(height), int(width)
        self.params = p = params or LPLC2Params()
        self.dt = 1.0 / float(fps)
        d_h, d_l = p.tau_h / self.dt, p.tau_l / self.dt
        self.b_high = d_h / (d_h + 1.0)
        self.a_low = 1.0 / (d_l + 1.0)
        self.reset()

    def reset(self) -> None:
        """Back to the state before the first frame."""
        shape = (self.height, self.width)
        self.t = 0
        self.lum_prev = np.zeros(shape)
        self.f_h = np.zeros(shape)
        self.fd_on = np.zeros(shape)
        self.fd_off = np.zeros(shape)
        self.active_prev: int | None = None
        self.v = self.params.v_rest
        self.lplc2 = np.zeros((self.height - 1, self.width - 1))
        self.arm_maps = np.zeros((4, self.height - 1, self.width - 1))
        self.motion_maps = np.zeros((4, self.height - 1, self.width - 1))

    def luminance(self, frame: np.ndarray) -> np.ndarray:
        """Frame -> float64 luminance in [0, 1], shape (H, W); validates shape and values.

        ``variant="real"``: the green channel of a BGR frame (a grey frame as it is), shrunk
        by :func:`matlab_imresize` to the array size (bicubic: may leave [0, 1] slightly)."""
        f = np.asarray(frame)
        where = f"frame {self.t}"
        if self.variant == "real":
            if f.ndim == 3 and f.shape[2] == 3 and f.dtype == np.uint8:
                f = f[:, :, 1]
            if f.ndim != 2 or f.shape != self.input_shape:
                raise InputError(where, f"expected a {self.input_shape[1]}x{self.input_shape[0]} grey or uint8 BGR "
                                        f"frame, got shape {f.shape} {f.dtype}")
            return matlab_imresize(self._unit_range(f, where), REAL_SCALE)
        if f.ndim != 2:
            raise InputError(where, f"expected an (H, W) grey frame, got shape {f.shape}")
        if f.shape != (self.height, self.width):
            raise InputError(where, f"expected {self.width}x{self.height} px, got {f.shape[1]}x{f.shape[0]}")
        return self._unit_range(f, where)

    @staticmethod
    def _unit_range(f: np.ndarray, where: str) -> np.ndarray:
        """uint8 / 255, or a float frame checked to be finite and in [0, 1]; float64."""
        if f.dtype == np.uint8:
            return f.astype(np.float64) / 255.0
        if not np.issubdtype(f.dtype, np.floating):
            raise InputError(where, f"a frame must be uint8 or float in [0, 1], got {f.dtype}")
        if not np.all(np.isfinite(f)) or f.min() < 0 or f.max() > 1:
            raise InputError(where, "a float frame must be finite luminance in [0, 1]")
        return f.astype(np.float64)

    def motion(self, lum: np.ndarray) -> np.ndarray:
        """Advance the EMD state by one frame; returns (left, right, up, down) motion, shape (4, H-1, W-1)."""
        p = self.params
        self.f_h = self.b_high * (lum - self.lum_prev) + self.b_high * self.f_h
        on = np.where(self.f_h > p.on_threshold, np.abs(self.f_h - p.on_threshold), 0.0)
        off = np.where(self.f_h < p.off_threshold, np.abs(self.f_h - p.off_threshold), 0.0)
        self.fd_on = self.a_low * on + (1.0 - self.a_low) * self.fd_on
        self.fd_off = self.a_low * off + (1.0 - self.a_low) * self.fd_off
        out = np.zeros((4, self.height - 1, self.width - 1))
        for x, fd in ((on, self.fd_on), (off, self.fd_off)):
            out[0] += x[:-1, :-1] * fd[:-1, 1:]  # leftward
            out[1] += fd[:-1, :-1] * x[:-1, 1:]  # rightward
            out[2] += x[:-1, :-1] * fd[1:, :-1]  # upward
            out[3] += fd[:-1, :-1] * x[1:, :-1]  # downward
        return out

    def arms(self, motion: np.ndarray) -> np.ndarray:
        """The four thresholded half-plane arms of every LPLC2 unit, shape (4, H-1, W-1)."""
        p = self.params
        hs, lo, hi = p.half_side, -p.band_before, p.band_after
        horizontal = motion[0] - motion[1]  # leftward - rightward
        vertical = motion[2] - motion[3]  # upward - downward
        a = np.stack([
            _window_sum(horizontal, lo, hi, -(hs - 1), 0),  # left half: outward = leftward
            _window_sum(-horizontal, lo, hi, 1, hs),  # right half: outward = rightward
            _window_sum(vertical, -(hs - 1), 0, lo, hi),  # upper half: outward = upward
            _window_sum(-vertical, 1, hs, lo, hi),  # lower half: outward = downward
        ])
        if self.variant == "real":
            return np.where(a > REAL_ARM_FLOOR, a, 0.0)
        return np.where(a > p.arm_threshold, a, 0.0)

    def units(self, arm_maps: np.ndarray) -> np.ndarray:
        """LPLC2 responses from the thresholded arms, shape (H-1, W-1): their product (``arena``), or
        ``|product|`` where at least :data:`REAL_MIN_ARMS` arms exceed :data:`REAL_ARM_THRESHOLD` (``real``)."""
        if self.variant == "real":
            strong = (arm_maps > REAL_ARM_THRESHOLD).sum(axis=0) >= REAL_MIN_ARMS
            return np.abs(arm_maps.prod(axis=0)) * strong
        return arm_maps.prod(axis=0)

    def _lif(self, v: float, current: float) -> float:
        """One RK4 substep of ``tau dV/dt = -V + L + R I`` (held at the floor when V <= floor)."""
        p = self.params
        if v <= p.v_floor:
            return p.v_floor
        h = self.dt / p.substeps

        def f(y: float) -> float:
            return (-y + p.v_rest + p.resistance * current) / p.tau_m

        k1 = f(v)
        k2 = f(v + k1 * h / 2)
        k3 = f(v + k2 * h / 2)
        k4 = f(v + k3 * h)
        return v + (k1 + 2 * k2 + 2 * k3 + k4) * h / 6

    def step(self, frame: np.ndarray) -> LPLC2Step:
        """Advance one frame; returns this frame's output (uses no later frame)."""
        lum = self.luminance(frame)
        p = self.params
        cy, cx = (self.height - 1) // 2 - 1, (self.width - 1) // 2 - 1  # MATLAB floor(end/2), 0-based
        if self.t == 0:
            self.lum_prev = lum
            self.t += 1
            return LPLC2Step(self.v, 0, False, 0, 0.0, 0.0, (0.0,) * 4, (self.v,) * p.substeps)
        motion = self.motion(lum)
        arm_maps = self.arms(motion)
        lplc2 = self.units(arm_maps)
        active = int(np.count_nonzero(lplc2 > 0))
        n1 = active / p.normal_count
        n2 = n1 if self.active_prev is None else self.active_prev / p.normal_count
        velocity = ((n1 - n2) / self.dt) / (p.normal_velocity / self.dt)
        current = 0.0 if n2 == 0 else p.w * n1 * velocity
        v, spikes, trace = self.v, 0, []
        for _ in range(p.substeps):
            v = self._lif(v, current)
            if v > p.v_threshold:
                spikes += 1
                trace.append(p.v_spike)
                v = p.v_reset
            else:
                trace.append(v)
        self.v = v
        self.lum_prev = lum
        self.active_prev = active
        self.lplc2, self.arm_maps, self.motion_maps = lplc2, arm_maps, motion
        self.t += 1
        core_arms = tuple(float(a) for a in arm_maps[:, max(cy, 0), max(cx, 0)])
        return LPLC2Step(float(v), spikes, spikes > 0, active, float(current), float(lplc2[max(cy, 0), max(cx, 0)]),
                         core_arms, tuple(trace))

    def run(self, frames: Iterable[np.ndarray]) -> dict[str, np.ndarray]:
        """Step through ``frames``; one array per :class:`LPLC2Step` field (arms (T, 4), trace (T, substeps))."""
        steps = [self.step(f) for f in frames]
        return {name: np.array([getattr(s, name) for s in steps]) for name in LPLC2Step.__dataclass_fields__}


class NumpyLPLC2Backend:
    """The float64 backend of the engine model :class:`cdnf_ti.models.lplc2.LPLC2`: the EMD and LPLC2
    stages of :class:`LPLC2Reference` behind the backend interface (``load``, ``pool``, ``fields``).

    Parameters
    ----------
    params : dataclass with the fields of :class:`LPLC2Params` (the model's parameters)
    shape : (H, W)
    fps : float
    """

    name = "numpy"

    def __init__(self, params, shape: tuple[int, int], fps: float):
        fields = {k: getattr(params, k) for k in LPLC2Params.__dataclass_fields__}
        self.ref = LPLC2Reference(shape[0], shape[1], fps=fps, params=LPLC2Params(**fields))
        self.shape = (int(shape[0]), int(shape[1]))

    def reset(self) -> None:
        self.ref.reset()

    def load(self, grey: np.ndarray, first: bool) -> None:
        """Photoreceptors and EMD of one frame (only stored when ``first``)."""
        ref = self.ref
        lum = ref.luminance(grey)
        if not first:
            ref.motion_maps = ref.motion(lum)
        ref.lum_prev = lum
        ref.t += 1

    def pool(self) -> tuple[int, float, tuple[float, float, float, float]]:
        """``(active units, centre response, centre arms (left, right, up, down))`` of the loaded frame."""
        ref = self.ref
        ref.arm_maps = ref.arms(ref.motion_maps)
        ref.lplc2 = ref.arm_maps.prod(axis=0)
        cy, cx = max((self.shape[0] - 1) // 2 - 1, 0), max((self.shape[1] - 1) // 2 - 1, 0)
        arms = tuple(float(a) for a in ref.arm_maps[:, cy, cx])
        return int(np.count_nonzero(ref.lplc2 > 0)), float(ref.lplc2[cy, cx]), arms

    def fields(self) -> dict[str, np.ndarray]:
        """The maps of the compiled model's :meth:`fields` (its unit grid), padded to (H, W) with zeros."""
        ref = self.ref
        m = ref.motion_maps
        maps = dict(horizontal=m[0] - m[1], vertical=m[2] - m[3], left=ref.arm_maps[0], right=ref.arm_maps[1],
                    up=ref.arm_maps[2], down=ref.arm_maps[3], lplc2=ref.lplc2)
        return {k: np.pad(v, ((0, 1), (0, 1))) for k, v in maps.items()}
