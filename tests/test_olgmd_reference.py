"""The float64 oLGMD reference (cdnf_ti.olgmd_reference): behaviour on the basic stimuli, streaming, causality, input.

The authors' code itself is compared in docs/figures/compare_olgmd.py (it needs their checkout).
"""
from __future__ import annotations

import functools

import cv2
import numpy as np
import pytest

from cdnf_ti.errors import InputError, UserError
from cdnf_ti.olgmd_reference import N_SP, N_TS, OLGMDReference, their_col_frame
from cdnf_ti.stimuli.basic import basic_stimulus

SIZE = 96
VARIANTS = ("code", "paper")


@functools.cache
def stimulus_frames(name: str) -> tuple:
    st = basic_stimulus(name, height=SIZE, width=SIZE)
    return tuple(st.frames()), st.fps


@functools.cache
def response(name: str, variant: str) -> dict:
    frames, fps = stimulus_frames(name)
    return OLGMDReference(SIZE, SIZE, variant=variant, fps=fps).run(frames)


def first_alert(r: dict):
    a = np.flatnonzero(r["alert"])
    return int(a[0]) if a.size else None


@pytest.mark.parametrize("variant", VARIANTS)
def test_dark_looming_raises_an_alert(variant):
    r = response("dark_looming", variant)
    assert first_alert(r) is not None
    assert r["k"].max() > 0.9


@pytest.mark.parametrize("variant", VARIANTS)
def test_dark_looming_alerts_only_in_the_second_half_of_the_approach(variant):
    r = response("dark_looming", variant)
    assert first_alert(r) >= len(r["k"]) // 2


@pytest.mark.parametrize("variant", VARIANTS)
def test_dark_receding_never_alerts(variant):
    assert first_alert(response("dark_receding", variant)) is None


@pytest.mark.parametrize("variant", [
    "code",
    pytest.param("paper", marks=pytest.mark.xfail(strict=True, reason=(
        "onset transient: dt = 33 ms makes a6 = 0.96, and the SFA passes the jump of k at motion onset "
        "(K = 0.96, S_spike = 2.05), which with three resting frames (0.33 each) reaches n_sp = 3"))),
])
@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_translating_bar_never_alerts(variant, polarity):
    assert first_alert(response(f"{polarity}_translating", variant)) is None


@pytest.mark.parametrize("variant", VARIANTS)
def test_on_channel_is_silent_so_light_looming_never_alerts(variant):
    """S_on = E - w1 (2 a_centre E + ...) < 0 for w1 >= 1, a_centre > 1/2: only luminance decrements count."""
    frames, fps = stimulus_frames("light_looming")
    ref = OLGMDReference(SIZE, SIZE, variant=variant, fps=fps)
    pm_on = []
    for f in frames:
        pm_on.append(ref.step(f).pm_on)
        assert not ref.s_layer.any()
    assert max(pm_on) >= ref.params.th_on  # the ON gate did open
    assert first_alert(response("light_looming", variant)) is None


@pytest.mark.parametrize("variant", VARIANTS)
def test_membrane_potential_stays_in_its_range(variant):
    for name in ("dark_looming", "dark_translating", "light_receding"):
        k = response(name, variant)["k"]
        assert np.all(k >= 0.5) and np.all(k < 1.0)


@pytest.mark.parametrize("variant", VARIANTS)
def test_streaming_in_chunks_equals_one_run(variant):
    frames, fps = stimulus_frames("dark_looming")
    whole = OLGMDReference(SIZE, SIZE, variant=variant, fps=fps).run(frames)
    ref = OLGMDReference(SIZE, SIZE, variant=variant, fps=fps)
    parts = [ref.run(frames[:17]), ref.run(frames[17:30]), ref.run(frames[30:])]
    for key, value in whole.items():
        np.testing.assert_array_equal(np.concatenate([p[key] for p in parts]), value, err_msg=key)


def test_reset_restarts_from_the_first_frame():
    frames, fps = stimulus_frames("dark_looming")
    ref = OLGMDReference(SIZE, SIZE, fps=fps)
    first = ref.run(frames)
    ref.reset()
    again = ref.run(frames)
    for key in first:
        np.testing.assert_array_equal(first[key], again[key], err_msg=key)


