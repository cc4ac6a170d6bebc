"""The event record every reader yields."""
from __future__ import annotations

import numpy as np

#: One event: ``t`` timestamp (µs, int64), ``x``, ``y`` pixel (column, row; 0 at the top left), ``p``
#: polarity (1 = ON, a rise of log intensity; 0 = OFF).
EVENT_DTYPE = np.dtype([("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")], align=True)  # 16 bytes, aligned
