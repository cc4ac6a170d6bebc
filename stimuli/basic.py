"""The six basic stimuli of the paper's Table I.

* looming: a square centred in the frame approaching at constant speed, so its
  half-size grows as ``r(t) = r_0 tau_0 / (tau_0 - t)`` (1 / time-to-contact);
* receding: the exact time reverse of looming;
* translating: a full-height bar crossing the frame left to right at constant speed.

"dark" objects are 0 on a background of 1, "light" objects 1 on 0.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Iterator

import numpy as np

BASIC_STIMULI = (
    "dark_looming",
    "light_looming",
    "dark_receding",
    "light_receding",
    "dark_translating",
    "light_translating",
)

PAPER_LABELS = {
    "dark_looming": "Dark approaching",
    "light_looming": "Light approaching",
    "dark_receding": "Dark receding",
    "light_receding": "Light receding",
    "dark_translating": "Dark translating",
    "light_translating": "Light translating",
}


@dataclass(frozen=True)
class BasicStimulus:
    """Parameters of one basic stimulus.

    Attributes
    ----------
    name : str
        One of :data:`BASIC_STIMULI` (``"<dark|light>_<looming|receding|translating>"``).
    height, width : int
        Frame size in pixels (600 x 600 in the paper).
    fps : float
        Frames per second (30).
    duration : float
        Length of the motion in seconds; the sequence has ``round(duration * fps) + 1``
        frames (frame 0 at t = 0, the last at t = duration).
    start_half_size : float
        Looming: half side of the square at t = 0 in px (receding: at the end).
    end_half_size : float or None
        Looming: half side at t = duration in px; ``None`` = 45% of the smaller
        frame side (the square nearly fills the frame). The constant-speed
        approach then has ``tau_0 = duration * r_1 / (r_1 - r_0)`` seconds to
        contact at t = 0, i.e. ``l / |v| = r_0 tau_0`` px*s in image units.
    bar_width : int or None
        Translating: bar width in px; ``None`` = a tenth of the frame width.
    """

    name: str = "dark_looming"
    height: int = 600
    width: int = 600
    fps: float = 30.0
    duration: float = 1.5
    start_half_size: float = 10.0
    end_half_size: float | None = None
    bar_width: int | None = None

    def __post_init__(self) -> None:
        if self.name not in BASIC_STIMULI:
            raise ValueError(f"unknown stimulus {self.name!r}; choose one of {', '.join(BASIC_STIMULI)}")
        if self.height < 8 or self.width < 8:
            raise ValueError(f"frame must be at least 8x8 px, got {self.width}x{self.height}")
        for name in ("fps", "duration", "start_half_size"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)}")
        if not (self.fps > 0 and self.duration > 0):
            raise ValueError("fps and duration must be > 0")
        if self.duration * self.fps > 1_000_000:
            raise ValueError(f"duration x fps = {self.duration * self.fps:g} frames is too many (max 1e6)")
        if self.end_half_size is None:
            object.__setattr__(self, "end_half_size", 0.45 * min(self.height, self.width))
        if not math.isfinite(self.end_half_size):
            raise ValueError(f"end_half_size must be finite, got {self.end_half_size}")
        if self.bar_width is None:
            object.__setattr__(self, "bar_width", max(1, int(round(self.width / 10))))
        if not (0 < self.start_half_size < self.end_half_size):
            raise ValueError("need 0 < start_half_size < end_half_size")
        if not (0 < self.bar_width < self.width):
            raise ValueError("need 0 < bar_width < width")

    @property
    def polarity(self) -> str:
        return self.name.split("_")[0]

    @property
    def motion(self) -> str:
        return self.name.split("_")[1]

    @property
    def n_frames(self) -> int:
        return int(round(self.duration * self.fps)) + 1

    @property
    def object_value(self) -> float:
        return 0.0 if self.polarity == "dark" else 1.0

    @property
    def background_value(self) -> float:
        return 1.0 - self.object_value

    @property
    def tau0(self) -> float:
        """Looming: time to contact at t = 0 (s)."""
        r0, r1 = self.start_half_size, self.end_half_size
        return self.duration * r1 / (r1 - r0)

    def half_size(self, k: int) -> float:
        """Looming/receding: the square's half side (px) on frame ``k``."""
        if self.motion == "receding":
            k = self.n_frames - 1 - k
        t = k / self.fps
        return self.start_half_size * self.tau0 / (self.tau0 - t)

    def object_mask(self, k: int) -> np.ndarray:
        """Boolean (H, W) mask of the object's pixels on frame ``k``."""
        H, W = self.height, self.width
        mask = np.zeros((H, W), dtype=bool)
        if self.motion == "translating":
            travel = W - self.bar_width
            x0 = int(round(travel * k / (self.n_frames - 1)))
            mask[:, x0 : x0 + self.bar_width] = True
        else:
            r = self.half_size(k)
            cy, cx = (H - 1) / 2.0, (W - 1) / 2.0
            y0, y1 = int(np.ceil(cy - r)), int(np.floor(cy + r))
            x0, x1 = int(np.ceil(cx - r)), int(np.floor(cx + r))
            mask[max(y0, 0) : min(y1 + 1, H), max(x0, 0) : min(x1 + 1, W)] = True
        return mask

    def frame(self, k: int) -> np.ndarray:
        """Frame ``k`` as float32 (H, W) in [0, 1]."""
        f = np.full((self.height, self.width), self.background_value, dtype=np.float32)
        f[self.object_mask(k)] = self.object_value
        return f

    def frames(self) -> Iterator[np.ndarray]:
        """Yield every frame in order."""
        for k in range(self.n_frames):
            yield self.frame(k)

    def __iter__(self) -> Iterator[np.ndarray]:
        return self.frames()

    def to_dict(self) -> dict:
        return asdict(self)


def check_seed(seed: object) -> int:
    """Return ``seed`` as an int, or raise ``ValueError`` unless it is a non-negative integer."""
    try:
        value = int(seed)  # type: ignore[call-overload]
    except (TypeError, ValueError):
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}") from None
    if value != seed or value < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return value


def basic_stimulus(name: str, **params) -> BasicStimulus:
    """Build a :class:`BasicStimulus` by name with keyword overrides."""
    return BasicStimulus(name=name, **params)
