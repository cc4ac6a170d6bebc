"""Synthetic rain on any frame stream (paper, Section III-A-2).

Per frame ``k`` a fresh rain layer ``R`` (zeros, same size as the frame):

* ``n`` droplets (:attr:`RainParams.drops`; default 500 at 426 x 240, scaled by
  the frame area), start row and column uniform over the frame;
* each droplet a streak ``length`` px downward (one pixel on each of ``length``
  consecutive rows), ``width`` px across, at an angle drawn uniformly from
  ``[-max_angle_deg, max_angle_deg]`` off vertical; pixel value ``grey``
  (overlaps keep ``grey``); streaks are cut at the frame border;
* ``R`` blurred by a normalised Gaussian of ``blur_sigma`` px (radius
  ``ceil(3 sigma)``, mirrored borders) - the motion blur;
* blended additively: ``out = clip(frame + weight * R, 0, 1)``.

SNR of a frame: ``10 log10(sum frame^2 / sum (out - frame)^2)`` (dB); a video's
SNR is the mean over its frames (:attr:`RainyFrames.snr_db`).

Droplets are drawn in Python from ``numpy.random.default_rng([seed, k])``;
the Taichi kernels of :mod:`cdnf_ti.kernels.stimuli` draw, blur and blend, so
frames do not depend on the thread count. :func:`rain_frame_numpy` is the
float64 NumPy reference of the same steps.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Iterable, Iterator

import numpy as np

from ..frames import to_grey
from ..taichi_runtime import dsl
from .basic import check_seed, taichi_stimulus_kernels

#: The paper's frame size for 500 droplets per frame (height, width).
REFERENCE_SHAPE = (240, 426)
REFERENCE_DROPS = 500


@dataclass(frozen=True)
class RainParams:
    """Parameters of the synthetic rain (defaults follow the paper / STIMULI.md).

    Attributes
    ----------
    drops : int or None
        Droplets per frame; ``None`` = 500 per 426 x 240 px, scaled by frame area.
    length : int
        Streak length in px (rows, downward): 8.
    width : int
        Streak width in px: 1.
    max_angle_deg : float
        Streak angle off vertical is uniform in ``[-max_angle_deg, max_angle_deg]``
        degrees: 10 (a "slight" deviation).
    grey : float
        Streak luminance in [0, 1] before blur: 200/255 (light grey, as the usual
        OpenCV rain recipe).
    blur_sigma : float
        Gaussian blur standard deviation in px: 1.0 (0 = no blur).
    weight : float
        Blend weight of the rain layer: 0.5.
    """

    drops: int | None = None
    length: int = 8
    width: int = 1
    max_angle_deg: float = 10.0
    grey: float = 200.0 / 255.0
    blur_sigma: float = 1.0
    weight: float = 0.5

    def __post_init__(self) -> None:
        if self.drops is not None and (int(self.drops) != self.drops or self.drops < 0):
            raise ValueError(f"rain drops must be a non-negative integer, got {self.drops}")
        if int(self.length) != self.length or self.length < 1:
            raise ValueError(f"rain streak length must be an integer >= 1, got {self.length}")
        if int(self.width) != self.width or self.width < 1:
            raise ValueError(f"rain streak width must be an integer >= 1, got {self.width}")
        if not (0.0 <= self.max_angle_deg < 90.0):
            raise ValueError(f"rain max_angle_deg must be in [0, 90), got {self.max_angle_deg}")
        if not (0.0 <= self.grey <= 1.0):
            raise ValueError(f"rain grey must be in [0, 1], got {self.grey}")
        if not (self.blur_sigma >= 0.0):
            raise ValueError(f"rain blur_sigma must be >= 0, got {self.blur_sigma}")
        if not (self.weight >= 0.0):
            raise ValueError(f"rain weight must be >= 0, got {self.weight}")

    def drops_for(self, shape: tuple[int, int]) -> int:
        """Droplets per frame for a frame of ``shape`` (H, W)."""
        if self.drops is not None:
            return int(self.drops)
        H, W = shape
        return int(round(REFERENCE_DROPS * H * W / (REFERENCE_SHAPE[0] * REFERENCE_SHAPE[1])))

    def blur_kernel(self) -> np.ndarray:
        """The normalised 1-D Gaussian (float64, odd length ``2 ceil(3 sigma) + 1``)."""
        if self.blur_sigma <= 0:
            return np.ones(1)
        R = int(math.ceil(3 * self.blur_sigma))
        x = np.arange(-R, R + 1, dtype=np.float64)
        g = np.exp(-0.5 * (x / self.blur_sigma) ** 2)
        return g / g.sum()

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class Drops:
    """One frame's droplets: ``row0`` (int), ``col0`` (float, px), ``slope`` = tan(angle)."""

    row0: np.ndarray
    col0: np.ndarray
    slope: np.ndarray

    @property
    def angle_deg(self) -> np.ndarray:
        return np.degrees(np.arctan(self.slope))


