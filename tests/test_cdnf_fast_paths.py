"""The lane-vectorised C-DNF fast path against the NumPy float64 reference.

Every stage of the fast path (``kernels/cdnf.py`` on the engine's lane layout) is checked
against :mod:`cdnf_ti.reference` on generated stimuli (basic, incoherent,
dashcam-like stand-in video) and on every border mode, at widths that are and
are not multiples of the lane width.
"""
import threading

import numpy as np
import pytest
from cdnf_engine import Driver, spans
from conftest import small_stimulus

from cdnf_ti import CDNF, CDNFParams
from cdnf_ti.backends.engine import Backend
from cdnf_ti.bench.inputs import standin_video
from cdnf_ti.kernels.engine import EMPTY_HI
from cdnf_ti.reference import NumpyCDNFBackend
from cdnf_ti.stimuli.basic import basic_stimulus
from cdnf_ti.stimuli.incoherent import incoherent_stimulus
from cdnf_ti.taichi_runtime import lanes

LANES = lanes()  # lanes per vector element of the fast path under this process's compiler

BORDERS = ["replicate", "reflect", "zero"]


def _pair(params, shape):
    return Driver(params, shape), NumpyCDNFBackend(params, shape)


def _assert_fields_close(fast, ref, atol):
    a, b = fast.fields(), ref.fields()
    for k in ("u_on", "u_off", "v", "P"):
        assert a[k].shape == b[k].shape, k
        assert np.max(np.abs(a[k] - b[k])) < atol, k


@pytest.mark.parametrize("border", BORDERS)
@pytest.mark.parametrize("width", [5 * LANES, 5 * LANES + 3])  # a multiple of the lane width, and not
def test_one_contrast_and_one_summation_update_match_reference(border, width):
    # Two frames of a light looming square: strong ON/OFF contrast next to the borders.
    stim = small_stimulus("light_looming", size=width)
    f0 = stim.frame(stim.n_frames - 3)[:70]
    f1 = stim.frame(stim.n_frames - 1)[:70]
    p = CDNFParams(border=border)
    fast, ref = _pair(p, f0.shape)
    for be in (fast, ref):
        be.load(f0, True)
        be.load(f1, False)
    r_fast = fast.contrast_iterate(0.75)
    r_ref = ref.contrast_iterate(0.75)
    assert np.allclose(r_fast, r_ref, atol=2e-6)
    _assert_fields_close(fast, ref, 2e-6)
    for be in (fast, ref):
        be.summation_input()
    # Summation from a non-uniform v: iterate a few times to leave the resting state.
    for _ in range(3):
        s_fast = fast.summation_iterate(1.0)
        s_ref = ref.summation_iterate(1.0)
        assert abs(s_fast[0] - s_ref[0]) < 5e-6
    _assert_fields_close(fast, ref, 5e-6)
    assert abs(fast.mean_activation() - ref.mean_activation()) < 1e-6


@pytest.mark.parametrize("border", BORDERS)
def test_fast_path_matches_reference_over_a_whole_stimulus_with_odd_width(border):
    stim = small_stimulus("dark_looming", size=75)
    p = CDNFParams(border=border)
    fast = CDNF(p)
    a = fast.run(stim.frames())
    b = CDNF(p, backend="numpy").run(stim.frames())
    assert fast._be.lane
    assert np.max(np.abs(a.output - b.output)) < 1e-4
    assert np.array_equal(a.spike, b.spike)
    assert np.all(a.diagnostics["residual_sum"] < p.tol)
    # same fixed-point schedule: iteration counts agree frame by frame (+-2 for float32 rounding
    # and the pixels frozen within tol / 16)
    assert np.max(np.abs(a.diagnostics["iterations_sum"] - b.diagnostics["iterations_sum"])) <= 2


def test_fast_path_matches_reference_on_incoherent_looming():
    stim = incoherent_stimulus("dark_looming", 0.5, seed=3, height=72, width=90, start_half_size=1.5)
    frames = list(stim.frames())
    a = CDNF().run(frames)
    b = CDNF(backend="numpy").run(frames)
    assert np.max(np.abs(a.output - b.output)) < 1e-4


def test_fast_path_matches_reference_on_dashcam_like_video():
    frames = [f[::2, ::3] for f in standin_video(8, seed=1)]  # 120 x 142, every pixel moves
    a = CDNF().run(frames)
    b = CDNF(backend="numpy").run(frames)
    assert np.max(np.abs(a.output - b.output)) < 1e-4
    assert a.diagnostics["iterations_on"][1:].min() > 3  # the contrast fields really iterate


