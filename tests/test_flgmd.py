"""F-LGMD ONn (reconstruction): Taichi vs NumPy, the feedback fixed point and its contraction bound."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti.baselines_reference import correlate3, delayed_spread, kernel_3x3
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
