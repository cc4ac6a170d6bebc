"""A second DVS emulator, written apart from :mod:`cdnf_ti.events.emulator`, for tests of the event path.

It differs on purpose where emulators differ: v2e's lin-log intensity (linear below
20 grey levels, log above, continuous at 20), no interpolation between frames (a
pixel's events of a frame interval are spread evenly over it), and the reference
level reset to the current intensity after firing (so the remainder below one
threshold is dropped rather than carried).
"""
from __future__ import annotations

import numpy as np

LIN_LOG_KNEE = 20.0  # grey levels (0..255)


def lin_log(grey255: np.ndarray) -> np.ndarray:
    """v2e's lin-log: ``x ln(20) / 20`` below 20 grey levels, ``ln x`` above."""
    x = np.asarray(grey255, dtype=np.float64)
    return np.where(x < LIN_LOG_KNEE, x * np.log(LIN_LOG_KNEE) / LIN_LOG_KNEE, np.log(np.maximum(x, LIN_LOG_KNEE)))


def other_emulate(frames, fps: float, threshold: float) -> np.ndarray:
    """All events of ``frames`` (grey, float in [0, 1] or uint8) as (t, x, y, p) records, sorted by t."""
    dt = 1e6 / fps
    ref = None
    records = []
    for k, f in enumerate(frames):
        g = np.asarray(f, dtype=np.float64)
        level = lin_log(g if f.dtype == np.uint8 else g * 255.0)
        if ref is None:
            ref = level
            continue
        diff = level - ref
        n = np.floor(np.abs(diff) / threshold).astype(int)
        ys, xs = np.nonzero(n)
        for y, x in zip(ys.tolist(), xs.tolist()):
            m = n[y, x]
            for j in range(m):
                t = int((k - 1) * dt + (j + 1) * dt / (m + 1))
                records.append((t, x, y, int(diff[y, x] > 0)))
        ref = np.where(n > 0, level, ref)
    ev = np.array(records, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
    return ev[np.argsort(ev["t"], kind="stable")]
