"""EMD-LPLC2 (cdnf_ti.models.lplc2) on the engine against its float64 reference (cdnf_ti.lplc2_reference).

Tolerances: the GF spikes, the spike count and the active-unit count of every frame must be equal;
the membrane V then follows from equal counts in float64 on both sides (1e-9 mV). The centre unit's
arms are float32 sums of up to 2000 detector outputs (40 x 50 px), each a float32 product of
float32-filtered luminance: within 2e-5 of the frame's largest arm (a few float32 ulps of the terms
summed), the unit's response (a product of four arms) within 1e-4 of its largest.
"""
from __future__ import annotations

import functools
import os
import subprocess
import sys
from itertools import islice

import numpy as np
import pytest

from cdnf_ti.bench.inputs import standin_video
from cdnf_ti.lplc2_reference import LPLC2Reference
from cdnf_ti.models import LPLC2, LPLC2Params, create_model
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus
from cdnf_ti.taichi_runtime import COMPILER_ENV, installed_compilers

H, W, FPS = 96, 128, 100.0  # the authors' stimuli run at 100 frames/s
ARMS = ("arm_left", "arm_right", "arm_up", "arm_down")
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@functools.cache
def stimulus_frames(name: str, height: int = H, width: int = W) -> tuple:
    return tuple(basic_stimulus(name, height=height, width=width, fps=FPS, duration=1.0).frames())


def run_both(frames, fps: float = FPS, generic: bool = False, monkeypatch=None):
    """The engine model's trace (the lane layout, or the pixel layout where ``generic``) and the reference's
    per-frame outputs on ``frames``."""
    model = LPLC2(fps=fps)
    model.fast = not generic
    trace = model.run(frames)
    assert model._be.lane is not generic
    h, w = np.asarray(frames[0]).shape[:2]
    return trace, LPLC2Reference(h, w, fps=fps).run(frames)


def assert_agrees(trace, ref):
    """Spikes and counts equal frame by frame; V, current, arms and the centre unit within the tolerances."""
    np.testing.assert_array_equal(trace.spike, ref["alert"])
    np.testing.assert_array_equal(trace.diagnostics["spikes"], ref["spikes"])
    np.testing.assert_array_equal(trace.diagnostics["active"], ref["active"])
    np.testing.assert_allclose(trace.output, ref["v"], atol=1e-9, rtol=0)
    np.testing.assert_allclose(trace.diagnostics["current"], ref["current"], atol=1e-9, rtol=0)
    arms = np.stack([trace.diagnostics[k] for k in ARMS], axis=1)
    np.testing.assert_allclose(arms, ref["arms"], atol=2e-5 * max(1.0, np.abs(ref["arms"]).max()), rtol=0)
    np.testing.assert_allclose(trace.diagnostics["core"], ref["core"], rtol=0,
                               atol=1e-4 * max(1.0, np.abs(ref["core"]).max()))


@pytest.mark.parametrize("stim", BASIC_STIMULI)
def test_engine_matches_reference_on_basic_stimulus(stim):
    trace, ref = run_both(stimulus_frames(stim))
    assert_agrees(trace, ref)


@pytest.mark.parametrize("stim", ["dark_looming", "light_translating"])
def test_generic_kernels_match_reference_on_basic_stimulus(stim, monkeypatch):
    trace, ref = run_both(stimulus_frames(stim), generic=True, monkeypatch=monkeypatch)
    assert_agrees(trace, ref)


@pytest.mark.parametrize("generic", [False, True])
def test_engine_matches_reference_on_a_generated_dashcam_like_clip(generic, monkeypatch):
    frames = standin_video(36, height=120, width=213, seed=1)  # ego-motion plus a looming object
    trace, ref = run_both(frames, fps=30.0, generic=generic, monkeypatch=monkeypatch)
    assert ref["active"].max() > 100 and ref["alert"].any()  # the clip drives the array and the GF
    assert_agrees(trace, ref)


@pytest.mark.parametrize("clip", ["c02.mp4", "serial_vehicle_collision.mp4"])
def test_engine_matches_reference_on_real_clip(clip, shared_real):
    if shared_real is None or not (shared_real / clip).exists():
        pytest.skip("the development dashcam clips are not present (covered by the generated clip)")
    from cdnf_ti.frames import iter_grey, open_source

    frames = list(islice(iter_grey(open_source(shared_real / clip)), 0, 45))
    trace, ref = run_both(frames, fps=30.0)
    assert_agrees(trace, ref)


# grid widths (W - 1) below, at and above one and two lane vectors, and one above three
@pytest.mark.parametrize("width", [9, 32, 33, 34, 65, 98])
def test_lane_maps_match_reference_maps_at_widths_around_the_lane_width(width):
    rng = np.random.default_rng(width)
    base = rng.random((40, width + 60))
    frames = [np.ascontiguousarray(base[:, 2 * t: 2 * t + width]).astype(np.float32) for t in range(5)]
    fast, ref = LPLC2(fps=FPS), LPLC2(fps=FPS, backend="numpy")
    fast.run(frames), ref.run(frames)
    assert fast._be.lane is (width + 1 >= 64)  # the lane layout from two lane vectors on, else the pixel layout
    fa, fb = fast.fields(), ref.fields()
    assert set(fa) == set(fb) == {"horizontal", "vertical", "left", "right", "up", "down", "lplc2"}
    for k in fb:
        scale = max(1.0, float(np.abs(fb[k]).max()))
        np.testing.assert_allclose(fa[k], fb[k], atol=(1e-4 if k == "lplc2" else 2e-5) * scale, rtol=0, err_msg=k)


