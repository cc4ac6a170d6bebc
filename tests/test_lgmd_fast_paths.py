"""The lane-vectorised fast paths of LGMD1, LGMD2 and F-LGMD against the NumPy float64 references.

Every launch of the fast paths (``kernels/lgmd.py``: each model's ``load`` and ``layers``, F-LGMD's
``solve`` and ``finish``, on the engine's lane layout) is checked against
:mod:`cdnf_ti.baselines_reference` on generated stimuli (basic, noisy, dashcam-like
stand-in video and, when the development clips are there, a real clip), at widths that are and
are not multiples of the lane width; F-LGMD's solve converging inside its launch and
outside it.
"""
from __future__ import annotations

import numpy as np
import pytest
from conftest import small_stimulus
from test_flgmd import noisy_stream
from test_row_runs import moving_noise

from cdnf_ti.bench.inputs import real_or_standin, standin_video
from cdnf_ti.models import FLGMDParams, create_model
from cdnf_ti.models.flgmd import FEEDBACK_STARTS
from cdnf_ti.taichi_runtime import lanes

ALWAYS_ON = FLGMDParams(t_ffi=1e9)  # no FFI hold: the per-pixel layers run on every frame
FAST_MODELS = ["lgmd1", "lgmd2", "flgmd_onn"]
STEPS = {"lgmd1": "sum_G", "lgmd2": "max_Ce", "flgmd_onn": "iterations"}  # a per-frame diagnostic of the layers

LANES = lanes()  # lanes per vector element of the fast path under this process's compiler


def on_lane_layout(be) -> bool:
    """Whether a model's backend runs the fast (lane) layout; False: the pixel layout (generic kernels)."""
    return be.lane


def default_params(model):
    return ALWAYS_ON if model == "flgmd_onn" else None


def run_fast_and_reference(frames, params=None, model="flgmd_onn"):
    fast, ref = create_model(model, params), create_model(model, params, backend="numpy")
    a, b = fast.run(frames), ref.run(frames)
    assert on_lane_layout(fast._be)
    return fast, a, ref, b


def assert_fields_close(fast, ref, rel=1e-4):
    fa, fb = fast.fields(), ref.fields()
    assert set(fa) == set(fb)
    for k in fb:
        scale = max(1.0, float(np.abs(fb[k]).max()))
        np.testing.assert_allclose(fa[k], fb[k], atol=rel * scale, rtol=0, err_msg=k)


# two lane elements and one column; whole lane elements only; 70: the width the other tests use (each
# width compiles the kernels once, so the other tests share 70, and the real clip 426). The lane
# width depends on the compiler (kernels.common.LANES_BY_COMPILER).
@pytest.mark.parametrize("width", [2 * LANES + 1, 3 * LANES, 70])
@pytest.mark.parametrize("model", FAST_MODELS)
def test_fast_path_matches_reference_at_widths_around_the_lane_width(model, width):
    frames = moving_noise(7, width, seed=width, n=7)
    fast, a, ref, b = run_fast_and_reference(frames, default_params(model), model)
    np.testing.assert_allclose(a.output, b.output, atol=1e-5, rtol=0)
    np.testing.assert_allclose(a.diagnostics[STEPS[model]], b.diagnostics[STEPS[model]], rtol=1e-4, atol=1e-5)
    assert_fields_close(fast, ref)


@pytest.mark.parametrize("model", FAST_MODELS)
def test_fast_path_matches_reference_on_dashcam_like_video(model):
    frames = [f[::2, ::3][:, :70] for f in standin_video(8, seed=1)]  # 120 x 70, every pixel moves
    fast, a, ref, b = run_fast_and_reference(frames, default_params(model), model)
    np.testing.assert_allclose(a.output, b.output, atol=1e-5, rtol=0)
    if model == "flgmd_onn":
        assert b.diagnostics["iterations"][1:].min() > 3  # the ON feedback really iterates
        assert np.abs(a.diagnostics["iterations"] - b.diagnostics["iterations"]).max() <= 1
    assert a.converged.all()
    assert_fields_close(fast, ref)


@pytest.mark.parametrize("model", FAST_MODELS)
def test_fast_path_matches_reference_on_real_footage_or_its_standin(model):
    _, frames = real_or_standin(6)  # the shared dashcam clip at 426 x 240 when present
    fast, a, ref, b = run_fast_and_reference(frames, None, model)
    np.testing.assert_allclose(a.output, b.output, atol=1e-5, rtol=0)
    np.testing.assert_array_equal(a.spike, b.spike)
    assert_fields_close(fast, ref)