@pytest.mark.parametrize("variant", VARIANTS)
def test_a_frame_output_does_not_depend_on_later_frames(variant):
    frames, fps = stimulus_frames("dark_looming")
    cut = 38
    rng = np.random.default_rng(7)
    other = list(frames[:cut]) + [rng.random((SIZE, SIZE)) for _ in frames[cut:]]
    a = OLGMDReference(SIZE, SIZE, variant=variant, fps=fps).run(frames)
    b = OLGMDReference(SIZE, SIZE, variant=variant, fps=fps).run(other)
    assert not np.array_equal(a["k"][cut:], b["k"][cut:])  # the later frames do matter to later outputs
    for key in a:
        np.testing.assert_array_equal(a[key][:cut], b[key][:cut], err_msg=key)


def test_their_alert_indexing_maps_onto_our_causal_alert():
    """Replay their Spike/Col bookkeeping on our S_spike: Col[j] is our alert at their_col_frame(j)."""
    r = response("dark_looming", "code")
    s = r["s_spike"]
    n = len(s)
    spike, col = [0.0] * n, [0] * n
    for t in range(2, n):
        if t < N_TS + 2:
            spike[3] = s[3] + s[2] if t >= 3 else s[2]
            spike[4] = s[4] + s[3] + s[2] if t >= 4 else spike[3]
            spike[5] = s[5] + s[4] + s[3] + s[2] if t >= 5 else spike[4]
        else:
            spike[t] = float(np.sum(s[t - N_TS : t]))
        col[t - 3] = int(spike[t] >= N_SP)
    assert any(col)
    for j in range(n - 3):
        assert bool(col[j]) == bool(r["alert"][their_col_frame(j)]), j


def test_code_variant_ignores_the_frame_rate():
    frames, _ = stimulus_frames("dark_looming")
    slow = OLGMDReference(SIZE, SIZE, variant="code", fps=10.0).run(frames)
    fast = OLGMDReference(SIZE, SIZE, variant="code", fps=60.0).run(frames)
    np.testing.assert_array_equal(slow["k"], fast["k"])
    paper_slow = OLGMDReference(SIZE, SIZE, variant="paper", fps=10.0).run(frames)
    paper_fast = OLGMDReference(SIZE, SIZE, variant="paper", fps=60.0).run(frames)
    assert not np.array_equal(paper_slow["k"], paper_fast["k"])


def test_code_variant_takes_grey_with_red_and_blue_swapped():
    blue = np.zeros((8, 8, 3), np.uint8)
    blue[..., 0] = 200  # OpenCV frames are BGR: channel 0 is blue
    code = OLGMDReference(8, 8, variant="code").grey(blue)
    paper = OLGMDReference(8, 8, variant="paper").grey(blue)
    np.testing.assert_allclose(code, 0.299 * 200, atol=0.5)  # blue weighted as red
    np.testing.assert_allclose(paper, 0.114 * 200, atol=0.5)
    np.testing.assert_array_equal(paper, cv2.cvtColor(blue, cv2.COLOR_BGR2GRAY))


def test_code_variant_drops_the_first_frame_difference():
    step = np.zeros((3, 16, 16))
    step[1:] = 1.0  # the only change is between frames 0 and 1
    frames = list(step) + [step[-1]] * 3
    code = OLGMDReference(16, 16, variant="code").run(frames)
    paper = OLGMDReference(16, 16, variant="paper").run(frames)
    assert not code["aim"].any()
    assert paper["aim"][1] > 0


@pytest.mark.parametrize("frame, problem", [
    (np.zeros((8, 9)), "expected 8x8 px"),
    (np.full((8, 8), 1.5), "[0, 1]"),
    (np.full((8, 8), np.nan), "[0, 1]"),
    (np.zeros((8, 8, 3), np.float32), "uint8 BGR"),
    (np.zeros((8, 8), np.int32), "uint8 or float"),
    (np.zeros((8, 8, 4), np.uint8), "grey or (H, W, 3)"),
])
def test_bad_frames_are_one_line_input_errors_naming_the_frame(frame, problem):
    ref = OLGMDReference(8, 8)
    ref.step(np.zeros((8, 8)))
    with pytest.raises(InputError) as e:
        ref.step(frame)
    assert str(e.value).startswith("frame 1: ") and problem in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("kw", [{"variant": "authors"}, {"fps": 0.0}, {"fps": float("nan")}, {"height": 2}])
def test_bad_arguments_are_user_errors(kw):
    args = {"height": 8, "width": 8, **kw}
    with pytest.raises(UserError):
        OLGMDReference(**args)
