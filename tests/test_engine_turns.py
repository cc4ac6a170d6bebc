"""An update that writes a ping-pong pair's ``before`` buffer itself (``Stage(turns=...)``, as F-LGMD's feedback
update does): the engine alternates the pair at every update and across launches, and refreshes the ghost
columns of the buffer written. Checked against a float64 NumPy iteration of the same 3x3 stencil, in both
layouts, for odd and even numbers of updates."""
from dataclasses import dataclass

import numpy as np
import pytest

from cdnf_ti.kernels.engine import Launch, Planes, Scalars, Stage, model
from cdnf_ti.models import MODELS, Model, StepResult, register_model

PLANES, SCALARS = Planes("U:2"), Scalars("updates tol grow")


def build(ti, lanes):
    from cdnf_ti.kernels import engine
    from cdnf_ti.kernels.engine import Coefs

    (U,) = PLANES

    @ti.func
    def blur(a: ti.template()):
        """``U_before = lam mean9(U) + (1 - lam) g``; returns its change."""
        c, e, d = a.window3(U)
        v = a.record(0) * ((c + e + d) / 9.0) + (1.0 - a.record(0)) * a.grey()
        a.put(U.before, v)
        return ti.max(v - c, c - v)

    @ti.func
    def total(a: ti.template()):
        return a.at(U)

    update = Stage(blur, residuals=1, turns=(U,), ghosts=(U.before,))
    return model(PLANES, Coefs(), SCALARS, engine.build(ti, lanes),
                 Launch("solve", update=(update,), scalars=SCALARS), Launch("read", Stage(total, sums="sum_U")))


@dataclass(frozen=True)
class BlurParams:
    updates: int = 3  # updates per frame
    lam: float = 0.75


@register_model
class Blur(Model):
    name, params_type = "toy_turns", BlurParams
    kernels = staticmethod(build)

    def _step(self, t, grey, loaded):
        n = self.params.updates
        residuals, _ = self._be.solve("solve", [(self.params.lam, 0.0)] * n, n, -1.0, 1e30)  # tol < 0: every update
        self.ran = len(residuals)
        (s,) = self._be.launch("read")
        return StepResult(t, s, False)


MODELS.pop(Blur.name)  # registered for this file's tests only


def blur_reference(g: np.ndarray, updates: int, lam: float) -> np.ndarray:
    """``updates`` iterations of ``u = lam mean9(u) + (1 - lam) g`` from 0, replicate border, float64."""
    g, u = g.astype(np.float64), np.zeros(g.shape)
    H, W = g.shape
    for _ in range(updates):
        p = np.pad(u, 1, mode="edge")
        u = lam * sum(p[1 + di:1 + di + H, 1 + dj:1 + dj + W] for di in (-1, 0, 1) for dj in (-1, 0, 1)) / 9.0
        u = u + (1.0 - lam) * g
    return u


@pytest.mark.parametrize("updates", [3, 4])
@pytest.mark.parametrize("width", [80, 40])  # the lane layout (ghost columns), the pixel layout
def test_an_update_that_turns_its_pair_iterates_as_numpy_across_updates_and_frames(width, updates):
    g = np.random.default_rng(7).random((9, width)).astype(np.float32)
    m = Blur(BlurParams(updates=updates))
    for frame in (1, 2):  # the second frame goes on from where the first left the pair
        r = m.step(g)
        assert m.ran == updates
        want = blur_reference(g, frame * updates, m.params.lam)
        np.testing.assert_allclose(m.fields()["U"], want, atol=1e-5, rtol=0)
        assert r.output == pytest.approx(want.sum(), rel=1e-5)


def test_a_stage_turns_only_pairs():
    with pytest.raises(ValueError):
        Stage(lambda a: a, residuals=1, turns=(Planes("V").V,))
