"""The six basic stimuli (paper Table I): geometry, contrast, timing."""
import numpy as np
import pytest

from cdnf_ti.stimuli.basic import BASIC_STIMULI, BasicStimulus, basic_stimulus


def test_defaults_are_the_papers_600x600_at_30fps():
    s = BasicStimulus()
    assert (s.height, s.width, s.fps) == (600, 600, 30.0)
    f = s.frame(0)
    assert f.shape == (600, 600) and f.dtype == np.float32


@pytest.mark.parametrize("name", BASIC_STIMULI)
def test_frames_are_binary_object_on_background(name):
    s = basic_stimulus(name, height=60, width=80)
    for k in (0, s.n_frames // 2, s.n_frames - 1):
        f = s.frame(k)
        assert set(np.unique(f)) <= {0.0, 1.0}
        assert np.all(f[s.object_mask(k)] == s.object_value)
        assert np.all(f[~s.object_mask(k)] == s.background_value)
    assert s.object_value == (0.0 if name.startswith("dark") else 1.0)


def test_looming_half_size_grows_as_inverse_time_to_contact():
    s = basic_stimulus("dark_looming", start_half_size=5, end_half_size=100, duration=1.0, fps=30)
    t = np.arange(s.n_frames) / s.fps
    r = np.array([s.half_size(k) for k in range(s.n_frames)])
    assert r[0] == pytest.approx(5) and r[-1] == pytest.approx(100)
    assert np.allclose(r * (s.tau0 - t), 5 * s.tau0)  # r * time-to-contact is constant


def test_looming_square_area_matches_half_size():
    s = basic_stimulus("light_looming", height=200, width=200, start_half_size=4, end_half_size=80)
    k = s.n_frames - 1
    side = np.sqrt(s.object_mask(k).sum())
    assert abs(side - 2 * s.half_size(k)) <= 2


def test_receding_is_the_time_reverse_of_looming():
    a = basic_stimulus("dark_looming", height=64, width=64)
    b = basic_stimulus("dark_receding", height=64, width=64)
    assert a.n_frames == b.n_frames
    for k in range(a.n_frames):
        assert np.array_equal(a.frame(k), b.frame(a.n_frames - 1 - k))


def test_translating_bar_is_a_tenth_wide_full_height_and_moves_at_constant_speed():
    s = basic_stimulus("light_translating", height=50, width=200)
    assert s.bar_width == 20
    lefts = []
    for k in range(s.n_frames):
        m = s.object_mask(k)
        assert m.all(axis=0).sum() == 20 and m.any(axis=1).all()
        lefts.append(np.flatnonzero(m[0])[0])
    steps = np.diff(lefts)
    assert lefts[0] == 0 and lefts[-1] == 180
    assert steps.max() - steps.min() <= 1  # constant speed up to pixel rounding


@pytest.mark.parametrize("kw", [{"name": "dark_spinning"}, {"height": 4}, {"start_half_size": 0},
                                {"start_half_size": 400}, {"fps": 0}, {"bar_width": 0}])
def test_invalid_stimulus_parameters_raise(kw):
    with pytest.raises(ValueError):
        BasicStimulus(**kw)


@pytest.mark.parametrize("kw", [{"fps": float("inf")}, {"duration": float("nan")}, {"start_half_size": float("inf")}])
def test_non_finite_stimulus_parameters_raise(kw):
    with pytest.raises(ValueError, match="finite|> 0"):
        BasicStimulus(**kw)


@pytest.mark.parametrize("seed", [-1, 1.5, "x"])
def test_seeds_must_be_non_negative_integers(seed):
    from cdnf_ti.stimuli.basic import check_seed
    from cdnf_ti.stimuli.incoherent import incoherent_stimulus
    from cdnf_ti.stimuli.rain import RainyFrames

    with pytest.raises(ValueError, match="seed"):
        check_seed(seed)
    with pytest.raises(ValueError, match="seed"):
        incoherent_stimulus("dark_looming", 0.5, seed=seed, height=32, width=32, start_half_size=1)
    with pytest.raises(ValueError, match="seed"):
        RainyFrames([np.zeros((8, 8), np.float32)], seed=seed)
