"""The real-environment variant of the EMD-LPLC2-GF reference (LPLC2Reference(variant="real")):
the 3-of-4 unit rule of the authors' folders 5-7, folder 7's green channel and quarter-size frames.

The authors' folder-7 MATLAB runs only when ``CDNF_TI_LPLC2_REPO`` names a checkout of
zhaojunyu01/EMD-LPLC2-GF-model and ``octave`` (with its image package) is on the path
(docs/figures/compare_lplc2_real_octave.py prints the full table).
"""
from __future__ import annotations

import functools
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from cdnf_ti.errors import InputError, UserError
from cdnf_ti.lplc2_reference import LPLC2Reference, matlab_imresize
from cdnf_ti.stimuli.basic import basic_stimulus

SIZE = 320  #: before the shrink: an 80x80 array
REPO_ENV = "CDNF_TI_LPLC2_REPO"


@functools.cache
def response(name: str) -> dict:
    st = basic_stimulus(name, height=SIZE, width=SIZE)
    return LPLC2Reference(SIZE, SIZE, fps=st.fps, variant="real").run(st.frames())


def units_of(arms: tuple, variant: str) -> float:
    """The response of one unit whose four raw arms are ``arms`` (left, right, up, down)."""
    ref = LPLC2Reference(8, 8, variant=variant)
    floor = -2.0 if variant == "real" else ref.params.arm_threshold
    a = np.array(arms, dtype=np.float64).reshape(4, 1, 1)
    return float(ref.units(np.where(a > floor, a, 0.0))[0, 0])


@pytest.mark.parametrize("arms", [(2.0, 2.0, 2.0, -1.0), (1.6, 1.6, 1.6, 0.5), (3.0, 3.0, 3.0, 3.0)])
def test_three_strong_arms_and_a_fourth_above_minus_two_make_a_unit(arms):
    assert units_of(arms, "real") == pytest.approx(abs(np.prod(arms)))


@pytest.mark.parametrize("arms", [(2.0, 2.0, 2.0, -2.0), (2.0, 2.0, 2.0, -2.5), (2.0, 2.0, 1.5, 1.0),
                                  (2.0, 2.0, 2.0, 0.0)])
def test_a_weak_fourth_arm_at_or_below_minus_two_or_a_third_weak_arm_makes_no_unit(arms):
    assert units_of(arms, "real") == 0.0


def test_arena_rule_needs_all_four_arms_above_two():
    assert units_of((2.0, 2.0, 2.0, -1.0), "arena") == 0.0
    assert units_of((2.5, 2.5, 2.5, 2.5), "arena") == pytest.approx(2.5**4)


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_looming_fires_the_giant_fibre(polarity):
    r = response(f"{polarity}_looming")
    assert r["alert"].any() and r["active"].max() > 0


@pytest.mark.parametrize("name", ["dark_receding", "light_receding", "dark_translating", "light_translating"])
def test_receding_and_translating_activate_no_unit(name):
    assert response(name)["active"].max() == 0


def test_the_array_is_a_quarter_of_the_frame_rounded_up():
    ref = LPLC2Reference(241, 426, variant="real")
    assert (ref.height, ref.width) == (61, 107)
    assert ref.lplc2.shape == (60, 106)


def test_only_the_green_channel_is_seen():
    frames = [np.full((64, 64, 3), 128, np.uint8) for _ in range(3)]
    frames[1][20:40, 20:40, 0] = 255  # blue square
    frames[2][20:40, 20:40, 2] = 0  # red square
    ref = LPLC2Reference(64, 64, variant="real")
    for f in frames:
        ref.step(f)
        assert not ref.f_h.any()


def test_a_grey_frame_is_its_own_green_channel():
    st = basic_stimulus("dark_looming", height=64, width=64)
    grey = list(st.frames())[-1]
    bgr = np.repeat(np.floor(grey[:, :, None] * 255.0 + 0.5).astype(np.uint8), 3, axis=2)
    ref = LPLC2Reference(64, 64, variant="real")
    np.testing.assert_array_equal(ref.luminance(bgr), ref.luminance(bgr[:, :, 1]))


def test_imresize_keeps_a_constant_and_rounds_the_size_up():
    out = matlab_imresize(np.full((41, 50), 0.3), 0.25)
    assert out.shape == (11, 13)
    np.testing.assert_allclose(out, 0.3, rtol=0, atol=1e-15)


def test_imresize_samples_a_ramp_at_the_output_pixel_centres():
    """Away from the border the antialiased bicubic kernel reproduces a linear function exactly:
    output pixel u (1-based) sits at input coordinate u / s + (1 - 1 / s) / 2."""
    ramp = np.tile(np.arange(1.0, 81.0), (8, 1)) / 100.0
    out = matlab_imresize(ramp, 0.25)
    u = np.arange(1, 21)
    np.testing.assert_allclose(out[0, 3:-3], ((u / 0.25 + 0.5 * (1 - 1 / 0.25)) / 100.0)[3:-3], rtol=0, atol=1e-14)


def test_bad_frames_are_one_line_input_errors_naming_the_frame():
    with pytest.raises(InputError, match="frame 0") as e:
        LPLC2Reference(64, 64, variant="real").step(np.zeros((64, 63, 3), np.uint8))
    assert "\n" not in str(e.value)


def test_an_unknown_variant_is_a_user_error():
    with pytest.raises(UserError):
        LPLC2Reference(64, 64, variant="outdoor")


@pytest.mark.skipif(not os.environ.get(REPO_ENV) or not shutil.which("octave"),
                    reason=f"{REPO_ENV} does not name a checkout of the authors' code, or octave is missing")
def test_real_variant_equals_the_authors_folder_7_matlab():
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "docs" / "figures"))
    import compare_lplc2_real_octave as oracle

    r = oracle.compare("octave", Path(os.environ[REPO_ENV]), oracle.basic_frames("dark_looming", 160))
    assert r["lum"] < 1e-12 and r["map_rel"] < 1e-9 and r["v"] < 1e-9 and r["count_diff"] == 0
    assert r["first"][0] == r["first"][1]
