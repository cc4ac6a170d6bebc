"""The compiled event-based looming detector (``event_looming``) against its float64 reference
(:mod:`cdnf_ti.event_looming_reference`): frames through the project's emulator, event bins directly,
both layouts. The suite runs once per compiler (``CDNF_TI_COMPILER``)."""
from __future__ import annotations

import functools

import cv2
import model_checks as checks
import numpy as np
import pytest
from test_lplc2_real import REPO, code_lines

from cdnf_ti.event_looming_reference import EventLoomingReference, frame_bins
from cdnf_ti.events.binning import bin_events, contrast_input
from cdnf_ti.events.emulator import emulate
from cdnf_ti.frames import to_grey
from cdnf_ti.models import EventLooming, EventLoomingParams
from cdnf_ti.models.event_looming import signed_map
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus

SIZE = 96
OUTPUT_TOL = 1e-4
PATHS = ("lanes", "pixels")  # the fast (lane) layout and fast=False (the pixel layout)
REAL_CLIPS = ("c01.mp4", "nc03.mp4")
REAL_SIZE = (192, 108)  # W, H: the clips resized (INTER_AREA), two lane vectors wide and more


def model(path: str = "lanes", variant: str = "code", fps: float = 30.0, backend: str = "taichi") -> EventLooming:
    m = EventLooming(EventLoomingParams(variant=variant), backend=backend, fps=fps)
    m.fast = path == "lanes"
    return m


@functools.cache
def stimulus(name: str) -> tuple[tuple[np.ndarray, ...], float]:
    st = basic_stimulus(name, height=SIZE, width=SIZE)
    return tuple(st.frames()), float(st.fps)


def real_frames(shared_real, clip: str, n: int = 40) -> list[np.ndarray]:
    return [to_grey(cv2.resize(f, REAL_SIZE, interpolation=cv2.INTER_AREA))
            for f in checks.clip_frames(shared_real, clip, n)]


def compare(m: EventLooming, inputs: list, reference_inputs=None) -> dict:
    """``m`` and the reference of its variant on ``inputs`` (frames or event bins; the reference steps
    ``reference_inputs``, the signed maps): largest output difference, alerts equal, alerts."""
    return checks.compare(m, lambda h, w: EventLoomingReference(h, w, m.params.variant), inputs, "output",
                          reference_inputs=reference_inputs)


def compare_frames(frames, fps: float, path: str, variant: str = "code") -> None:
    """Output within OUTPUT_TOL and the alert equal on every frame, the reference stepping the emulator's
    events of the frames."""
    checks.assert_agrees(compare(model(path, variant, fps), frames, list(frame_bins(frames, fps))),
                         output=OUTPUT_TOL)


def event_bins(frames, fps: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """The emulator's events of ``frames`` binned one frame interval each, as the models' ON/OFF input."""
    h, w = np.asarray(frames[0]).shape[:2]
    return [contrast_input(c) for c in bin_events(emulate(frames, fps), (w, h), 1000.0 / fps)]


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", BASIC_STIMULI)
def test_compiled_model_equals_the_reference_on_basic_stimuli(name, path):
    frames, fps = stimulus(name)
    compare_frames(frames, fps, path)


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", ("dark_looming", "light_receding"))
def test_paper_variant_equals_the_reference(name, path):
    frames, fps = stimulus(name)
    compare_frames(frames, fps, path, "paper")


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("clip", REAL_CLIPS)
def test_compiled_model_equals_the_reference_on_real_clips(shared_real, clip, path):
    compare_frames(real_frames(shared_real, clip), 30.0, path)


@pytest.mark.parametrize("path", PATHS)
def test_event_bins_equal_the_reference_on_their_signed_maps(path):
    frames, fps = stimulus("dark_looming")
    bins = event_bins(frames, fps)
    r = compare(model(path, fps=fps), bins, [signed_map(*b) for b in bins])
    assert r["alerts"] > 0
    checks.assert_agrees(r, output=OUTPUT_TOL)


def test_an_event_bin_pixel_takes_the_polarity_with_more_contrast():
    p_on, p_off = np.zeros((8, 80)), np.zeros((8, 80))
    p_on[2, 3], p_off[2, 3] = 0.3, 0.15
    p_off[5, 7] = 0.15
    p_on[6, 9], p_off[6, 9] = 0.3, 0.3
    m = model()
    m.step_on_off(p_on, p_off)
    expected = np.zeros((8, 80))
    expected[2, 3], expected[5, 7] = 1, -1
    np.testing.assert_array_equal(m.fields()["X"], expected)


def test_frame_zero_has_no_events_and_frame_k_holds_the_emulator_s_events_since_frame_k_minus_1():
    frames, fps = stimulus("dark_looming")
    m = model()
    for k, (f, b) in enumerate(zip(frames[:12], frame_bins(frames[:12], fps))):
        m.step(f)
        np.testing.assert_array_equal(m.fields()["X"], b, err_msg=f"frame {k}")


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("clip", REAL_CLIPS)
def test_the_signed_map_of_uint8_frames_is_the_emulator_s_on_every_frame(shared_real, clip, path):
    frames = real_frames(shared_real, clip)
    assert frames[0].dtype == np.uint8  # the levels table and the band of grey levels that cannot cross
    bins = list(frame_bins(frames, 30.0))
    assert np.mean([np.abs(b).mean() for b in bins]) > 0.01  # a moving camera: events over much of the frame
    m = model(path)
    for k, (f, b) in enumerate(zip(frames, bins)):
        m.step(f)
        np.testing.assert_array_equal(m.fields()["X"], b, err_msg=f"frame {k}")


@pytest.mark.parametrize("path", PATHS)
def test_flow_fields_equal_the_reference_layers(path):
    frames, fps = stimulus("dark_looming")
    m, ref = model(path, fps=fps), EventLoomingReference(SIZE, SIZE)
    for f, b in zip(frames, frame_bins(frames, fps)):
        m.step(f)
        ref.step(b)
    fields = m.fields()
    for name in ("vx", "vy", "v_r"):
        assert np.abs(ref.layers[name]).max() > 0
        np.testing.assert_allclose(fields[name], ref.layers[name], rtol=0, atol=1e-5, err_msg=name)


def test_numpy_backend_is_the_reference():
    frames, fps = stimulus("light_looming")
    tr = model(backend="numpy", fps=fps).run(frames)
    ref = EventLoomingReference(SIZE, SIZE).run(frame_bins(frames, fps))
    np.testing.assert_array_equal(tr.output, ref["output"])
    np.testing.assert_array_equal(tr.spike, ref["alert"])


def test_streaming_after_reset_repeats_the_run():
    frames, fps = stimulus("dark_looming")
    m = model("lanes", "paper", fps)
    first = [m.step(f).output for f in frames]
    m.reset()
    assert [m.step(f).output for f in frames] == first


def test_the_alert_is_output_above_zero():
    rule = model().alert_rule()
    assert (rule.column, rule.level, rule.strict) == ("output", 0.0, True)


@pytest.mark.parametrize("bad", [dict(variant="nope"), dict(kern_half_size=0), dict(kern_half_size=32),
                                 dict(reg=0.0), dict(dt=-1.0), dict(sigma_pos=0.0)])
def test_bad_parameters_are_value_errors(bad):
    with pytest.raises(ValueError):
        EventLoomingParams(**bad)


def test_the_model_and_its_kernels_are_at_most_250_code_lines():
    assert code_lines(REPO / "kernels" / "event_looming.py") + code_lines(
        REPO / "cdnf_ti" / "models" / "event_looming.py") <= 250
