"""Solve launches: several field updates per kernel launch, coefficients in and residuals out
through a launch record (``kernels.common.LaunchRecord``), never through a return value.

C-DNF's solves on the pixel layout (GPUs and narrow frames) run the solver's updates one parallel loop
each, gated on the residuals of the updates before: checked here on the CPU against the NumPy float64
reference and against one update per launch, on dashcam-like video.
"""
import ast
from pathlib import Path

import numpy as np
import pytest
from cdnf_engine import Driver

from cdnf_ti import CDNFParams, create_model
from cdnf_ti.bench.inputs import standin_video
from cdnf_ti.kernels.common import MAX_STEPS, LaunchRecord
from cdnf_ti.reference import NumpyCDNFBackend
from cdnf_ti.solver import RESTART_GROWTH, ChebyshevSchedule

REPO = Path(__file__).resolve().parents[1]


def _video(n: int) -> list[np.ndarray]:
    """``n`` frames of the dashcam-like stand-in video, 120 x 70 px (narrow: the generic kernels)."""
    return [np.ascontiguousarray(f[::2, ::3][:, :70]) for f in standin_video(n, seed=3)]


def _loaded_pair(params: CDNFParams) -> tuple[Driver, NumpyCDNFBackend]:
    """C-DNF on the pixel layout and the reference, two frames loaded."""
    f0, f1 = _video(2)
    be, ref = Driver(params, f0.shape, fast=False), NumpyCDNFBackend(params, f0.shape)
    for b in (be, ref):
        b.load(f0, True)
        b.load(f1, False)
    return be, ref


def _expected_count(residuals: list[tuple[float, ...]], tol: float, grow: float) -> int:
    """Updates a launch runs: up to the first whose residuals are all <= tol or whose worst exceeds
    ``grow`` times the best before it."""
    best = np.inf
    for k, r in enumerate(residuals):
        if max(r) <= tol or max(r) > grow * best:
            return k + 1
        best = min(best, max(r))
    return len(residuals)


def test_a_launch_record_rejects_an_empty_or_oversized_launch():
    rec = LaunchRecord(2)
    for coefs in ([], [(1.0, 0.0)] * (MAX_STEPS + 1)):
        with pytest.raises(ValueError, match="updates per launch"):
            rec.start(coefs)


def test_a_launch_record_reports_only_the_updates_that_ran():
    rec = LaunchRecord(2)
    arr = rec.start([(0.5, 0.0), (0.7, 0.1), (0.9, 0.2)])
    assert arr.dtype == np.float32 and arr.shape == (MAX_STEPS, 4)
    assert np.allclose(arr[:3, :2], [(0.5, 0.0), (0.7, 0.1), (0.9, 0.2)])
    assert (arr[:, 2:] == -1.0).all()  # nothing ran yet
    arr[0, 2:] = (0.25, 0.5)
    arr[1, 2:] = (0.125, 0.0)
    assert rec.residuals(3) == [(0.25, 0.5), (0.125, 0.0)]


def test_a_contrast_launch_stops_after_the_update_that_converges():
    p = CDNFParams(tol=1e-3)
    be, ref = _loaded_pair(p)
    coefs = ChebyshevSchedule(*p.chebyshev_bounds()[0]).take(8)
    expected = [ref.contrast_iterate(lam, mom) for lam, mom in coefs]
    count = _expected_count(expected, p.tol, RESTART_GROWTH)
    assert 1 < count < 8  # the launch must stop early for this test to mean anything
    got = be.contrast_iterate_many(coefs)
    assert len(got) == count
    assert np.allclose(got, expected[:count], atol=2e-6)
    ref2 = _loaded_pair(p)[1]
    for lam, mom in coefs[:count]:
        ref2.contrast_iterate(lam, mom)
    for name in ("u_on", "u_off"):  # the launch left the fields of its last update
        assert np.max(np.abs(be.fields()[name] - ref2.fields()[name])) < 2e-6, name


def test_a_contrast_launch_stops_after_a_growing_residual():
    p = CDNFParams()
    be, ref = _loaded_pair(p)
    coefs = [(3.0, 0.0)] * 8  # over-relaxed: the high spatial frequencies grow by about 2x per update
    expected = [ref.contrast_iterate(lam, mom) for lam, mom in coefs]
    count = _expected_count(expected, p.tol, RESTART_GROWTH)
    assert max(expected[count - 1]) > RESTART_GROWTH * min(max(r) for r in expected[: count - 1]) and count < 8
    got = be.contrast_iterate_many(coefs)
    assert len(got) == count
    assert np.allclose(got, expected[:count], rtol=1e-5, atol=2e-6)


def test_longer_solves_run_every_update_they_are_given():
    p = CDNFParams()
    be, ref = _loaded_pair(p)
    coefs = ChebyshevSchedule(*p.chebyshev_bounds()[0]).take(7)
    expected = [ref.contrast_iterate(lam, mom) for lam, mom in coefs]
    assert _expected_count(expected, p.tol, RESTART_GROWTH) == 7
    got = be.contrast_iterate_many(coefs)
    assert len(got) == 7 and np.allclose(got, expected, atol=2e-6)


def test_eight_updates_per_solve_call_compute_what_one_per_call_computes():
    frames = _video(8)
    traces = []
    for steps in (1, 8):
        model = create_model("cdnf", CDNFParams(steps_per_launch=steps))
        model.fast = False  # the pixel layout, which GPUs run
        traces.append(model.run(frames))
    one, eight = traces
    assert np.array_equal(one.output, eight.output)  # same arithmetic, bit for bit
    for key in ("iterations_on", "iterations_off", "iterations_sum"):
        assert np.array_equal(one.diagnostics[key], eight.diagnostics[key]), key
    ref = create_model("cdnf", backend="numpy").run(frames)
    assert np.max(np.abs(eight.output - ref.output)) < 1e-4 and eight.converged.all()


@pytest.mark.parametrize("module", ["engine", "stimuli", "common"])  # the models declare stages only
def test_no_kernel_returns_a_value(module):
    # A kernel's results go to an array argument: a returned vector costs ~210 us per launch on
    # the CPU under taichi 1.7.4, and a returned reduction 1-2 ms on a GPU
    # (docs/PERFORMANCE.md, "Design decisions that still hold").
    tree = ast.parse((REPO / "kernels" / f"{module}.py").read_text())
    kernels = [f for f in ast.walk(tree) if isinstance(f, ast.FunctionDef)
               and any(ast.unparse(d).endswith("kernel") for d in f.decorator_list)]
    assert kernels, module
    returning = [f.name for f in kernels if f.returns is not None]
    assert returning == [], f"kernels/{module}.py: {returning} return a value"