@pytest.mark.parametrize("stim", ["dark_looming", "light_translating"])
@pytest.mark.parametrize("model", FAST_MODELS)
def test_fast_path_matches_reference_on_basic_stimuli(model, stim):
    frames = [f[:, 13:83] for f in small_stimulus(stim, 96).frames()]  # 96 x 70, centred
    _, a, _, b = run_fast_and_reference(frames, None, model)
    np.testing.assert_allclose(a.output, b.output, atol=1e-5, rtol=0)
    np.testing.assert_array_equal(a.diagnostics["count"], b.diagnostics["count"])


def test_fast_path_with_feedback_on_both_channels():
    p = FLGMDParams(beta_off=0.3, t_ffi=1e9)
    fast, a, ref, b = run_fast_and_reference(noisy_stream("dark_looming", seed=2, h=48, w=70), p)
    np.testing.assert_allclose(a.output, b.output, atol=1e-5, rtol=0)
    assert b.diagnostics["residual_off"][1:].max() > 0 or b.diagnostics["iterations"][1:].max() > 1
    assert a.diagnostics["residual_off"].max() < p.tol
    assert_fields_close(fast, ref)


def test_fast_path_plain_scheme_matches_reference():
    p = FLGMDParams(scheme="plain", t_ffi=1e9)
    _, a, _, b = run_fast_and_reference(noisy_stream("light_looming", seed=5, h=40, w=70), p)
    np.testing.assert_allclose(a.output, b.output, atol=1e-5, rtol=0)
    assert a.converged.all()


def test_unconverged_launches_finish_the_layers_in_a_separate_kernel():
    # With a budget of 2 updates the solve launch never converges, so the layers come from
    # the finish launch instead of the solve launch; both backends run the same 2 updates.
    p = FLGMDParams(max_iter=2, t_ffi=1e9)
    frames = noisy_stream("light_looming", seed=11, h=40, w=70)
    with pytest.warns(Warning):
        fast, a, ref, b = run_fast_and_reference(frames, p)
    assert not b.converged[1:].any()
    np.testing.assert_allclose(a.output, b.output, atol=1e-5, rtol=0)
    assert_fields_close(fast, ref)


def burst_then_calm():
    """Dashcam-like frames (every pixel moves), then a dark square moving over the last one: 120 x 70."""
    busy = [f[::2, ::3][:, :70] for f in standin_video(6, seed=4)]
    calm = []
    for k in range(8):
        f = busy[-1].copy()
        f[20 + 2 * k:30 + 2 * k, 20:34] = 10
        calm.append(f)
    return busy + calm


@pytest.mark.parametrize("model", ["lgmd1", "flgmd_onn"])  # the models with feed-forward inhibition
def test_frames_that_ffi_holds_drop_their_channels_as_in_the_reference(model):
    frames = burst_then_calm()
    ffi = create_model(model, backend="numpy").run(frames).diagnostics["FFI"]
    t_ffi = 0.5 * (ffi.max() + ffi[-1])  # held around the burst, computed again once it calms down
    params = create_model(model).params_type(t_ffi=float(t_ffi))
    fast, a, ref, b = run_fast_and_reference(frames, params, model)
    held = b.diagnostics["held"]
    assert held.any() and not held[-1] and b.diagnostics["sum_G"][-1] > 0
    np.testing.assert_array_equal(a.diagnostics["held"], held)
    np.testing.assert_allclose(a.output, b.output, atol=1e-5, rtol=0)
    np.testing.assert_allclose(a.diagnostics["sum_G"], b.diagnostics["sum_G"], rtol=1e-4, atol=1e-3)
    assert_fields_close(fast, ref)


@pytest.mark.parametrize("model", FAST_MODELS)
def test_fast_and_generic_kernels_give_the_same_trace(model):
    frames = noisy_stream("light_looming", seed=11, w=70)
    fast = create_model(model).run(frames)
    generic_model = create_model(model)
    generic_model.fast = False
    generic = generic_model.run(frames)
    assert not on_lane_layout(generic_model._be)
    np.testing.assert_allclose(fast.output, generic.output, atol=1e-6, rtol=0)
    np.testing.assert_allclose(fast.diagnostics[STEPS[model]], generic.diagnostics[STEPS[model]], rtol=1e-5)


