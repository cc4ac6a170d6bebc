"""Float64 NumPy reference of the event-based looming detector of Schubert, Knight, Philippides and Nowotny.

Source: Schubert, Knight, Philippides, Nowotny, *Bio-inspired event-based
looming object detection for automotive collision avoidance*, Neuromorphic
Computing and Engineering 5:024016, 2025, and the authors' code in
``FabianSchubert/Bio-Inspired-Event-Based-Looming-Object-Detection-for-Automotive-Collision-Avoidance``:
``src/pytorch/looming_detector.py`` with ``src/pytorch/network_settings.py``
(``variant="code"``, the PyTorch model with its untrained defaults) and the
GeNN model ``src/looming_sim/emd/models_emd.py`` with
``src/looming_sim/emd/network_settings.py`` (``variant="paper"``). Nothing of
theirs is copied here: this is a transcription of the computation, one bin at
a time.

Input: one signed event map per time bin, ``B(t)`` in {-1, 0, +1} per pixel
(the polarity of the pixel's last event in the bin; 0 without events),
split into ``X_p = [B > 0]`` and ``X_n = [B < 0]``. Per bin ``t``:

* flow from the previous bin's map and the current one, per polarity q:
  ``v_x^q = -X_q(t) (K_x * X_q(t-1)) dt / (reg + dt^2 K_n * X_q(t-1))`` (``v_y`` with ``K_y``),
  ``K_n`` the normalised 5x5 Gaussian (sigma = 0.3 * 2 px), ``K_x = x K_n``,
  ``K_y = y K_n`` (``x`` the column offset, ``y`` the row offset), correlations
  with zero padding; ``v = v^p + v^n``;
* radial projection ``v_r = v_x w_x + v_y w_y``, ``w_x`` running from -1 to 1
  across the columns and ``w_y`` from ``-H/W`` to ``H/W`` down the rows;
* left / right responses ``R_l``, ``R_r``: sums of ``v_r`` weighted by the
  Gaussian ``exp(-(w_x^2 + w_y^2) / (2 0.25^2))`` over the columns left of
  ``W // 2`` and from ``W // 2`` on;
* ``r = s_out min(R_l, R_r) sigma(a R_l - b) sigma(a R_r - b)``
  (``sigma`` the logistic function);
* ``code``: output ``r - theta`` (their ``out_th``); ``paper``: output the
  leaky integral ``V(t) = alpha V(t-1) + (1 - alpha) r``, ``alpha = exp(-dt / tau_m)``.

The alert is ``output > 0`` (their classification, ``outputs > 0``).

Frame alignment: their model takes a pair of bins ``(B(t-1), B(t))``; its
output is this reference's output at bin ``t``. Bin 0 has no predecessor
(an empty map stands in for it). On frames, bin ``k`` holds the emulator's
events between frames ``k - 1`` and ``k`` (frame ``k``'s output); frame 0 has
none.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Iterator

import numpy as np

from .errors import InputError, UserError
from .events.emulator import EmulatorParams, emulate
from .lgmd_p_on_off_reference import correlate_same

VARIANTS = ("code", "paper")


@dataclass(frozen=True)
class EventLoomingParams:
    """Constants of the detector (lengths in px, times in ms); ``None`` takes the variant's value."""

    kern_half_size: int = 2  #: flow kernels are (2 h + 1)^2
    sigm_kern: float = 0.3  #: Gaussian sigma = sigm_kern * kern_half_size px
    reg: float = 0.1  #: flow regulariser
    sigma_pos: float = 0.25  #: left/right position weights: Gaussian of this sigma in (w_x, w_y)
    dt: float | None = None  #: bin width in the flow formula, ms (code 10, their DT; paper 1, their DT_MS)
    out_scale: float | None = None  #: s_out (code 1.5, untrained; paper 4.663991, their OUTPUT_SCALE)
    sigm_scale: float | None = None  #: a (code 1.5; paper 7.703327, FILT_SCALE_OUT)
    sigm_bias: float | None = None  #: b (code 0; paper -0.549131, FILT_BIAS_OUT)
    out_th: float = 0.0  #: code: output = r - out_th (untrained: 0)
    tau_m: float = 50.0  #: paper: output leak time constant (TAU_MEM_OUT), ms


