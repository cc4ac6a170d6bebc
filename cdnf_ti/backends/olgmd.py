"""The compiled backend of oLGMD (:class:`cdnf_ti.models.olgmd.OLGMD`), driven by :mod:`cdnf_ti.kernels.olgmd`.

The model's control (PM, gates, SFA, spikes) runs in Python; a backend owns the layers (float32)
and launches two kernels per frame: :meth:`~OLGMDBackend.photoreceptors` and
:meth:`~OLGMDBackend.layers`. :class:`LaneOLGMDBackend` is the fast CPU path (lane arrays),
:class:`OLGMDBackend` the generic one (narrow frames, GPUs).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..kernels import common
from ..kernels.schedule import MAX_WORKERS
from ..taichi_runtime import cpu_threads, dsl, ensure_taichi, kernels, lanes
from .workspace import Scratch


def lowpass(dt: float, tau: float) -> float:
    """``a = dt / (dt + tau)`` (ms): the weight of the current frame in a delay of time constant ``tau``."""
    return dt / (dt + tau)


class OLGMDBackend:
    """oLGMD's layers for frames of ``shape`` (H, W).

    Arrays: ``L`` (1, H, W) grey levels of the frame before; ``P`` (2, H, W) the last two
    luminance changes; ``chan`` (4, H, W) ``P_on`` (planes 0, 1) and ``P_off`` (planes 2, 3),
    this frame's and the one before; ``lay`` (3, H, W) ``S``, ``Ce``, ``G``.

    Parameters
    ----------
    model : OLGMD
        Reads ``params``, ``dt`` (ms) and ``variant``.
    shape : (H, W)
    arch : str
        ``cpu``: the layers run on the scheduler's persistent workers; other archs: plain loops.
    """

    name = "taichi"

    def __init__(self, model: Any, shape: tuple[int, int], arch: str = "cpu"):
        arch = ensure_taichi(arch)
        self.K = kernels("olgmd")
        self.shape = tuple(int(s) for s in shape)
        self.code = model.params.variant == "code"
        self.workers = arch == "cpu"
        self.blocks = common.column_blocks(self.shape[1], arch)  # work items per row of the plain loops
        self.nw = min(cpu_threads(), MAX_WORKERS)
        self.lock = Scratch.get().lock  # the scheduler's scratch, one per process (Model.step holds it)
        self.L, self.P, self.chan, self.lay = (self._array(n) for n in (1, 2, 4, 3))
        self.coef = dsl().ndarray(dsl().f32, self.K.N_COEF)
        self.coef.from_numpy(self.coefficients(model.params, model.dt))
        self.fr = np.zeros(self.K.N_FRAME, dtype=np.float32)  # the frame's scalars (kernels.olgmd F_*)
        self.out = np.zeros(2)
        self.grey: np.ndarray | None = None
        self.reset()

    def _array(self, planes: int) -> Any:
        """A float32 ndarray of ``planes`` (H, W) planes."""
        ti = dsl()
        return ti.ndarray(ti.f32, (planes, *self.shape))

    def _frame(self, x: np.ndarray) -> np.ndarray:
        """An array's ``to_numpy()`` as (planes, H, W)."""
        return x

    def coefficients(self, p: Any, dt: float) -> np.ndarray:
        """The ``coef`` array (slots ``C_*`` of :mod:`cdnf_ti.kernels.olgmd`) of ``params`` at ``dt`` ms."""
        K = self.K
        coef = np.zeros(K.N_COEF, dtype=np.float64)
        for base, weights, taus in ((K.C_ON, p.w_on, p.t_on), (K.C_OFF, p.w_off, p.t_off)):
            a = [lowpass(dt, tau) for tau in taus]
            coef[base:base + 3] = [w * ai for w, ai in zip(weights, a)]
            coef[base + 3:base + 6] = [w * (1.0 - ai) for w, ai in zip(weights, a)]
        coef[K.C_A1] = p.a1
        coef[K.C_O:K.C_O + 3] = (p.o1, p.o2, p.o3)
        coef[[K.C_CW, K.C_DC, K.C_CDE, K.C_TDE]] = (p.cw, p.delta_c, p.cde, p.tde)
        return coef.astype(np.float32)

    def reset(self) -> None:
        for a in (self.L, self.P, self.chan, self.lay):
            a.fill(0.0)
        self.cur = 1  # plane of this frame's P / P_on / P_off; the next frame writes the other one

    def load(self, grey: np.ndarray, first: bool) -> None:
        """Keep the frame (H, W; uint8, or float in [0, 1]) for :meth:`photoreceptors`."""
        self.grey = grey

    def photoreceptors(self, active: bool, a_1: float, a_2: float) -> tuple[float, float]:
        """Grey levels of the loaded frame; when ``active``, ``P`` (persistence ``a_1``, ``a_2``),
        ``P_on`` and ``P_off``. Returns ``(sum P_on, sum P_off)`` (0 when not ``active``)."""
        K, fr, out = self.K, self.fr, self.out
        c = 1 - self.cur
        fr[[K.F_SCALE, K.F_ACTIVE, K.F_A_1, K.F_A_2]] = (1.0 if self.grey.dtype == np.uint8 else 255.0,
                                                         float(active), a_1, a_2)
        out.fill(0.0)
        self._launch_load(c)
        if active:
            self.cur = c
        return float(out[0]), float(out[1])

    def _launch_load(self, c: int) -> None:
        self.K.load(self.grey, self.L, self.P, self.chan, self.coef, self.fr, c, self.blocks, self.out)

    def _launch_layers(self) -> None:
        if self.workers:
            self.K.layers(self.chan, self.lay, self.coef, self.fr, self.cur, self.nw, self.out, self.code)
        else:
            self.K.layers_loops(self.chan, self.lay, self.coef, self.fr, self.cur, self.out, self.code, self.blocks)

    def layers(self, w: tuple[float, float], gates: tuple[bool, bool], before: tuple[float, float]
               ) -> tuple[float, float]:
        """``S``, ``Ce``, ``G`` of this frame's channels: biases ``w = (w1, w2)``, ``gates`` (ON, OFF open),
        weights ``before`` of ON / OFF ``E(t-1)``. Returns ``(sum G, max Ce)``."""
        K, fr, out = self.K, self.fr, self.out
        fr[[K.F_W1, K.F_W2, K.F_GATE_ON, K.F_GATE_OFF, K.F_PREV_ON, K.F_PREV_OFF]] = (*w, *map(float, gates), *before)
        out.fill(0.0)
        self._launch_layers()
        return float(out[0]), float(out[1])

    def fields(self) -> dict[str, np.ndarray]:
        """``P``, ``ON`` (P_on), ``OFF`` (P_off), ``S``, ``Ce``, ``G`` of the last frame, (H, W) each."""
        c = self.cur
        chan, lay = self._frame(self.chan.to_numpy()), self._frame(self.lay.to_numpy())
        return {"P": self._frame(self.P.to_numpy())[c], "ON": chan[c], "OFF": chan[2 + c],
                "S": lay[0], "Ce": lay[1], "G": lay[2]}


