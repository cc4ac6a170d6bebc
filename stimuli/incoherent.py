"""Incoherent versions of the six basic stimuli (paper, Section III-A-1; Dewell and Gabbiani 2018).

Coherence degree ``c`` in (0, 1] is the fraction of the moving object's pixels
that stay in place. On every frame ``k`` with coherent object mask ``M_k``:

* ``n_d = round((1 - c) |M_k|)`` object positions are *displaced*: they show
  the background, and each has its own *target*, a background position (not in
  ``M_k``, not another target) that shows the object colour instead;
* the other ``|M_k| - n_d`` object positions are *kept* (object colour);

so the object-coloured pixel count is exactly ``|M_k|``, as in the coherent
stimulus. State persists across frames (positions, not object-relative
coordinates): a kept position stays kept and a displaced position keeps its
target while the position stays inside the object. When a position leaves the
object its target disappears with it; when the growing object covers a
target, that target is redrawn elsewhere; positions entering the object are
displaced at random in the number that restores ``n_d`` (entering positions
that were covered targets are kept in preference, as they already show the
object colour; kept positions are displaced, or displaced ones restored, only
when the entering positions cannot absorb the count). The luminance change per frame therefore follows the
coherent one as closely as the geometry allows (see
:func:`luminance_change_match`).

Halting rule (paper): when the background cannot hold the displaced pixels
(``n_d > H W - |M_k|``) at frame ``h``, the motion stops and the sequence
jumps to its final frame, which every frame ``k >= h`` repeats (``halted_at =
h``): the last frame before ``h``, i.e. the largest object the background can
hold, still incoherent. ``c = 1`` gives the coherent stimulus exactly.

Two constructions (``scatter``) differ only in what happens to a displaced
pixel's target when its source leaves the object (a translating bar; a growing
square never loses positions, so looming and receding are the same under both):

* ``flicker`` (default): the target disappears with its source and an entering
  source draws a new one at random, so the luminance change per frame follows
  the coherent one, and for a moving bar scattered dots switch on and off
  every frame;
* ``static``: the leaving source hands its target to an entering source (in a
  seeded random pairing), so a dot, once placed, stays where it is; only a dot
  that the object covers is redrawn. The dots never move or flicker, and the
  change per frame is about ``c`` times the coherent one (only the kept part
  of the object moves).

Receding is the exact time reverse of incoherent looming with the same
coherence and seed, as the coherent receding stimulus is the time reverse of
looming. When that looming sequence halts, the receding one therefore starts by
holding the largest incoherent object that fits for ``held_frames`` frames and
then recedes (a literal forward rule would make receding at low coherence a
single jump to a still image, since the large starting object leaves no room).
``moving_frames`` is the range of frames that show the motion in both cases.

Random numbers come from ``numpy.random.default_rng([seed, k])`` per frame
(Python side); the Taichi kernels of :mod:`cdnf_ti.kernels.stimuli` do the
per-pixel scattering and rendering, so frames are identical for any thread
count and equal to the NumPy reference backend.
"""
from __future__ import annotations

from typing import Iterator

import numpy as np

from .basic import BasicStimulus, basic_stimulus, check_seed, taichi_stimulus_kernels

BACKGROUND, KEPT, DISPLACED, TARGET = 0, 1, 2, 3
BACKENDS = ("taichi", "numpy")
#: How displaced pixels behave when their source leaves the object (see :class:`IncoherentStimulus`).
SCATTERS = ("flicker", "static")


def displaced_count(n_object: int, coherence: float) -> int:
    """``round((1 - c) n_object)`` (halves round up): object pixels displaced on a frame."""
    return int(np.floor((1.0 - coherence) * n_object + 0.5))


def render_numpy(state: np.ndarray, obj: float, bg: float) -> np.ndarray:
    """NumPy reference of :func:`cdnf_ti.kernels.stimuli.incoherent_render`.

    Parameters
    ----------
    state : ndarray of int8, shape (H, W)
        Pixel states (BACKGROUND, KEPT, DISPLACED, TARGET).
    obj, bg : float
        Object and background luminance in [0, 1].

    Returns
    -------
    ndarray of float32, shape (H, W)
    """
    show = (state == KEPT) | (state == TARGET)
    return np.where(show, np.float32(obj), np.float32(bg)).astype(np.float32)


