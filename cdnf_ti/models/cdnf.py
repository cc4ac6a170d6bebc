"""The C-DNF model: ON/OFF contrast fields and the Summation field, per frame.

Equations and parameters: :mod:`cdnf_ti.params`. Per-pixel kernels:
:mod:`cdnf_ti.kernels.cdnf` (Taichi) or :mod:`cdnf_ti.reference` (NumPy
float64). Convergence control: :mod:`cdnf_ti.solver`.
"""
from __future__ import annotations

import numpy as np

from ..frames import to_grey
from ..params import THETA_SCALE, CDNFParams, contrast_kernel, dog_profiles, resting_level, sigmoid
from ..reference import NumpyCDNFBackend
from ..solver import SolveReport, solve_fixed_point
from .base import Model, StepResult


class TaichiCDNFBackend:
    """C-DNF field state in Taichi ndarrays (float32) driven by the kernels.

    Parameters
    ----------
    params : CDNFParams
    shape : (H, W)
    arch : str
        Taichi architecture.
    """

    name = "taichi"

    def __init__(self, params: CDNFParams, shape: tuple[int, int], arch: str = "cpu"):
        from ..taichi_runtime import ensure_taichi

        ensure_taichi(arch)
        import taichi as ti

        from ..kernels import cdnf as K
        from ..kernels.common import BORDER_CODES, COLUMN_BLOCKS

        self.K = K
        self.params = params
        self.shape = tuple(shape)
        self.mode = BORDER_CODES[params.border]
        self.blocks = COLUMN_BLOCKS

        def nd() -> "ti.Ndarray":
            return ti.ndarray(ti.f32, self.shape)

        self.L, self.P, self.S = nd(), nd(), nd()
        self.u_on, self.u_off, self.v = [nd(), nd()], [nd(), nd()], [nd(), nd()]
        self.row1, self.row2 = nd(), nd()
        self.rest_u, self.rest_v = nd(), nd()
        self.c = 0  # index of the current contrast buffers
        self.s = 0  # index of the current Summation buffer
        wc = contrast_kernel(params.sigma_c)
        self.wc = (float(wc[1, 1]), float(wc[0, 1]), float(wc[0, 0]))
        g1, g2 = dog_profiles(params)
        self.g1 = ti.ndarray(ti.f32, g1.shape)
        self.g2 = ti.ndarray(ti.f32, g2.shape)
        self.g1.from_numpy(g1.astype(np.float32))
        self.g2.from_numpy(g2.astype(np.float32))
        u0 = resting_level(params.h, 1.0)
        v0 = resting_level(params.h, float(params.A * g1.sum() ** 2 - params.B * g2.sum() ** 2))
        for a in self.u_on + self.u_off:
            K.fill(a, u0)
        for a in self.v:
            K.fill(a, v0)

    def save_rest(self) -> None:
        self.K.copy(self.u_on[self.c], self.rest_u)
        self.K.copy(self.v[self.s], self.rest_v)

    def restore_rest(self) -> None:
        self.K.copy(self.rest_u, self.u_on[self.c])
        self.K.copy(self.rest_u, self.u_off[self.c])
        self.K.copy(self.rest_v, self.v[self.s])

    def load(self, grey: np.ndarray, first: bool) -> None:
        scale = 1.0 / 255.0 if grey.dtype == np.uint8 else 1.0
        self.K.load_frame(grey, self.L, self.P, scale, int(first))

    def clear_input(self) -> None:
        self.K.fill(self.P, 0.0)

    def contrast_iterate(self, lam: float) -> tuple[float, float]:
        c, n = self.c, 1 - self.c
        r = self.K.contrast_iterate(self.P, self.u_on[c], self.u_off[c], self.u_on[n], self.u_off[n],
                                    *self.wc, self.params.h, lam, self.blocks, self.mode)
        self.c = n
        return float(r[0]), float(r[1])

    def summation_input(self) -> None:
        p = self.params
        self.K.summation_input(self.u_on[self.c], self.u_off[self.c], self.S,
                               p.alpha_on, p.alpha_off, THETA_SCALE)

    def summation_iterate(self, lam: float) -> tuple[float]:
        p = self.params
        s, n = self.s, 1 - self.s
        r = self.K.summation_iterate(self.S, self.v[s], self.row1, self.row2, self.v[n], self.g1, self.g2,
                                     p.A, p.B, p.h, lam, self.blocks, self.mode)
        self.s = n
        return (float(r),)

    def mean_activation(self) -> float:
        return float(self.K.mean_activation(self.v[self.s], THETA_SCALE, self.blocks))

    def fields(self) -> dict[str, np.ndarray]:
        return {
            "u_on": self.u_on[self.c].to_numpy(),
            "u_off": self.u_off[self.c].to_numpy(),
            "v": self.v[self.s].to_numpy(),
            "P": self.P.to_numpy(),
        }