#: Per-variant values of the ``None`` fields of :class:`EventLoomingParams`.
VARIANT_DEFAULTS = {
    "code": dict(dt=10.0, out_scale=1.5, sigm_scale=1.5, sigm_bias=0.0),
    "paper": dict(dt=1.0, out_scale=4.663991, sigm_scale=7.703327, sigm_bias=-0.549131),
}


@dataclass(frozen=True)
class EventLoomingStep:
    """One bin's output (scalars)."""

    output: float  #: code: r - out_th; paper: the leaky V
    alert: bool  #: output > 0
    left: float  #: R_l
    right: float  #: R_r
    r: float  #: s_out min(R_l, R_r) sigma(a R_l - b) sigma(a R_r - b)


def flow_kernels(half: int, sigm_kern: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(K_n, K_x, K_y)``, each (2 half + 1)^2: the normalised Gaussian and its products with the
    column offset (``K_x``) and the row offset (``K_y``)."""
    o = np.arange(-half, half + 1, dtype=np.float64)
    xs, ys = np.meshgrid(o, o)
    g = np.exp(-(xs**2 + ys**2) / (2.0 * (sigm_kern * half) ** 2))
    g /= g.sum()
    return g, xs * g, ys * g


def signed_bins(chunks: Iterable[np.ndarray], shape: tuple[int, int], bin_us: float, t0: int = 0,
                n_bins: int | None = None) -> Iterator[np.ndarray]:
    """Events -> one signed map per bin: the polarity (+1 ON, -1 OFF) of each pixel's last event in the bin.

    Parameters
    ----------
    chunks : iterable of structured arrays with fields ``t`` (µs), ``x``, ``y``, ``p``
        Time-sorted, as :func:`cdnf_ti.events.readers.open_events` and the emulator give them.
    shape : (H, W)
    bin_us : float
        Bin width, µs: bin ``k`` holds ``t0 + k bin_us <= t < t0 + (k + 1) bin_us``.
    t0 : int
        Start of bin 0, µs.
    n_bins : int, optional
        Bins to produce (default: up to the last event's).

    Yields
    ------
    ndarray, shape (H, W), int8
        Events outside the sensor or before ``t0`` are left out.
    """
    h, w = shape
    cur = np.zeros(shape, dtype=np.int8)
    k = 0
    for c in chunks:
        t = np.asarray(c["t"], dtype=np.int64)
        x, y = np.asarray(c["x"], dtype=np.int64), np.asarray(c["y"], dtype=np.int64)
        keep = (x < w) & (y < h) & (t >= t0)
        t, x, y = t[keep], x[keep], y[keep]
        sign = np.where(np.asarray(c["p"])[keep] > 0, 1, -1).astype(np.int8)
        b = np.floor((t - t0) / bin_us).astype(np.int64)
        for kb in np.unique(b):
            while k < kb:
                if n_bins is not None and k >= n_bins:
                    return
                yield cur
                cur, k = np.zeros(shape, dtype=np.int8), k + 1
            sel = b == kb
            cur[y[sel], x[sel]] = sign[sel]  # NumPy assigns in order: the last event wins
    while n_bins is None or k < n_bins:
        yield cur
        cur, k = np.zeros(shape, dtype=np.int8), k + 1
        if n_bins is None:
            return


def frame_bins(frames: Iterable[np.ndarray], fps: float, params: EmulatorParams | None = None,
               seed: int = 0) -> Iterator[np.ndarray]:
    """Grey frames -> one signed map per frame (empty at frame 0) from the project's event emulator."""
    frames = iter(frames)
    first = np.asarray(next(frames))
    yield np.zeros(first.shape, dtype=np.int8)

    def all_frames():
        yield first
        yield from frames

    for chunk in emulate(all_frames(), fps, params or EmulatorParams(), seed):
        yield next(signed_bins([chunk], first.shape, float("inf"), 0, 1))


class EventLoomingReference:
    """Streaming, causal detector: :meth:`step` takes one signed bin map and returns its :class:`EventLoomingStep`.

    Parameters
    ----------
    height, width : int
        Sensor (crop) size in px, at least 2x2.
    variant : {"code", "paper"}
        ``"code"``: the PyTorch model with its untrained defaults (dt 10 ms,
        ``out_scale = sigm_scale = 1.5``, ``sigm_bias = out_th = 0``, no output
        filter; dropout is a training device and is off). ``"paper"``: the GeNN
        model's output neuron and parameters (dt 1 ms, the fitted scale and
        bias, a leaky output with ``tau_m`` = 50 ms).
    params : EventLoomingParams, optional
    """

    def __init__(self, height: int, width: int, variant: str = "code", params: EventLoomingParams | None = None):
        if variant not in VARIANTS:
            raise UserError(f"variant must be one of {', '.join(VARIANTS)}, got {variant!r}")
        if int(height) < 2 or int(width) < 2:
            raise UserError(f"sensor must be at least 2x2 px, got {width}x{height}")
        p = params or EventLoomingParams()
        self.values = {k: (getattr(p, k) if getattr(p, k) is not None else v)
                       for k, v in VARIANT_DEFAULTS[variant].items()}
        if not self.values["dt"] > 0:
            raise UserError(f"dt must be > 0 ms, got {self.values['dt']}")
        self.height, self.width = int(height), int(width)
        self.variant, self.params = variant, p
        self.k_n, self.k_x, self.k_y = flow_kernels(p.kern_half_size, p.sigm_kern)
        self.w_x = np.broadcast_to(np.linspace(-1.0, 1.0, self.width)[None, :], (self.height, self.width))
        self.w_y = np.broadcast_to(np.linspace(-self.height / self.width, self.height / self.width,
                                              self.height)[:, None], (self.height, self.width))
        w_pos = np.exp(-self.w_x**2 / (2.0 * p.sigma_pos**2)) * np.exp(-self.w_y**2 / (2.0 * p.sigma_pos**2))
        half = self.width // 2
        self.w_left = np.where(np.arange(self.width)[None, :] < half, w_pos, 0.0)
        self.w_right = np.where(np.arange(self.width)[None, :] >= half, w_pos, 0.0)
        self.alpha = float(np.exp(-self.values["dt"] / p.tau_m))
        self.reset()

    def reset(self) -> None:
        """Back to the state before the first bin."""
        self.t = 0
        self.prev = np.zeros((self.height, self.width), dtype=np.int8)
        self.v = 0.0
        self.layers: dict[str, np.ndarray] = {}

    def _flow(self, cur: np.ndarray, prev: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(v_x, v_y)`` of one polarity from its 0/1 maps at ``t`` and ``t - 1``."""
        dt, reg = self.values["dt"], self.params.reg
        denom = reg + dt * dt * correlate_same(prev, self.k_n, "constant")
        return (-cur * correlate_same(prev, self.k_x, "constant") * dt / denom,
                -cur * correlate_same(prev, self.k_y, "constant") * dt / denom)

    def step(self, bin_map: np.ndarray) -> EventLoomingStep:
        """Advance one bin; returns its output (uses no later bin)."""
        b = np.asarray(bin_map)
        if b.shape != (self.height, self.width):
            raise InputError(f"bin {self.t}", f"expected a {self.width}x{self.height} event map, got shape {b.shape}")
        if not np.issubdtype(b.dtype, np.number) or not np.all(np.isfinite(b)):
            raise InputError(f"bin {self.t}", "an event map must hold finite numbers (the signs are used)")
        vx, vy = np.zeros(b.shape), np.zeros(b.shape)
        for sign in (1, -1):
            fx, fy = self._flow((sign * b > 0).astype(np.float64), (sign * self.prev > 0).astype(np.float64))
            vx += fx
            vy += fy
        v_r = vx * self.w_x + vy * self.w_y
        left, right = float((v_r * self.w_left).sum()), float((v_r * self.w_right).sum())
        val = self.values
        r = (val["out_scale"] * min(left, right) / (1.0 + np.exp(-(val["sigm_scale"] * left - val["sigm_bias"])))
             / (1.0 + np.exp(-(val["sigm_scale"] * right - val["sigm_bias"]))))
        if self.variant == "code":
            out = r - self.params.out_th
        else:
            self.v = self.alpha * self.v + (1.0 - self.alpha) * r
            out = self.v
        self.layers = {"vx": vx, "vy": vy, "v_r": v_r}
        self.prev = np.sign(b).astype(np.int8)
        self.t += 1
        return EventLoomingStep(float(out), bool(out > 0), left, right, float(r))

    def run(self, bins: Iterable[np.ndarray]) -> dict[str, np.ndarray]:
        """Step through ``bins`` from the current state; one array per :class:`EventLoomingStep` field, shape (T,)."""
        steps = [self.step(b) for b in bins]
        return {name: np.array([getattr(s, name) for s in steps]) for name in EventLoomingStep.__dataclass_fields__}