class IncoherentStimulus:
    """A basic stimulus at coherence degree ``c``, generated frame by frame.

    Parameters
    ----------
    base : BasicStimulus
        The coherent stimulus (geometry, size, fps, polarity).
    coherence : float
        ``c`` in (0, 1]: fraction of object pixels that stay in place.
    seed : int
        Seed of the random displacement; same seed, same frames.
    backend : {"taichi", "numpy"}
        Taichi kernels (default) or the NumPy reference for the per-pixel work.
    scatter : {"flicker", "static"}
        What a leaving source's target does: disappear (``flicker``, default)
        or pass to an entering source (``static``); see the module docstring.

    Attributes
    ----------
    n_frames, fps, height, width : as ``base``.
    halted_at : int or None
        First frame of the held final frame (halting rule), or ``None``
        (always ``None`` for receding; see ``held_frames``).
    final_frame_index : int
        Frame of ``base`` that the held final frame shows (``n_frames - 1`` when
        no halt).
    held_frames : int
        Receding: number of leading frames that hold the starting frame (0
        when the looming twin does not halt); 0 otherwise.
    moving_frames : range
        Frames that show the motion with exact pixel counts (before the halt,
        or after the held prefix).

    Raises
    ------
    ValueError
        ``coherence`` outside (0, 1], or no frame of ``base`` can hold its
        displaced pixels.
    """

    def __init__(self, base: BasicStimulus, coherence: float, seed: int = 0, backend: str = "taichi",
                 scatter: str = "flicker"):
        if not isinstance(base, BasicStimulus):
            raise TypeError("base must be a BasicStimulus")
        coherence = float(coherence)
        if not (0.0 < coherence <= 1.0):
            raise ValueError(f"coherence must be in (0, 1], got {coherence:g}")
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
        if scatter not in SCATTERS:
            raise ValueError(f"unknown scatter {scatter!r}; choose one of {', '.join(SCATTERS)}")
        self.scatter = scatter
        self.base = base
        self.coherence = coherence
        self.seed = check_seed(seed)
        self.backend = backend
        self.held_frames = 0
        self._forward: IncoherentStimulus | None = None
        if base.motion == "receding":
            twin = BasicStimulus(**{**base.to_dict(), "name": f"{base.polarity}_looming"})
            self._forward = IncoherentStimulus(twin, coherence, seed, backend=backend, scatter=scatter)
            self.object_pixels = self._forward.object_pixels[::-1].copy()
            self.halted_at = None
            self.final_frame_index = base.n_frames - 1
            fh = self._forward.halted_at
            self.held_frames = 0 if fh is None else base.n_frames - fh
            self._kernels = None
            return
        hw = base.height * base.width
        counts = np.array([int(base.object_mask(k).sum()) for k in range(base.n_frames)])
        fits = np.array([displaced_count(int(n), coherence) <= hw - int(n) for n in counts])
        self.object_pixels = counts
        self.halted_at: int | None = None
        self.final_frame_index = base.n_frames - 1
        if not fits.all():
            h = int(np.argmin(fits))
            self.halted_at = h
            if fits[-1]:
                self.final_frame_index = base.n_frames - 1
            elif h > 0:
                self.final_frame_index = h - 1
            else:
                raise ValueError(
                    f"{base.name} at coherence {coherence:g}: the background cannot hold the displaced "
                    f"pixels on any frame (raise the coherence or shrink the object)")
        self._kernels = None
        if backend == "taichi":
            # lazy: kernels compile for the compiler/arch that the runtime picks at run time
            self._kernels, self._blocks = taichi_stimulus_kernels(base.width)

    # -- basic properties -------------------------------------------------
    @property
    def moving_frames(self) -> range:
        """Frames that show the motion (exact pixel counts): before the halt / after the held prefix."""
        end = self.n_frames if self.halted_at is None else self.halted_at
        return range(self.held_frames, end)

    @property
    def name(self) -> str:
        return self.base.name

    @property
    def n_frames(self) -> int:
        return self.base.n_frames

    @property
    def fps(self) -> float:
        return self.base.fps

    @property
    def height(self) -> int:
        return self.base.height

    @property
    def width(self) -> int:
        return self.base.width

    @property
    def object_value(self) -> float:
        return self.base.object_value

    @property
    def background_value(self) -> float:
        return self.base.background_value

    def to_dict(self) -> dict:
        """Every parameter (for sidecars): base stimulus, coherence, seed, halting."""
        return {"stimulus": self.name, "coherence": self.coherence, "seed": self.seed, "scatter": self.scatter,
                "halted_at": self.halted_at, "final_frame_index": self.final_frame_index,
                "held_frames": self.held_frames,
                "basic": self.base.to_dict()}

    # -- generation -------------------------------------------------------
    def _set(self, state: np.ndarray, idx: np.ndarray, value: int) -> None:
        if idx.size == 0:
            return
        if self._kernels is not None:
            self._kernels.scatter_state(np.ascontiguousarray(idx, dtype=np.int32), value, state)
        else:
            state.reshape(-1)[idx] = value

    def _render(self, state: np.ndarray) -> np.ndarray:
        obj, bg = self.object_value, self.background_value
        if self._kernels is None:
            return render_numpy(state, obj, bg)
        out = np.empty(state.shape, dtype=np.float32)
        self._kernels.incoherent_render(state, out, obj, bg, self._blocks)
        return out

    def _step(self, k: int, state: np.ndarray, target_of: np.ndarray, source_of: np.ndarray) -> None:
        """Advance the persistent state to base frame ``k`` (in place)."""
        rng = np.random.default_rng([self.seed, k])
        flat = state.reshape(-1)
        static = self.scatter == "static"
        M = self.base.object_mask(k).reshape(-1)
        n_d = displaced_count(int(M.sum()), self.coherence)
        orphans = np.empty(0, dtype=np.int64)  # static: targets whose source left, still shown
        # 1. positions that left the object: their targets disappear with them (flicker)
        #    or wait for an entering source (static)
        inside = (flat == KEPT) | (flat == DISPLACED)
        left = np.flatnonzero(inside & ~M)
        if left.size:
            left_d = left[flat[left] == DISPLACED]
            t = target_of[left_d]
            if static:
                orphans = t
            else:
                self._set(state, t, BACKGROUND)
            source_of[t] = -1
            target_of[left_d] = -1
            self._set(state, left, BACKGROUND)
        # 2. targets covered by the object: redraw them below
        covered = np.flatnonzero((flat == TARGET) & M)
        if covered.size:
            src = source_of[covered]
            target_of[src[src >= 0]] = -1
            source_of[covered] = -1
            self._set(state, covered, BACKGROUND)
            if orphans.size:
                orphans = np.setdiff1d(orphans, covered, assume_unique=True)
        # 3. positions entering the object: displace as many as restore n_d
        # (covered targets go last: they already show the object colour, so
        # keeping them in place costs no luminance change)
        fresh = np.setdiff1d(np.flatnonzero(M & (flat == BACKGROUND)), covered, assume_unique=True)
        entering = np.concatenate([fresh[rng.permutation(fresh.size)], covered[rng.permutation(covered.size)]])
        n_now = int(np.count_nonzero(flat == DISPLACED))
        need = n_d - n_now
        if need >= 0:
            take = min(need, entering.size)
            self._set(state, np.sort(entering[:take]), DISPLACED)
            self._set(state, np.sort(entering[take:]), KEPT)
            if need > take:  # entering positions cannot absorb: displace kept ones
                kept = np.flatnonzero(flat == KEPT)
                self._set(state, np.sort(rng.choice(kept, need - take, replace=False)), DISPLACED)
        else:
            self._set(state, entering, KEPT)
            disp = np.flatnonzero(flat == DISPLACED)
            back = np.sort(rng.choice(disp, -need, replace=False))
            t = target_of[back]
            if static:
                orphans = np.concatenate([orphans, t])
            else:
                self._set(state, t, BACKGROUND)
            source_of[t] = -1
            target_of[back] = -1
            self._set(state, back, KEPT)
        # 4. a target for every displaced position without one (static: the
        #    orphaned targets first, so those dots stay where they are)
        lost = np.flatnonzero((flat == DISPLACED) & (target_of < 0))
        if orphans.size:
            handed = orphans[rng.permutation(orphans.size)][: lost.size]
            target_of[lost[: handed.size]] = handed
            source_of[handed] = lost[: handed.size]
            self._set(state, np.sort(orphans[source_of[orphans] < 0]), BACKGROUND)  # more dots than sources
            lost = lost[handed.size:]
        if lost.size:
            free = np.flatnonzero(flat == BACKGROUND)
            tg = free[rng.choice(free.size, lost.size, replace=False)]
            target_of[lost] = tg
            source_of[tg] = lost
            self._set(state, tg, TARGET)

    def frames(self) -> Iterator[np.ndarray]:
        """Yield the ``n_frames`` frames, float32 (H, W) in [0, 1], one at a time."""
        if self._forward is not None:
            yield from self._reversed_frames()
            return
        H, W = self.height, self.width
        state = np.zeros((H, W), dtype=np.int8)
        target_of = np.full(H * W, -1, dtype=np.int64)
        source_of = np.full(H * W, -1, dtype=np.int64)
        held: np.ndarray | None = None
        for k in range(self.n_frames):
            if self.halted_at is not None and k >= self.halted_at:
                if held is None:
                    if self.final_frame_index != k - 1:
                        state[:] = BACKGROUND
                        target_of[:] = -1
                        source_of[:] = -1
                        self._step(self.final_frame_index, state, target_of, source_of)
                    held = self._render(state)
                yield held.copy()
                continue
            self._step(k, state, target_of, source_of)
            yield self._render(state)

    def _reversed_frames(self) -> Iterator[np.ndarray]:
        """Receding: the looming twin's frames in reverse, kept as 1-bit masks (H W / 8 bytes each)."""
        H, W = self.height, self.width
        obj = self._forward.object_value
        packed = [np.packbits((f == obj).reshape(-1)) for f in self._forward.frames()]
        for bits in reversed(packed):
            mask = np.unpackbits(bits, count=H * W).reshape(H, W).astype(bool)
            yield np.where(mask, np.float32(self.object_value), np.float32(self.background_value))

    def __iter__(self) -> Iterator[np.ndarray]:
        return self.frames()

    def __len__(self) -> int:
        return self.n_frames


