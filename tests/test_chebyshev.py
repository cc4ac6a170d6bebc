"""Chebyshev semi-iteration: bounds from the kernels, same fixed point as plain, the safeguard."""
import math
import warnings

import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti import CDNF, CDNFParams
from cdnf_ti.params import contrast_kernel, dog_kernel, jacobian_bounds
from cdnf_ti.solver import ChebyshevSchedule, solve_fixed_point


def _periodic_matrix(kernel: np.ndarray, n: int) -> np.ndarray:
    """The correlation with ``kernel`` on an ``n x n`` periodic grid, as an (n^2, n^2) matrix."""
    r = kernel.shape[0] // 2
    m = np.zeros((n * n, n * n))
    for y in range(n):
        for x in range(n):
            for dy in range(-r, r + 1):
                for dx in range(-r, r + 1):
                    m[y * n + x, ((y + dy) % n) * n + (x + dx) % n] += kernel[dy + r, dx + r]
    return m


def test_default_bounds_are_the_spectra_of_the_kernels():
    c, s = CDNFParams().chebyshev_bounds()
    assert c == pytest.approx((-0.048, 0.5), abs=1e-3)
    assert s == pytest.approx((-0.786, 0.729), abs=1e-3)


@pytest.mark.parametrize("which", ["contrast", "summation"])
def test_every_jacobian_eigenvalue_lies_within_the_bounds(which):
    # J = diag(0.5 sech^2) W with random sech^2 in (0, 1]; W on a periodic 12x12 grid.
    p = CDNFParams(sigma_1=0.4, A=1.2, B=0.6) if which == "summation" else CDNFParams(sigma_c=0.7)
    w = dog_kernel(p) if which == "summation" else contrast_kernel(p.sigma_c)
    a, b = jacobian_bounds(w)
    m = _periodic_matrix(w, 12)
    sech2 = np.random.default_rng(0).uniform(0.05, 1.0, m.shape[0])
    ev = np.linalg.eigvals(0.5 * sech2[:, None] * m).real
    assert ev.min() >= a - 1e-9 and ev.max() <= b + 1e-9
    # and the bounds are tight for sech^2 = 1
    ev1 = np.linalg.eigvalsh(0.5 * (m + m.T) / 2)
    assert ev1.max() == pytest.approx(b, abs=0.02)


def test_chebyshev_rate_beats_plain_for_the_default_summation_bounds():
    a, b = CDNFParams().chebyshev_bounds()[1]
    assert ChebyshevSchedule(a, b).rate < 0.6 * max(abs(a), abs(b))


