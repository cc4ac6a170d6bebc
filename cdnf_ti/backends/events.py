"""Event bins into a compiled backend's ON/OFF input stage."""
from __future__ import annotations

import numpy as np


def load_net_contrast(backend, p_on: np.ndarray, p_off: np.ndarray):
    """Load an event bin through ``backend.load``: a zero frame as the first, then the net contrast
    ``P = p_on - p_off`` as a float frame (float32, so ``P = P - 0`` exactly; the LGMD family's load
    scales a float frame to grey levels, ``255 P``).

    Each load writes the same targets from the same state (the photoreceptors, ``P`` and what the
    model's input stage derives from ``P``: C-DNF's local start, the LGMD family's ON/OFF channels
    from their previous values, SDNF's ``E``), so the second load alone decides them.

    Returns
    -------
    What ``backend.load`` returns for the net contrast.
    """
    net = (np.asarray(p_on, np.float64) - np.asarray(p_off, np.float64)).astype(np.float32)
    backend.load(np.zeros_like(net), True)
    return backend.load(net, False)
