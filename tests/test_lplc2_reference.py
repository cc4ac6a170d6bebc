"""The float64 EMD-LPLC2-GF reference (cdnf_ti.lplc2_reference): behaviour, geometry, streaming, causality, input.

The authors' MATLAB itself is compared in docs/figures/compare_lplc2_octave.py (it needs GNU Octave).
"""
from __future__ import annotations

import functools

import numpy as np
import pytest

from cdnf_ti.errors import InputError, UserError
from cdnf_ti.lplc2_reference import LPLC2Params, LPLC2Reference
from cdnf_ti.stimuli.basic import basic_stimulus

H, W, FPS = 96, 128, 100.0  # the authors' stimuli run at 100 frames/s


@functools.cache
def stimulus_frames(name: str) -> tuple:
    return tuple(basic_stimulus(name, height=H, width=W, fps=FPS, duration=1.0).frames())


@functools.cache
def response(name: str) -> dict:
    return LPLC2Reference(H, W, fps=FPS).run(stimulus_frames(name))


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_looming_fires_the_giant_fibre(polarity):
    r = response(f"{polarity}_looming")
    assert r["alert"].any()
    assert r["active"].max() > 0


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_looming_fires_only_near_the_end_of_the_approach(polarity):
    r = response(f"{polarity}_looming")
    assert np.flatnonzero(r["alert"])[0] >= 3 * len(r["alert"]) // 4


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_receding_activates_no_lplc2_unit(polarity):
    r = response(f"{polarity}_receding")
    assert not r["active"].any() and not r["alert"].any()


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_translating_activates_no_lplc2_unit(polarity):
    r = response(f"{polarity}_translating")
    assert not r["active"].any() and not r["alert"].any()


def test_expansion_drives_all_four_arms_of_the_centre_unit_translation_at_most_one():
    assert (response("dark_looming")["arms"] > 0).all(axis=1).any()
    assert (response("dark_translating")["arms"] > 0).sum(axis=1).max() <= 1


def test_membrane_rests_at_minus_60_mv_without_input():
    r = response("dark_receding")
    np.testing.assert_allclose(r["v"], LPLC2Params().v_rest)


def brute_force_arms(motion: np.ndarray, p: LPLC2Params) -> np.ndarray:
    """The half-plane sums of every unit by explicit loops over the receptive field."""
    _, h, w = motion.shape
    horizontal, vertical = motion[0] - motion[1], motion[2] - motion[3]
    out = np.zeros((4, h, w))
    for y in range(h):
        for x in range(w):
            rows = range(y - p.band_before, y + p.band_after + 1)
            cols = range(x - p.band_before, x + p.band_after + 1)
            for yy in rows:
                for xx in range(x - p.half_side + 1, x + p.half_side + 1):
                    if 0 <= yy < h and 0 <= xx < w:
                        out[0 if xx <= x else 1, y, x] += horizontal[yy, xx] * (1 if xx <= x else -1)
            for xx in cols:
                for yy in range(y - p.half_side + 1, y + p.half_side + 1):
                    if 0 <= yy < h and 0 <= xx < w:
                        out[2 if yy <= y else 3, y, x] += vertical[yy, xx] * (1 if yy <= y else -1)
    return out


def test_arms_pool_outward_motion_over_the_four_half_planes():
    p = LPLC2Params(half_side=5, band_before=2, band_after=3, arm_threshold=-np.inf)
    ref = LPLC2Reference(15, 19, params=p)
    motion = np.random.default_rng(3).random((4, 14, 18))
    np.testing.assert_allclose(ref.arms(motion), brute_force_arms(motion, p), rtol=1e-12, atol=1e-12)


def test_arms_below_threshold_are_zero():
    p = LPLC2Params(half_side=5, band_before=2, band_after=3)
    ref = LPLC2Reference(15, 19, params=p)
    motion = np.random.default_rng(4).random((4, 14, 18)) * 0.2
    raw = brute_force_arms(motion, p)
    np.testing.assert_allclose(ref.arms(motion), np.where(raw > p.arm_threshold, raw, 0.0), atol=1e-12)


def test_streaming_in_chunks_equals_one_run():
    frames = stimulus_frames("dark_looming")
    whole = response("dark_looming")
    ref = LPLC2Reference(H, W, fps=FPS)
    parts = [ref.run(frames[:40]), ref.run(frames[40:77]), ref.run(frames[77:])]
    for key, value in whole.items():
        np.testing.assert_array_equal(np.concatenate([p[key] for p in parts]), value, err_msg=key)


def test_a_frame_output_does_not_depend_on_later_frames():
    frames = stimulus_frames("dark_looming")
    cut = 93
    rng = np.random.default_rng(11)
    other = list(frames[:cut]) + [rng.random((H, W)) for _ in frames[cut:]]
    a = response("dark_looming")
    b = LPLC2Reference(H, W, fps=FPS).run(other)
    assert not np.array_equal(a["active"][cut:], b["active"][cut:])
    for key in a:
        np.testing.assert_array_equal(a[key][:cut], b[key][:cut], err_msg=key)


def test_uint8_frames_are_luminance_over_255():
    frames = stimulus_frames("dark_looming")[85:95]
    as_float = LPLC2Reference(H, W, fps=FPS).run(frames)
    as_bytes = LPLC2Reference(H, W, fps=FPS).run([np.round(f * 255).astype(np.uint8) for f in frames])
    np.testing.assert_allclose(as_bytes["current"], as_float["current"], atol=1e-9)


@pytest.mark.parametrize("frame, problem", [
    (np.zeros((8, 8)), "expected 9x8 px"),
    (np.zeros((8, 9, 3)), "(H, W) grey"),
    (np.full((8, 9), -0.1), "[0, 1]"),
    (np.full((8, 9), np.inf), "[0, 1]"),
    (np.zeros((8, 9), np.int16), "uint8 or float"),
])
def test_bad_frames_are_one_line_input_errors_naming_the_frame(frame, problem):
    ref = LPLC2Reference(8, 9)
    with pytest.raises(InputError) as e:
        ref.step(frame)
    assert str(e.value).startswith("frame 0: ") and problem in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("kw", [{"fps": -1.0}, {"fps": float("inf")}, {"height": 1}])
def test_bad_arguments_are_user_errors(kw):
    with pytest.raises(UserError):
        LPLC2Reference(**{"height": 8, "width": 8, **kw})
