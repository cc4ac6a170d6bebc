"""The engine's picked results: ``a.pick(name, v, r, c)`` in a stage with ``picks=`` sets the launch's result
``name`` to ``v`` at frame pixel (r, c) (0 where no cell holds it), after the stage's reductions, in both layouts."""
from dataclasses import dataclass

import numpy as np
import pytest

from cdnf_ti.kernels.engine import Coefs, Launch, Planes, Scalars, Stage, model
from cdnf_ti.models import MODELS, Model, StepResult, register_model

PLANES, SCALARS = Planes("Y"), Scalars("r0 c0 r1 c1")


def build(ti, lanes):
    from cdnf_ti.kernels import engine

    (Y,) = PLANES

    @ti.func
    def affine(a: ti.template()):
        y = 3.0 * a.grey() + 1.0
        a.put(Y, y)
        for name, r, c in ti.static((("here", SCALARS.r0, SCALARS.c0), ("there", SCALARS.r1, SCALARS.c1))):
            a.pick(name, y, ti.cast(a.value(r), ti.i32), ti.cast(a.value(c), ti.i32))
        return y * a.frame_mask()

    step = Launch("step", Stage(affine, sums="total", picks="here there"))
    return model(PLANES, Coefs(), SCALARS, engine.build(ti, lanes), step)


@dataclass(frozen=True)
class PickParams:
    here: tuple = (0, 0)
    there: tuple = (0, 0)


@register_model
class Pick(Model):
    name, params_type = "toy_pick", PickParams
    kernels = staticmethod(build)

    def _step(self, t, grey, loaded):
        (r0, c0), (r1, c1) = self.params.here, self.params.there
        self.results = self._be.launch("step", r0=r0, c0=c0, r1=r1, c1=c1)
        return StepResult(t, self.results[0], False)


MODELS.pop(Pick.name)  # registered for this file's tests only


@pytest.mark.parametrize("fast", [True, False])  # the lane layout, the pixel layout
@pytest.mark.parametrize("here, there", [((0, 0), (8, 99)), ((4, 37), (2, 64)), ((8, 31), (3, 32))])
def test_picks_are_the_values_at_their_pixels_after_the_sums(fast, here, there):
    rng = np.random.default_rng(5)
    frame = rng.integers(0, 256, size=(9, 100)).astype(np.uint8)  # 100 columns: a partial last element
    m = Pick(PickParams(here, there))
    m.fast = fast
    m.step(frame)
    assert m._be.lane is fast
    y = 3.0 * frame.astype(np.float64) + 1.0  # integers: exact in float32
    assert m.results == (y.sum(), y[here], y[there])


@pytest.mark.parametrize("fast", [True, False])
def test_a_pick_outside_the_frame_stays_0(fast):
    m = Pick(PickParams((9, 5), (2, 100)))  # one row below, one column right of the 9 x 100 frame
    m.fast = fast
    m.step(np.full((9, 100), 7, np.uint8))
    assert m.results[1:] == (0.0, 0.0)
