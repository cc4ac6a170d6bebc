"""The compiled SDNF backend, driven by :mod:`cdnf_ti.kernels.sdnf`."""
from __future__ import annotations

import numpy as np

from ..kernels import common
from ..models.sdnf import SDNFParams
from ..params import THETA_SCALE
from ..taichi_runtime import dsl, ensure_taichi, kernels
from .workspace import event_bin


class TaichiSDNFBackend:
    """SDNF field state in one stacked Taichi ndarray (float32, planes of :mod:`cdnf_ti.kernels.sdnf`),
    driven by its kernels; the model's coefficients in one small array set once."""

    name = "taichi"

    def __init__(self, params: SDNFParams, shape: tuple[int, int], arch: str = "cpu"):
        arch = ensure_taichi(arch)  # the arch in use ("gpu" resolves to one)
        ti = dsl()

        self.K = kernels("sdnf")
        self.params = params
        self.shape = tuple(shape)
        self.blocks = common.column_blocks(self.shape[1], arch)  # work items per row
        self.x = ti.ndarray(ti.f32, (self.K.PLANES, *self.shape))  # L, P, E, u
        self.rows = ti.ndarray(ti.f32, (2, *self.shape))  # the DoG's row passes
        self.F = [ti.ndarray(ti.f32, self.shape) for _ in range(2)]  # f(u) of the last two frames
        coefs = coefficients(params)
        self.coef = ti.ndarray(ti.f32, coefs.shape)  # on the device once, not copied per launch
        self.coef.from_numpy(coefs)
        self._update = self.K.field_update_kernel(int(params.radius))
        self._load_out = np.zeros(1)  # load_binary's sum E
        self._update_out = np.zeros(1)  # field_update's sum F
        self.reset()

    def reset(self) -> None:
        K = self.K
        K.fill_planes(self.x, 0, K.PLANES, 0.0)
        K.fill_planes(self.x, K.U_, K.U_ + 1, -self.params.h)
        K.fill_planes(self.rows, 0, 2, 0.0)
        for a in self.F:
            K.fill(a, 0.0)
        self.c = 0

    def load(self, grey: np.ndarray, first: bool) -> float:
        scale = 1.0 / 255.0 if grey.dtype == np.uint8 else 1.0
        out = self._load_out
        out.fill(0.0)
        self.K.load_binary(grey, self.x, self.coef, scale, int(first), self.blocks, out)
        return float(out[0]) / (self.shape[0] * self.shape[1])

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> float:
        """Take an event bin (H, W each, in [0, 1]), one upload: ``E = [max(p_on, p_off) >= T_b]`` (a
        pixel with either polarity at the threshold is active), ``P = p_on - p_off``; returns what
        :meth:`load` returns (the active fraction)."""
        out = self._load_out
        out.fill(0.0)
        self.K.load_binary(event_bin(p_on, p_off), self.x, self.coef, 1.0, int(first), self.blocks, out)
        return float(out[0]) / (self.shape[0] * self.shape[1])

    def update(self, b_t: float) -> float:
        out = self._update_out
        out.fill(0.0)
        self._update(self.x, self.F[self.c], self.F[1 - self.c], self.rows, self.coef, b_t, self.blocks, out)
        self.c = 1 - self.c
        return float(out[0]) / (self.shape[0] * self.shape[1])

    def fields(self) -> dict[str, np.ndarray]:
        K, x = self.K, self.x.to_numpy()
        return {"P": x[K.P_], "E": x[K.E_], "u": x[K.U_], "activity": self.F[self.c].to_numpy()}


def coefficients(params: SDNFParams) -> np.ndarray:
    """SDNF's coefficient array (float32; slots of :mod:`cdnf_ti.kernels.sdnf`): ``A``, ``h``, theta's
    scale, ``T_b``, then the DoG profiles ``g1``, ``g2``."""
    g1, g2 = params.dog_profiles()
    head = [params.A, params.h, THETA_SCALE, params.t_b]
    return np.concatenate([np.asarray(head, np.float64).astype(np.float32),
                           g1.astype(np.float32), g2.astype(np.float32)])


def make_backend(model, shape: tuple[int, int], arch: str) -> TaichiSDNFBackend:
    """SDNF's backend (the generic kernels on every arch)."""
    return TaichiSDNFBackend(model.params, shape, model.arch)
