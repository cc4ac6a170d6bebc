"""The engine's relaxation updates and pending spans: a toy field ``u = g + c (sum of u's 4 neighbours)``
solved by relaxation, its input marking the elements it changed, checked against NumPy float64 and
against the pixel layout (which visits every pixel and never freezes)."""
from dataclasses import dataclass

import numpy as np

from cdnf_ti.kernels.engine import EMPTY_LO, Coefs, Launch, Planes, Scalars, Span, Stage, model
from cdnf_ti.models import MODELS, Model, StepResult, register_model

PLANES, SCALARS = Planes("G U:2 _span"), Scalars("updates tol grow tau")
G, U, SPAN_PLANE = PLANES
SPAN = Span(SPAN_PLANE, U)
COUPLING = 0.05  # c: the field's weight of each of its four neighbours (a contraction: 4 c < 1)


def build(ti, lanes):
    from cdnf_ti.kernels import engine

    @ti.func
    def load(a: ti.template()):
        """``G`` = the frame; returns whether it changed here (the span group's input)."""
        g = a.grey()
        changed = a.any(g != a.at(G))
        a.put(G, g)
        return changed

    @ti.func
    def relax(a: ti.template()):
        """``F(u) - u`` with ``F(u) = g + c (u_up + u_down + u_left + u_right)``."""
        lateral = (a.at(U, -1, 0) + a.at(U, 1, 0)) + (a.at(U, 0, -1) + a.at(U, 0, 1))
        return a.at(G) + COUPLING * lateral - a.at(U)

    @ti.func
    def total(a: ti.template()):
        return a.at(U)

    solve = Launch("solve", Stage(total, sums="sum_U"), before=(Stage(load, marks=SPAN),),
                   update=(Stage(relax, relax=(U,), spans=SPAN, rows=1),), scalars=SCALARS)
    return model(PLANES, Coefs(), SCALARS, engine.build(ti, lanes), solve, spans=(SPAN,))


@dataclass(frozen=True)
class FieldParams:
    tol: float = 1e-6
    tau: float = 0.0


@register_model
class Field(Model):
    name, params_type = "toy_span_field", FieldParams
    kernels = staticmethod(build)

    def _step(self, t, grey, loaded):
        p = self.params
        self.residuals, (s,) = self._be.solve("solve", [(1.0, 0.0)] * 32, 32, p.tol, 10.0, tau=p.tau)
        return StepResult(t, s / grey.size, False, bool(self.residuals) and max(self.residuals[-1]) <= p.tol)


MODELS.pop(Field.name)  # registered for this file's tests only


def reference(frames, tol, tau):
    """NumPy float64: each frame, relaxation updates of every pixel (replicate border) until the residual
    ``max |F(u) - u|`` is at most ``tol``; pixels with ``|F(u) - u| <= tau`` keep their value."""
    u = np.zeros(frames[0].shape)
    for g in frames:
        for _ in range(32):
            p = np.pad(u, 1, mode="edge")
            d = g + COUPLING * ((p[:-2, 1:-1] + p[2:, 1:-1]) + (p[1:-1, :-2] + p[1:-1, 2:])) - u
            u = np.where(np.abs(d) > tau, u + d, u)
            if np.abs(d).max() <= tol:
                break
    return u


def frames(height=32, width=96):
    """A random frame, then the same frame with a small patch (rows 2-3, columns 40-43) changed."""
    rng = np.random.default_rng(3)
    first = rng.random((height, width)).astype(np.float32)
    second = first.copy()
    second[2:4, 40:44] = 1.0 - second[2:4, 40:44]
    return [first, second]


def run(clip, fast, **params):
    m = Field(FieldParams(**params))
    m.fast = fast
    for f in clip:
        r = m.step(f)
    return m, r


def test_a_relaxation_solve_converges_to_the_fixed_point_of_numpy():
    clip = frames()
    m, r = run(clip, True)
    assert r.converged and m._be.lane
    np.testing.assert_allclose(m.fields()["U"], reference(clip, 1e-6, 0.0), atol=2e-6)


def test_with_spans_the_lane_layout_equals_the_pixel_layout_that_visits_every_pixel():
    # tau = 0: a lane moves unless F(u) = u exactly, so an element left out is one the pixel layout leaves as is
    clip = frames()
    lane, _ = run(clip, True)
    pixel, _ = run(clip, False)
    assert lane._be.lane and not pixel._be.lane
    np.testing.assert_allclose(lane.fields()["U"], pixel.fields()["U"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(lane.residuals, pixel.residuals, rtol=0, atol=1e-6)


def test_a_local_change_leaves_the_rows_far_from_it_without_a_pending_span():
    clip = frames()
    m, r = run(clip, True, tol=1e-3, tau=1e-3)  # the first frame's last update moved no lane
    assert r.converged
    x = m._be.x.to_numpy()[SPAN_PLANE.slot, :, 0, :4]  # (H, 4): lo, hi of parity 0, of parity 1
    lo = x[:, [0, 2]]
    assert (lo[8:] == EMPTY_LO).all()  # 4 rows past the patch and more: nothing moved by more than tau
    assert (lo[2:4] < EMPTY_LO).any()  # the patch's rows moved
    np.testing.assert_allclose(m.fields()["U"], reference(clip, 1e-3, 1e-3), atol=3e-3)


def test_frozen_lanes_keep_their_values_exactly():
    # tau above every residual: no lane ever moves, the field stays at its reset value 0
    m, r = run(frames(), True, tol=1.0, tau=10.0)
    assert r.converged and not m.fields()["U"].any()