_OTHER_COMPILER = """
import numpy as np
from cdnf_ti.models import LPLC2
from cdnf_ti.lplc2_reference import LPLC2Reference
from cdnf_ti.stimuli.basic import basic_stimulus
from cdnf_ti.taichi_runtime import current_compiler
frames = list(basic_stimulus("dark_looming", height=72, width=100, fps=100.0, duration=1.0).frames())
t = LPLC2(fps=100.0).run(frames)
r = LPLC2Reference(72, 100, fps=100.0).run(frames)
print(current_compiler(), int(r["alert"].sum()), bool(np.array_equal(t.spike, r["alert"])),
      bool(np.array_equal(t.diagnostics["active"], r["active"])), float(np.abs(t.output - r["v"]).max()))
"""


@pytest.mark.parametrize("compiler", installed_compilers())
def test_engine_matches_reference_under_each_compiler(compiler):
    env = dict(os.environ, **{COMPILER_ENV: compiler})
    proc = subprocess.run([sys.executable, "-c", _OTHER_COMPILER], cwd=REPO, env=env, capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    comp, alerts, spikes_equal, active_equal, dv = proc.stdout.split()
    assert comp == compiler and int(alerts) > 0
    assert spikes_equal == "True" and active_equal == "True" and float(dv) < 1e-9


@functools.cache
def engine_response(name: str):
    return LPLC2(fps=FPS).run(stimulus_frames(name))


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_expansion_drives_the_array_and_the_giant_fibre(polarity):
    trace = engine_response(f"{polarity}_looming")
    assert trace.diagnostics["active"].max() > 100 and trace.spike.any()


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_translation_drives_it_far_less_than_expansion(polarity):
    looming, translating = engine_response(f"{polarity}_looming"), engine_response(f"{polarity}_translating")
    assert translating.diagnostics["active"].max() <= 0.01 * looming.diagnostics["active"].max()
    assert not translating.spike.any()


def test_expansion_activates_all_four_arms_of_the_centre_unit_translation_at_most_one():
    arms = lambda tr: np.stack([tr.diagnostics[k] for k in ARMS], axis=1) > 0  # noqa: E731
    assert arms(engine_response("dark_looming")).all(axis=1).any()
    assert arms(engine_response("dark_translating")).sum(axis=1).max() <= 1


def test_an_arm_responds_to_outward_motion_on_its_own_side_only():
    # a dark bar moving left across the left half of the centre unit's field: its left arm only
    frames = []
    for t in range(12):
        f = np.ones((H, W), np.float32)
        x = W // 2 - 8 - 2 * t
        f[:, x: x + 4] = 0.0
        frames.append(f)
    trace = LPLC2(fps=FPS).run(frames)
    d = trace.diagnostics
    assert d["arm_left"].max() > 0
    assert d["arm_right"].max() == d["arm_up"].max() == d["arm_down"].max() == 0


def test_the_first_frame_only_stores_the_picture():
    trace = LPLC2(fps=FPS).run(stimulus_frames("dark_looming")[:1])
    assert trace.output[0] == LPLC2Params().v_rest and not trace.spike[0]
    assert trace.diagnostics["active"][0] == 0


def test_reset_returns_the_engine_to_its_first_frame_state():
    model = LPLC2(fps=FPS)
    frames = stimulus_frames("light_looming")[-30:]
    a, b = model.run(frames), model.run(frames)
    np.testing.assert_array_equal(a.output, b.output)
    np.testing.assert_array_equal(a.diagnostics["active"], b.diagnostics["active"])


def test_registered_under_its_name_with_both_backends():
    assert isinstance(create_model("lplc2"), LPLC2)
    assert isinstance(create_model("lplc2", backend="numpy"), LPLC2)


@pytest.mark.parametrize("bad", [dict(half_side=0), dict(band_before=-1), dict(tau_m=0.0), dict(substeps=0),
                                 dict(v_reset=-40.0)])
def test_invalid_parameters_are_refused(bad):
    with pytest.raises(ValueError, match="LPLC2Params"):
        LPLC2Params(**bad)


@pytest.mark.parametrize("v_threshold", [-56.0, -50.0, -44.0])
def test_threshold_sweep_replays_what_a_rerun_at_that_threshold_gives(v_threshold):
    frames = stimulus_frames("dark_looming")
    swept = LPLC2.sweep_alerts(engine_response("dark_looming"), [v_threshold])[0]
    rerun = LPLC2(LPLC2Params(v_threshold=v_threshold), fps=FPS).run(frames).spike
    np.testing.assert_array_equal(swept, rerun)
