"""The engine's symmetric stencils, on both layouts, against NumPy float64: ``a.smooth3`` (a separable 3x3
``W = k k^T``) and ``a.taps`` (symmetric 1-D taps along the rows or the columns), each border mode."""
from dataclasses import dataclass

import numpy as np
import pytest

from cdnf_ti.kernels.engine import Coefs, Launch, Planes, Scalars, Stage, model
from cdnf_ti.models import MODELS, Model, StepResult, register_model

PLANES, COEFS = Planes("G W3 TX TY"), Coefs(k=2, w=3)
G, W3, TX, TY = PLANES
K1 = np.array([0.25, 0.5, 0.25])  # k = (k1, k0, k1)
TAPS = (0.05, 0.2, 0.5, 0.2, 0.05)  # R = 2


def build(ti, lanes):
    from cdnf_ti.kernels import engine

    @ti.func
    def load(a: ti.template()):
        a.put(G, a.grey())

    @ti.func
    def stencils(a: ti.template()):
        a.put(W3, a.smooth3(G, COEFS.k, COEFS.w))
        a.put(TX, a.taps(G, "g"))
        a.put(TY, a.taps(G, "g", True))

    run = Launch("run", Stage(load, ghosts=(G,), halo=2), Stage(stencils))
    return model(PLANES, COEFS, Scalars(""), engine.build(ti, lanes), run)


@dataclass(frozen=True)
class StencilParams:
    border: str = "replicate"


@register_model
class Stencils(Model):
    name, params_type = "toy_stencils", StencilParams
    kernels = staticmethod(build)

    def coefficients(self):
        w = np.outer(K1, K1)
        return {"k": (K1[1], K1[0]), "w": (w[1, 1], w[0, 1], w[0, 0])}

    def kernel_options(self):
        return {"g": TAPS}

    def borders(self):
        return {"G": self.params.border}

    def _step(self, t, grey, loaded):
        self._be.launch("run")
        return StepResult(t, 0.0, False)


MODELS.pop(Stencils.name)  # registered for this file's tests only

PAD = {"replicate": "edge", "reflect": "reflect", "zero": "constant"}


def correlate(g, kernel, border):
    """``sum kernel[dy, dx] g[i + dy, j + dx]`` with the border mode (float64)."""
    ry, rx = kernel.shape[0] // 2, kernel.shape[1] // 2
    p = np.pad(g.astype(np.float64), ((ry, ry), (rx, rx)), mode=PAD[border])
    H, W = g.shape
    return sum(kernel[y, x] * p[y:y + H, x:x + W] for y in range(kernel.shape[0]) for x in range(kernel.shape[1]))


@pytest.mark.parametrize("fast", [True, False])
@pytest.mark.parametrize("border", ["replicate", "reflect", "zero"])
def test_the_symmetric_stencils_match_numpy_on_both_layouts(fast, border):
    g = np.random.default_rng(5).random((12, 72)).astype(np.float32)
    m = Stencils(StencilParams(border))
    m.fast = fast
    m.step(g)
    assert m._be.lane == fast
    f = m.fields()
    taps = np.array(TAPS)
    np.testing.assert_allclose(f["W3"], correlate(g, np.outer(K1, K1), border), atol=1e-6)
    np.testing.assert_allclose(f["TX"], correlate(g, taps[None, :], border), atol=1e-6)
    np.testing.assert_allclose(f["TY"], correlate(g, taps[:, None], border), atol=1e-6)