def draw_drops(shape: tuple[int, int], params: RainParams, seed: int, frame_index: int) -> Drops:
    """Droplets of frame ``frame_index``: start points uniform over the frame, uniform angles."""
    H, W = shape
    n = params.drops_for(shape)
    rng = np.random.default_rng([int(seed), int(frame_index)])
    row0 = rng.integers(0, H, size=n).astype(np.int32)
    col0 = rng.uniform(0.0, W, size=n).astype(np.float32)
    ang = np.radians(rng.uniform(-params.max_angle_deg, params.max_angle_deg, size=n))
    return Drops(row0, col0, np.tan(ang).astype(np.float32))


def streak_layer_numpy(shape: tuple[int, int], drops: Drops, params: RainParams) -> np.ndarray:
    """NumPy reference of :func:`cdnf_ti.kernels.stimuli.draw_streaks` (unblurred layer, float64)."""
    H, W = shape
    layer = np.zeros(shape, dtype=np.float64)
    half = (params.width - 1) // 2
    s = np.arange(params.length)
    for r, c, m in zip(drops.row0, drops.col0, drops.slope):
        i = int(r) + s
        jc = np.floor(np.float32(c) + s.astype(np.float32) * np.float32(m)).astype(np.int64)
        for w in range(params.width):
            j = jc + w - half
            ok = (i >= 0) & (i < H) & (j >= 0) & (j < W)
            layer[i[ok], j[ok]] = np.float32(params.grey)
    return layer


def blur_numpy(layer: np.ndarray, params: RainParams) -> np.ndarray:
    """NumPy reference of :func:`cdnf_ti.kernels.stimuli.gaussian_blur` (mirrored borders)."""
    g = params.blur_kernel()
    R = (g.size - 1) // 2
    if R == 0:
        return layer.astype(np.float64)
    p = np.pad(layer.astype(np.float64), ((0, 0), (R, R)), mode="reflect")
    tmp = sum(g[d] * p[:, d : d + layer.shape[1]] for d in range(g.size))
    p = np.pad(tmp, ((R, R), (0, 0)), mode="reflect")
    return sum(g[d] * p[d : d + layer.shape[0], :] for d in range(g.size))


def blend_numpy(frame: np.ndarray, rain: np.ndarray, weight: float) -> np.ndarray:
    """``clip(frame + weight * rain, 0, 1)`` (frame float in [0, 1]; float64)."""
    return np.clip(np.asarray(frame, np.float64) + weight * np.asarray(rain, np.float64), 0.0, 1.0)


def _as_unit(frame: np.ndarray) -> np.ndarray:
    g = to_grey(frame)
    return g.astype(np.float64) / 255.0 if g.dtype == np.uint8 else g.astype(np.float64)


def rain_frame_numpy(frame: np.ndarray, params: RainParams | None = None, seed: int = 0,
                     frame_index: int = 0) -> np.ndarray:
    """NumPy float64 reference of one rainy frame (what :class:`RainyFrames` yields for frame ``k``)."""
    params = params or RainParams()
    f = _as_unit(frame)
    drops = draw_drops(f.shape, params, seed, frame_index)
    layer = blur_numpy(streak_layer_numpy(f.shape, drops, params), params)
    return blend_numpy(f, layer, params.weight)


def snr_db(clean: np.ndarray, rainy: np.ndarray) -> float:
    """SNR of one frame in dB: ``10 log10(sum clean^2 / sum (rainy - clean)^2)``.

    Both arrays are grey (H, W), uint8 (0..255, divided by 255) or float in
    [0, 1] (BGR is converted by :func:`cdnf_ti.frames.to_grey`). Returns ``inf``
    when the frames are equal.
    """
    c = _as_unit(clean)
    r = _as_unit(rainy)
    if c.shape != r.shape:
        raise ValueError(f"frame shapes differ: {c.shape} vs {r.shape}")
    noise = float(((r - c) ** 2).sum())
    signal = float((c ** 2).sum())
    if noise == 0.0:
        return float("inf")
    if signal == 0.0:
        return float("-inf")
    return 10.0 * math.log10(signal / noise)


