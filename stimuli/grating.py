"""A drifting square-wave grating: a non-looming stimulus full of moving edges.

Bars of ``bar_width`` px repeat every ``period`` px and drift at ``speed``
px/s, perpendicular to the bars (vertical bars move along x). Every frame has
the same amount of each grey level, so nothing expands: a looming detector
should stay silent. The starting phase is drawn from ``seed`` (``seed=None``:
phase 0), so the same seed gives the same frames.

On frame ``k`` the pattern is shifted by ``shift_k = floor(phase_0 + speed k /
fps)`` px (integer), and pixel position ``p`` (column, or row for horizontal
bars) shows the bar grey where ``(p - shift_k) mod period < bar_width``. The
integer shift makes the Taichi kernel
(:func:`cdnf_ti.kernels.stimuli.render_grating`) and the NumPy reference
(:func:`grating_numpy`) give identical frames.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .basic import BACKENDS, FrameStream, check_seed, taichi_stimulus_kernels

ORIENTATIONS = ("vertical", "horizontal")


def grating_numpy(height: int, width: int, shift: int, period: int, bar: int, vertical: bool,
                  obj: float, bg: float) -> np.ndarray:
    """NumPy reference of :func:`cdnf_ti.kernels.stimuli.render_grating`.

    Returns
    -------
    ndarray of float32, shape (height, width)
        ``obj`` where ``(p - shift) mod period < bar`` (``p`` the column if
        ``vertical`` else the row), ``bg`` elsewhere.
    """
    p = np.arange(width if vertical else height)
    on = np.mod(p - shift, period) < bar
    line = np.where(on, np.float32(obj), np.float32(bg)).astype(np.float32)
    if vertical:
        return np.repeat(line[None, :], height, axis=0)
    return np.repeat(line[:, None], width, axis=1)


@dataclass(frozen=True)
class GratingStimulus(FrameStream):
    """A drifting square-wave grating, generated frame by frame.

    Attributes
    ----------
    height, width : int
        Frame size in px.
    fps : float
        Frames per second.
    duration : float
        Seconds; ``round(duration * fps) + 1`` frames.
    period : int or None
        Spatial period in px; ``None`` = a fifth of the frame side across the
        bars (64 px at 320 px: bars 32 px wide).
    bar_width : int or None
        Width of the bar-grey part of each period in px; ``None`` = half the
        period.
    speed : float or None
        Drift speed in px/s; ``None`` = one period per second.
    orientation : {"vertical", "horizontal"}
        Bars vertical (drift along x) or horizontal (drift along y).
    bar_grey, background_grey : float
        Grey levels in [0, 1] (different).
    seed : int or None
        Seed of the starting phase (uniform in [0, period) px); None = 0.
    backend : {"taichi", "numpy"}
        Who renders the frames (identical results).
    """

    height: int = 240
    width: int = 320
    fps: float = 30.0
    duration: float = 1.5
    period: int | None = None
    bar_width: int | None = None
    speed: float | None = None
    orientation: str = "vertical"
    bar_grey: float = 0.0
    background_grey: float = 1.0
    seed: int | None = None
    backend: str = "taichi"

    def __post_init__(self) -> None:
        if self.height < 8 or self.width < 8:
            raise ValueError(f"frame must be at least 8x8 px, got {self.width}x{self.height}")
        if self.orientation not in ORIENTATIONS:
            raise ValueError(f"unknown orientation {self.orientation!r}; choose one of {', '.join(ORIENTATIONS)}")
        if self.backend not in BACKENDS:
            raise ValueError(f"unknown backend {self.backend!r}; choose one of {', '.join(BACKENDS)}")
        for name in ("fps", "duration"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v}")
        if self.duration * self.fps > 1_000_000:
            raise ValueError(f"duration x fps = {self.duration * self.fps:g} frames is too many (max 1e6)")
        across = self.width if self.vertical else self.height
        if self.period is None:
            object.__setattr__(self, "period", max(2, int(round(across / 5))))
        if int(self.period) != self.period or self.period < 2:
            raise ValueError(f"period must be a whole number of px >= 2, got {self.period}")
        object.__setattr__(self, "period", int(self.period))
        if self.bar_width is None:
            object.__setattr__(self, "bar_width", self.period // 2)
        if int(self.bar_width) != self.bar_width or not (0 < self.bar_width < self.period):
            raise ValueError(f"bar_width must be a whole number of px in (0, period), got {self.bar_width}")
        object.__setattr__(self, "bar_width", int(self.bar_width))
        if self.speed is None:
            object.__setattr__(self, "speed", float(self.period))
        if not math.isfinite(self.speed):
            raise ValueError(f"speed must be finite, got {self.speed}")
        for name in ("bar_grey", "background_grey"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0.0 <= v <= 1.0):
                raise ValueError(f"{name} must be in [0, 1], got {v}")
        if self.bar_grey == self.background_grey:
            raise ValueError("bar_grey and background_grey must differ")
        if self.seed is not None:
            check_seed(self.seed)

    @property
    def vertical(self) -> bool:
        return self.orientation == "vertical"

    @property
    def n_frames(self) -> int:
        return int(round(self.duration * self.fps)) + 1

    @property
    def phase0(self) -> float:
        """Starting phase in px, drawn from ``seed`` (0 without a seed)."""
        if self.seed is None:
            return 0.0
        return float(np.random.default_rng([self.seed, 0x67]).uniform(0.0, self.period))

    def shift(self, k: int) -> int:
        """Integer pattern shift (px) on frame ``k``."""
        return int(math.floor(self.phase0 + self.speed * k / self.fps))

    def frame(self, k: int) -> np.ndarray:
        """Frame ``k`` as float32 (H, W) in [0, 1]."""
        sh = self.shift(k)
        if self.backend == "numpy":
            return grating_numpy(self.height, self.width, sh, self.period, self.bar_width, self.vertical,
                                 self.bar_grey, self.background_grey)
        K, blocks = taichi_stimulus_kernels(self.width)
        out = np.empty((self.height, self.width), dtype=np.float32)
        K.render_grating(out, sh, self.period, self.bar_width, int(self.vertical), self.bar_grey,
                         self.background_grey, blocks)
        return out

    def to_dict(self) -> dict:
        return {"name": "grating", **asdict(self)}
