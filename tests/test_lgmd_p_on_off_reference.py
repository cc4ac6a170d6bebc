"""The float64 LGMD_P_ON_OFF reference (cdnf_ti.lgmd_p_on_off_reference): behaviour from the equations.

The authors' Python itself runs only when ``CDNF_TI_LGMD_P_ON_OFF_REPO`` names a checkout of
fuqinbing/harmonizing-motion-and-contrast-vision-for-looming-detection
(docs/figures/compare_lgmd_p_on_off.py prints the full table).
"""
from __future__ import annotations

import dataclasses
import functools
import os
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from cdnf_ti.errors import InputError, UserError
from cdnf_ti.lgmd_p_on_off_reference import (
    LGMDPOnOffParams,
    LGMDPOnOffReference,
    correlate_same,
    gaussian_kernel,
    inhibition_kernel,
)
from cdnf_ti.stimuli.basic import basic_stimulus

SIZE = 96
ONSET = 3  #: frames after motion onset whose response is the onset transient (E(t-1) = 0 at frame 1)
REPO_ENV = "CDNF_TI_LGMD_P_ON_OFF_REPO"


@functools.cache
def stimulus_frames(name: str) -> tuple:
    return tuple(basic_stimulus(name, height=SIZE, width=SIZE).frames())


@functools.cache
def response(name: str, variant: str = "code", **params) -> dict:
    return LGMDPOnOffReference(SIZE, SIZE, variant=variant, params=LGMDPOnOffParams(**params)).run(
        stimulus_frames(name))


def first_alert(r: dict):
    a = np.flatnonzero(r["alert"])
    return int(a[0]) if a.size else None


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_looming_excites_more_than_receding_after_the_onset(polarity):
    looming = response(f"{polarity}_looming")["mp"][ONSET:]
    receding = response(f"{polarity}_receding")["mp"][ONSET:]
    assert looming.max() > receding.max() + 0.2


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_looming_alerts_in_the_last_quarter_of_the_approach(polarity):
    r = response(f"{polarity}_looming")
    assert first_alert(r) is not None
    assert first_alert(r) >= 3 * len(r["mp"]) // 4


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_receding_alerts_at_most_on_the_motion_onset_frame(polarity):
    """Frame 1 has no delayed inhibition (E(0) = 0), so the large receding square's first edge passes."""
    r = response(f"{polarity}_receding")
    assert not r["alert"][ONSET:].any()


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_translating_bar_never_alerts(polarity):
    assert first_alert(response(f"{polarity}_translating")) is None


def test_contrast_pathway_lowers_the_translating_response():
    with_contrast = response("dark_translating")["sum_g"]
    without = response("dark_translating", alpha_3=0.0, alpha_5=0.0)["sum_g"]
    assert without[ONSET:].sum() > with_contrast[ONSET:].sum()
    assert np.all(without >= with_contrast - 1e-9)


def test_on_and_off_polarities_are_symmetric():
    """Inverting the picture swaps P_on and P_off; with alpha_2..5 and theta_1, theta_2 equal, mp is the same."""
    np.testing.assert_allclose(response("dark_looming")["mp"], response("light_looming")["mp"], rtol=0, atol=1e-12)


def test_a_static_scene_rests_at_one_half():
    frame = np.asarray(stimulus_frames("dark_looming")[0])
    r = LGMDPOnOffReference(SIZE, SIZE, variant="paper").run([frame] * 5)
    np.testing.assert_array_equal(r["mp"], 0.5)
    assert not r["alert"].any()


def test_frame_zero_is_zero_in_code_and_rest_in_paper():
    assert response("dark_looming", "code")["mp"][0] == 0.0
    assert response("dark_looming", "paper")["mp"][0] == 0.5


def test_variants_agree_on_grey_frames_after_frame_zero():
    np.testing.assert_array_equal(response("dark_looming", "code")["mp"][1:],
                                  response("dark_looming", "paper")["mp"][1:])


