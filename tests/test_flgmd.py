"""F-LGMD ONn (reconstruction): Taichi vs NumPy, the feedback fixed point and its contraction bound."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti.baselines_reference import correlate3, delayed_spread, kernel_3x3
from cdnf_ti.bench.inputs import standin_video
from cdnf_ti.models import FLGMDONn, FLGMDParams
from cdnf_ti.stimuli.basic import BASIC_STIMULI


def noisy_stream(name: str, seed: int, h: int = 72, w: int = 104, sigma: float = 20.0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    s = small_stimulus(name, size=max(h, w))
    out = []
    for f in s.frames():
        g = f[:h, :w].astype(np.float64) * 200 + 28 + rng.normal(0, sigma, (h, w))
        out.append(np.clip(np.rint(g), 0, 255).astype(np.uint8))
    return out


def run_both(frames, params=None):
    a, b = FLGMDONn(params, backend="taichi"), FLGMDONn(params, backend="numpy")
    return a, a.run(frames), b, b.run(frames)


@pytest.mark.parametrize("stim", BASIC_STIMULI)
def test_taichi_matches_numpy_reference_on_basic_stimulus(stim):
    _, ta, _, nu = run_both(list(small_stimulus(stim, 96).frames()))
    np.testing.assert_allclose(ta.output, nu.output, atol=1e-5, rtol=0)
    np.testing.assert_allclose(ta.diagnostics["Kh"], nu.diagnostics["Kh"], atol=1e-5, rtol=0)
    np.testing.assert_array_equal(ta.diagnostics["count"], nu.diagnostics["count"])
    assert ta.converged.all() and nu.converged.all()


def test_taichi_matches_numpy_reference_on_noisy_video_like_stream():
    a, ta, b, nu = run_both(noisy_stream("light_looming", seed=11))
    np.testing.assert_allclose(ta.output, nu.output, atol=1e-5, rtol=0)
    np.testing.assert_array_equal(ta.spike, nu.spike)
    assert nu.diagnostics["iterations"].max() > 3  # the ON feedback is really iterated
    assert np.abs(ta.diagnostics["iterations"] - nu.diagnostics["iterations"]).max() <= 1
    fa, fb = a.fields(), b.fields()
    assert set(fa) == set(fb) >= {"P", "ON", "OFF", "S_on", "S_off", "S", "G"}
    for k in fb:
        np.testing.assert_allclose(fa[k], fb[k], rtol=1e-3, atol=5e-2, err_msg=k)


def test_taichi_matches_numpy_with_feedback_on_both_channels():
    p = FLGMDParams(beta_off=0.3)
    _, ta, _, nu = run_both(noisy_stream("dark_looming", seed=2, h=48, w=64), p)
    np.testing.assert_allclose(ta.output, nu.output, atol=1e-5, rtol=0)
    assert nu.diagnostics["residual_off"].max() < p.tol


def test_channels_settle_at_the_feedback_fixed_point():
    frames = noisy_stream("light_looming", seed=7, h=40, w=56)
    m = FLGMDONn(backend="numpy")
    m.run(frames[:-1])
    be = m._be
    m.step(frames[-1])
    p = m.params
    on, on_prev = be.ON, be.ON_prev
    k = kernel_3x3(0.0, *p.k_lateral)
    a = kernel_3x3(0.0, *[33 / (33 + t) for t in p.tau_lateral])
    s_on = np.maximum(correlate3(on, p.excitation_kernel()) - p.w_i_on * delayed_spread(on, on_prev, k, a), 0)
    # ON = [ON0 + beta S_on(ON)]+ within the tolerance (contraction: error <= tol / (1 - L))
    assert np.abs(np.maximum(be.ON0 + p.beta_on * s_on, 0) - on).max() < p.tol / (1 - p.contraction("on"))
    assert s_on.max() > 1.0  # the feedback is active on this stream


def test_negative_on_feedback_lowers_the_on_channel_below_its_drive():
    frames = list(small_stimulus("light_looming", 64).frames())
    neg = FLGMDONn(backend="numpy")
    off = FLGMDONn(FLGMDParams(beta_on=0.0), backend="numpy")
    neg.run(frames)
    off.run(frames)
    assert neg.fields()["ON"].sum() < off.fields()["ON"].sum()
    assert (neg._be.ON <= neg._be.ON0 + 1e-9).all()


@pytest.mark.parametrize("beta", [-0.6, 0.7, -1.0])
def test_feedback_coefficient_outside_the_contraction_bound_is_refused(beta):
    with pytest.raises(ValueError, match="contraction"):
        FLGMDParams(beta_on=beta)


def test_default_feedback_is_negative_on_on_only():
    p = FLGMDParams()
    assert p.beta_on < 0 and p.beta_off == 0 and p.contraction("on") < 1


def test_model_is_documented_as_a_reconstruction():
    import cdnf_ti.models.flgmd as mod

    assert "RECONSTRUCTION" in FLGMDONn.__doc__ and "own choice" in mod.__doc__


def test_feedback_stencil_splits_the_local_summation_into_iterated_and_constant_parts():
    from cdnf_ti.models.flgmd import feedback_stencil
    from cdnf_ti.models.lgmd2 import lowpass_coefficient

    rng = np.random.default_rng(3)
    x, x_prev = rng.uniform(0, 40, (2, 30, 41))
    p = FLGMDParams()
    a = tuple(lowpass_coefficient(33, t) for t in p.tau_lateral)
    k = kernel_3x3(0.0, *p.k_lateral)
    direct = correlate3(x, p.excitation_kernel()) - p.w_i_on * delayed_spread(x, x_prev, k, kernel_3x3(0.0, *a))
    c, e, d = feedback_stencil(p.excitation_kernel(), p.k_lateral, a, p.w_i_on)
    q = p.w_i_on * correlate3(x_prev, kernel_3x3(0.0, *(kk * (1 - aa) for kk, aa in zip(p.k_lateral, a))))
    split = correlate3(x, kernel_3x3(c, e, d)) - q
    np.testing.assert_allclose(split, direct, atol=1e-12)


def _periodic_operator(stencil: np.ndarray, n: int) -> np.ndarray:
    """Matrix of the 3x3 correlation on an n x n torus."""
    m = np.zeros((n * n, n * n))
    for i in range(n):
        for j in range(n):
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    m[i * n + j, ((i + di) % n) * n + (j + dj) % n] += stencil[di + 1, dj + 1]
    return m


@pytest.mark.parametrize("beta_on", [-0.5, 0.5])
def test_chebyshev_bounds_hold_the_spectrum_of_the_feedback_jacobian(beta_on):
    p = FLGMDParams(beta_on=beta_on)
    lo, hi = p.chebyshev_bounds(33)
    c, e, d = p.feedback_stencils(33)[0]
    w = _periodic_operator(np.array([[d, e, d], [e, c, e], [d, e, d]]), 12)
    mask = np.diag((np.random.default_rng(1).random(144) < 0.6).astype(float))
    for jac in (beta_on * w, mask @ (beta_on * w) @ mask):  # all rectifiers active; a random active set
        ev = np.linalg.eigvals(jac)
        assert np.abs(ev.imag).max() < 1e-9
        assert lo - 1e-9 <= ev.real.min() and ev.real.max() <= hi + 1e-9
    assert (lo < -0.1) if beta_on < 0 else (hi > 0.1)  # the bounds are not trivially wide
    assert -1 < lo <= 0 <= hi < 1


def test_chebyshev_and_plain_schemes_reach_the_same_fixed_point_in_fewer_iterations():
    frames = noisy_stream("light_looming", seed=11)
    cheb = FLGMDONn(backend="numpy").run(frames)
    plain = FLGMDONn(FLGMDParams(scheme="plain"), backend="numpy").run(frames)
    assert cheb.converged.all() and plain.converged.all()
    np.testing.assert_allclose(cheb.output, plain.output, atol=1e-5, rtol=0)
    computed = plain.diagnostics["iterations"] > 0
    assert cheb.diagnostics["iterations"][computed].mean() < 0.8 * plain.diagnostics["iterations"][computed].mean()


def test_taichi_matches_numpy_reference_with_the_plain_scheme():
    _, ta, _, nu = run_both(noisy_stream("dark_looming", seed=5, h=48, w=64), FLGMDParams(scheme="plain"))
    np.testing.assert_allclose(ta.output, nu.output, atol=1e-5, rtol=0)
    assert np.abs(ta.diagnostics["iterations"] - nu.diagnostics["iterations"]).max() <= 1


def test_unknown_scheme_is_refused():
    with pytest.raises(ValueError, match="scheme"):
        FLGMDParams(scheme="anderson")


# --- where the feedback iteration starts (FLGMDParams.start) -------------------------------------


@pytest.mark.parametrize("beta_on, beta_off", [(-0.5, 0.0), (-0.3, 0.4), (0.5, -0.2)])
def test_local_start_is_the_fixed_point_of_a_uniform_neighbourhood(beta_on, beta_off):
    p = FLGMDParams(beta_on=beta_on, beta_off=beta_off)
    x0 = np.linspace(0.0, 80.0, 41)
    q = np.array([0.0, 5.0, 30.0])[:, None]  # inhibition from the previous frame
    for beta, (w, kappa) in zip((beta_on, beta_off), p.local_start_gains(33)):
        start = x0 + kappa * np.maximum(w * x0 - q, 0.0)
        # a pixel whose neighbours all hold `start`: W_x (*) X = w X
        np.testing.assert_allclose(np.maximum(x0 + beta * np.maximum(w * start - q, 0.0), 0.0), start,
                                   atol=1e-12)
        assert (start >= 0.0).all()


def test_drive_start_has_no_gain():
    for w, kappa in FLGMDParams(start="drive", beta_off=0.3).local_start_gains(33):
        assert kappa == 0.0 and w > 0.0


def uniform_step(h=40, w=56, levels=(100, 100, 160)):
    return [np.full((h, w), g, np.uint8) for g in levels]


@pytest.mark.parametrize("backend", ["numpy", "taichi"])
def test_local_start_settles_a_uniform_luminance_step_without_iterating(backend):
    p = FLGMDParams(t_ffi=1e9)  # no FFI hold: the step is computed
    local = FLGMDONn(p, backend=backend).run(uniform_step())
    drive = FLGMDONn(FLGMDParams(t_ffi=1e9, start="drive"), backend=backend).run(uniform_step())
    assert drive.diagnostics["iterations"][-1] >= 3
    assert local.diagnostics["iterations"][-1] <= 1
    np.testing.assert_allclose(local.output, drive.output, atol=1e-6, rtol=0)


def test_every_start_reaches_the_same_fixed_point():
    frames = [f[::2, ::3][:, :70] for f in standin_video(10, seed=2)]  # dashcam-like, 120 x 70
    local = FLGMDONn(FLGMDParams(t_ffi=1e9), backend="numpy").run(frames)
    drive = FLGMDONn(FLGMDParams(t_ffi=1e9, start="drive"), backend="numpy").run(frames)
    assert local.converged.all() and drive.converged.all()
    assert drive.diagnostics["iterations"][1:].min() >= 3  # the feedback really iterates
    np.testing.assert_allclose(local.output, drive.output, atol=1e-6, rtol=0)
    np.testing.assert_array_equal(local.spike, drive.spike)


def test_local_start_needs_fewer_updates_on_a_translating_object():
    frames = list(small_stimulus("dark_translating", 96).frames())
    local = FLGMDONn(FLGMDParams(t_ffi=1e9), backend="numpy").run(frames)
    drive = FLGMDONn(FLGMDParams(t_ffi=1e9, start="drive"), backend="numpy").run(frames)
    exact = FLGMDONn(FLGMDParams(t_ffi=1e9, tol=1e-9, max_iter=400), backend="numpy").run(frames)
    assert local.diagnostics["iterations"].sum() < 0.9 * drive.diagnostics["iterations"].sum()
    # both are within tol of the fixed point; here S crosses its threshold T_s near the drive's answer
    np.testing.assert_allclose(local.output, exact.output, atol=1e-6, rtol=0)
    np.testing.assert_allclose(drive.output, exact.output, atol=1e-3, rtol=0)


def test_unknown_start_is_refused():
    with pytest.raises(ValueError, match="start"):
        FLGMDParams(start="previous")
