"""Event bins through the models' ON/OFF input stage (``Model.step_on_off``, the CLI on event files).

C-DNF's ON field takes ``P_on = p_on`` and its OFF field ``P_off = p_off`` (a pixel with both
polarities in one bin drives both fields); SDNF's input is ``E = [max(p_on, p_off) >= T_b]``; the
LGMD family takes the net luminance change ``P = p_on - p_off``. The compiled paths of all five
models are checked against the NumPy float64 references on bins with mixed ON and OFF pixels, and
C-DNF's Table I row (``cdnf_ti.paper.TABLE1``) is checked through the CLI on events of the six
basic stimuli made by an emulator other than cdnf_ti's.
"""
from __future__ import annotations

import csv

import numpy as np
import pytest
from other_emulator import other_emulate

from cdnf_ti import CDNF
from cdnf_ti.errors import UserError
from cdnf_ti.events import open_event_source
from cdnf_ti.frames import iter_grey
from cdnf_ti.inputs import resolve_input
from cdnf_ti.models import MODELS, create_model
from cdnf_ti.paper import TABLE1
from cdnf_ti.run import main
from cdnf_ti.stimuli.basic import BASIC_STIMULI
from cdnf_ti.taichi_runtime import lanes

SIZE = 128  # the basic stimuli at 128 px keep C-DNF's Table I row on frames


