"""The counts-to-contrast mapping on emulated events of the six basic stimuli.

The basic stimuli are full-contrast (grey 0 and 1), so every pixel that changes between two
frames changes by the whole range: the frames' ON/OFF split is ``P_on = [P]+``, ``P_off = [-P]+``
with ``|P| = 1`` (255 grey levels for the LGMD family). The event input must give the same, from
either emulator (cdnf_ti's, and an independent one with v2e's lin-log intensity and no
interpolation) and for every sensor threshold from 0.1 to 0.3: the whole model family then sees
on events what it sees on frames.
"""
from __future__ import annotations

import numpy as np
import pytest
from other_emulator import other_emulate

from cdnf_ti.events import EmulatorParams, bin_events, contrast_input, emulate
from cdnf_ti.frames import iter_grey
from cdnf_ti.inputs import resolve_input
from cdnf_ti.stimuli.basic import BASIC_STIMULI

SIZE = 64


def frames_split(frames: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
    """``([P]+, [-P]+)`` of each frame after the first, ``P = L(t) - L(t-1)``, L in [0, 1]."""
    g = [np.asarray(f, dtype=np.float64) / (255.0 if f.dtype == np.uint8 else 1.0) for f in frames]
    return [(np.maximum(b - a, 0.0), np.maximum(a - b, 0.0)) for a, b in zip(g[:-1], g[1:])]


@pytest.fixture(scope="module", params=BASIC_STIMULI)
def stimulus(request):
    src = resolve_input(f"stim:{request.param}?size={SIZE}")
    return src, list(iter_grey(src))


@pytest.mark.parametrize("emulator", ["cdnf_ti", "lin-log"])
@pytest.mark.parametrize("threshold", [0.1, 0.2, 0.3])
def test_event_input_equals_the_frames_on_off_split(stimulus, emulator, threshold):
    src, frames = stimulus
    if emulator == "cdnf_ti":
        events = list(emulate(frames, src.fps, EmulatorParams(threshold, threshold)))
    else:
        events = [other_emulate(frames, src.fps, threshold)]
    bins = list(bin_events(events, (SIZE, SIZE), t0=0))  # the default bin: one 30 fps frame
    want = frames_split(frames)
    assert len(bins) <= len(want)
    assert sum(int(b.sum()) for b in bins) > 0
    for k, (on, off) in enumerate(want):  # bin k: the change from frame k to frame k + 1
        p_on, p_off = contrast_input(bins[k], threshold) if k < len(bins) else (0 * on, 0 * off)
        np.testing.assert_array_equal(p_on, on, err_msg=f"ON, bin {k}")
        np.testing.assert_array_equal(p_off, off, err_msg=f"OFF, bin {k}")


@pytest.mark.parametrize("name", ["lgmd1", "lgmd2", "flgmd_onn"])
@pytest.mark.parametrize("backend", ["numpy", "taichi"])
def test_the_lgmd_family_sees_on_events_what_it_sees_on_frames(name, backend):
    # an event bin drives the ON/OFF channels with 255 p_on, 255 p_off: on a full-contrast stimulus that
    # is the frames' [P]+, [-P]+ in grey levels, so the step of bin k equals the step of frame k + 1
    from cdnf_ti.models import create_model

    src = resolve_input(f"stim:dark_looming?size={SIZE}")
    frames = list(iter_grey(src))
    events = list(emulate(frames, src.fps, EmulatorParams(0.2, 0.2)))
    bins = list(bin_events(events, (SIZE, SIZE), t0=0))
    k = next(i for i, b in enumerate(bins) if b.sum() > 0)  # the first change: frame k to frame k + 1
    on_frames = create_model(name, backend=backend)
    trace = on_frames.run(frames[k:k + 2])
    on_events = create_model(name, backend=backend)
    step = on_events.step_on_off(*contrast_input(bins[k], 0.2))
    assert step.output == trace.output[1]
    fa, fb = on_events.fields(), on_frames.fields()
    assert set(fa) == set(fb) and fb["OFF"].max() == 255.0  # the dark square's edge moved
    for f in fb:
        np.testing.assert_array_equal(fa[f], fb[f], err_msg=f)


def test_a_pixel_with_on_and_off_events_in_one_bin_drives_both_inputs():
    # Two ON events and one OFF event in one bin at one pixel: p_on = 2 C, p_off = C. C-DNF's
    # fields take each as it is, and SDNF's input is active where either reaches T_b (their
    # net change C alone would stay below it).
    from cdnf_ti.baselines_reference import NumpySDNFBackend
    from cdnf_ti.models.sdnf import SDNFParams
    from cdnf_ti.params import CDNFParams
    from cdnf_ti.reference import NumpyCDNFBackend

    counts = np.zeros((2, 4, 5), np.int64)
    counts[1, 1, 2], counts[0, 1, 2] = 2, 1  # ON (index 1) and OFF (index 0) events
    p_on, p_off = contrast_input(counts, 0.2)
    assert p_on[1, 2] == pytest.approx(0.4) and p_off[1, 2] == pytest.approx(0.2)
    cdnf = NumpyCDNFBackend(CDNFParams(), p_on.shape)
    cdnf.load_on_off(p_on, p_off, True)
    np.testing.assert_array_equal(cdnf.P_on, p_on)
    np.testing.assert_array_equal(cdnf.P_off, p_off)
    sdnf = NumpySDNFBackend(SDNFParams(t_b=0.3), p_on.shape)
    active = sdnf.load_on_off(p_on, p_off, True)
    assert sdnf.E[1, 2] == 1.0 and active == pytest.approx(1 / p_on.size)
