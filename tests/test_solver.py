"""The shared fixed-point controller: stopping, per-field counts, damping, honesty."""
import numpy as np

from cdnf_ti.solver import solve_fixed_point


def _affine_map(slope, fixed):
    state = {"x": 0.0}

    def iterate(lam):
        x = state["x"]
        f = fixed + slope * (x - fixed)
        state["x"] = x + lam * (f - x)
        return (abs(f - x),)

    return state, iterate


def test_contraction_converges_without_damping():
    state, it = _affine_map(0.5, 1.0)
    rep = solve_fixed_point(it, 1, tol=1e-8, max_iter=100)
    assert rep.converged and rep.damping == 1.0
    assert abs(state["x"] - 1.0) < 1e-7


def test_oscillating_map_is_damped_until_it_converges():
    # slope -3: plain iteration diverges; lam <= 1/2 makes it a contraction.
    state, it = _affine_map(-3.0, 1.0)
    rep = solve_fixed_point(it, 1, tol=1e-8, max_iter=500, stall_patience=2)
    assert rep.converged
    assert rep.damping < 1.0
    assert abs(state["x"] - 1.0) < 1e-7


def test_unconverged_solve_is_reported_not_hidden():
    state, it = _affine_map(0.99, 1.0)
    rep = solve_fixed_point(it, 1, tol=1e-12, max_iter=5)
    assert not rep.converged
    assert rep.iterations == (5,)
    assert rep.residuals[0] > 1e-12


def test_per_field_iteration_counts_are_recorded_separately():
    xs = [0.0, 0.0]

    def it(lam):
        res = []
        for i, slope in enumerate((0.1, 0.6)):
            f = 1.0 + slope * (xs[i] - 1.0)
            res.append(abs(f - xs[i]))
            xs[i] += lam * (f - xs[i])
        return tuple(res)

    rep = solve_fixed_point(it, 2, tol=1e-6, max_iter=100)
    assert rep.converged
    assert rep.iterations[0] < rep.iterations[1]
    assert np.allclose(xs, 1.0, atol=1e-5)


def _batched(iterate, tol, calls):
    """``iterate_many`` over a one-step map, stopping after the first update within tol."""
    def many(coefs):
        calls.append(len(coefs))
        out = []
        for lam, _mom in coefs:
            out.append(iterate(lam))
            if max(out[-1]) <= tol:
                break
        return out
    return many


def test_plain_scheme_in_batches_takes_the_same_steps_as_one_at_a_time():
    _, one = _affine_map(0.8, 1.0)
    single = solve_fixed_point(one, 1, tol=1e-8, max_iter=200)
    _, two = _affine_map(0.8, 1.0)
    calls: list[int] = []
    batched = solve_fixed_point(two, 1, tol=1e-8, max_iter=200, steps=16,
                                iterate_many=_batched(two, 1e-8, calls))
    assert batched.converged and batched.iterations == single.iterations
    assert batched.residuals == single.residuals
    assert len(calls) < single.iterations[0] and max(calls) == 16  # several updates per launch


def test_plain_scheme_in_batches_still_damps_an_oscillating_map():
    state, it = _affine_map(-3.0, 1.0)
    rep = solve_fixed_point(it, 1, tol=1e-8, max_iter=500, stall_patience=2, steps=8,
                            iterate_many=_batched(it, 1e-8, []))
    assert rep.converged and rep.damping < 1.0
    assert abs(state["x"] - 1.0) < 1e-7


def test_bounds_that_do_not_show_a_contraction_fall_back_to_the_plain_scheme():
    """A Jacobian bound b >= 1 (a wide Summation kernel) leaves Chebyshev inapplicable: the plain, damped
    scheme solves it, as the paper's scheme does, instead of refusing the parameters."""
    from cdnf_ti.solver import solve_fixed_point

    u = np.zeros(3)

    def iterate(lam, mom=0.0):
        new = 0.5 * np.tanh(u) + 0.1
        r = float(np.abs(new - u).max())
        u[:] = u + lam * (new - u)
        return (r,)

    rep = solve_fixed_point(iterate, 1, tol=1e-9, max_iter=500, damping=1.0, bounds=(-0.5, 1.5))
    assert rep.converged and rep.scheme == "plain"
