"""The float64 D-LGMD reference (cdnf_ti.dlgmd_reference): behaviour from the equations.

The authors' MATLAB runs only when ``CDNF_TI_DLGMD_REPO`` names a checkout of cquzjn/D-LGMD and
``octave`` (with its image package) is on the path (docs/figures/compare_dlgmd.py prints the full table).
"""
from __future__ import annotations

import functools
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from cdnf_ti.dlgmd_reference import SFA_START, WARMUP, DLGMDParams, DLGMDReference, dlgmd_kernels
from cdnf_ti.errors import InputError, UserError
from cdnf_ti.stimuli.basic import basic_stimulus

SIZE = 96
REPO_ENV = "CDNF_TI_DLGMD_REPO"


@functools.cache
def stimulus_frames(name: str) -> tuple:
    return tuple(basic_stimulus(name, height=SIZE, width=SIZE).frames())


@functools.cache
def response(name: str) -> dict:
    return DLGMDReference(SIZE, SIZE).run(stimulus_frames(name))


def first_alert(r: dict):
    a = np.flatnonzero(r["alert"])
    return int(a[0]) if a.size else None


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_looming_excites_more_than_receding(polarity):
    assert response(f"{polarity}_looming")["g_sum"].max() > 10 * response(f"{polarity}_receding")["g_sum"].max()


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_looming_alerts_in_the_last_quarter_of_the_approach(polarity):
    r = response(f"{polarity}_looming")
    assert first_alert(r) is not None and first_alert(r) >= 3 * len(r["g_sum"]) // 4


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_receding_never_alerts(polarity):
    assert first_alert(response(f"{polarity}_receding")) is None


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_translating_bar_is_cancelled_by_the_delayed_inhibition(polarity):
    r = response(f"{polarity}_translating")
    assert first_alert(r) is None
    assert r["g_sum"].max() < 0.01 * response(f"{polarity}_looming")["g_sum"].max()


def test_nothing_before_three_differences_and_no_membrane_before_frame_five():
    r = response("dark_receding")
    assert not r["s_sum"][:WARMUP].any() and r["s_sum"][WARMUP:].any()
    assert not r["mp"][:SFA_START].any() and r["mp"][SFA_START:].any()


def test_excitation_is_the_centre_and_its_four_neighbours():
    k_e, _, _ = dlgmd_kernels(DLGMDParams())
    r = DLGMDParams().r
    support = np.argwhere(k_e > 0) - r
    assert sorted(map(tuple, support)) == [(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)]


def test_delay_one_ring_lies_inside_the_delay_two_surround():
    k_e, k_1, k_2 = dlgmd_kernels(DLGMDParams())
    r = DLGMDParams().r
    d = np.hypot(*np.mgrid[-r : r + 1, -r : r + 1])
    assert not ((k_e > 0) & (k_1 > 0)).any() and not ((k_1 > 0) & (k_2 > 0)).any()
    assert d[k_1 > 0].max() < d[k_2 > 0].min()
    assert ((k_e > 0) | (k_1 > 0) | (k_2 > 0)).all()


def test_grouping_window_is_matlab_conv2_same_with_a_4x4_kernel():
    from scipy.signal import convolve2d

    ref = DLGMDReference(SIZE, SIZE)
    step = [ref.step(f) for f in stimulus_frames("dark_looming")][-1]
    s = ref.layers["S"]
    full = convolve2d(s, np.ones((4, 4)), mode="full")  # MATLAB 'same' keeps rows/columns ceil((4-1)/2) = 2 ..
    expected = s * full[2 : 2 + SIZE, 2 : 2 + SIZE]
    expected[expected < step.thresh_g] = 0.0
    assert step.g_sum > 0
    np.testing.assert_allclose(ref.layers["G"], np.minimum(expected, 1.0), rtol=0, atol=1e-12)


def test_grouping_threshold_follows_the_oldest_difference():
    """T_G = min(0.3, 0.5 sum(D_3) 0.001 / 200) with D_3 = |L(t-2) - L(t-3)|: a step at frame 1 sets it at frame 3."""
    frames = [np.zeros((SIZE, SIZE), np.uint8)] + [np.full((SIZE, SIZE), 255, np.uint8)] * 4
    r = DLGMDReference(SIZE, SIZE).run(frames)
    assert r["thresh_g"][3] == pytest.approx(min(0.3, 0.5 * SIZE * SIZE * 0.001 / 200))
    assert r["thresh_g"][4] == 0.0


def test_g_is_clipped_at_one_and_zero_below_threshold():
    frames = stimulus_frames("dark_looming")
    ref = DLGMDReference(SIZE, SIZE)
    steps = [ref.step(f) for f in frames]
    g = ref.layers["G"]
    assert g.max() <= 1.0
    assert not ((g > 0) & (g < steps[-1].thresh_g)).any()


def test_streaming_after_reset_repeats_the_run():
    ref = DLGMDReference(SIZE, SIZE)
    first = ref.run(stimulus_frames("dark_looming"))
    ref.reset()
    second = ref.run(stimulus_frames("dark_looming"))
    for name in first:
        np.testing.assert_array_equal(first[name], second[name])


def test_a_frame_output_does_not_depend_on_later_frames():
    prefix = DLGMDReference(SIZE, SIZE).run(stimulus_frames("dark_looming")[:30])
    np.testing.assert_array_equal(prefix["g_sum"], response("dark_looming")["g_sum"][:30])


@pytest.mark.parametrize("frame, problem", [
    (np.zeros((SIZE, SIZE + 1)), "px"),
    (np.full((SIZE, SIZE), -0.5), "[0, 1]"),
])
def test_bad_frames_are_one_line_input_errors_naming_the_frame(frame, problem):
    with pytest.raises(InputError, match="frame 0") as e:
        DLGMDReference(SIZE, SIZE).step(frame)
    assert problem in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("kw", [dict(height=1), dict(params=DLGMDParams(r=0))])
def test_bad_arguments_are_user_errors(kw):
    with pytest.raises(UserError):
        DLGMDReference(**(dict(height=SIZE, width=SIZE) | kw))


@pytest.mark.skipif(not os.environ.get(REPO_ENV) or not shutil.which("octave"),
                    reason=f"{REPO_ENV} does not name a checkout of the authors' code, or octave is missing")
@pytest.mark.parametrize("name", ["dark_looming", "dark_receding"])
def test_reference_equals_the_authors_matlab(name):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "docs" / "figures"))
    import compare_dlgmd as oracle

    frames = [oracle.grey_u8(f) for f in basic_stimulus(name, height=64, width=64).frames()]
    r = oracle.compare(Path(os.environ[REPO_ENV]), frames, "octave")
    assert r["G"] < 1e-5 and r["S"] < 1e-5 and r["FFI"] < 1e-5  # their im2single: float32
    assert r["first_theirs"] == r["first_ours"]
