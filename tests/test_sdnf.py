"""SDNF (reconstruction): Taichi vs NumPy, binary input, delayed lateral term, dynamic threshold."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti.models import SDNF, SDNFParams
from cdnf_ti.stimuli.basic import BASIC_STIMULI


def noisy_stream(name: str, seed: int, h: int = 72, w: int = 104, sigma: float = 20.0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    s = small_stimulus(name, size=max(h, w))
    out = []
    for f in s.frames():
        g = f[:h, :w].astype(np.float64) * 200 + 28 + rng.normal(0, sigma, (h, w))
        out.append(np.clip(np.rint(g), 0, 255).astype(np.uint8))
    return out


@pytest.mark.parametrize("stim", BASIC_STIMULI)
def test_taichi_matches_numpy_reference_on_basic_stimulus(stim):
    frames = list(small_stimulus(stim, 96).frames())
    ta, nu = SDNF(backend="taichi").run(frames), SDNF(backend="numpy").run(frames)
    np.testing.assert_allclose(ta.output, nu.output, atol=1e-6, rtol=0)
    np.testing.assert_allclose(ta.diagnostics["rho"], nu.diagnostics["rho"], atol=1e-12)
    np.testing.assert_array_equal(ta.spike, nu.spike)


@pytest.mark.parametrize("radius", [1, 5])
def test_taichi_matches_numpy_reference_at_other_kernel_radii(radius):
    frames = noisy_stream("light_looming", seed=4, h=40, w=56)
    p = SDNFParams(radius=radius)
    a, b = SDNF(p, backend="taichi"), SDNF(p, backend="numpy")
    ta, nu = a.run(frames), b.run(frames)
    np.testing.assert_allclose(ta.output, nu.output, atol=1e-6, rtol=0)
    np.testing.assert_allclose(a.fields()["u"], b.fields()["u"], atol=1e-4)


def test_taichi_matches_numpy_reference_on_noisy_video_like_stream():
    frames = noisy_stream("dark_looming", seed=9)
    a, b = SDNF(backend="taichi"), SDNF(backend="numpy")
    ta, nu = a.run(frames), b.run(frames)
    np.testing.assert_allclose(ta.output, nu.output, atol=1e-6, rtol=0)
    assert nu.diagnostics["rho"][1:].min() > 0.01  # the noise crosses the binarisation threshold
    fa, fb = a.fields(), b.fields()
    assert set(fa) == set(fb) == {"P", "E", "u", "activity"}
    for k in fb:
        np.testing.assert_allclose(fa[k], fb[k], atol=1e-4, err_msg=k)


@pytest.mark.parametrize("backend", ["numpy", "taichi"])
def test_input_is_binary_so_contrast_strength_is_lost(backend):
    def stream(level):
        f0 = np.zeros((24, 24), np.float32)
        f1 = f0.copy()
        f1[8:16, 8:16] = level
        return [f0, f1]

    weak = SDNF(backend=backend).run(stream(0.05))   # below T_b = 0.1
    mid = SDNF(backend=backend)
    t_mid = mid.run(stream(0.3))
    strong = SDNF(backend=backend).run(stream(1.0))
    assert weak.output[1] == 0.5
    assert t_mid.output[1] == pytest.approx(strong.output[1], abs=1e-7)
    assert set(np.unique(mid.fields()["E"])) == {0.0, 1.0}


@pytest.mark.parametrize("backend", ["numpy", "taichi"])
def test_lateral_term_uses_the_previous_frames_field(backend):
    # first moving frame: the previous field is at rest (zero firing), so no lateral input yet
    frames = list(small_stimulus("dark_translating", 48).frames())[:2]
    m = SDNF(backend=backend)
    m.run(frames)
    f = m.fields()
    np.testing.assert_allclose(f["u"], f["E"] - m.params.h, atol=1e-6)


def test_adaptive_inhibition_grows_with_the_input_fraction():
    tr = SDNF(backend="numpy").run(small_stimulus("dark_looming", 64).frames())
    p = SDNFParams()
    np.testing.assert_allclose(tr.diagnostics["B_t"], p.B * (1 + p.kappa * tr.diagnostics["rho"]))


def test_dynamic_threshold_follows_the_previous_output():
    tr = SDNF(backend="numpy").run(small_stimulus("dark_receding", 96).frames())
    dyn = tr.diagnostics["dyn_threshold"]
    np.testing.assert_allclose(dyn[1:], np.maximum(0.506, tr.output[:-1]))
    # the receding response peaks on its first moving frames and falls: never 3 rising frames above 0.506
    assert tr.output.max() > 0.506 and tr.first_alert is None


def test_alert_needs_consecutive_rising_frames():
    tr = SDNF(backend="numpy").run(small_stimulus("dark_looming", 96).frames())
    fa = tr.first_alert
    assert fa is not None
    assert (tr.diagnostics["above"][fa - 2 : fa + 1] == 1).all()
    assert (np.diff(tr.output[fa - 2 : fa + 1]) > 0).all()


@pytest.mark.parametrize("bad, msg", [(dict(t_b=0), "t_b"), (dict(sigma_1=0), "sigma"),
                                      (dict(n_persist=0), "n_persist"), (dict(kappa=-1), "kappa")])
def test_invalid_params_raise_clear_value_error(bad, msg):
    with pytest.raises(ValueError, match=msg):
        SDNFParams(**bad)


def test_model_is_documented_as_a_reconstruction():
    import cdnf_ti.models.sdnf as mod

    assert "RECONSTRUCTION" in SDNF.__doc__ and "own choice" in mod.__doc__


def test_sweep_alerts_at_default_epsilon_reproduces_the_run_alerts():
    from conftest import small_stimulus

    from cdnf_ti import SDNF

    for name in ("dark_looming", "dark_translating"):
        tr = SDNF().run(small_stimulus(name, size=96).frames())
        (alerts,) = SDNF.sweep_alerts(tr, [SDNF.sweep_default()])
        assert np.array_equal(alerts, tr.spike)
