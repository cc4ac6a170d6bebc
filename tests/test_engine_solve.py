"""The engine's solve launches (update stages with residual gates), as C-DNF's and F-LGMD's solves use them:
a per-pixel fixed point ``u = (1 - lam) u + lam g`` whose residual ``|du|`` halves each update, checked against
its closed form in both layouts."""
from dataclasses import dataclass

import numpy as np
import pytest

from cdnf_ti.kernels.engine import Launch, Planes, Scalars, Stage, model
from cdnf_ti.models import MODELS, Model, StepResult, register_model

PLANES, SCALARS = Planes("U"), Scalars("updates tol grow")


def build(ti, lanes):
    from cdnf_ti.kernels import engine
    from cdnf_ti.kernels.engine import Coefs

    (U,) = PLANES

    @ti.func
    def relax(a: ti.template()):
        u = a.at(U)
        v = u + a.record(0) * (a.grey() - u)
        a.put(U, v)
        return ti.max(v - u, u - v)

    @ti.func
    def total(a: ti.template()):
        return a.at(U)

    solve = Launch("solve", Stage(total, sums="sum_U"), update=(Stage(relax, residuals=1),), scalars=SCALARS)
    return model(PLANES, Coefs(), SCALARS, engine.build(ti, lanes), solve)


@dataclass(frozen=True)
class RelaxParams:
    tol: float = 1e-3


@register_model
class Relax(Model):
    name, params_type = "toy_relax", RelaxParams
    kernels = staticmethod(build)

    def _step(self, t, grey, loaded):
        residuals, (s,) = self._be.solve("solve", [(0.5, 0.0)] * 32, 32, self.params.tol, 10.0)
        self.residuals = residuals
        return StepResult(t, s / grey.size, False, bool(residuals) and residuals[-1][0] <= self.params.tol)


MODELS.pop(Relax.name)  # registered for this file's tests only


@pytest.mark.parametrize("width", [80, 40])  # the lane layout (scheduler gates), the pixel layout (backend gates)
def test_a_solve_runs_its_updates_until_the_residual_reaches_the_tolerance_then_its_after_stage(width):
    g = np.full((8, width), 0.75, np.float32)
    model = Relax()
    r = model.step(g)
    # |du| of update j is 0.75 / 2^(j+1): the first <= 1e-3 is update 9 (0.75 / 1024)
    np.testing.assert_allclose([x[0] for x in model.residuals], [0.75 / 2 ** (j + 1) for j in range(10)], rtol=1e-6)
    assert r.converged
    assert r.output == pytest.approx(0.75 * (1 - 2.0 ** -10), rel=1e-6)


def test_a_solve_that_does_not_converge_in_its_updates_skips_its_after_stage():
    model = Relax(RelaxParams(tol=-1.0))  # never reached
    r = model.step(np.full((8, 80), 0.75, np.float32))
    assert len(model.residuals) == 32 and not r.converged
    assert r.output == 0.0  # the after stage did not run: its sum stays 0
