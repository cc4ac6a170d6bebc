"""The six basic stimuli of the paper's Table I.

* looming: a square centred in the frame approaching at constant speed, so its
  half-size grows as ``r(t) = r_0 tau_0 / (tau_0 - t)`` (1 / time-to-contact;
  ``expansion="inverse"``, the default), or, for the selectivity grid, with its
  edges moving at constant image speed (``expansion="linear"``);
* receding: the exact time reverse of looming;
* translating: a full-height bar crossing the frame left to right at constant
  speed (the whole crossing in ``duration``, or at ``speed`` px/s).

"dark" objects are 0 on a background of 1, "light" objects 1 on 0; the grey
levels can be set (``object_grey``, ``background_grey``) for low-contrast
stimuli. The default start half-size scales with the frame
(:func:`default_start_half_size`, ``min(H, W) / 60``: 10 px at 600 px), the
one place that rule lives.

Frames are rendered by NumPy (``backend="numpy"``, the reference) or by the
Taichi kernel :func:`cdnf_ti.kernels.stimuli.render_box` (``backend="taichi"``);
both give identical frames.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Iterator

import numpy as np

from ..kernels import stimuli as stimulus_kernels
from ..taichi_runtime import current_arch, ensure_taichi, kernels

#: Image-size laws of the looming/receding square (``BasicStimulus.expansion``).
EXPANSIONS = ("inverse", "linear")
BACKENDS = ("numpy", "taichi")

#: Start half-size of the looming square as a fraction of the smaller frame side.
START_HALF_SIZE_FRACTION = 1.0 / 60.0


def default_start_half_size(height: int, width: int | None = None) -> float:
    """Default start half side of the looming square in px: ``min(H, W) / 60`` (10 px at 600 px).

    The one source of the project's ``size / 60`` rule: every stimulus built
    for a frame size (demo, experiments, ``stim:`` inputs, ``generate``) gets
    the paper's 600 px geometry scaled to that size.
    """
    side = height if width is None else min(height, width)
    return side * START_HALF_SIZE_FRACTION


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


class FrameStream:
    """Mixin for a stimulus with ``n_frames`` and ``frame(k)``: streams its frames, one at a time."""

    n_frames: int

    def frame(self, k: int) -> np.ndarray:  # pragma: no cover - supplied by the stimulus
        raise NotImplementedError

    def frames(self) -> Iterator[np.ndarray]:
        """Yield every frame in order, (H, W) float32 grey in [0, 1] each."""
        for k in range(self.n_frames):
            yield self.frame(k)

    def __iter__(self) -> Iterator[np.ndarray]:
        return self.frames()


@dataclass(frozen=True)
class BasicStimulus(FrameStream):
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
    start_half_size : float or None
        Looming: half side of the square at t = 0 in px (receding: at the end);
        ``None`` = :func:`default_start_half_size` (``min(H, W) / 60``).
    end_half_size : float or None
        Looming: half side at t = duration in px; ``None`` = 45% of the smaller
        frame side (the square nearly fills the frame). The constant-speed
        approach then has ``tau_0 = duration * r_1 / (r_1 - r_0)`` seconds to
        contact at t = 0, i.e. ``l / |v| = r_0 tau_0`` px*s in image units.
    bar_width : int or None
        Translating: bar width in px; ``None`` = a tenth of the frame width.
    expansion : {"inverse", "linear"}
        Looming/receding size law: ``"inverse"`` (constant approach speed,
        ``r(t) = r_0 tau_0 / (tau_0 - t)``) or ``"linear"`` (constant edge
        speed, ``r(t) = r_0 + (r_1 - r_0) t / duration``).
    object_grey, background_grey : float or None
        Grey levels in [0, 1]; ``None`` = the polarity's (dark: 0 on 1, light:
        1 on 0). A dark object must be darker than its background, a light one
        lighter.
    speed : float or None
        Translating: bar speed in px/s; the sequence then lasts the crossing,
        ``duration = (width - bar_width) / speed`` (``duration`` is replaced).
        ``None``: the bar crosses the frame in ``duration``.
    backend : {"numpy", "taichi"}
        Who renders the frames (identical results).
    """

    name: str = "dark_looming"
    height: int = 600
    width: int = 600
    fps: float = 30.0
    duration: float = 1.5
    start_half_size: float | None = None
    end_half_size: float | None = None
    bar_width: int | None = None
    expansion: str = "inverse"
    object_grey: float | None = None
    background_grey: float | None = None
    speed: float | None = None
    backend: str = "numpy"

    def __post_init__(self) -> None:
        if self.name not in BASIC_STIMULI:
            raise ValueError(f"unknown stimulus {self.name!r}; choose one of {', '.join(BASIC_STIMULI)}")
        if self.height < 8 or self.width < 8:
            raise ValueError(f"frame must be at least 8x8 px, got {self.width}x{self.height}")
        if self.expansion not in EXPANSIONS:
            raise ValueError(f"unknown expansion {self.expansion!r}; choose one of {', '.join(EXPANSIONS)}")
        if self.backend not in BACKENDS:
            raise ValueError(f"unknown backend {self.backend!r}; choose one of {', '.join(BACKENDS)}")
        if self.start_half_size is None:
            object.__setattr__(self, "start_half_size", default_start_half_size(self.height, self.width))
        if self.bar_width is None:
            object.__setattr__(self, "bar_width", max(1, int(round(self.width / 10))))
        if self.speed is not None:
            if not (math.isfinite(self.speed) and self.speed > 0):
                raise ValueError(f"speed must be a finite number > 0 px/s, got {self.speed}")
            if self.motion != "translating":
                raise ValueError("speed applies to translating stimuli only")
            object.__setattr__(self, "duration", (self.width - self.bar_width) / self.speed)
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
        if not (0 < self.start_half_size < self.end_half_size):
            raise ValueError("need 0 < start_half_size < end_half_size")
        if not (0 < self.bar_width < self.width):
            raise ValueError("need 0 < bar_width < width")
        if self.n_frames < 2:
            raise ValueError(f"duration x fps = {self.duration * self.fps:g}: need at least 2 frames")
        dark = self.polarity == "dark"
        if self.object_grey is None:
            object.__setattr__(self, "object_grey", 0.0 if dark else 1.0)
        if self.background_grey is None:
            object.__setattr__(self, "background_grey", 1.0 if dark else 0.0)
        for name in ("object_grey", "background_grey"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0.0 <= v <= 1.0):
                raise ValueError(f"{name} must be in [0, 1], got {v}")
        if dark and not self.object_grey < self.background_grey:
            raise ValueError(f"a dark object needs object_grey < background_grey, got "
                             f"{self.object_grey:g} on {self.background_grey:g}")
        if not dark and not self.object_grey > self.background_grey:
            raise ValueError(f"a light object needs object_grey > background_grey, got "
                             f"{self.object_grey:g} on {self.background_grey:g}")

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
        """Object grey level in [0, 1]."""
        return float(self.object_grey)

    @property
    def background_value(self) -> float:
        """Background grey level in [0, 1]."""
        return float(self.background_grey)

    @property
    def contrast(self) -> float:
        """Michelson contrast ``|o - b| / (o + b)`` of object and background."""
        o, b = self.object_value, self.background_value
        return abs(o - b) / (o + b)

    @property
    def tau0(self) -> float:
        """Looming (``expansion="inverse"``): time to contact at t = 0 (s)."""
        r0, r1 = self.start_half_size, self.end_half_size
        return self.duration * r1 / (r1 - r0)

    def half_size(self, k: int) -> float:
        """Looming/receding: the square's half side (px) on frame ``k``."""
        if self.motion == "receding":
            k = self.n_frames - 1 - k
        t = k / self.fps
        if self.expansion == "linear":
            return self.start_half_size + (self.end_half_size - self.start_half_size) * t / self.duration
        return self.start_half_size * self.tau0 / (self.tau0 - t)

    def bar_left(self, k: int) -> int:
        """Translating: the bar's left column on frame ``k``."""
        travel = self.width - self.bar_width
        if self.speed is not None:
            return min(int(round(self.speed * k / self.fps)), travel)
        return int(round(travel * k / (self.n_frames - 1)))

    def box(self, k: int) -> tuple[int, int, int, int]:
        """The object's pixels on frame ``k`` as ``(y0, y1, x0, x1)``: rows ``y0..y1-1``, columns ``x0..x1-1``."""
        H, W = self.height, self.width
        if self.motion == "translating":
            x0 = self.bar_left(k)
            return 0, H, x0, x0 + self.bar_width
        r = self.half_size(k)
        cy, cx = (H - 1) / 2.0, (W - 1) / 2.0
        y0, y1 = int(np.ceil(cy - r)), int(np.floor(cy + r))
        x0, x1 = int(np.ceil(cx - r)), int(np.floor(cx + r))
        return max(y0, 0), min(y1 + 1, H), max(x0, 0), min(x1 + 1, W)

    def object_mask(self, k: int) -> np.ndarray:
        """Boolean (H, W) mask of the object's pixels on frame ``k``."""
        mask = np.zeros((self.height, self.width), dtype=bool)
        y0, y1, x0, x1 = self.box(k)
        mask[y0:y1, x0:x1] = True
        return mask

    def frame(self, k: int) -> np.ndarray:
        """Frame ``k`` as float32 (H, W) in [0, 1]."""
        f = np.full((self.height, self.width), self.background_value, dtype=np.float32)
        y0, y1, x0, x1 = self.box(k)
        if self.backend == "taichi":
            K, blocks = taichi_stimulus_kernels(self.width)
            K.render_box(f, y0, y1, x0, x1, self.object_value, self.background_value, blocks)
            return f
        f[y0:y1, x0:x1] = self.object_value
        return f

    def to_dict(self) -> dict:
        return asdict(self)


def taichi_stimulus_kernels(width: int):
    """``(cdnf_ti.kernels.stimuli, work items per row)`` for frames ``width`` px wide.

    Initialises Taichi on first use (on the process's arch); the work items per row are
    :func:`cdnf_ti.kernels.stimuli.column_blocks` of that arch.
    """
    arch = ensure_taichi(current_arch() or "cpu")
    return kernels("stimuli"), stimulus_kernels.column_blocks(width, arch)


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
