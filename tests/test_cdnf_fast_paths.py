"""The lane-vectorised C-DNF fast path against the NumPy float64 reference.

Every kernel of the fast path (``kernels/cdnf.py``, ``lanes_*``) is checked
against :mod:`cdnf_ti.reference` on generated stimuli (basic, incoherent,
dashcam-like stand-in video) and on every border mode, at widths that are and
are not multiples of the lane width.
"""
import threading

import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti import CDNF, CDNFParams
from cdnf_ti.bench.inputs import standin_video
from cdnf_ti.kernels.cdnf import tile_blocks
from cdnf_ti.models.cdnf import LaneTaichiCDNFBackend, TaichiCDNFBackend
from cdnf_ti.reference import NumpyCDNFBackend
from cdnf_ti.stimuli.basic import basic_stimulus
from cdnf_ti.stimuli.incoherent import incoherent_stimulus

BORDERS = ["replicate", "reflect", "zero"]


def _pair(params, shape):
    return LaneTaichiCDNFBackend(params, shape), NumpyCDNFBackend(params, shape)


def _assert_fields_close(fast, ref, atol):
    a, b = fast.fields(), ref.fields()
    for k in ("u_on", "u_off", "v", "P"):
        assert a[k].shape == b[k].shape, k
        assert np.max(np.abs(a[k] - b[k])) < atol, k


@pytest.mark.parametrize("border", BORDERS)
@pytest.mark.parametrize("width", [80, 83])
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
    assert isinstance(fast._be, LaneTaichiCDNFBackend)
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
    assert isinstance(slow_model._be, TaichiCDNFBackend)
    assert np.max(np.abs(fast.output - slow.output)) < 1e-6


def test_narrow_frames_fall_back_to_generic_kernels():
    model = CDNF()
    model.run([np.zeros((20, 12), np.float32), np.ones((20, 12), np.float32)])
    assert isinstance(model._be, TaichiCDNFBackend)


def test_interleaved_models_of_one_size_share_the_workspace_without_mixing_state():
    # Two models of the same frame size share one set of Taichi fields; stepping
    # them alternately must give what each gives alone.
    fa = list(small_stimulus("dark_looming", size=64).frames())
    fb = list(small_stimulus("light_receding", size=64).frames())
    alone_a = CDNF().run(fa).output
    alone_b = CDNF().run(fb).output
    ma, mb = CDNF(), CDNF()
    out_a, out_b = [], []
    for x, y in zip(fa, fb):
        out_a.append(ma.step(x).output)
        out_b.append(mb.step(y).output)
    assert np.array_equal(np.array(out_a), alone_a)
    assert np.array_equal(np.array(out_b), alone_b)
    assert np.abs(alone_a - alone_b).max() > 1e-3  # the two streams really differ


@pytest.mark.parametrize("e1", [2, 3, 9, 17, 54, 76])
def test_tile_blocks_cover_each_element_once_and_last_block_holds_two(e1):
    bs, nblk = tile_blocks(e1)
    spans = [(1 + b * bs, min(1 + b * bs + bs, e1 + 1)) for b in range(nblk)]
    covered = [e for a, z in spans for e in range(a, z)]
    assert covered == list(range(1, e1 + 1))
    assert spans[-1][1] - spans[-1][0] >= 2


def test_sparse_stimulus_iterates_only_tiles_near_the_moving_edges():
    # A small dark square looming on a 200x200 frame: after the first frames most
    # tiles never leave rest, and the active list must say so.
    stim = small_stimulus("dark_looming", size=200)
    frames = list(stim.frames())[:12]
    model = CDNF()
    be_counts = []
    for f in frames:
        model.step(f)
        be_counts.append(model._be.ws.tiles["s"]["cnt"][None])
    n_tiles = model._be.ws.n_tiles
    assert max(be_counts[3:]) < n_tiles / 2
    ref = CDNF(backend="numpy").run(frames)
    again = CDNF().run(frames)
    assert np.max(np.abs(again.output - ref.output)) < 1e-4


def test_frozen_tiles_give_the_same_answer_as_iterating_everything():
    # freeze = 0: only bit-exact still pixels stop; the default freezes |F(u) - u| <= tol / 16.
    frames = list(small_stimulus("light_looming", size=96).frames())
    default = CDNF().run(frames)
    exact = CDNF()
    exact._make_backend(frames[0].shape)
    exact._be.tau = 0.0
    full = exact.run(frames)
    assert np.max(np.abs(default.output - full.output)) < 1e-6
    ref = CDNF(backend="numpy").run(frames)
    assert np.max(np.abs(full.output - ref.output)) < 1e-4


def test_restoring_rest_reactivates_every_tile():
    model = CDNF()
    frames = list(small_stimulus("dark_translating", size=96).frames())[:6]
    model.run(frames)
    model._be.restore_rest()
    t = model._be.ws.tiles
    assert t["c"]["cnt"][None] == model._be.ws.n_tiles
    assert t["s"]["cnt"][None] == model._be.ws.n_tiles


def test_models_sharing_a_lane_workspace_in_threads_give_their_sequential_results():
    """Two C-DNF models of one frame size share the lane workspace; run in two threads at once
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