def test_fast_and_generic_taichi_kernels_give_the_same_trace():
    frames = list(small_stimulus("light_translating", size=64).frames())
    fast = CDNF().run(frames)
    slow_model = CDNF()
    slow_model.fast = False
    slow = slow_model.run(frames)
    assert not slow_model._be.lane
    assert np.max(np.abs(fast.output - slow.output)) < 1e-6


def test_narrow_frames_fall_back_to_generic_kernels():
    model = CDNF()
    model.run([np.zeros((20, 12), np.float32), np.ones((20, 12), np.float32)])
    assert not model._be.lane


def test_interleaved_models_of_one_size_keep_their_own_state():
    # Two models of the same frame size each own their arrays and share the process's
    # scratch; stepping them alternately must give what each gives alone.
    fa = list(small_stimulus("dark_looming", size=64).frames())
    fb = list(small_stimulus("light_receding", size=64).frames())
    alone_a = CDNF().run(fa).output
    alone_b = CDNF().run(fb).output
    ma, mb = CDNF(), CDNF()
    out_a, out_b = [], []
    for x, y in zip(fa, fb):
        out_a.append(ma.step(x).output)
        out_b.append(mb.step(y).output)
    assert ma._be.x is not mb._be.x and ma._be.lock is mb._be.lock  # own state, shared scratch
    assert np.array_equal(np.array(out_a), alone_a)
    assert np.array_equal(np.array(out_b), alone_b)
    assert np.abs(alone_a - alone_b).max() > 1e-3  # the two streams really differ


def _compiled_instances() -> int:
    """Kernels compiled (or loaded from the compile cache) so far in this process."""
    from cdnf_ti.taichi_runtime import compile_count

    return compile_count()


def test_a_second_model_of_a_frame_size_compiles_nothing_new():
    frames = [np.ascontiguousarray(f[::2, ::3]) for f in standin_video(3, seed=5)]
    CDNF().run(frames)
    before = _compiled_instances()
    CDNF().run(frames)
    assert before > 0 and _compiled_instances() == before


def _pending_rows(model, group):
    both, parity = spans(model, group)
    return int(np.sum(both[parity][:, 1] != EMPTY_HI)), both.shape[1]


def test_sparse_stimulus_iterates_only_rows_near_the_moving_edges():
    # A small dark square looming on a 200x200 frame: after the first frames most
    # rows never leave rest, and the pending spans must say so.
    stim = small_stimulus("dark_looming", size=200)
    frames = list(stim.frames())[:12]
    model = CDNF()
    pending = []
    for f in frames:
        model.step(f)
        pending.append(_pending_rows(model, "c")[0] + _pending_rows(model, "s")[0])
    assert 0 < max(pending[3:]) < 200  # of 2 x 200 rows
    ref = CDNF(backend="numpy").run(frames)
    again = CDNF().run(frames)
    assert np.max(np.abs(again.output - ref.output)) < 1e-4


def test_frozen_pixels_give_the_same_answer_as_iterating_everything():
    # freeze = 0: only bit-exact still pixels stop; the default freezes |F(u) - u| <= tol / 16.
    frames = list(small_stimulus("light_looming", size=96).frames())
    default = CDNF().run(frames)
    exact = CDNF()
    exact.freeze = 0.0
    full = exact.run(frames)
    assert np.max(np.abs(default.output - full.output)) < 1e-6
    ref = CDNF(backend="numpy").run(frames)
    assert np.max(np.abs(full.output - ref.output)) < 1e-4