def incoherent_stimulus(name: str, coherence: float, seed: int = 0, backend: str = "taichi",
                        scatter: str = "flicker", **basic_kwargs) -> IncoherentStimulus:
    """Build an :class:`IncoherentStimulus` from a basic stimulus name and keyword overrides.

    Examples
    --------
    >>> s = incoherent_stimulus("dark_looming", 0.2, seed=1, height=120, width=120, start_half_size=2)
    >>> frame0 = next(iter(s))   # float32 (120, 120)
    """
    return IncoherentStimulus(basic_stimulus(name, **basic_kwargs), coherence, seed, backend=backend,
                              scatter=scatter)


def luminance_change(frames) -> np.ndarray:
    """Per-frame luminance change ``sum |F_k - F_{k-1}|`` for k >= 1, shape (T - 1,), float64."""
    out = []
    prev = None
    for f in frames:
        f = np.asarray(f, dtype=np.float64)
        if prev is not None:
            out.append(float(np.abs(f - prev).sum()))
        prev = f
    return np.array(out, dtype=np.float64)


def luminance_change_match(stim: IncoherentStimulus) -> dict:
    """Compare the incoherent per-frame luminance change with the coherent one.

    Only transitions between frames of ``stim.moving_frames`` are compared.

    Returns
    -------
    dict
        ``ratio``: total incoherent change / total coherent change;
        ``mean_abs_rel_err``: mean over frames with coherent change > 0 of
        ``|inc - coh| / coh``; ``corr``: Pearson correlation of the per-frame
        changes (nan when either is constant); ``frames``: frames compared;
        ``halted_at``.
    """
    coh = luminance_change(stim.base.frames())
    inc = luminance_change(stim.frames())
    start, stop = stim.moving_frames.start, stim.moving_frames.stop
    coh, inc = coh[start:max(stop - 1, start)], inc[start:max(stop - 1, start)]
    n = int(coh.size)
    pos = coh > 0
    ratio = float(inc.sum() / coh.sum()) if coh.sum() > 0 else float("nan")
    rel = float(np.mean(np.abs(inc[pos] - coh[pos]) / coh[pos])) if pos.any() else float("nan")
    corr = float(np.corrcoef(inc, coh)[0, 1]) if n > 1 and inc.std() > 0 and coh.std() > 0 else float("nan")
    return {"ratio": ratio, "mean_abs_rel_err": rel, "corr": corr, "frames": int(n), "halted_at": stim.halted_at,
            "held_frames": stim.held_frames}
