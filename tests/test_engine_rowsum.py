"""The engine's row windows: ``a.put_prefix(P, v)`` then ``a.row_sum(P, k0, k1)`` is ``sum_{d=k0..k1} v(column + d)``,
0 outside the frame, in both layouts, against NumPy's zero padding of the same frame (windows wider than a lane
vector, beside the pixel, and past either edge)."""
from dataclasses import dataclass

import numpy as np
import pytest

from cdnf_ti.kernels.engine import Coefs, Launch, Planes, Scalars, Stage, model
from cdnf_ti.models import MODELS, Model, StepResult, register_model

LANES = 32  # the lane width of both compilers (kernels.common.LANES_BY_COMPILER)
#: Windows (k0, k1), each with its weight: a half-plane each side, a band, one column, windows beside the pixel.
WINDOWS = ((-49, 0, 1.0), (1, 50, 2.0), (-19, 20, 4.0), (0, 0, 8.0), (3, 7, 16.0), (-40, -33, 32.0),
           (-LANES, LANES, 64.0))
REACH = 51  # the farthest column a window's prefixes read: 1 - k0 of the first window
PLANES = Planes("P Y")


def build(ti, lanes):
    from cdnf_ti.kernels import engine

    P, Y = PLANES

    @ti.func
    def prefix(a: ti.template()):
        a.put_prefix(P, a.grey())

    @ti.func
    def windows(a: ti.template()):
        y = a.zeros()
        for k0, k1, w in ti.static(WINDOWS):
            y += w * a.row_sum(P, k0, k1)
        a.put(Y, y)

    step = Launch("step", Stage(prefix), Stage(windows, halo="reach"))
    return model(PLANES, Coefs(), Scalars(""), engine.build(ti, lanes), step)


@dataclass(frozen=True)
class RowSumParams:
    pass


@register_model
class RowSum(Model):
    name, params_type = "toy_rowsum", RowSumParams
    kernels = staticmethod(build)

    def borders(self):
        return {"P": "zero"}

    def kernel_options(self):
        return {"reach": REACH}

    def _step(self, t, grey, loaded):
        self._be.launch("step")
        return StepResult(t, 0.0, False)


MODELS.pop(RowSum.name)  # registered for this file's tests only


def expected_windows(frame: np.ndarray) -> np.ndarray:
    """``sum w sum_{d=k0..k1} frame(i, j + d)`` of :data:`WINDOWS`, zero outside the frame (float64)."""
    p = REACH
    x = np.pad(frame.astype(np.float64), ((0, 0), (p, p)))
    W = frame.shape[1]
    return sum(w * sum(x[:, p + d:p + d + W] for d in range(k0, k1 + 1)) for k0, k1, w in WINDOWS)


@pytest.mark.parametrize("fast", [True, False])  # the lane layout (2 ghost elements), the pixel layout
@pytest.mark.parametrize("width", [100, 128])  # a partial last element, whole elements
def test_row_sum_is_the_sum_of_the_row_window_with_zero_outside_the_frame(fast, width):
    rng = np.random.default_rng(11)
    frame = rng.integers(0, 256, size=(7, width)).astype(np.uint8)
    m = RowSum()
    m.fast = fast
    m.step(frame)
    assert m._be.lane is fast and (not fast or m._be.ghosts == 2)
    # integer sums below 2^24: exact in float32, whichever the order
    np.testing.assert_array_equal(m.fields()["Y"], expected_windows(frame).astype(np.float32))


def test_row_sum_reaching_past_the_ghost_elements_is_refused_at_compile_time():
    class Short(RowSum):
        def kernel_options(self):
            return {"reach": LANES}  # one ghost element: the window -49 .. 0 reads the prefixes 50 columns left

    m = Short()
    with pytest.raises(Exception, match="ghost elements"):
        m.step(np.zeros((7, 100), np.uint8))
