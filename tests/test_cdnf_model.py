"""C-DNF model behaviour: resting state, convergence, Taichi vs NumPy float64 reference."""

import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti import CDNF, CDNFParams
from cdnf_ti.models.base import NotConvergedWarning
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus


def _run(name, backend, params=None, size=96, **kw):
    return CDNF(params, backend=backend).run(small_stimulus(name, size=size, **kw).frames())


@pytest.mark.parametrize("backend", ["taichi", "numpy"])
@pytest.mark.parametrize("border", ["replicate", "reflect", "zero"])
def test_resting_state_gives_exactly_half_and_no_spike(backend, border):
    model = CDNF(CDNFParams(border=border), backend=backend)
    frames = [np.full((40, 56), 0.3, np.float32)] * 5
    tr = model.run(frames)
    assert np.all(tr.output == 0.5)
    assert not tr.spike.any()


def test_first_frame_has_no_luminance_change_and_outputs_half():
    model = CDNF()
    r = model.step(np.random.default_rng(0).random((32, 48)).astype(np.float32))
    assert r.t == 0 and r.output == 0.5 and not r.spike


@pytest.mark.parametrize("name", BASIC_STIMULI)
def test_every_field_converges_below_tolerance_on_basic_stimuli(name):
    p = CDNFParams()
    tr = _run(name, "taichi", p)
    assert tr.converged.all()
    for key in ("residual_on", "residual_off", "residual_sum"):
        assert np.all(tr.diagnostics[key] < p.tol), key
    assert tr.diagnostics["iterations_sum"].max() < p.max_iter


@pytest.mark.parametrize("name", BASIC_STIMULI)
def test_taichi_agrees_with_numpy_reference_over_whole_small_stimuli(name):
    ti_trace = _run(name, "taichi")
    np_trace = _run(name, "numpy")
    assert np.max(np.abs(ti_trace.output - np_trace.output)) < 1e-4
    assert np.array_equal(ti_trace.spike, np_trace.spike)


def test_taichi_agrees_with_numpy_reference_at_paper_size_600():
    stim = basic_stimulus("light_looming", height=600, width=600, start_half_size=10, duration=0.4)
    a = CDNF(backend="taichi").run(stim.frames())
    b = CDNF(backend="numpy").run(stim.frames())
    assert a.n_frames == stim.n_frames
    assert np.max(np.abs(a.output - b.output)) < 1e-4
    assert a.output.max() > 0.5  # the stimulus does excite the model


@pytest.mark.parametrize("border", ["reflect", "zero"])
def test_border_modes_agree_with_reference(border):
    p = CDNFParams(border=border)
    a = _run("dark_translating", "taichi", p, size=64)
    b = _run("dark_translating", "numpy", p, size=64)
    assert np.max(np.abs(a.output - b.output)) < 1e-4


def test_zero_border_differs_from_replicate():
    a = _run("light_looming", "numpy", CDNFParams(border="zero"), size=64)
    b = _run("light_looming", "numpy", CDNFParams(border="replicate"), size=64)
    assert np.max(np.abs(a.output - b.output)) > 1e-6


@pytest.mark.parametrize("backend", ["taichi", "numpy"])
@pytest.mark.parametrize("start", ["local", "previous"])
def test_every_start_agrees_with_the_cold_start(backend, start):
    warm = _run("dark_receding", backend, CDNFParams(start=start))
    cold = _run("dark_receding", backend, CDNFParams(start="rest"))
    assert np.max(np.abs(warm.output - cold.output)) < 1e-5


def test_taichi_agrees_with_reference_on_noisy_video_like_input():
    rng = np.random.default_rng(7)
    stim = small_stimulus("dark_looming", size=80)
    frames = [np.clip(f + rng.normal(0, 0.05, f.shape), 0, 1).astype(np.float32) for f in stim.frames()]
    a = CDNF(backend="taichi").run(frames)
    b = CDNF(backend="numpy").run(frames)
    assert np.max(np.abs(a.output - b.output)) < 1e-4


def test_unconverged_frames_are_flagged_and_warned():
    model = CDNF(CDNFParams(max_iter=2))
    with pytest.warns(NotConvergedWarning):
        tr = model.run(small_stimulus("light_looming", size=48).frames())
    assert not tr.converged.all()
    assert np.any(tr.diagnostics["residual_sum"] >= 1e-5)


