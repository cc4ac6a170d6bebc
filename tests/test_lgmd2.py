"""LGMD2: Taichi vs NumPy reference, and the details that are easy to get wrong."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti.models import LGMD2, LGMD2Params, create_model
from cdnf_ti.models.lgmd2 import LGMDFamily, frame_interval_ms, sfa_step, spike_count
from cdnf_ti.stimuli.basic import BASIC_STIMULI


def noisy_stream(name: str, seed: int, h: int = 72, w: int = 104, sigma: float = 20.0) -> list[np.ndarray]:
    """A basic stimulus (non-square) as uint8 grey with seeded Gaussian noise: a video-like stream."""
    rng = np.random.default_rng(seed)
    s = small_stimulus(name, size=max(h, w))
    out = []
    for f in s.frames():
        g = f[:h, :w].astype(np.float64) * 200 + 28 + rng.normal(0, sigma, (h, w))
        out.append(np.clip(np.rint(g), 0, 255).astype(np.uint8))
    return out


def both(model: str, frames, **kw):
    ta = create_model(model, backend="taichi", **kw).run(frames)
    nu = create_model(model, backend="numpy", **kw).run(frames)
    return ta, nu


def assert_traces_agree(ta, nu, tol=1e-5):
    np.testing.assert_allclose(ta.output, nu.output, atol=tol, rtol=0)
    np.testing.assert_allclose(ta.diagnostics["Kh"], nu.diagnostics["Kh"], atol=tol, rtol=0)
    np.testing.assert_array_equal(ta.spike, nu.spike)
    np.testing.assert_array_equal(ta.diagnostics["count"], nu.diagnostics["count"])


@pytest.mark.parametrize("stim", BASIC_STIMULI)
def test_taichi_matches_numpy_reference_on_basic_stimulus(stim):
    s = small_stimulus(stim, 96)
    ta, nu = both("lgmd2", list(s.frames()))
    assert_traces_agree(ta, nu)
    np.testing.assert_allclose(ta.diagnostics["sum_G"], nu.diagnostics["sum_G"], rtol=1e-4, atol=1e-2)


def test_taichi_matches_numpy_reference_on_noisy_video_like_stream():
    frames = noisy_stream("dark_looming", seed=3)
    m_ta, m_nu = LGMD2(backend="taichi"), LGMD2(backend="numpy")
    ta, nu = m_ta.run(frames), m_nu.run(frames)
    assert_traces_agree(ta, nu)
    assert nu.diagnostics["PM"].max() > 1.0  # the noise drives the PM pathway
    f_ta, f_nu = m_ta.fields(), m_nu.fields()
    assert set(f_ta) == set(f_nu) >= {"P", "ON", "OFF", "I_on", "I_off", "S", "G"}
    for k in f_nu:
        np.testing.assert_allclose(f_ta[k], f_nu[k], rtol=1e-4, atol=1e-2, err_msg=k)


def test_frame_interval_is_integer_ms():
    assert frame_interval_ms(30) == 33
    assert frame_interval_ms(29.97) == 33
    assert frame_interval_ms(25) == 40
    assert LGMD2(fps=30).dt == 33


def test_pm_low_pass_uses_integer_dt_of_33_ms():
    frames = [np.zeros((6, 8), np.uint8), np.full((6, 8), 90, np.uint8)]
    tr = LGMD2(backend="numpy", fps=30).run(frames)
    a = 33 / (33 + 90)  # not 33.33 / (33.33 + 90)
    assert tr.diagnostics["PM"][1] == pytest.approx(a * 90.0, rel=1e-12)
    assert tr.diagnostics["w_on"][1] == pytest.approx(max(a * 90.0 / 8.0, 1.0), rel=1e-12)


def _single_pixel_frames(value_pattern, base=0):
    """7x7 frames: centre pixel set to each value in turn, the rest at ``base``."""
    out = []
    for v in value_pattern:
        f = np.full((7, 7), base, np.uint8)
        f[3, 3] = v
        out.append(f)
    return out


@pytest.mark.parametrize("backend", ["numpy", "taichi"])
def test_delayed_inhibition_mixes_current_and_previous_input_not_recursive(backend):
    # ON at the centre: 100 on frame 1, then 10 and 1 (residue 0.1) while the frame stays.
    frames = _single_pixel_frames([0, 100, 100, 100])
    m = LGMD2(backend=backend, fps=30)
    dt = 33
    a = [dt / (dt + t) for t in (15.0, 30.0, 45.0)]
    expect = {}
    m.step(frames[0])
    for t, (on_now, on_prev) in zip((1, 2, 3), ((100.0, 0.0), (10.0, 100.0), (1.0, 10.0))):
        m.step(frames[t])
        f = m.fields()
        assert f["ON"][3, 3] == pytest.approx(on_now, rel=1e-6)
        # centre weight 2, edge 0.5, diagonal 0.25; only the centre pixel is non-zero
        expect["centre"] = 2.0 * (a[0] * on_now + (1 - a[0]) * on_prev)
        expect["edge"] = 0.5 * (a[1] * on_now + (1 - a[1]) * on_prev)
        expect["diag"] = 0.25 * (a[2] * on_now + (1 - a[2]) * on_prev)
        assert f["I_on"][3, 3] == pytest.approx(expect["centre"], rel=1e-5)
        assert f["I_on"][2, 3] == pytest.approx(expect["edge"], rel=1e-5)
        assert f["I_on"][4, 4] == pytest.approx(expect["diag"], rel=1e-5)
        assert f["I_on"][0, 0] == 0.0
    # frame 3 only sees ON(2) = 10 and ON(3) = 1: a recursive filter would still remember 100
    assert expect["centre"] == pytest.approx(2.0 * (a[0] * 1.0 + (1 - a[0]) * 10.0))


@pytest.mark.parametrize("backend", ["numpy", "taichi"])
def test_inhibition_kernels_include_the_centre(backend):
    # A darkening centre pixel: OFF = 100 there and 0 elsewhere on frame 1.
    frames = _single_pixel_frames([200, 100], base=200)
    m = LGMD2(backend=backend)
    m.run(frames)
    f = m.fields()
    a0 = 33 / (33 + 60.0)
    assert f["OFF"][3, 3] == pytest.approx(100.0)
    assert f["I_off"][3, 3] == pytest.approx(1.0 * a0 * 100.0, rel=1e-5)  # OFF centre weight 1
    # S_off = [OFF - w_off I_off]+ with w_off = 0.5 (PM below T_pm): the centre inhibits itself
    assert f["S"][3, 3] == pytest.approx(100.0 - 0.5 * a0 * 100.0, rel=1e-5)


def test_sfa_floor_is_one_half():
    assert sfa_step(0.5, 0.9, 0.6, 0.003, 800 / 833) == 0.5  # falling K adapts below 0.5 -> floored
    assert sfa_step(0.0, 0.0, 0.3, 0.003, 800 / 833) == 0.5  # rising but small K -> floored
    assert sfa_step(0.0, 0.0, 0.9, 0.003, 800 / 833) == pytest.approx(0.9 * 800 / 833)
    assert sfa_step(0.8, 0.9, 0.902, 0.003, 800 / 833) == pytest.approx((0.8 + 0.002) * 800 / 833)


def test_sfa_output_never_falls_below_one_half_on_a_stimulus():
    s = small_stimulus("dark_receding", 96)
    tr = LGMD2(backend="numpy").run(s.frames())
    assert tr.diagnostics["Kh"].min() == 0.5


def test_spike_count_adds_spikes_and_resets_on_a_frame_without_spikes():
    assert spike_count(0.5, 0.78, 4) == 0
    assert spike_count(0.9, 0.78, 4) == 1
    assert spike_count(1.0, 0.78, 4) == 2
    m = LGMD2(backend="numpy")
    seq = [1.0, 1.0, 1.0, 0.5, 1.0, 1.0, 1.0, 1.0, 0.9]
    counts, alerts = [], []
    for kh in seq:
        _, alert = LGMDFamily._spikes(m, kh)
        counts.append(m.count)
        alerts.append(alert)
    assert counts == [2, 4, 6, 0, 2, 4, 6, 8, 9]
    assert alerts == [False] * 7 + [True, True]


def test_first_frame_gives_resting_output_and_no_spike():
    r = LGMD2(backend="numpy").step(np.full((8, 8), 255, np.uint8))
    assert r.output == 0.5 and not r.spike and r.t == 0


def test_float_frames_are_scaled_to_grey_levels():
    s = small_stimulus("dark_looming", 64)
    floats = list(s.frames())
    ints = [np.rint(f * 255).astype(np.uint8) for f in floats]
    a = LGMD2(backend="numpy").run(floats)
    b = LGMD2(backend="numpy").run(ints)
    np.testing.assert_allclose(a.output, b.output, atol=1e-12)


def test_frame_size_change_is_refused():
    m = LGMD2(backend="numpy")
    m.step(np.zeros((8, 8), np.uint8))
    with pytest.raises(ValueError, match="runs at 8x8"):
        m.step(np.zeros((8, 9), np.uint8))


def test_reset_forgets_state():
    s = small_stimulus("dark_looming", 64)
    m = LGMD2()
    a = m.run(s.frames())
    b = m.run(s.frames())  # run() resets first
    np.testing.assert_array_equal(a.output, b.output)


@pytest.mark.parametrize("bad, msg", [
    (dict(t_pm=0), "t_pm"), (dict(tau_sfa=-1), "tau_sfa"), (dict(n_ts=0), "n_ts"),
    (dict(k_on=(1.0, 2.0)), "k_on"), (dict(dc=1.5), "dc"),
])
def test_invalid_params_raise_clear_value_error(bad, msg):
    with pytest.raises(ValueError, match=msg):
        LGMD2Params(**bad)


def test_cli_runs_several_models_on_an_npy_video(tmp_path, capsys):
    from cdnf_ti.run import main

    s = small_stimulus("dark_looming", 64)
    arr = np.stack(list(s.frames()))
    path = tmp_path / "clip.npy"
    np.save(path, arr)
    out = tmp_path / "out"
    rc = main([str(path), "--model", "lgmd2,lgmd1,sdnf,flgmd-onn", "--out", str(out), "--no-progress"])
    assert rc == 0
    text = capsys.readouterr().out
    for m in ("lgmd2", "lgmd1", "sdnf", "flgmd_onn"):
        assert f"[{m}]" in text
        assert (out / f"clip.{m}.csv").exists()
    header = (out / "clip.lgmd2.csv").read_text().splitlines()[0].split(",")
    assert header[:4] == ["frame", "K", "spike", "converged"] and "Kh" in header
    assert len(set(header)) == len(header)


def test_sweep_alerts_at_default_count_reproduces_the_run_alerts():
    from conftest import small_stimulus

    from cdnf_ti import LGMD2

    tr = LGMD2().run(small_stimulus("dark_looming", size=96).frames())
    (alerts,) = LGMD2.sweep_alerts(tr, [LGMD2.sweep_default()])
    assert np.array_equal(alerts, tr.spike)
    loose = LGMD2.sweep_alerts(tr, [1.0])[0]
    assert loose.sum() >= tr.spike.sum()


@pytest.mark.parametrize("backend", ["taichi", "numpy"])
def test_float_frames_are_rounded_to_8_bit_grey_as_the_authors_code(backend):
    """Float grey in [0, 1] runs as rint(255 x) uint8 (the authors' code takes byte frames)."""
    from cdnf_ti.models import create_model
    from cdnf_ti.stimuli.basic import basic_stimulus

    s = basic_stimulus("dark_looming", height=48, width=48, object_grey=0.25, background_grey=0.75)
    frames = [f.copy() for f in s.frames()]
    a = create_model("lgmd2", backend=backend).run(iter(frames), progress=False)
    b = create_model("lgmd2", backend=backend).run(
        iter([np.rint(f * 255.0).astype(np.uint8) for f in frames]), progress=False)
    assert np.array_equal(a.output, b.output)
    assert np.array_equal(a.diagnostics["PM"], b.diagnostics["PM"])