def mixed_bins(n: int, shape: tuple[int, int], seed: int, density: float = 0.3) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` bins of ``(p_on, p_off)``: event counts 0..3 at threshold 0.2 on a fraction ``density`` of
    the pixels per polarity, so some pixels get both polarities in one bin."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        on, off = (np.minimum(0.2 * rng.integers(0, 4, shape) * (rng.random(shape) < density), 1.0) for _ in "ab")
        out.append((on, off))
    return out


def test_mixed_bins_have_pixels_with_both_polarities():
    on, off = mixed_bins(1, (40, 70), seed=0)[0]
    assert np.any((on > 0) & (off > 0)) and np.any((on > 0) & (off == 0)) and np.any((on == 0) & (off > 0))


@pytest.mark.parametrize("fast", [True, False])
def test_cdnf_event_bins_match_the_reference_on_mixed_on_off_pixels(fast):
    width = 2 * lanes() + 6  # the lane path needs frames at least two lane elements wide
    bins = mixed_bins(4, (40, width), seed=1)
    model = CDNF()
    model.fast = fast
    a = model.run(bins)
    b = CDNF(backend="numpy").run(bins)
    assert model._be.lane == fast  # the engine's lane layout, or its pixel layout
    assert np.max(np.abs(a.output - b.output)) < 1e-5
    assert np.max(np.abs(a.output - 0.5)) > 1e-4  # the bins really move I_v


def test_every_event_bin_is_a_full_step_including_bin_0():
    on, off = mixed_bins(1, (24, 24), seed=2)[0]
    trace = CDNF(backend="numpy").run([(on, off)])
    assert trace.n_frames == 1
    assert trace.diagnostics["iterations_on"][0] > 1
    assert trace.output[0] != 0.5


def both_polarities_bin(shape: tuple[int, int], level: float) -> tuple[np.ndarray, np.ndarray]:
    """A bin whose middle block has ON and OFF events alike (``p_on = p_off = level``): no net change."""
    on = np.zeros(shape)
    on[shape[0] // 4: 3 * shape[0] // 4, shape[1] // 4: 3 * shape[1] // 4] = level
    return on, on.copy()


def test_cdnf_drives_both_fields_where_a_pixel_has_both_polarities():
    on, off = both_polarities_bin((24, 24), 0.6)
    both = CDNF(backend="numpy")
    both.step_on_off(on, off)
    rest = CDNF(backend="numpy")
    rest.step_on_off(0 * on, 0 * off)
    f, r = both.fields(), rest.fields()
    inside = on > 0
    assert np.all(f["u_on"][inside] > r["u_on"][inside] + 0.1)  # P_on = p_on, not [p_on - p_off]+ = 0
    assert np.all(f["u_off"][inside] > r["u_off"][inside] + 0.1)
    np.testing.assert_array_equal(f["P"], on - off)  # the net change, for pictures


@pytest.mark.parametrize("fast", [True, False])
def test_cdnf_compiled_event_input_matches_the_reference_where_a_pixel_has_both_polarities(fast):
    width = 2 * lanes() + 6
    bins = [both_polarities_bin((40, width), 0.6), *mixed_bins(2, (40, width), seed=3)]
    model = CDNF()
    model.fast = fast
    a = model.run(bins)
    ref = CDNF(backend="numpy")
    b = ref.run(bins)
    assert model._be.lane == fast  # the engine's lane layout, or its pixel layout
    assert np.max(np.abs(a.output - b.output)) < 1e-5
    fa, fb = model.fields(), ref.fields()
    for k in ("u_on", "u_off", "v", "P"):
        np.testing.assert_allclose(fa[k], fb[k], rtol=0, atol=1e-4, err_msg=k)


@pytest.mark.parametrize("fast", [True, False])
def test_cdnf_frames_after_event_bins_take_the_on_off_split_of_p_again(fast):
    # One backend, bins then frames: each input takes its own ON/OFF stage.
    width = 2 * lanes() + 6
    rng = np.random.default_rng(8)
    frames = [rng.integers(0, 256, (40, width), dtype=np.uint8) for _ in range(2)]
    model, ref = CDNF(), CDNF(backend="numpy")
    model.fast = fast
    for m in (model, ref):
        for on, off in mixed_bins(2, (40, width), seed=9):
            m.step_on_off(on, off)
        m.step(frames[0])  # not the first step: P = L(t) - L(t-1), L(t-1) = 0 (the bins set no L)
        m.step(frames[1])
    fa, fb = model.fields(), ref.fields()
    for k in ("u_on", "u_off", "v", "P"):
        np.testing.assert_allclose(fa[k], fb[k], rtol=0, atol=1e-4, err_msg=k)


def test_sdnf_event_input_is_active_where_either_polarity_reaches_the_threshold():
    width = 2 * lanes() + 6
    t_b = MODELS["sdnf"].params_type().t_b
    on, off = both_polarities_bin((40, width), t_b)  # no net change, each polarity at the threshold
    on[0, :5] = 0.5 * t_b  # below the threshold: inactive
    model = create_model("sdnf")
    model.step_on_off(on, off)
    ref = create_model("sdnf", backend="numpy")
    ref.step_on_off(on, off)
    want = (np.maximum(on, off) >= t_b).astype(float)
    assert want.sum() > 0
    np.testing.assert_array_equal(ref.fields()["E"], want)
    np.testing.assert_array_equal(model.fields()["E"], want)


#: Every registered model with an event input stage but C-DNF (whose fields are checked above).
EVENT_MODELS = [n for n, m in MODELS.items() if m.takes_events and n != "cdnf"]


@pytest.mark.parametrize("name", EVENT_MODELS)
@pytest.mark.parametrize("fast", [True, False])
def test_every_event_models_bins_match_the_reference_on_mixed_on_off_pixels(name, fast):
    width = 2 * lanes() + 6
    bins = mixed_bins(5, (40, width), seed=5, density=0.04)  # sparse: below the LGMD family's FFI
    model = create_model(name)
    model.fast = fast
    a = model.run(bins)
    b = create_model(name, backend="numpy").run(bins)
    assert a.n_frames == len(bins)
    assert np.max(np.abs(a.output - b.output)) < 1e-4
    assert np.array_equal(a.spike, b.spike)
    assert any(np.ptp(f) > 1e-3 for f in model.fields().values())  # the bins really reach the model's planes


def test_lgmd_channels_take_255_times_the_net_contrast():
    on, off = mixed_bins(1, (24, 24), seed=6)[0]
    model = create_model("lgmd1", backend="numpy")
    model.step_on_off(on, off)
    np.testing.assert_allclose(model.fields()["P"], 255.0 * (on - off), rtol=0, atol=1e-9)


def test_a_model_without_an_event_input_stage_says_so():
    on, off = mixed_bins(1, (24, 24), seed=4)[0]
    model = CDNF(backend="numpy")
    type(model).takes_events, was = False, type(model).takes_events
    try:
        with pytest.raises(UserError, match="does not take event input"):
            model.step_on_off(on, off)
    finally:
        type(model).takes_events = was


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """Per threshold, events (lin-log emulator) of the six basic stimuli as .npy files."""
    folder = tmp_path_factory.mktemp("events")
    frames = {}
    for name in BASIC_STIMULI:
        src = resolve_input(f"stim:{name}?size={SIZE}")
        frames[name] = (src.fps, list(iter_grey(src)))

    def make(threshold: float) -> dict[str, str]:
        out = {}
        for name, (fps, fr) in frames.items():
            path = folder / f"{name}_{threshold:g}.npy"
            if not path.exists():
                np.save(path, other_emulate(fr, fps, threshold))
            out[name] = str(path)
        return out

    return make, {k: len(v[1]) for k, v in frames.items()}


@pytest.mark.parametrize("threshold", [0.1, 0.2, 0.3])
def test_cdnf_keeps_its_table_i_row_on_event_recordings_through_the_cli(recordings, tmp_path, threshold):
    make, n_frames = recordings
    paths = make(threshold)
    out = tmp_path / "out"
    code = main([*paths.values(), "--model", "cdnf", "--event-threshold", str(threshold), "--bin-ms", "33.333",
                 "--sensor-size", f"{SIZE}x{SIZE}", "--out", str(out), "--no-progress"])
    assert code == 0
    for name, path in paths.items():
        with open(out / f"{name}_{threshold:g}.cdnf.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        n_bins = sum(1 for _ in open_event_source(path, (SIZE, SIZE), 33.333).counts())
        assert len(rows) == n_bins  # one row per bin
        if "receding" not in name:  # events up to the last frame: one bin per frame interval
            assert n_bins == n_frames[name] - 1
        alerted = any(r["spike"] == "1" for r in rows)
        assert alerted == (TABLE1["cdnf"][name] == 1), name


# -- the LGMD family: an event bin drives the ON and the OFF channel separately ---------------------
LGMD_FAMILY = ["lgmd1", "lgmd2", "flgmd_onn"]


def lgmd_channel_drives(model) -> tuple[np.ndarray, np.ndarray]:
    """The ON and OFF channels that a reference LGMD-family backend computed from its last input
    (F-LGMD: its feed-forward drives ``ON0``/``OFF0``, before the feedback)."""
    be = model._be
    return (be.ON0, be.OFF0) if model.name == "flgmd_onn" else (be.ON, be.OFF)


@pytest.mark.parametrize("name", LGMD_FAMILY)
def test_a_pixel_with_both_polarities_drives_both_lgmd_channels(name):
    on, off = np.zeros((24, 24)), np.zeros((24, 24))
    on[5, 5], off[5, 5] = 0.4, 0.2  # both polarities, ON stronger
    on[12, 7], off[12, 7] = 0.2, 0.6  # both, OFF stronger
    on[3, 18], off[20, 2] = 0.2, 0.4  # one each
    both = (on > 0) & (off > 0)
    model = create_model(name, backend="numpy")
    model.step_on_off(on, off)
    on_channel, off_channel = lgmd_channel_drives(model)
    # ON = P_on [P_on >= clip] + dc ON(t-1), OFF = P_off + dc OFF(t-1), P = 255 p, nothing before the first bin
    clip = model.params.clip
    np.testing.assert_allclose(on_channel, np.where(255.0 * on >= clip, 255.0 * on, 0.0), rtol=0, atol=1e-9)
    np.testing.assert_allclose(off_channel, 255.0 * off, rtol=0, atol=1e-9)
    assert (on_channel[both] > 0).all() and (off_channel[both] > 0).all()  # not their difference


@pytest.mark.parametrize("name", LGMD_FAMILY)
def test_lgmd_channels_keep_their_residue_across_event_bins(name):
    (on1, off1), (on2, off2) = mixed_bins(2, (24, 24), seed=10, density=0.04)
    model = create_model(name, backend="numpy")
    model.step_on_off(on1, off1)
    first_on, first_off = (np.copy(c) for c in lgmd_channel_drives(model))
    if name == "flgmd_onn":  # the residue of F-LGMD's channels is their settled value
        first_on, first_off = model._be.ON.copy(), model._be.OFF.copy()
    model.step_on_off(on2, off2)
    on_channel, off_channel = lgmd_channel_drives(model)
    dc, clip = model.params.dc, model.params.clip
    np.testing.assert_allclose(on_channel, np.where(255.0 * on2 >= clip, 255.0 * on2, 0.0) + dc * first_on,
                               rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(off_channel, 255.0 * off2 + dc * first_off, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("name", LGMD_FAMILY)
@pytest.mark.parametrize("fast", [True, False])
def test_lgmd_event_channels_match_the_reference_on_pixels_with_both_polarities(name, fast):
    width = 2 * lanes() + 6
    bins = mixed_bins(3, (40, width), seed=13, density=0.04)  # sparse: below the FFI
    assert all(((on > 0) & (off > 0)).any() for on, off in bins)
    model, ref = create_model(name), create_model(name, backend="numpy")
    model.fast = fast
    for on, off in bins:
        a, b = model.step_on_off(on, off), ref.step_on_off(on, off)
        assert abs(a.output - b.output) < 1e-5
    fa, fb = model.fields(), ref.fields()
    assert set(fa) == set(fb)
    for k in fb:  # P, ON, OFF and every layer
        np.testing.assert_allclose(fa[k], fb[k], atol=1e-4 * max(1.0, float(np.abs(fb[k]).max())), rtol=0,
                                   err_msg=k)


@pytest.mark.parametrize("name", LGMD_FAMILY)
@pytest.mark.parametrize("backend", ["numpy", "taichi"])
def test_lgmd_pm_and_ffi_take_the_total_contrast_of_both_polarities(name, backend):
    width = 2 * lanes() + 6
    on, off = mixed_bins(1, (40, width), seed=9)[0]
    model = create_model(name, backend=backend)
    model.step_on_off(on, off)  # builds the backend
    loaded = model._be.load_on_off(on, off, False)  # numpy: the drive; the engine keeps the bin for the load
    assert model._input(1, None, loaded) == pytest.approx(255.0 * (on + off).sum(), rel=1e-6)
