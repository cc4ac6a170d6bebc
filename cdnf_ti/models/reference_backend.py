"""The ``numpy`` backend of a model whose float64 reference steps a whole frame.

A published model's NumPy oracle (``cdnf_ti/<name>_reference.py``) is a streaming object: ``step(frame)``
(and ``step_on_off(p_on, p_off)`` for a model that takes event bins) advances it one frame and returns
that frame's record; ``reset()`` restarts it; ``layers`` holds the last frame's planes. :class:`ReferenceBackend`
makes one the model's :class:`~cdnf_ti.models.base.ModelBackend`, so the model runs on ``backend="numpy"``;
the model's ``_step`` recognises the record and reports it.
"""
from __future__ import annotations

from typing import Any

import numpy as np


class ReferenceBackend:
    """A float64 reference as a model's ``numpy`` backend: every frame steps it whole.

    Parameters
    ----------
    reference : object
        The reference, built for frames of ``shape``: ``step(grey)``, ``reset()``, ``layers`` (a dict of
        (H, W) arrays) and, for a model that takes event bins, ``step_on_off(p_on, p_off)``.
    shape : (H, W)
        Frame size in px.
    """

    name = "numpy"

    def __init__(self, reference: Any, shape: tuple[int, int]):
        self.shape = tuple(shape)
        self.ref = reference

    def load(self, grey: np.ndarray, first: bool) -> Any:
        """Step the reference on the grey frame (H, W); returns its record of the frame."""
        return self.ref.step(grey)

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> Any:
        """Step the reference on an event bin's ``p_on``, ``p_off`` (H, W each, in [0, 1]); returns its record."""
        return self.ref.step_on_off(p_on, p_off)

    def reset(self) -> None:
        """Back to the state before the first frame."""
        self.ref.reset()

    def fields(self) -> dict[str, np.ndarray]:
        """The reference's planes of the last frame, (H, W) each."""
        return dict(self.ref.layers)