class CDNF(Model):
    """Contrast-based Dynamic Neural Field (Qin, Fu, Peng, Yue).

    Each frame: ``P = L(t) - L(t-1)`` splits into ON/OFF contrasts; the ON and
    OFF fields and then the Summation field are solved to their stationary
    state by damped fixed-point iteration; ``I_v = sigmoid(mean theta([v]+))``
    and ``spike = I_v > 0.5 + epsilon``. Frame 0 gives ``I_v = 0.5``, no spike.

    Parameters
    ----------
    params : CDNFParams, optional
    backend : {"taichi", "numpy"}
        Taichi kernels (float32 fields) or the NumPy float64 reference.
    arch : {"cpu", "cuda", "vulkan", "gpu"}
        Taichi architecture (taichi backend only).
    fps : float
        Input frame rate (unused by the equations; kept for the interface).

    Examples
    --------
    >>> from cdnf_ti import CDNF
    >>> trace = CDNF().run(frames)          # doctest: +SKIP
    >>> trace.output, trace.spike           # I_v and alerts per frame  # doctest: +SKIP
    """

    name = "cdnf"
    output_name = "I_v"
    params_type = CDNFParams
    description = "C-DNF: ON/OFF contrast DNFs + Summation DNF (Qin et al.)"

    def __init__(self, params: CDNFParams | None = None, *, backend: str = "taichi", arch: str = "cpu",
                 fps: float = 30.0):
        super().__init__(params, backend=backend, arch=arch, fps=fps)
        self._be: TaichiCDNFBackend | NumpyCDNFBackend | None = None
        self._t = 0
        if backend == "taichi":
            from ..taichi_runtime import ensure_taichi

            ensure_taichi(arch)

    @property
    def threshold(self) -> float:
        return self.params.threshold

    def _make_backend(self, shape: tuple[int, int]) -> None:
        p = self.params
        if self.backend_name == "taichi":
            be = TaichiCDNFBackend(p, shape, self.arch)
        else:
            be = NumpyCDNFBackend(p, shape)
        # The resting state for this frame size and border: the solution with no input.
        be.clear_input()
        self._solve(be)
        be.save_rest()
        self._be = be

    def _solve(self, be) -> tuple[SolveReport, SolveReport]:
        p = self.params
        kw = dict(tol=p.tol, max_iter=p.max_iter, damping=p.damping, min_damping=p.min_damping,
                  stall_patience=p.stall_patience)
        rc = solve_fixed_point(be.contrast_iterate, 2, **kw)
        be.summation_input()
        rs = solve_fixed_point(be.summation_iterate, 1, **kw)
        return rc, rs

    def reset(self) -> None:
        self._t = 0
        if self._be is not None:
            self._be.restore_rest()

    def step(self, frame: np.ndarray) -> StepResult:
        """Process one frame; see :class:`StepResult`.

        Diagnostics: ``iterations_on/off/sum``, ``residual_on/off/sum``,
        ``damping_sum`` (the relaxation in force at the end of the Summation solve).
        """
        grey = to_grey(frame)
        if self._be is None:
            self._make_backend(grey.shape)
        elif grey.shape != self._be.shape:
            raise ValueError(f"frame {self._t} is {grey.shape[1]}x{grey.shape[0]} but this model runs at "
                             f"{self._be.shape[1]}x{self._be.shape[0]}; call reset() on a new model")
        be = self._be
        first = self._t == 0
        be.load(grey, first)
        t = self._t
        self._t += 1
        if first:
            be.restore_rest()
            diag = dict(iterations_on=0, iterations_off=0, iterations_sum=0,
                        residual_on=0.0, residual_off=0.0, residual_sum=0.0, damping_sum=1.0)
            return StepResult(t, 0.5, False, True, diag)
        if not self.params.warm_start:
            be.restore_rest()
        rc, rs = self._solve(be)
        i_v = sigmoid(be.mean_activation())
        converged = rc.converged and rs.converged
        if not converged:
            self._unconverged += 1
        diag = dict(
            iterations_on=rc.iterations[0], iterations_off=rc.iterations[1], iterations_sum=rs.iterations[0],
            residual_on=rc.residuals[0], residual_off=rc.residuals[1], residual_sum=rs.residuals[0],
            damping_sum=rs.damping,
        )
        return StepResult(t, i_v, bool(i_v > self.params.threshold), converged, diag)

    def fields(self) -> dict[str, np.ndarray]:
        """The ON, OFF and Summation fields and the luminance change, (H, W) each."""
        if self._be is None:
            return {}
        return self._be.fields()
