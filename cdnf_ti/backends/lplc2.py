"""The compiled EMD-LPLC2 backends, driven by :mod:`cdnf_ti.kernels.lplc2`: a generic one ((H, W) arrays,
every arch) and a lane one (the fast CPU path)."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..kernels.lplc2 import BANDS, COEF, MAPS, OUT
from ..kernels.pooling import ghost_elements, lane_layout
from ..taichi_runtime import dsl, ensure_taichi, kernels, lanes


class TaichiLPLC2Backend:
    """EMD state and LPLC2 maps in Taichi ndarrays (float32; the pooling sums run in float64).

    Per-pixel state (H, W): luminance ``lum``, high-pass ``f_h``, delayed ON/OFF ``fd_on``,
    ``fd_off``. On the (H-1, W-1) grid: the opponent motion maps, the column passes and the
    four thresholded arms and their product ``lplc2``.

    Parameters
    ----------
    params : LPLC2Params
    shape : (H, W)
        Frame size (px), at least 2x2.
    fps : float
        Frame rate (``dt = 1 / fps`` s sets the filters' coefficients).
    arch : str
    """

    name = "taichi"
    #: The maps listed by :meth:`fields` (on the unit grid, padded to (H, W) with a zero last row and column).
    MAPS = ("horizontal", "vertical", "left", "right", "up", "down", "lplc2")

    def __init__(self, params: Any, shape: tuple[int, int], fps: float, arch: str = "cpu"):
        ensure_taichi(arch)
        ti = dsl()
        self.K = kernels("lplc2")
        self.params = params
        self.shape = (int(shape[0]), int(shape[1]))
        H, W = self.shape
        grid = (H - 1, W - 1)
        self._arrays = [ti.ndarray(ti.f32, self.shape) for _ in range(4)]
        self.lum, self.f_h, self.fd_on, self.fd_off = self._arrays
        for name in self.MAPS + ("h_band", "up_cols", "down_cols"):
            setattr(self, name, ti.ndarray(ti.f32, grid))
            self._arrays.append(getattr(self, name))
        self.coef = ti.ndarray(ti.f64, len(COEF))
        self.coef.from_numpy(coefficients(params, self.shape, fps, ghosts=0))
        self._out = np.zeros(len(OUT))
        self.reset()

    def reset(self) -> None:
        fill = kernels("common").fill
        for a in self._arrays:
            fill(a, 0.0)

    def load(self, grey: np.ndarray, first: bool) -> None:
        """Photoreceptors, temporal filters and opponent motion of one frame (only stored when ``first``)."""
        denom = 255.0 if grey.dtype == np.uint8 else 1.0
        self.K.emd_step(grey, self.lum, self.f_h, self.fd_on, self.fd_off, self.horizontal, self.vertical,
                        self.coef, denom, int(first))

    def pool(self) -> tuple[int, float, tuple[float, float, float, float]]:
        """The LPLC2 array of the loaded frame: ``(active units, centre response, centre arms (l, r, u, d))``."""
        K, out = self.K, self._out
        out.fill(0.0)
        K.lplc2_columns(self.horizontal, self.vertical, self.h_band, self.up_cols, self.down_cols, self.coef)
        K.lplc2_arms(self.h_band, self.up_cols, self.down_cols, self.left, self.right, self.up, self.down,
                     self.lplc2, self.coef, out)
        return int(round(out[0])), float(out[1]), tuple(float(a) for a in out[2:6])

    def fields(self) -> dict[str, np.ndarray]:
        H, W = self.shape
        out = {}
        for name in self.MAPS:
            m = np.zeros(self.shape, np.float32)
            m[: H - 1, : W - 1] = getattr(self, name).to_numpy()
            out[name] = m
        return out


class LaneTaichiLPLC2Backend:
    """The fast CPU backend: :class:`TaichiLPLC2Backend`'s equations and results on lane arrays (``LANES``
    float32 columns per element, ``G`` ghost elements either side: :mod:`cdnf_ti.kernels.pooling`),
    kernels compiled with explicit vector types (the ``lanes_*`` kernels of :mod:`cdnf_ti.kernels.lplc2`).

    Parameters
    ----------
    params : LPLC2Params
    shape : (H, W)
    fps : float
    arch : str
    """

    name = "taichi"
    MAPS = TaichiLPLC2Backend.MAPS

    @staticmethod
    def supports(shape: tuple[int, int], arch: str = "cpu") -> bool:
        """The CPU (any frame of at least 2x2 px)."""
        return arch == "cpu"

    def __init__(self, params: Any, shape: tuple[int, int], fps: float, arch: str = "cpu"):
        ensure_taichi(arch)
        self.K = kernels("lplc2")
        C = kernels("common")
        self.params = p = params
        self.shape = (int(shape[0]), int(shape[1]))
        H, W = self.shape
        self.L = lanes()
        reach = max(p.half_side, p.band_before, p.band_after) + 1  # the farthest prefix a row window reads
        self.G = ghost_elements(reach, self.L)
        _, nb = lane_layout(W, self.L, self.G)
        self.lum, self.f_h, self.fd_on, self.fd_off = (C.lane_array(H=H, NB=nb) for _ in range(4))
        self.horizontal, self.vertical = (C.lane_array(H=H - 1, NB=nb) for _ in range(2))
        self.bands, self.prefix = (C.lane_array(len(BANDS), H=H - 1, NB=nb) for _ in range(2))
        self.maps = C.lane_array(len(MAPS), H=H - 1, NB=nb)
        self._arrays = [self.lum, self.f_h, self.fd_on, self.fd_off, self.horizontal, self.vertical, self.bands,
                        self.prefix, self.maps]
        self.coef = dsl().ndarray(dsl().f64, len(COEF))
        self.coef.from_numpy(coefficients(params, self.shape, fps, ghosts=self.G))
        self._geometry = (int(p.half_side), int(p.band_before), int(p.band_after))
        self._out = np.zeros(len(OUT))
        self.reset()

    def reset(self) -> None:
        for a in self._arrays:
            a.fill(0.0)

    def load(self, grey: np.ndarray, first: bool) -> None:
        """Photoreceptors, temporal filters and opponent motion of one frame (only stored when ``first``)."""
        denom = 255.0 if grey.dtype == np.uint8 else 1.0
        self.K.lanes_emd_step(grey, self.lum, self.f_h, self.fd_on, self.fd_off, self.horizontal, self.vertical,
                              self.coef, denom, int(first))

    def pool(self) -> tuple[int, float, tuple[float, float, float, float]]:
        """The LPLC2 array of the loaded frame: ``(active units, centre response, centre arms (l, r, u, d))``."""
        K, out = self.K, self._out
        out.fill(0.0)
        K.lanes_columns(self.horizontal, self.vertical, self.bands, self.coef)
        K.lanes_arms(self.bands, self.prefix, self.maps, self.coef, out, *self._geometry)
        return int(round(out[0])), float(out[1]), tuple(float(a) for a in out[2:6])

    def _grid(self, x: np.ndarray) -> np.ndarray:
        """The (H-1, W-1) grid columns of a lane array's ``to_numpy()`` rows (H-1, NB, LANES)."""
        H, W = self.shape
        start = self.G * self.L
        return x.reshape(H - 1, -1)[:, start: start + W - 1]

    def fields(self) -> dict[str, np.ndarray]:
        H, W = self.shape
        grids = {"horizontal": self._grid(self.horizontal.to_numpy()),
                 "vertical": self._grid(self.vertical.to_numpy())}
        maps = self.maps.to_numpy()
        grids.update({name: self._grid(maps[m]) for m, name in enumerate(MAPS)})
        out = {}
        for name in self.MAPS:
            m = np.zeros(self.shape, np.float32)
            m[: H - 1, : W - 1] = grids[name]
            out[name] = m
        return out