class _TaichiRain:
    """Per-shape Taichi buffers and kernels for the rain steps."""

    def __init__(self, shape: tuple[int, int], params: RainParams):
        self.K, self.blocks = taichi_stimulus_kernels(shape[1])  # starts the runtime on first use
        self.shape = shape
        ti = dsl()  # taichi or quadrants, chosen at run time
        self.layer = ti.ndarray(ti.f32, shape)
        self.tmp = ti.ndarray(ti.f32, shape)
        self.blurred = ti.ndarray(ti.f32, shape)
        g = params.blur_kernel().astype(np.float32)
        self.g = ti.ndarray(ti.f32, g.shape)
        self.g.from_numpy(g)
        self.blur = g.size > 1
        self.signal = np.zeros(shape[0] * self.blocks, dtype=np.float64)  # partial sums per work item
        self.noise = np.zeros(shape[0] * self.blocks, dtype=np.float64)

    def layer_for(self, drops: Drops, params: RainParams) -> "object":
        self.K.fill(self.layer, 0.0)
        if drops.row0.size:
            self.K.draw_streaks(drops.row0, drops.col0, drops.slope, int(params.length), int(params.width),
                                float(np.float32(params.grey)), self.layer)
        if not self.blur:
            return self.layer
        self.K.gaussian_blur(self.layer, self.tmp, self.blurred, self.g, self.blocks)
        return self.blurred

    def blend(self, grey: np.ndarray, rain, weight: float) -> tuple[np.ndarray, float]:
        out = np.empty(self.shape, dtype=np.float32)
        scale = 1.0 / 255.0 if grey.dtype == np.uint8 else 1.0
        self.K.rain_blend(grey, rain, out, scale, float(weight), self.signal, self.noise, self.blocks)
        s, e = float(self.signal.sum()), float(self.noise.sum())
        snr = float("inf") if e == 0 else (float("-inf") if s == 0 else 10.0 * math.log10(s / e))
        return out, snr


class RainyFrames:
    """Synthetic rain added to a frame stream, lazily (one frame in memory at a time).

    Parameters
    ----------
    frames : iterable of ndarray
        Input frames: grey (H, W) uint8 or float in [0, 1], or BGR uint8
        (converted by :func:`cdnf_ti.frames.to_grey`).
    params : RainParams, optional
        Rain parameters (defaults: the paper's).
    seed : int
        Seed; frame ``k`` uses ``default_rng([seed, k])``.
    backend : {"taichi", "numpy"}
        Taichi kernels (default) or the float64 NumPy reference.

    Attributes
    ----------
    snr_per_frame : list of float
        SNR (dB) of each frame yielded so far.
    snr_db : float
        Mean of the finite values of :attr:`snr_per_frame` (frames where the
        rain changed nothing, e.g. all clipped on white, have SNR = inf and are
        left out); ``inf`` if no frame changed, nan before the first frame.

    Notes
    -----
    Iterating yields float32 (H, W) rainy frames in [0, 1]. Iterating again
    restarts the input iterable (when it is re-iterable) and the SNR record.
    """

    def __init__(self, frames: Iterable[np.ndarray], params: RainParams | None = None, seed: int = 0,
                 backend: str = "taichi"):
        if backend not in ("taichi", "numpy"):
            raise ValueError(f"unknown backend {backend!r}; choose taichi or numpy")
        self.frames = frames
        self.params = params or RainParams()
        self.seed = check_seed(seed)
        self.backend = backend
        self.snr_per_frame: list[float] = []
        self._engine: _TaichiRain | None = None

    @property
    def snr_db(self) -> float:
        finite = [s for s in self.snr_per_frame if math.isfinite(s)]
        if finite:
            return float(np.mean(finite))
        return float("inf") if self.snr_per_frame else float("nan")

    def __iter__(self) -> Iterator[np.ndarray]:
        self.snr_per_frame = []
        p = self.params
        for k, frame in enumerate(self.frames):
            grey = to_grey(frame)
            if self.backend == "numpy":
                f = _as_unit(grey)
                out = rain_frame_numpy(grey, p, self.seed, k)
                noise = float(((out - f) ** 2).sum())
                sig = float((f ** 2).sum())
                self.snr_per_frame.append(float("inf") if noise == 0 else 10.0 * math.log10(sig / noise)
                                          if sig > 0 else float("-inf"))
                yield out.astype(np.float32)
                continue
            if self._engine is None or self._engine.shape != grey.shape:
                self._engine = _TaichiRain(grey.shape, p)
            drops = draw_drops(grey.shape, p, self.seed, k)
            rain = self._engine.layer_for(drops, p)
            out, snr = self._engine.blend(grey, rain, p.weight)
            self.snr_per_frame.append(snr)
            yield out

    def layers(self, shape: tuple[int, int], n_frames: int = 1, blur: bool = True) -> Iterator[np.ndarray]:
        """Just the rain layers ``R`` (float32 (H, W), before weighting) of frames 0..n_frames-1."""
        p = self.params
        for k in range(n_frames):
            drops = draw_drops(shape, p, self.seed, k)
            if self.backend == "numpy":
                lay = streak_layer_numpy(shape, drops, p)
                yield (blur_numpy(lay, p) if blur else lay).astype(np.float32)
                continue
            if self._engine is None or self._engine.shape != tuple(shape):
                self._engine = _TaichiRain(tuple(shape), p)
            e = self._engine
            if blur:
                yield e.layer_for(drops, p).to_numpy()
            else:
                e.K.fill(e.layer, 0.0)
                if drops.row0.size:
                    e.K.draw_streaks(drops.row0, drops.col0, drops.slope, int(p.length), int(p.width),
                                     float(np.float32(p.grey)), e.layer)
                yield e.layer.to_numpy()