def test_restoring_rest_marks_every_element_pending():
    model = CDNF()
    frames = list(small_stimulus("dark_translating", size=96).frames())[:6]
    model.run(frames)
    model._restore_rest()
    e1 = -(-frames[0].shape[1] // LANES)  # the last element holding frame columns
    for group in ("c", "s"):
        for a in spans(model, group)[0]:  # both parities
            assert np.all(a[:, 0] == 1) and np.all(a[:, 1] == e1)


@pytest.mark.parametrize("workers", [1, 3])
def test_solve_gives_bit_identical_results_with_any_number_of_workers(workers):
    # Rows are claimed dynamically by the persistent workers; each row is computed by one
    # worker with the same arithmetic, so the answer must not depend on how many there are.
    frames = [f[::2, ::3] for f in standin_video(6, seed=4)]
    two = CDNF().run(frames)
    other = CDNF()
    other._make_backend(frames[0].shape)
    other._be.nw = workers
    got = other.run(frames)
    assert np.array_equal(got.output, two.output)
    for k in ("iterations_on", "iterations_off", "iterations_sum", "residual_sum"):
        assert np.array_equal(got.diagnostics[k], two.diagnostics[k]), k


def test_models_sharing_the_scratch_in_threads_give_their_sequential_results():
    """Two C-DNF models of one frame size share the process's scratch; run in two threads at once
    (as in a Dask worker with several threads) each still gives what it gives alone."""
    def frames(name):
        return list(basic_stimulus(name, height=96, width=96, start_half_size=2.0).frames())

    stims = {"dark_looming": frames("dark_looming"), "light_translating": frames("light_translating")}
    alone = {k: CDNF().run(v).output for k, v in stims.items()}
    together: dict = {}

    def work(name):
        together[name] = CDNF().run(stims[name]).output

    threads = [threading.Thread(target=work, args=(k,)) for k in stims]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    for k in stims:
        np.testing.assert_allclose(together[k], alone[k], rtol=0, atol=1e-7)


def _converged_frame_backend():
    frames = [np.ascontiguousarray(f[::2, ::3]) for f in standin_video(4, seed=2)]
    model = CDNF()
    for f in frames[:3]:
        model.step(f)
    be = Driver(model=model)
    be.load(frames[3], False)
    return model, be


def test_contrast_solve_that_converges_computes_the_summation_input_of_its_result():
    model, be = _converged_frame_backend()
    res = be.contrast_iterate_many([(1.0, 0.0)] * 16)
    assert max(res[-1]) <= np.float32(model.params.tol) and model._s_ready  # converged within the launch
    be.summation_input()  # uses what the launch computed
    fused = be.planes()["S"]
    model._s_ready = False
    be.summation_input()  # the stand-alone launch on the same fields
    assert np.array_equal(fused, be.planes()["S"])


def test_summation_solve_that_converges_computes_the_mean_activation_of_its_result():
    model, be = _converged_frame_backend()
    be.contrast_iterate_many([(1.0, 0.0)] * 16)
    be.summation_input()
    res = be.summation_iterate_many([(1.0, 0.0)] * 16)
    assert res[-1][0] <= np.float32(model.params.tol) and model._mean is not None
    fused = be.mean_activation()
    again = be.mean_activation()  # nothing cached any more: the stand-alone launch
    assert model._mean is None
    assert abs(fused - again) < 1e-12
    ref = np.mean(np.tanh(np.maximum(be.fields()["v"].astype(np.float64), 0.0)) / np.tanh(1.0))
    assert abs(fused - ref) < 1e-6


def test_lane_kernels_serve_the_cpu_and_gpus_get_the_generic_kernels():
    # the persistent workers of the solve kernels wait for each other on CPU threads only
    assert Backend.lane_layout(True, (240, 426), "cpu")
    assert not Backend.lane_layout(True, (240, 426), "cuda")
    assert not Backend.lane_layout(True, (240, 20), "cpu")  # narrower than two lane elements


def test_contrast_launch_loads_the_frame_as_the_stand_alone_load_does():
    frames = [np.ascontiguousarray(f[::2, ::3]) for f in standin_video(3, seed=5)]
    fused, alone = CDNF(), CDNF()
    for m in (fused, alone):
        m.step(frames[0])
        m.step(frames[1])
    fused_be, alone_be = Driver(model=fused), Driver(model=alone)
    fused_be.load(frames[2], False)
    fused_be.contrast_iterate_many([(1.0, 0.0)])  # loads the frame in its first phase
    alone_be.load(frames[2], False)
    alone._flush_load()  # the stand-alone launch
    alone_be.contrast_iterate_many([(1.0, 0.0)])
    a, b = fused.fields(), alone.fields()
    for k in ("P", "u_on", "u_off"):
        assert np.array_equal(a[k], b[k]), k


def test_fields_read_right_after_load_show_the_new_frame():
    frames = [np.ascontiguousarray(f[::2, ::3]) for f in standin_video(2, seed=6)]
    model = CDNF()
    model.step(frames[0])
    Driver(model=model).load(frames[1], False)
    p = model.fields()["P"]
    assert np.allclose(p, frames[1].astype(np.float64) / 255.0 - frames[0] / 255.0, atol=1e-6)


@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
def test_the_backend_prepares_its_contrast_launch_for_the_first_frames_type(dtype):
    # warm_up compiles the contrast launch for one frame type (each variant costs start-up time):
    # the first frame's, so 8-bit video and float frames both start with what they need
    video = [f[::2, ::3] for f in standin_video(4, seed=7)]  # uint8
    as_float = [(f / 255.0).astype(np.float32) for f in video]
    model, floats = CDNF(), CDNF()
    frames = video if dtype == np.uint8 else as_float
    a = [model.step(f).output for f in frames][1:]
    floats.step(as_float[0])
    b = [floats.step(f).output for f in as_float[1:]]
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)