def _linear_map(eigs, seed=0):
    """``F(u) = M u + c`` with a symmetric M of the given eigenvalues; fixed point known."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((len(eigs), len(eigs))))
    m = q @ np.diag(eigs) @ q.T
    c = rng.standard_normal(len(eigs))
    x_star = np.linalg.solve(np.eye(len(eigs)) - m, c)
    st = {"u": np.zeros(len(eigs)), "prev": np.zeros(len(eigs))}

    def iterate(lam, mom=0.0):
        u = st["u"]
        d = m @ u + c - u
        st["u"], st["prev"] = u + mom * (u - st["prev"]) + lam * d, u
        return (float(np.abs(d).max()),)

    return st, iterate, x_star


def test_chebyshev_solves_a_linear_map_in_far_fewer_steps_than_plain():
    eigs = np.linspace(-0.78, 0.72, 40)
    st, it, x = _linear_map(eigs)
    cheb = solve_fixed_point(it, 1, tol=1e-9, max_iter=500, bounds=(-0.786, 0.729), steps=3)
    assert cheb.converged and cheb.scheme == "chebyshev" and cheb.restarts == 0
    assert np.abs(st["u"] - x).max() < 1e-7
    st2, it2, _ = _linear_map(eigs)
    plain = solve_fixed_point(it2, 1, tol=1e-9, max_iter=500)
    assert plain.converged
    assert cheb.iterations[0] * 2 < plain.iterations[0]


def test_chebyshev_with_wrong_bounds_diverges_without_the_safeguard():
    # bounds that miss the spectrum badly: the bare recurrence blows up ...
    eigs = np.linspace(-0.78, 0.72, 40)
    st, it, _ = _linear_map(eigs)
    sched = ChebyshevSchedule(0.9, 0.95)
    res = [it(*sched.next())[0] for _ in range(60)]
    assert res[-1] > 1e3 * res[0] or not math.isfinite(res[-1])
    # ... and the safeguard restarts, then falls back to damped plain iteration, and converges.
    st, it, x = _linear_map(eigs)
    rep = solve_fixed_point(it, 1, tol=1e-9, max_iter=500, bounds=(0.9, 0.95), steps=2)
    assert rep.converged and rep.scheme == "plain" and rep.restarts >= 1
    assert np.abs(st["u"] - x).max() < 1e-7


@pytest.mark.parametrize("backend", ["taichi", "numpy"])
def test_model_with_wrong_bounds_still_converges_to_the_reference(backend):
    frames = list(small_stimulus("light_looming", size=64).frames())
    bad = CDNFParams(summation_bounds=(0.9, 0.95), contrast_bounds=(0.9, 0.95))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an unconverged frame would warn
        tr = CDNF(bad, backend=backend).run(frames)
    ref = CDNF(CDNFParams(scheme="plain"), backend="numpy").run(frames)
    assert tr.converged.all()
    assert tr.diagnostics["restarts"].max() >= 1  # the safeguard did act
    assert np.max(np.abs(tr.output - ref.output)) < 1e-4


@pytest.mark.parametrize("backend", ["taichi", "numpy"])
def test_chebyshev_and_plain_reach_the_same_fixed_point(backend):
    frames = list(small_stimulus("dark_looming", size=72).frames())
    tight = dict(tol=1e-7)
    model_c = CDNF(CDNFParams(scheme="chebyshev", **tight), backend=backend)
    model_p = CDNF(CDNFParams(scheme="plain", **tight), backend=backend)
    for f in frames:
        rc, rp = model_c.step(f), model_p.step(f)
        assert abs(rc.output - rp.output) < 1e-6
    fc, fp = model_c.fields(), model_p.fields()
    for k in ("u_on", "u_off", "v"):
        assert np.max(np.abs(fc[k] - fp[k])) < 2e-5, k


def test_chebyshev_needs_fewer_iterations_than_plain_on_every_field():
    frames = list(small_stimulus("light_translating", size=80).frames())[:20]
    c = CDNF(CDNFParams(scheme="chebyshev")).run(frames).diagnostics
    p = CDNF(CDNFParams(scheme="plain")).run(frames).diagnostics
    for k in ("iterations_off", "iterations_sum"):
        assert c[k][1:].sum() < 0.75 * p[k][1:].sum(), k


def test_several_updates_per_launch_give_the_same_trace_and_counts():
    frames = list(small_stimulus("dark_translating", size=80).frames())[:20]
    one = CDNF(CDNFParams(steps_per_launch=1)).run(frames)
    four = CDNF(CDNFParams(steps_per_launch=4)).run(frames)
    assert np.max(np.abs(one.output - four.output)) < 1e-6
    for k in ("iterations_on", "iterations_off", "iterations_sum"):
        assert np.array_equal(one.diagnostics[k], four.diagnostics[k]), k


def test_real_clip_agrees_with_the_reference_under_both_schemes(shared_real):
    if shared_real is None:
        pytest.skip("the development dashcam clips are not present")
    from cdnf_ti.frames import iter_grey, open_source

    frames = [f[::2, ::2] for f in iter_grey(open_source(shared_real / "serial_vehicle_collision.mp4"))]
    ref = CDNF(CDNFParams(tol=1e-9, scheme="plain"), backend="numpy").run(frames)
    for scheme in ("chebyshev", "plain"):
        tr = CDNF(CDNFParams(scheme=scheme)).run(frames)
        assert tr.converged.all(), scheme
        assert np.max(np.abs(tr.output - ref.output)) < 1e-4, scheme
