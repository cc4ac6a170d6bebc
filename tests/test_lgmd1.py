"""LGMD1 (ON/OFF + SFA): Taichi vs NumPy reference and its differences from LGMD2."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti.models import LGMD1, LGMD1Params
from cdnf_ti.stimuli.basic import BASIC_STIMULI


def noisy_stream(name: str, seed: int, h: int = 72, w: int = 104, sigma: float = 20.0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    s = small_stimulus(name, size=max(h, w))
    out = []
    for f in s.frames():
        g = f[:h, :w].astype(np.float64) * 200 + 28 + rng.normal(0, sigma, (h, w))
        out.append(np.clip(np.rint(g), 0, 255).astype(np.uint8))
    return out


def run_both(frames, **kw):
    a, b = LGMD1(backend="taichi", **kw), LGMD1(backend="numpy", **kw)
    return a, a.run(frames), b, b.run(frames)


@pytest.mark.parametrize("stim", BASIC_STIMULI)
def test_taichi_matches_numpy_reference_on_basic_stimulus(stim):
    _, ta, _, nu = run_both(list(small_stimulus(stim, 96).frames()))
    np.testing.assert_allclose(ta.output, nu.output, atol=1e-5, rtol=0)
    np.testing.assert_allclose(ta.diagnostics["Kh"], nu.diagnostics["Kh"], atol=1e-5, rtol=0)
    np.testing.assert_array_equal(ta.diagnostics["count"], nu.diagnostics["count"])
    np.testing.assert_array_equal(ta.diagnostics["held"], nu.diagnostics["held"])


def test_taichi_matches_numpy_reference_on_noisy_video_like_stream():
    a, ta, b, nu = run_both(noisy_stream("light_looming", seed=5))
    np.testing.assert_allclose(ta.output, nu.output, atol=1e-5, rtol=0)
    np.testing.assert_array_equal(ta.spike, nu.spike)
    fa, fb = a.fields(), b.fields()
    assert set(fa) == set(fb) >= {"P", "ON", "OFF", "I_on", "E_off", "S", "G"}
    for k in fb:
        np.testing.assert_allclose(fa[k], fb[k], rtol=1e-4, atol=1e-2, err_msg=k)


@pytest.mark.parametrize("backend", ["numpy", "taichi"])
def test_lateral_spread_excludes_the_centre_and_is_delayed(backend):
    frames = [np.zeros((7, 7), np.uint8) for _ in range(2)]
    frames[1][3, 3] = 100
    m = LGMD1(backend=backend)
    m.run(frames)
    f = m.fields()
    a_edge, a_diag = 33 / 63, 33 / 93
    assert f["I_on"][3, 3] == 0.0  # centre weight 0
    assert f["I_on"][2, 3] == pytest.approx(0.25 * a_edge * 100, rel=1e-5)
    assert f["I_on"][2, 2] == pytest.approx(0.125 * a_diag * 100, rel=1e-5)
    # S_on = ON - 0.5 I_on = 100 at the centre (>= 30 kept); negative around it -> 0
    assert f["S"][3, 3] == pytest.approx(100.0)
    assert f["S"][2, 3] == 0.0


@pytest.mark.parametrize("backend", ["numpy", "taichi"])
def test_s_cells_below_threshold_are_zeroed(backend):
    frames = [np.zeros((7, 7), np.uint8) for _ in range(2)]
    frames[1][3, 3] = 20  # S = 20 < T_s = 30
    m = LGMD1(backend=backend)
    tr = m.run(frames)
    assert m.fields()["S"].max() == 0.0
    assert tr.output[1] == 0.5


def test_off_excitation_is_the_delayed_spread_and_off_itself_inhibits():
    frames = [np.full((7, 7), 200, np.uint8) for _ in range(2)]
    frames[1][3, 3] = 100  # OFF = 100 at the centre
    m = LGMD1(backend="numpy")
    m.run(frames)
    f = m.fields()
    assert f["E_off"][3, 3] == 0.0
    # neighbour: E_off = 0.25 a 100 and no OFF of its own -> S_off positive but < 30 -> 0
    assert f["E_off"][3, 4] == pytest.approx(0.25 * 33 / 63 * 100)
    assert f["S"].max() == 0.0  # the centre: 0 - 1.0 * 100 < 30


def test_feed_forward_inhibition_holds_the_output_at_rest():
    # full-frame flicker: mean |P| = 255, so FFI jumps above 8 on frame 1
    frames = [np.full((16, 16), 255 * (t % 2), np.uint8) for t in range(6)]
    tr = LGMD1(backend="numpy").run(frames)
    ffi1 = 33 / (33 + 90) * 255
    assert tr.diagnostics["FFI"][1] == pytest.approx(ffi1)
    assert (tr.diagnostics["held"][1:] == 1).all()
    assert (tr.output[1:] == 0.5).all() and (tr.diagnostics["Kh"][1:] == 0.5).all()
    assert not tr.spike.any() and (tr.diagnostics["count"] == 0).all()


def test_sfa_uses_lgmd1_threshold_and_time_constant():
    s = small_stimulus("dark_looming", 96)
    tr = LGMD1(backend="numpy").run(s.frames())
    K, Kh = tr.output, tr.diagnostics["Kh"]
    a_s = 500 / 533
    for t in range(2, tr.n_frames):
        if tr.diagnostics["held"][t] or tr.diagnostics["held"][t - 1]:
            continue
        d = K[t] - K[t - 1]
        want = a_s * (Kh[t - 1] + d) if d <= 0.005 else a_s * K[t]
        assert Kh[t] == pytest.approx(max(want, 0.5), abs=1e-12)


@pytest.mark.parametrize("bad, msg", [(dict(t_ffi=0), "t_ffi"), (dict(k_lateral=(1.0,)), "k_lateral"),
                                      (dict(n_ts=2.5), "n_ts")])
def test_invalid_params_raise_clear_value_error(bad, msg):
    with pytest.raises(ValueError, match=msg):
        LGMD1Params(**bad)