def feedback_iterate_start(model, frame):
    """The ON/OFF iterate's start of a Taichi F-LGMD model after the load of ``frame`` (a frame after the
    first), as (H, W) arrays: the planes ``X_on``, ``X_off`` that the load launch writes."""
    model._be.load(frame, False)
    model._input(1, frame, None)
    planes = model._be.fields()
    return planes["X_on"], planes["X_off"]


@pytest.mark.parametrize("start", FEEDBACK_STARTS)
@pytest.mark.parametrize("fast", [True, False], ids=["lane", "generic"])
def test_feedback_iteration_starts_where_the_reference_starts(fast, start):
    frames = [np.ascontiguousarray(f[::2, ::3][:, :70]) for f in standin_video(5, seed=3)]  # dashcam-like
    p = FLGMDParams(t_ffi=1e9, beta_off=0.3, start=start)  # feedback on both channels
    model, ref = create_model("flgmd_onn", p), create_model("flgmd_onn", p, backend="numpy")
    model.fast = fast
    model.run(frames[:-1])
    ref.run(frames[:-1])
    assert on_lane_layout(model._be) is fast
    ref._be.load(frames[-1], False)
    ref._be.prepare()
    on, off = feedback_iterate_start(model, frames[-1])
    rb = ref._be
    np.testing.assert_allclose(on, rb.ON, atol=1e-3, rtol=1e-5)
    np.testing.assert_allclose(off, rb.OFF, atol=1e-3, rtol=1e-5)
    moved = max(np.abs(rb.ON - rb.ON0).max(), np.abs(rb.OFF - rb.OFF0).max())
    assert moved > 1.0 if start == "local" else moved == 0.0


@pytest.mark.parametrize("model", FAST_MODELS)
def test_narrow_frames_fall_back_to_generic_kernels(model):
    m = create_model(model)
    m.run(moving_noise(6, 20, seed=1, n=2))
    assert not on_lane_layout(m._be)


def own_state_shared_scratch(a, b) -> bool:
    """Whether two backends hold their own state arrays and share the process's scratch (its lock)."""
    return a.x is not b.x and a.lock is b.lock


@pytest.mark.parametrize("model", FAST_MODELS)
def test_interleaved_models_of_one_size_keep_their_own_state(model):
    fa = noisy_stream("dark_looming", seed=3, h=40, w=70)
    fb = noisy_stream("light_receding", seed=4, h=40, w=70)
    p = default_params(model)
    alone_a, alone_b = create_model(model, p).run(fa).output, create_model(model, p).run(fb).output
    ma, mb = create_model(model, p), create_model(model, p)
    out_a, out_b = [], []
    for x, y in zip(fa, fb):
        out_a.append(ma.step(x).output)
        out_b.append(mb.step(y).output)
    assert own_state_shared_scratch(ma._be, mb._be)
    assert np.array_equal(np.array(out_a), alone_a)
    assert np.array_equal(np.array(out_b), alone_b)
    assert np.abs(alone_a - alone_b).max() > 1e-4  # the two streams really differ


@pytest.mark.parametrize("workers", [1, 3])
@pytest.mark.parametrize("model", FAST_MODELS)
def test_launch_gives_the_same_results_with_any_number_of_workers(model, workers):
    # Rows are claimed dynamically; each row is computed by one worker with the same arithmetic.
    # Sums of rows are float64 (their order may change the last bits of sum G only).
    frames = [f[::2, ::3][:, :70] for f in standin_video(6, seed=4)]
    two = create_model(model, default_params(model)).run(frames)
    other = create_model(model, default_params(model))
    other._make_backend(frames[0].shape)
    other._be.nw = workers
    got = other.run(frames)
    np.testing.assert_allclose(got.output, two.output, atol=1e-12, rtol=0)
    np.testing.assert_allclose(got.diagnostics[STEPS[model]], two.diagnostics[STEPS[model]], rtol=1e-12, atol=0)


@pytest.mark.parametrize("model", FAST_MODELS)
def test_reset_returns_the_fast_path_to_its_first_frame_state(model):
    frames = noisy_stream("dark_looming", seed=8, h=40, w=70)
    m = create_model(model, default_params(model))
    first = m.run(frames).output
    again = m.run(frames).output  # run() resets first
    assert np.array_equal(first, again)