def coefficients(params: Any, shape: tuple[int, int], fps: float, ghosts: int) -> np.ndarray:
    """The kernels' coefficient array (:data:`~cdnf_ti.kernels.lplc2.COEF`) for ``params`` at ``fps``, frames
    of ``shape`` (H, W), lane arrays with ``ghosts`` ghost elements either side (0: the generic kernels)."""
    p = params
    dt = 1.0 / float(fps)
    d_h, d_l = p.tau_h / dt, p.tau_l / dt
    core_row, core_col = core_unit(shape)
    values = dict(b_high=d_h / (d_h + 1.0), a_low=1.0 / (d_l + 1.0), on_threshold=p.on_threshold,
                  off_threshold=p.off_threshold, arm_threshold=p.arm_threshold, half_side=p.half_side,
                  band_before=p.band_before, band_after=p.band_after, core_row=core_row, core_col=core_col,
                  ghosts=ghosts, grid_cols=shape[1] - 1)
    return np.array([values[k] for k in COEF], np.float64)


def core_unit(shape: tuple[int, int]) -> tuple[int, int]:
    """The centre unit (row, column) of the (H-1, W-1) grid: MATLAB's ``floor(end / 2)``, 0-based."""
    return max((shape[0] - 1) // 2 - 1, 0), max((shape[1] - 1) // 2 - 1, 0)


def make_backend(model, shape: tuple[int, int], arch: str) -> Any:
    """EMD-LPLC2's backend: the lane one on the CPU (and ``model.fast``), else the generic one."""
    lane = model.fast and LaneTaichiLPLC2Backend.supports(shape, arch)
    kind = LaneTaichiLPLC2Backend if lane else TaichiLPLC2Backend
    return kind(model.params, shape, model.fps, model.arch)
