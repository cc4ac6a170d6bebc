"""Size limits checked before any work, so that an impossible request fails at once with one line
instead of a MemoryError (or hours of swapping) later.

Limits (see docs/CLI.md, "Limits"):

* frame side at least :data:`MIN_SIDE` px where models run (the widest kernel: a smaller frame
  cannot hold one receptive field, and the models' output on it means nothing), and at most
  :data:`MAX_SIDE` px;
* estimated working memory of one run at most half of this machine's physical
  memory: :data:`BYTES_PER_PIXEL_PER_MODEL` bytes per pixel per model (measured:
  C-DNF ~90 B/px, LGMD2 ~48, LGMD1 ~44, SDNF ~40, with float32 fields and
  solver work space) plus :data:`BYTES_PER_PIXEL_PIPELINE` for decoding, rain and
  prefetched frames, plus :data:`BYTES_PER_PIXEL_BINNING` when the input is an event recording
  and :data:`BYTES_PER_PIXEL_EMULATOR` when a video is turned into events (``events VIDEO``).
  On a 16 GB machine one model runs frames up to about 7,300 x 7,300 px; all five models
  together about 3,500 x 3,500. ``run``, ``dataset``, ``events --info`` and the emulator all
  check this one estimate (:func:`check_frame_size`) before any work;
* rain droplets per frame at most :data:`MAX_DROPS` and at most one per pixel
  (at that density every pixel is already covered ``length`` times over).
"""
from __future__ import annotations

import math
import os

from .errors import UserError

MAX_SIDE = 16384
#: The widest default kernel (px): C-DNF's Summation DoG, ``2 ceil(3 sigma_2) + 1`` with ``sigma_2 = 1``.
MIN_SIDE = 7
BYTES_PER_PIXEL_PER_MODEL = 128
BYTES_PER_PIXEL_PIPELINE = 32
#: Binning an event recording into model input, B/px (measured 56 B/px on a 1000x800 sensor: the
#: bin being filled, one part's counts and the bin handed on, 2 x int64 each, plus the ON/OFF
#: float64 inputs; :func:`cdnf_ti.events.binning.bin_events`).
BYTES_PER_PIXEL_BINNING = 64
#: The video-to-events emulator's per-pixel state, B/px (measured 74 B/px on 800x600 frames: log
#: intensity, references, thresholds, last event time; :func:`cdnf_ti.events.emulator.emulate`).
#: The events of one frame come on top (16 B each).
BYTES_PER_PIXEL_EMULATOR = 96
MAX_DROPS = 1_000_000
#: Fraction of physical memory one run may plan to use.
MEMORY_FRACTION = 0.5


def physical_memory() -> int | None:
    """Bytes of physical memory, or None when unknown."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def frame_bytes(height: int, width: int, n_models: int = 1, binning: bool = False, emulating: bool = False) -> int:
    """Estimated working memory (bytes) of running ``n_models`` models on (height, width) frames.

    ``binning``: the frames are bins of an event recording (adds :data:`BYTES_PER_PIXEL_BINNING`);
    ``emulating``: a video is turned into events (adds :data:`BYTES_PER_PIXEL_EMULATOR`).
    """
    per_pixel = BYTES_PER_PIXEL_PER_MODEL * max(1, n_models) + BYTES_PER_PIXEL_PIPELINE
    per_pixel += BYTES_PER_PIXEL_BINNING * bool(binning) + BYTES_PER_PIXEL_EMULATOR * bool(emulating)
    return int(height) * int(width) * per_pixel


def _gb(b: float) -> str:
    return f"{b / 2**30:.1f} GB"


def check_frame_size(height: int, width: int, n_models: int = 1, what: str = "frame", binning: bool = False,
                     emulating: bool = False) -> None:
    """Raise :class:`~cdnf_ti.errors.UserError` if (height, width) frames cannot be run here.

    Parameters
    ----------
    height, width : int
        Frame size in px.
    n_models : int
        Models run together on each frame (0: frames are only written, e.g. ``generate``; then
        the :data:`MIN_SIDE` limit does not apply).
    what : str
        What the size belongs to, for the message (``"--size"``, ``"clip.mp4"``).
    binning, emulating : bool
        The frames are binned from events / turned into events (:func:`frame_bytes`).
    """
    h, w = int(height), int(width)
    if n_models > 0 and (h < MIN_SIDE or w < MIN_SIDE):
        raise UserError(f"{what}: frames of {w}x{h} px are smaller than the widest kernel; the models need at "
                        f"least {MIN_SIDE}x{MIN_SIDE} px")
    if h < 2 or w < 2:
        raise UserError(f"{what}: a frame must be at least 2x2 px, got {w}x{h}")
    if max(h, w) > MAX_SIDE:
        raise UserError(f"{what}: frames of {w}x{h} px are too large (at most {MAX_SIDE} px a side)")
    mem = physical_memory()
    need = frame_bytes(h, w, n_models, binning, emulating)
    if mem is not None and need > MEMORY_FRACTION * mem:
        side = int(math.sqrt(MEMORY_FRACTION * mem / (frame_bytes(1, 1, n_models, binning, emulating))))
        work = " and ".join([s for s, on in (("binning events", binning), ("emulating events", emulating)) if on]
                            + [f"{n_models} model(s)"] * (n_models > 0))
        raise UserError(f"{what}: frames of {w}x{h} px need about {_gb(need)} for {work}, more "
                        f"than half of this machine's {_gb(mem)} of memory; largest square frame here: about "
                        f"{side}x{side} px")


def check_drops(drops: int | None, shape: tuple[int, int] | None = None, what: str = "--rain-drops") -> None:
    """Raise :class:`~cdnf_ti.errors.UserError` for an impossible rain droplet count.

    ``None`` (the default density) is always fine. With ``shape`` the count is
    also checked against the frame area.
    """
    if drops is None:
        return
    if drops < 0:
        raise UserError(f"{what} must be >= 0, got {drops}")
    if drops > MAX_DROPS:
        raise UserError(f"{what} {drops} is too many droplets per frame (at most {MAX_DROPS:,})")
    if shape is not None and drops > shape[0] * shape[1]:
        raise UserError(f"{what} {drops} is more droplets than the {shape[1]}x{shape[0]} frame has pixels "
                        f"({shape[0] * shape[1]:,})")