class LaneOLGMDBackend(OLGMDBackend):
    """The fast CPU backend: the same arrays as lane arrays (``LANES`` float32 per element with ghost
    columns, :func:`~cdnf_ti.kernels.common.lane_array`), the kernels ``lanes_*`` of
    :mod:`cdnf_ti.kernels.olgmd` (explicit vector types, compiled for the frame width)."""

    @staticmethod
    def supports(shape: tuple[int, int], arch: str = "cpu") -> bool:
        """The CPU, frames at least ``2 * LANES`` wide."""
        return arch == "cpu" and shape[1] >= 2 * lanes()

    def _array(self, planes: int) -> Any:
        C = kernels("common")
        return C.lane_array(planes, H=self.shape[0], NB=C.lane_layout(self.shape[1])[1])

    def _frame(self, x: np.ndarray) -> np.ndarray:
        n, (H, W) = lanes(), self.shape
        return np.ascontiguousarray(x.reshape(x.shape[0], H, -1)[:, :, n:n + W])

    def _launch_load(self, c: int) -> None:
        self.K.lanes_load(self.grey, self.L, self.P, self.chan, self.coef, self.fr, c, self.shape[1], self.out)

    def _launch_layers(self) -> None:
        self.K.lanes_layers(self.chan, self.lay, self.coef, self.fr, self.cur, self.nw, self.out, self.code,
                            self.shape[1])

def make_backend(model: Any, shape: tuple[int, int], arch: str) -> OLGMDBackend:
    """The backend of an :class:`~cdnf_ti.models.olgmd.OLGMD` model: the lane one where it applies
    (and ``model.fast``)."""
    if model.fast and LaneOLGMDBackend.supports(shape, ensure_taichi(arch)):
        return LaneOLGMDBackend(model, shape, arch)
    return OLGMDBackend(model, shape, arch)
