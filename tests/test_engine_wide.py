"""The engine's wide stencils: ``a.at(P, di, dj)`` at column offsets beyond one lane vector (the lane arrays
get ``ceil(halo / LANES)`` ghost elements either side, refreshed ``halo`` columns wide), and ``a.within``, in
both layouts and under each border mode, against NumPy's padding of the same frame."""
from dataclasses import dataclass

import numpy as np
import pytest

from cdnf_ti.kernels.engine import Coefs, Launch, Planes, Scalars, Stage, model
from cdnf_ti.models import MODELS, Model, StepResult, register_model

LANES = 32  # the lane width of both compilers (kernels.common.LANES_BY_COMPILER)
#: Column offsets up to two lane vectors and three columns either side, and row offsets, each with its weight.
TAPS = ((0, -(2 * LANES + 3), 1.0), (0, -(LANES + 1), 2.0), (0, -LANES, 4.0), (0, -3, 8.0), (0, 0, 16.0),
        (0, 5, 32.0), (0, LANES, 64.0), (0, LANES + 7, 128.0), (0, 2 * LANES + 3, 256.0), (2, -(LANES + 2), 512.0),
        (-1, 2 * LANES, 1024.0))
REACH = 2 * LANES + 3
PLANES, SCALARS = Planes("X Y Z"), Scalars("r0 r1 c0 c1")
NUMPY_MODES = {"replicate": "edge", "reflect": "reflect", "zero": "constant"}  # reflect: reflect-101


def build(ti, lanes):
    from cdnf_ti.kernels import engine

    X, Y, Z = PLANES

    @ti.func
    def copy(a: ti.template()):
        a.put(X, a.grey())

    @ti.func
    def taps(a: ti.template()):
        y = a.zeros()
        for di, dj, w in ti.static(TAPS):
            y += w * a.at(X, di, dj)
        a.put(Y, y)
        a.put(Z, a.within(ti.cast(a.value(SCALARS.r0), ti.i32), ti.cast(a.value(SCALARS.r1), ti.i32),
                          ti.cast(a.value(SCALARS.c0), ti.i32), ti.cast(a.value(SCALARS.c1), ti.i32)))
        return y

    step = Launch("step", Stage(copy, ghosts=(X,), halo="reach"), Stage(taps, sums="sum_Y"))
    return model(PLANES, Coefs(), SCALARS, engine.build(ti, lanes), step)


@dataclass(frozen=True)
class WideParams:
    border: str = "replicate"


@register_model
class Wide(Model):
    name, params_type = "toy_wide", WideParams
    kernels = staticmethod(build)

    def borders(self):
        return {"X": self.params.border}

    def kernel_options(self):
        return {"reach": REACH}

    def _step(self, t, grey, loaded):
        (total,) = self._be.launch("step", r0=2, r1=grey.shape[0] - 1, c0=LANES + 3, c1=2 * LANES + 9)
        return StepResult(t, total, False)


MODELS.pop(Wide.name)  # registered for this file's tests only


def expected_taps(frame: np.ndarray, border: str) -> np.ndarray:
    """``sum w X(i + di, j + dj)`` of :data:`TAPS` with NumPy's padding (float64)."""
    p = REACH
    x = np.pad(frame.astype(np.float64), p, mode=NUMPY_MODES[border])
    H, W = frame.shape
    return sum(w * x[p + di:p + di + H, p + dj:p + dj + W] for di, dj, w in TAPS)


@pytest.mark.parametrize("fast", [True, False])  # the lane layout (3 ghost elements), the pixel layout
@pytest.mark.parametrize("border", sorted(NUMPY_MODES))
def test_a_stage_reads_offsets_wider_than_a_lane_vector_with_the_planes_border(border, fast):
    rng = np.random.default_rng(7)
    frame = rng.integers(0, 256, size=(9, 100)).astype(np.uint8)  # 100 columns: a partial last element
    m = Wide(WideParams(border))
    m.fast = fast
    r = m.step(frame)
    assert m._be.lane is fast and (not fast or m._be.ghosts == 3)
    want = expected_taps(frame, border)
    np.testing.assert_array_equal(m.fields()["Y"], want.astype(np.float32))  # integer sums: exact in float32
    assert r.output == want.sum()


@pytest.mark.parametrize("fast", [True, False])
def test_within_masks_the_rows_and_columns_of_a_box_of_the_frame(fast):
    m = Wide()
    m.fast = fast
    m.step(np.zeros((9, 100), np.uint8))
    want = np.zeros((9, 100), np.float32)
    want[2:8, LANES + 3:2 * LANES + 9] = 1.0
    np.testing.assert_array_equal(m.fields()["Z"], want)
