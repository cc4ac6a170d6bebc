"""The video-to-events emulator: threshold crossings, timing, refractory period, noise, mismatch, seeds."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cdnf_ti.events import EmulatorParams, emulate
from cdnf_ti.inputs import resolve_input

FPS = 30.0


def all_events(frames, params=None, seed=0, fps=FPS) -> np.ndarray:
    return np.concatenate(list(emulate(frames, fps, params or EmulatorParams(), seed)))


def flat(value: float, shape=(4, 5)) -> np.ndarray:
    return np.full(shape, value)


def test_a_brightness_step_gives_floor_of_log_change_over_threshold_on_events():
    ev = all_events([flat(0.2), flat(0.8)])
    n = math.floor(math.log(0.81 / 0.21) / 0.15)
    assert ev.size == 20 * n and ev["p"].all()
    assert np.bincount(ev["y"].astype(int) * 5 + ev["x"], minlength=20).tolist() == [n] * 20


def test_a_darkening_gives_off_events_with_their_own_threshold():
    ev = all_events([flat(0.8), flat(0.2)], EmulatorParams(threshold_on=0.1, threshold_off=0.3))
    assert ev.size == 20 * math.floor(math.log(0.81 / 0.21) / 0.3) and not ev["p"].any()


def test_event_times_are_the_interpolated_crossings_in_order():
    ev = all_events([flat(0.2, (1, 1)), flat(0.8, (1, 1))])
    dl = math.log(0.81 / 0.21)
    want = [j * 0.15 / dl * round(1e6 / FPS) for j in range(1, ev.size + 1)]  # frame 1 at round(1e6 / fps) us
    np.testing.assert_array_equal(ev["t"], np.floor(want))  # rounded down to the µs


def test_the_reference_level_carries_the_remainder_to_the_next_frame():
    # 0.5 threshold steps: a change of 0.7 fires once and leaves 0.2; another 0.4 fires again
    l0, l1, l2 = 0.0, 0.7, 1.1
    frames = [flat(math.exp(v) - 0.01, (1, 1)) / math.exp(1.2) for v in (l0, l1, l2)]
    ev = all_events(frames, EmulatorParams(threshold_on=0.5, threshold_off=0.5))
    assert ev.size == 2 and ev["t"][0] < 1e6 / FPS < ev["t"][1]


def test_the_refractory_period_removes_events_too_close_to_the_previous_one():
    frames = [flat(0.02, (1, 1)), flat(1.0, (1, 1))]
    free = all_events(frames)
    ev = all_events(frames, EmulatorParams(refractory_ms=5.0))
    kept, last = [], -1e9
    for t in free["t"].tolist():  # sequential reference
        if t - last >= 5000:
            kept.append(t)
            last = t
    assert ev["t"].tolist() == kept and 0 < len(kept) < free.size


def test_shot_noise_has_the_given_rate_and_depends_only_on_the_seed():
    frames = [flat(0.5, (20, 20))] * 31  # a static scene: 1 s, every event is noise
    params = EmulatorParams(shot_noise_hz=10.0)
    ev = all_events(frames, params, seed=3)
    assert abs(ev.size - 4000) < 5 * math.sqrt(4000)
    assert 0.45 < ev["p"].mean() < 0.55
    np.testing.assert_array_equal(all_events(frames, params, seed=3), ev)
    assert not np.array_equal(all_events(frames, params, seed=4)["t"][:50], ev["t"][:50])


def test_threshold_mismatch_spreads_the_counts_and_depends_on_the_seed():
    frames = [flat(0.2, (10, 10)), flat(0.8, (10, 10))]
    params = EmulatorParams(threshold_sigma=0.2)

    def per_pixel(seed):
        e = all_events(frames, params, seed=seed)
        return np.bincount(e["y"].astype(int) * 10 + e["x"], minlength=100)

    counts = per_pixel(1)
    assert counts.min() < counts.max()  # without mismatch every pixel fires 9 times
    np.testing.assert_array_equal(per_pixel(1), counts)
    assert not np.array_equal(per_pixel(2), counts)


@pytest.mark.parametrize("name, polarity", [("dark_looming", 0), ("light_looming", 1)])
def test_a_looming_square_fires_one_polarity_at_a_growing_rate(name, polarity):
    src = resolve_input(f"stim:{name}?size=64")
    chunks = list(emulate(src, src.fps))
    ev = np.concatenate(chunks)
    assert ev.size > 0 and (ev["p"] == polarity).all()
    sizes = [c.size for c in chunks]
    assert sum(sizes[-5:]) > sum(sizes[-10:-5]) > 0


def test_emulator_params_refuse_bad_values():
    for bad in ({"threshold_on": 0.0}, {"refractory_ms": -1.0}, {"log_eps": float("nan")}):
        with pytest.raises(ValueError):
            EmulatorParams(**bad)


def test_a_crossing_owed_on_a_flat_interval_fires_at_its_start():
    # the level sits exactly one threshold above the reference but did not move in this interval (d = 0):
    # the ON event is owed from before (e.g. a refractory period), and fires at the interval's start
    from cdnf_ti.events.emulator import _crossings

    level, ref = np.full((1, 1), 0.5), np.full((1, 1), 0.0)
    last = np.full((1, 1), -1e9)
    with np.errstate(all="raise"):  # no 0/0 on the way
        ev = _crossings(level.copy(), level.copy(), ref, np.full((1, 1), 0.5), np.full((1, 1), 0.5), 1000.0, 2000.0,
                        last, 0.0)
    assert ev.size == 1 and ev["t"][0] == 1000 and ev["p"][0] == 1
    assert ref[0, 0] == 0.5
