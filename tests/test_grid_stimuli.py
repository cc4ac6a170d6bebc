"""Stimuli of the selectivity grid: drifting grating, bar speeds, size laws, grey levels, kernels vs NumPy."""
import numpy as np
import pytest

from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus, default_start_half_size
from cdnf_ti.stimuli.grating import GratingStimulus, grating_numpy


def test_default_start_half_size_is_a_sixtieth_of_the_smaller_side():
    assert default_start_half_size(600) == pytest.approx(10.0)
    assert default_start_half_size(120, 240) == pytest.approx(2.0)
    assert basic_stimulus("dark_looming", height=240, width=320).start_half_size == pytest.approx(4.0)


@pytest.mark.parametrize("name", BASIC_STIMULI)
@pytest.mark.parametrize("expansion", ["inverse", "linear"])
def test_taichi_render_equals_numpy_reference(name, expansion):
    grey = (0.4, 0.6) if name.startswith("dark") else (0.6, 0.4)
    kw = dict(height=45, width=70, expansion=expansion, object_grey=grey[0], background_grey=grey[1])
    a = basic_stimulus(name, backend="taichi", **kw)
    b = basic_stimulus(name, backend="numpy", **kw)
    for fa, fb in zip(a.frames(), b.frames()):
        assert fa.dtype == np.float32 and fa.shape == (45, 70)
        assert np.array_equal(fa, fb)


def test_linear_expansion_grows_the_half_size_at_constant_speed():
    s = basic_stimulus("dark_looming", start_half_size=3, end_half_size=93, duration=1.0, fps=30,
                       expansion="linear")
    r = np.array([s.half_size(k) for k in range(s.n_frames)])
    assert r[0] == pytest.approx(3) and r[-1] == pytest.approx(93)
    assert np.allclose(np.diff(r), 3.0)


def test_linear_receding_is_the_time_reverse_of_linear_looming():
    a = basic_stimulus("light_looming", height=64, width=64, expansion="linear")
    b = basic_stimulus("light_receding", height=64, width=64, expansion="linear")
    for k in range(a.n_frames):
        assert np.array_equal(a.frame(k), b.frame(a.n_frames - 1 - k))


def test_grey_levels_set_object_and_background():
    s = basic_stimulus("dark_looming", height=40, width=40, object_grey=0.4, background_grey=0.6)
    f = s.frame(s.n_frames - 1)
    assert set(np.unique(f)) == {np.float32(0.4), np.float32(0.6)}
    assert s.contrast == pytest.approx(0.2)


@pytest.mark.parametrize("name,grey", [("dark_looming", (0.7, 0.3)), ("light_receding", (0.2, 0.5))])
def test_grey_levels_must_match_the_polarity(name, grey):
    with pytest.raises(ValueError, match="object"):
        basic_stimulus(name, object_grey=grey[0], background_grey=grey[1])


def test_translating_speed_sets_the_crossing_time_and_bar_steps():
    s = basic_stimulus("dark_translating", height=50, width=200, speed=360.0, fps=30)
    assert s.duration == pytest.approx((200 - 20) / 360.0)
    lefts = [s.bar_left(k) for k in range(s.n_frames)]
    assert lefts[:3] == [0, 12, 24] and lefts[-1] == 180
    assert all(s.object_mask(k).sum() == 50 * 20 for k in range(s.n_frames))


def test_speed_only_for_translating():
    with pytest.raises(ValueError, match="translating"):
        basic_stimulus("dark_looming", speed=100.0)


@pytest.mark.parametrize("orientation", ["vertical", "horizontal"])
def test_grating_taichi_equals_numpy(orientation):
    kw = dict(height=37, width=53, period=10, bar_width=3, speed=-77.0, orientation=orientation, seed=5,
              bar_grey=0.25, background_grey=0.75)
    a, b = GratingStimulus(backend="taichi", **kw), GratingStimulus(backend="numpy", **kw)
    for fa, fb in zip(a.frames(), b.frames()):
        assert fa.dtype == np.float32 and fa.shape == (37, 53)
        assert np.array_equal(fa, fb)


def test_grating_defaults_give_bars_of_a_tenth_of_the_width():
    g = GratingStimulus()
    assert (g.height, g.width, g.period, g.bar_width) == (240, 320, 64, 32)
    f = g.frame(0)
    assert np.array_equal(f[:, :32], np.zeros((240, 32), np.float32))
    assert np.array_equal(f[:, 32:64], np.ones((240, 32), np.float32))


def test_grating_drifts_at_its_speed():
    g = GratingStimulus(height=20, width=60, period=12, speed=60.0, fps=30, backend="numpy")
    f0, f1 = g.frame(0), g.frame(1)
    assert np.array_equal(np.roll(f0, 2, axis=1), f1)  # 60 px/s at 30 fps: 2 px per frame


def test_grating_keeps_the_grey_level_shares_constant():
    g = GratingStimulus(height=30, width=60, period=12, bar_width=4, speed=47.0, seed=1)
    shares = {float((f == g.bar_grey).mean()) for f in g.frames()}
    assert shares == {4 / 12}


def test_grating_is_deterministic_for_a_seed_and_the_seed_moves_the_phase():
    a = [f.copy() for f in GratingStimulus(height=16, width=40, period=10, seed=2).frames()]
    b = [f.copy() for f in GratingStimulus(height=16, width=40, period=10, seed=2).frames()]
    c = GratingStimulus(height=16, width=40, period=10, seed=4).frame(0)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[0], c)


def test_grating_streams_frames():
    g = GratingStimulus(height=16, width=16, duration=100.0, fps=60.0)
    it = g.frames()
    assert next(it).shape == (16, 16) and g.n_frames == 6001


@pytest.mark.parametrize("kw,match", [(dict(period=1), "period"), (dict(period=10, bar_width=10), "bar_width"),
                                      (dict(bar_grey=0.5, background_grey=0.5), "differ"),
                                      (dict(orientation="diagonal"), "orientation"), (dict(seed=-1), "seed"),
                                      (dict(fps=0.0), "fps")])
def test_grating_rejects_bad_parameters(kw, match):
    with pytest.raises(ValueError, match=match):
        GratingStimulus(**kw)


def test_grating_numpy_reference_handles_negative_shifts():
    f = grating_numpy(2, 10, -3, 5, 2, True, 1.0, 0.0)
    assert f[0].tolist() == [0, 0, 1, 1, 0, 0, 0, 1, 1, 0]


def test_stim_spec_builds_a_grating_and_grid_settings():
    from cdnf_ti.inputs import make_stimulus, parse_stim_spec

    name, p = parse_stim_spec("stim:grating?size=64&period=16&speed=32&orientation=horizontal&seed=2")
    g = make_stimulus(name, p)
    assert isinstance(g, GratingStimulus)
    assert (g.height, g.width, g.period, g.speed, g.orientation, g.seed) == (64, 64, 16, 32.0, "horizontal", 2)
    name, p = parse_stim_spec("stim:light_looming?size=60&expansion=linear&object_grey=0.6&background_grey=0.4")
    s = make_stimulus(name, p)
    assert (s.expansion, s.object_value, s.background_value, s.start_half_size) == ("linear", 0.6, 0.4, 1.0)


def test_stim_spec_refuses_an_incoherent_grating():
    from cdnf_ti.inputs import make_stimulus, parse_stim_spec

    with pytest.raises(ValueError, match="grating"):
        make_stimulus(*parse_stim_spec("stim:grating?coherence=0.5"))
