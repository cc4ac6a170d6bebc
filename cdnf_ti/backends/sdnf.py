"""The compiled SDNF backend, driven by :mod:`cdnf_ti.kernels.sdnf`."""
from __future__ import annotations

import numpy as np

from ..kernels import common
from ..models.sdnf import SDNFParams
from ..params import THETA_SCALE
from ..taichi_runtime import dsl, ensure_taichi, kernels
from .events import load_net_contrast


class TaichiSDNFBackend:
    """SDNF field state in Taichi ndarrays (float32), driven by :mod:`cdnf_ti.kernels.sdnf`."""

    name = "taichi"

    def __init__(self, params: SDNFParams, shape: tuple[int, int], arch: str = "cpu"):
        arch = ensure_taichi(arch)  # the arch in use ("gpu" resolves to one)
        ti = dsl()

        self.K = kernels("sdnf")
        self.params = params
        self.shape = tuple(shape)
        self.blocks = common.column_blocks(self.shape[1], arch)  # work items per row
        nd = lambda: ti.ndarray(ti.f32, self.shape)  # noqa: E731
        self.L, self.P, self.E, self.row1, self.row2 = nd(), nd(), nd(), nd(), nd()
        self.u = [nd(), nd()]
        self.F = [nd(), nd()]  # firing rates f(u), kept so the lateral pass reads them once
        g1, g2 = params.dog_profiles()
        self.g1 = ti.ndarray(ti.f32, g1.shape)
        self.g2 = ti.ndarray(ti.f32, g2.shape)
        self.g1.from_numpy(g1.astype(np.float32))
        self.g2.from_numpy(g2.astype(np.float32))
        self._load_out = np.zeros(1)  # load_binary's sum E
        self._update_out = np.zeros(1)  # field_update's sum F
        self.reset()

    def reset(self) -> None:
        for a in (self.L, self.P, self.E, self.row1, self.row2):
            self.K.fill(a, 0.0)
        for a in self.u:
            self.K.fill(a, -self.params.h)
        for a in self.F:
            self.K.fill(a, 0.0)
        self.c = 0

    def load(self, grey: np.ndarray, first: bool) -> float:
        scale = 1.0 / 255.0 if grey.dtype == np.uint8 else 1.0
        out = self._load_out
        out.fill(0.0)
        self.K.load_binary(grey, self.L, self.P, self.E, scale, int(first), self.params.t_b, self.blocks, out)
        return float(out[0]) / (self.shape[0] * self.shape[1])

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> float:
        """Take an event bin (H, W each, in [0, 1]) as the net change ``P = p_on - p_off``:
        ``E = [|P| >= T_b]``; returns what :meth:`load` returns (the active fraction)."""
        return load_net_contrast(self, p_on, p_off)

    def update(self, b_t: float) -> float:
        p = self.params
        c, n = self.c, 1 - self.c
        out = self._update_out
        out.fill(0.0)
        self.K.field_update(self.E, self.F[c], self.row1, self.row2, self.u[n], self.F[n], self.g1, self.g2,
                            p.A, b_t, p.h, THETA_SCALE, self.blocks, int(p.radius), out)
        self.c = n
        return float(out[0]) / (self.shape[0] * self.shape[1])

    def fields(self) -> dict[str, np.ndarray]:
        return {"P": self.P.to_numpy(), "E": self.E.to_numpy(), "u": self.u[self.c].to_numpy(),
                "activity": self.F[self.c].to_numpy()}


def make_backend(model, shape: tuple[int, int], arch: str) -> TaichiSDNFBackend:
    """SDNF's backend (the generic kernels on every arch)."""
    return TaichiSDNFBackend(model.params, shape, model.arch)