def test_code_variant_weighs_blue_as_red_on_bgr_frames():
    """Their COLOR_RGB2GRAY on OpenCV's BGR frames: a blue step is weighted 0.299 in code, 0.114 in paper."""
    frames = [np.zeros((SIZE, SIZE, 3), np.uint8) for _ in range(2)]
    frames[1][:, : SIZE // 2, 0] = 255  # blue half
    ref = {v: LGMDPOnOffReference(SIZE, SIZE, variant=v) for v in ("code", "paper")}
    for f in frames:
        for r in ref.values():
            r.step(f)
    p_code, p_paper = ref["code"].layers["P"][0, 0], ref["paper"].layers["P"][0, 0]
    assert (p_code, p_paper) == (cv2.cvtColor(frames[1], cv2.COLOR_RGB2GRAY)[0, 0],
                                 cv2.cvtColor(frames[1], cv2.COLOR_BGR2GRAY)[0, 0])
    assert p_code > p_paper


def test_inhibition_kernel_is_edge_twice_diagonal_centre_zero():
    k = inhibition_kernel(0.125)
    np.testing.assert_array_equal(k, [[0.125, 0.25, 0.125], [0.25, 0.0, 0.25], [0.125, 0.25, 0.125]])


def test_gaussian_kernel_equals_opencv():
    g = cv2.getGaussianKernel(9, 5.0, cv2.CV_64F)
    np.testing.assert_allclose(gaussian_kernel(9, 5.0), g @ g.T, rtol=0, atol=1e-16)


@pytest.mark.parametrize("side", [3, 9])
def test_reflect_correlation_equals_opencv_filter2d(side):
    rng = np.random.default_rng(0)
    x, k = rng.random((20, 17)), rng.random((side, side))
    np.testing.assert_allclose(correlate_same(x, k, "reflect"), cv2.filter2D(x, -1, k), rtol=0, atol=1e-12)


def test_streaming_after_reset_repeats_the_run():
    ref = LGMDPOnOffReference(SIZE, SIZE)
    first = ref.run(stimulus_frames("dark_looming"))
    ref.reset()
    second = ref.run(stimulus_frames("dark_looming"))
    for name in first:
        np.testing.assert_array_equal(first[name], second[name])


def test_a_frame_output_does_not_depend_on_later_frames():
    frames = stimulus_frames("dark_looming")
    prefix = LGMDPOnOffReference(SIZE, SIZE).run(frames[:30])
    np.testing.assert_array_equal(prefix["mp"], response("dark_looming")["mp"][:30])


@pytest.mark.parametrize("frame, problem", [
    (np.zeros((SIZE, SIZE + 1)), "px"),
    (np.full((SIZE, SIZE), 2.0), "[0, 1]"),
    (np.zeros((SIZE, SIZE), np.int32), "uint8/float"),
    (np.zeros((SIZE, SIZE, 3), np.float32), "uint8 BGR"),
])
def test_bad_frames_are_one_line_input_errors_naming_the_frame(frame, problem):
    with pytest.raises(InputError, match="frame 0") as e:
        LGMDPOnOffReference(SIZE, SIZE).step(frame)
    assert problem in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("kw", [dict(variant="nope"), dict(height=8), dict(params=LGMDPOnOffParams(gauss_size=4))])
def test_bad_arguments_are_user_errors(kw):
    args = dict(height=SIZE, width=SIZE) | kw
    with pytest.raises(UserError):
        LGMDPOnOffReference(**args)


@pytest.mark.skipif(not os.environ.get(REPO_ENV), reason=f"{REPO_ENV} does not name a checkout of the authors' code")
@pytest.mark.parametrize("name", ["dark_looming", "light_receding", "dark_translating"])
def test_code_variant_equals_the_authors_python(name):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "docs" / "figures"))
    import compare_lgmd_p_on_off as oracle

    module = oracle.load_authors(Path(os.environ[REPO_ENV]))
    frames, fps = oracle.basic_clip(name, 64)
    r = oracle.compare(module, frames, fps)
    assert r["mp"] < 1e-12 and r["S"] < 1e-12
    assert r["first_theirs"] == r["first_ours"]


def test_params_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        LGMDPOnOffParams().beta = 1.0
