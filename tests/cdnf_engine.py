"""C-DNF on the engine, driven one solve launch at a time through the model's solver hooks (tests only).

:class:`Driver` gives a compiled C-DNF the one-update interface of the NumPy reference
(:class:`cdnf_ti.reference.NumpyCDNFBackend`: ``load``, ``contrast_iterate``, ``summation_input``, ...), so
a test can step both the same way; :func:`spans` reads a span group's pending spans.
"""
from __future__ import annotations

import numpy as np

from cdnf_ti import CDNF
from cdnf_ti.kernels import cdnf as layout


class Driver:
    """A C-DNF model's engine backend and solve hooks, fresh (fields at their resting levels, every element
    pending) for frames of ``shape``, or those of ``model`` (already stepped)."""

    def __init__(self, params=None, shape=None, fast: bool = True, model: CDNF | None = None):
        if model is None:
            model = CDNF(params)
            model.fast = fast
            model._be = model._engine().backend(model, tuple(shape))
        self.model, self.be = model, model._be

    def load(self, grey: np.ndarray, first: bool) -> None:
        self.model._flush_load()  # the frame taken before, if never solved
        self.be.load(grey, first)
        scale = 1.0 / 255.0 if grey.dtype == np.uint8 else 1.0
        self._take({"load": 1, "first": int(first), "scale": scale}, events=False)

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> None:
        self.model._flush_load()
        self.be.load_on_off(p_on, p_off, first)
        self._take({"load": 1, "first": int(first), "scale": 1.0}, events=True)

    def _take(self, pending: dict, events: bool) -> None:
        m = self.model
        m._pending, m._events, m._s_ready, m._mean = pending, events, False, None

    def contrast_iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        return self.model._contrast_many([(lam, mom)])[0]

    def contrast_iterate_many(self, coefs) -> list:
        return self.model._contrast_many(coefs)

    def summation_input(self) -> None:
        self.model._summation_input()

    def summation_iterate(self, lam: float, mom: float = 0.0) -> tuple[float]:
        return self.model._summation_many([(lam, mom)])[0]

    def summation_iterate_many(self, coefs) -> list:
        return self.model._summation_many(coefs)

    def mean_activation(self) -> float:
        return self.model._mean_activation()

    def restore_rest(self) -> None:
        self.model._restore_rest()

    def fields(self) -> dict[str, np.ndarray]:
        return self.model.fields()

    def planes(self) -> dict[str, np.ndarray]:
        """Every plane of the engine's state (``S`` included), (H, W) each."""
        self.model._flush_load()
        return self.be.fields()


def spans(model: CDNF, group: str) -> tuple[np.ndarray, int]:
    """The pending spans of ``group`` (``"c"``: contrast, ``"s"``: Summation): int (2, H, 2), ``[lo, hi]`` per
    parity and row, and the parity the next update reads."""
    span = layout.SPAN_C if group == "c" else layout.SPAN_S
    be = model._be
    x = be.x.to_numpy()[span.store.slot, :, 0, :4].astype(np.int64)
    return np.stack([x[:, 0:2], x[:, 2:4]]), (be.mask >> span.pair.bit) & 1
