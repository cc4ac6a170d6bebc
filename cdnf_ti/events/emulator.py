"""Video -> events: a DVS pixel model run on frames (``python -m cdnf_ti.run events VIDEO --out FILE``).

Per pixel, as ESIM (Rebecq et al., CoRL 2018) and v2e (Hu et al., CVPR-W 2021):

* log intensity ``l = ln(L + eps)`` of the grey level ``L`` in [0, 1] (``eps``,
  default 0.01, keeps black finite; v2e uses a linear segment near black to the
  same end);
* a reference level ``r``, set to ``l`` at the first frame;
* between two frames ``l`` moves linearly in time (ESIM's interpolation); each
  time it crosses ``r + C_on`` an ON event is emitted at the interpolated
  crossing time and ``r += C_on`` (OFF: ``r - C_off``, ``r -= C_off``), so a
  change ``dl`` gives ``floor(dl / C)`` events;
* threshold mismatch: per-pixel thresholds ``C (1 + sigma z)``, ``z ~ N(0, 1)``
  drawn once (clipped at ``0.01 C``), as v2e's ``sigma_thres``;
* refractory period: an event closer than ``refractory_ms`` to the pixel's
  previous event is not emitted; the reference still moves (the change is
  consumed, as in v2e);
* shot noise: per pixel a Poisson process of ``shot_noise_hz`` events/s with
  random polarity and uniform times (v2e's ``shot_noise_rate_hz``); noise events
  leave the reference as it is.

Not modelled (v2e has them): the photoreceptor's intensity-dependent low-pass
bandwidth, leak events, temporal noise of the thresholds. Frame ``k`` is at
``round(k 1e6 / fps)`` µs; an event's timestamp is its crossing time rounded down
to the µs and before the next frame's, so the events between frames ``k - 1`` and
``k`` fall in bin ``k - 1`` of bins one frame long. Every random draw comes from one
``numpy.random.default_rng(seed)``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Iterator

import numpy as np

from .types import EVENT_DTYPE


@dataclass(frozen=True)
class EmulatorParams:
    """Pixel model of :func:`emulate` (see the module docstring).

    Attributes
    ----------
    threshold_on, threshold_off : float
        ``C_on``, ``C_off``: log-intensity steps per ON / OFF event (> 0).
    threshold_sigma : float
        Relative standard deviation of the per-pixel thresholds (>= 0).
    refractory_ms : float
        Minimum time between two events of one pixel, ms (>= 0).
    shot_noise_hz : float
        Noise events per pixel per second (>= 0).
    log_eps : float
        ``eps`` of ``ln(L + eps)`` (> 0).
    """

    threshold_on: float = 0.15
    threshold_off: float = 0.15
    threshold_sigma: float = 0.0
    refractory_ms: float = 0.0
    shot_noise_hz: float = 0.0
    log_eps: float = 0.01

    def __post_init__(self):
        for name in ("threshold_on", "threshold_off", "log_eps"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v}")
        for name in ("threshold_sigma", "refractory_ms", "shot_noise_hz"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")


def _grey01(frame: np.ndarray) -> np.ndarray:
    g = np.asarray(frame, dtype=np.float64)
    return g / 255.0 if frame.dtype == np.uint8 else g


def emulate(frames: Iterable[np.ndarray], fps: float, params: EmulatorParams = EmulatorParams(),
            seed: int = 0) -> Iterator[np.ndarray]:
    """Events of a grey video, one time-sorted chunk per frame interval.

    Parameters
    ----------
    frames : iterable of ndarray, shape (H, W)
        Grey frames, uint8 (0..255) or float in [0, 1].
    fps : float
        Frame rate, frames/s.
    params : EmulatorParams
    seed : int
        Seed of the threshold mismatch and the shot noise.

    Yields
    ------
    ndarray of :data:`~cdnf_ti.events.types.EVENT_DTYPE`
        The events between frame ``k - 1`` and frame ``k`` (``k >= 1``), sorted by ``t``.
    """
    rng = np.random.default_rng(seed)
    p = params
    refractory_us = p.refractory_ms * 1000.0
    ref = l_prev = c_on = c_off = last = None
    for k, frame in enumerate(frames):
        l_new = np.log(_grey01(frame) + p.log_eps)
        if ref is None:
            h, w = l_new.shape
            ref = l_new.copy()
            c_on = np.full((h, w), p.threshold_on)
            c_off = np.full((h, w), p.threshold_off)
            if p.threshold_sigma > 0:
                c_on *= np.maximum(1.0 + p.threshold_sigma * rng.standard_normal((h, w)), 0.01)
                c_off *= np.maximum(1.0 + p.threshold_sigma * rng.standard_normal((h, w)), 0.01)
            last = np.full((h, w), -np.inf)
            l_prev = l_new
            continue
        t_a, t_b = round((k - 1) * 1e6 / fps), round(k * 1e6 / fps)
        parts = [_crossings(l_prev, l_new, ref, c_on, c_off, t_a, t_b, last, refractory_us)]
        if p.shot_noise_hz > 0:
            parts.append(_shot_noise(rng, l_new.shape, p.shot_noise_hz, t_a, t_b))
        ev = np.concatenate(parts)
        yield ev[np.argsort(ev["t"], kind="stable")]
        l_prev = l_new


def _crossings(l_prev, l_new, ref, c_on, c_off, t_a, t_b, last, refractory_us) -> np.ndarray:
    """Threshold crossings of the linear path ``l_prev -> l_new`` over ``[t_a, t_b]``; updates ``ref``, ``last``."""
    n_on = np.floor(np.maximum(l_new - ref, 0.0) / c_on).astype(np.int64)
    n_off = np.floor(np.maximum(ref - l_new, 0.0) / c_off).astype(np.int64)
    n = np.maximum(n_on, n_off)
    ys, xs = np.nonzero(n)
    out = []
    if ys.size:
        nn, on = n[ys, xs], n_on[ys, xs] > 0
        step = np.where(on, c_on[ys, xs], -c_off[ys, xs])
        r0, a, d = ref[ys, xs], l_prev[ys, xs], l_new[ys, xs] - l_prev[ys, xs]
        lst = last[ys, xs]
        for j in range(1, int(nn.max()) + 1):
            sel = nn >= j
            # where the path is flat (d = 0) the crossing is owed from before the interval: at its start
            frac = np.clip(np.divide(r0[sel] + j * step[sel] - a[sel], d[sel], out=np.zeros(int(sel.sum())),
                                     where=d[sel] != 0.0), 0.0, 1.0)
            t = np.minimum(np.floor(t_a + frac * (t_b - t_a)), max(t_b - 1, t_a))
            ok = t - lst[sel] >= refractory_us
            idx = np.flatnonzero(sel)[ok]
            lst[idx] = t[ok]
            e = np.empty(idx.size, dtype=EVENT_DTYPE)
            e["t"], e["x"], e["y"], e["p"] = t[ok], xs[idx], ys[idx], on[idx]
            out.append(e)
        last[ys, xs] = lst
        ref[ys, xs] = r0 + nn * step
    return np.concatenate(out) if out else np.empty(0, dtype=EVENT_DTYPE)


def _shot_noise(rng: np.random.Generator, shape: tuple[int, int], rate_hz: float, t_a: int, t_b: int) -> np.ndarray:
    h, w = shape
    counts = rng.poisson(rate_hz * (t_b - t_a) * 1e-6, size=h * w)
    pix = np.repeat(np.arange(h * w), counts)
    e = np.empty(pix.size, dtype=EVENT_DTYPE)
    e["t"] = rng.integers(t_a, max(t_b, t_a + 1), size=pix.size)
    e["x"], e["y"] = pix % w, pix // w
    e["p"] = rng.integers(0, 2, size=pix.size)
    return e