def test_uint8_float_and_bgr_frames_give_the_same_output():
    stim = small_stimulus("dark_translating", size=48)
    grey_u8 = [np.round(f * 255).astype(np.uint8) for f in stim.frames()]
    bgr = [np.repeat(g[:, :, None], 3, axis=2) for g in grey_u8]
    a = CDNF().run([g.astype(np.float32) / 255 for g in grey_u8])
    b = CDNF().run(grey_u8)
    c = CDNF().run(bgr)
    assert np.max(np.abs(a.output - b.output)) < 1e-6
    assert np.max(np.abs(b.output - c.output)) < 1e-6


def test_frame_size_change_mid_run_raises_value_error():
    model = CDNF()
    model.step(np.zeros((20, 30), np.float32))
    with pytest.raises(ValueError, match="30x20"):
        model.step(np.zeros((21, 30), np.float32))


def test_float_frames_outside_unit_range_are_rejected():
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        CDNF().step(np.full((8, 8), 2.0, np.float32))


def test_reset_restarts_the_stream_identically():
    model = CDNF()
    frames = list(small_stimulus("light_receding", size=48).frames())
    a = model.run(frames)
    b = model.run(frames)
    assert np.array_equal(a.output, b.output)


def test_fields_exposes_on_off_and_summation_fields():
    model = CDNF()
    stim = small_stimulus("dark_looming", size=48)
    for f in list(stim.frames())[:40]:
        model.step(f)
    fields = model.fields()
    assert set(fields) >= {"u_on", "u_off", "v"}
    for v in fields.values():
        assert v.shape == (48, 48)
    assert fields["u_off"].max() > 0 > fields["u_on"].max()  # a dark square darkens: OFF contrast only


def test_trace_csv_round_trip(tmp_path):
    tr = _run("dark_looming", "taichi", size=48)
    tr.to_csv(tmp_path / "t.csv")
    back = type(tr).from_csv(tmp_path / "t.csv")
    assert np.allclose(back.output, tr.output, atol=1e-9)
    assert np.array_equal(back.spike, tr.spike)
    assert np.array_equal(back.diagnostics["iterations_sum"], tr.diagnostics["iterations_sum"])


@pytest.mark.parametrize("arch", ["metal-ish", "tpu"])
def test_unknown_arch_is_a_clear_error(arch):
    with pytest.raises(ValueError, match="arch"):
        CDNF(arch=arch)


def test_real_clip_taichi_agrees_with_reference(shared_real):
    if shared_real is None:
        pytest.skip("the development dashcam clips are not present (covered by the generated-video tests)")
    from itertools import islice

    from cdnf_ti.frames import iter_grey, open_source

    frames = list(islice(iter_grey(open_source(shared_real / "c21.mp4")), 196, 216))
    a = CDNF(backend="taichi").run(frames)
    b = CDNF(backend="numpy").run(frames)
    assert a.converged.all()
    assert np.max(np.abs(a.output - b.output)) < 1e-4


@pytest.mark.parametrize("backend", ["taichi", "numpy"])
def test_contrast_over_relaxation_reaches_the_same_answer_in_fewer_iterations(backend):
    # over-relaxation is a parameter of the paper's plain scheme (Chebyshev chooses its own steps), which
    # starts from the previous frame's solution (the local start leaves edges, where it gains nothing)
    plain = _run("light_looming", backend, CDNFParams(scheme="plain", start="previous"))
    sor = _run("light_looming", backend, CDNFParams(scheme="plain", start="previous", contrast_relaxation=4 / 3))
    assert sor.converged.all()
    assert np.max(np.abs(sor.output - plain.output)) < 1e-5
    busy = plain.diagnostics["iterations_on"] > 5  # frames with ON input (others converge at once)
    assert busy.sum() > 5
    assert sor.diagnostics["iterations_on"][busy].sum() < 0.85 * plain.diagnostics["iterations_on"][busy].sum()


@pytest.mark.parametrize("bad", [0.0, 2.0, -1.0])
def test_contrast_relaxation_outside_0_2_is_rejected(bad):
    with pytest.raises(ValueError, match="contrast_relaxation"):
        CDNFParams(contrast_relaxation=bad)
