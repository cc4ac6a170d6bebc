"""D-LGMD on the engine (cdnf_ti.models.dlgmd): agreement with the float64 reference (cdnf_ti.dlgmd_reference).

The suite runs once per compiler (``CDNF_TI_COMPILER=taichi|quadrants``). Tolerance: the engine's layers are
float32 (the wide kernels as separable row and column passes) and its sums float64; the output ``mp`` must
agree to 1e-4 and the alert on every frame. A ``G`` cell within float32 round-off of ``T_G`` could flip and
move ``k`` by at most ``0.3 / (2.4 n)``; on these inputs ``mp`` agrees to about 1e-8.
"""
from __future__ import annotations

import functools

import model_checks as checks
import numpy as np
import pytest

from cdnf_ti.dlgmd_reference import DLGMDReference, dlgmd_kernels
from cdnf_ti.models import DLGMD, DLGMDParams
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus
from cdnf_ti.taichi_runtime import lanes

SIZE = 96
MP_TOL = 1e-4
PATHS = ("lanes", "pixels")  # the fast (lane) layout and the pixel layout (fast=False)
REAL_CLIPS = ("c01.mp4", "c38.mp4", "nc03.mp4")


def engine(path: str = "lanes", **kw) -> DLGMD:
    model = DLGMD(DLGMDParams(**kw))
    model.fast = path == "lanes"
    return model


def compare(inputs: list, path: str, **kw) -> dict:
    """Engine and reference on ``inputs`` (frames or event bins): largest ``mp`` and relative ``g_sum``
    differences, alerts equal, the reference's peak ``g_sum``."""
    model = engine(path, **kw)
    r = checks.compare(model, lambda h, w: DLGMDReference(h, w, DLGMDParams(**kw)), inputs, "mp",
                       relative={"g_sum": 1.0}, peak="g_sum")
    assert model._be.lane is (path == "lanes")
    return r


def assert_agrees(r: dict) -> None:
    checks.assert_agrees(r, mp=MP_TOL, g_sum=1e-4)


@functools.cache
def stimulus(name: str) -> tuple[np.ndarray, ...]:
    return tuple(basic_stimulus(name, height=SIZE, width=SIZE).frames())


def difference_bins(frames) -> list[tuple[np.ndarray, np.ndarray]]:
    """Event bins of the frames' luminance changes: ``(p_on, p_off) = ([dL]^+, [-dL]^+)`` of frames 1, 2, ...
    (float frames in [0, 1] as the model reads them: 8-bit grey levels ``floor(255 x + 0.5)``)."""
    lum = [np.floor(np.asarray(f, np.float64) * 255.0 + 0.5) / 255.0 for f in frames]
    return [(np.maximum(b - a, 0.0), np.maximum(a - b, 0.0)) for a, b in zip(lum[:-1], lum[1:])]


# -- engine against the reference -------------------------------------------------------------------
@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", BASIC_STIMULI)
def test_engine_matches_reference_on_basic_stimulus(name, path):
    assert_agrees(compare(list(stimulus(name)), path))


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("clip", REAL_CLIPS)
def test_engine_matches_reference_on_real_clip(shared_real, clip, path):
    assert_agrees(compare(checks.clip_frames(shared_real, clip, 40), path))


@pytest.mark.parametrize("path", PATHS)
def test_engine_matches_reference_at_other_kernel_shapes(path):
    """A smaller radius, another delay map (a wider excitation disc) and an odd grouping window."""
    frames = list(stimulus("dark_looming"))
    kw = dict(r=4, lamda=0.35, sigma_i=3.0, group_side=3)
    assert len(engine(path, **kw).kernel_options()["cells"]) > 5
    assert_agrees(compare(frames, path, **kw))


def test_engine_alerts_where_the_reference_does_on_a_looming_square():
    r = compare(list(stimulus("dark_looming")), "lanes")
    assert r["alerts"] > 0 and r["alerts_equal"]


def test_frames_two_lane_vectors_wide_take_the_lane_layout_and_narrower_ones_the_pixel_layout():
    for width, lane in ((2 * lanes(), True), (2 * lanes() - 1, False)):
        model = engine()
        model.step(np.zeros((8, width), np.uint8))
        assert model._be.lane is lane


@pytest.mark.parametrize("path", PATHS)
def test_layers_match_the_reference_layers(path):
    frames = stimulus("dark_looming")
    model = engine(path)
    model.run(list(frames))
    ref = DLGMDReference(SIZE, SIZE)
    ref.run(frames)
    got = model.fields()
    for name in ("E", "I", "S", "G"):
        np.testing.assert_allclose(got[name], ref.layers[name], rtol=0, atol=1e-5, err_msg=name)
    assert ref.layers["G"].max() > 0.1


# -- event input -------------------------------------------------------------------------------------
@pytest.mark.parametrize("path", PATHS)
def test_event_bins_match_the_reference(path):
    r = compare(difference_bins(stimulus("light_looming")), path)
    assert r["peak"] > 100
    assert_agrees(r)


def test_an_event_bin_of_a_frame_change_drives_the_model_as_that_frame_does():
    """Every bin is a difference (bin 0 included): bin ``t`` gives frame ``t + 1``'s output."""
    frames = stimulus("dark_looming")
    on_frames = engine().run(list(frames))
    on_bins = engine().run(difference_bins(frames))
    np.testing.assert_allclose(on_bins.output, on_frames.output[1:], rtol=0, atol=1e-6)
    np.testing.assert_array_equal(on_bins.spike, on_frames.spike[1:])
    assert on_frames.spike.any()


# -- the separable form of the authors' kernels ------------------------------------------------------
@pytest.mark.parametrize("kw", [{}, dict(r=4, lamda=0.35, sigma_i=3.0), dict(r=8, beta=0.45)])
def test_row_and_column_taps_rebuild_the_authors_delay_kernels(kw):
    """The stages' taps and options give ``K_E``, ``K_1`` (disc minus the delay-0 cells) and ``K_2`` (square
    minus the disc) exactly as :func:`dlgmd_kernels` makes them."""
    model = DLGMD(DLGMDParams(**kw))
    p, opt = model.params, model.kernel_options()
    taps = model.coefficients()["taps"].astype(np.float64)
    r, cells = p.r, opt["cells"]
    row = np.concatenate([taps[r:0:-1], taps[: r + 1]])
    col = taps[r + 1 : 3 * r + 2]
    full = np.outer(col, row)
    disc = np.array([[abs(j) <= w for j in range(-r, r + 1)] for w in opt["disc"]])
    k_e, near = np.zeros_like(full), np.zeros_like(full)
    for n, (di, dj) in enumerate(cells):
        k_e[di + r, dj + r] = taps[3 * r + 2 + n]
        near[di + r, dj + r] = taps[3 * r + 2 + len(cells) + n]
    want_e, want_1, want_2 = dlgmd_kernels(p)
    tol = dict(rtol=1e-6, atol=1e-7)  # the taps are float32 (the delay-0 cells of K_1: disc minus N, ~1e-9)
    np.testing.assert_allclose(k_e, want_e, **tol)
    np.testing.assert_allclose(np.where(disc, full, 0.0) - near, want_1, **tol)
    np.testing.assert_allclose(np.where(disc, 0.0, full), want_2, **tol)


# -- the model's interface ---------------------------------------------------------------------------
def test_alert_rule_is_mp_at_least_the_threshold():
    rule = DLGMD(backend="numpy").alert_rule()
    assert (rule.column, rule.level, rule.strict) == ("mp", 0.6, False)


def test_sweep_alerts_at_the_default_threshold_reproduce_the_run_alerts():
    tr = DLGMD(backend="numpy").run(list(stimulus("dark_looming")))
    (alerts,) = DLGMD.sweep_alerts(tr, [DLGMD.sweep_default()])
    assert tr.spike.any()
    np.testing.assert_array_equal(alerts, tr.spike)


def test_numpy_backend_is_the_reference():
    frames = stimulus("light_looming")
    tr = DLGMD(backend="numpy").run(list(frames))
    ref = DLGMDReference(SIZE, SIZE).run(frames)
    np.testing.assert_array_equal(tr.output, ref["mp"])
    np.testing.assert_array_equal(tr.spike, ref["alert"])


@pytest.mark.parametrize("bad, msg", [(dict(r=9), "r must"), (dict(sigma_i=0.0), "sigma"),
                                      (dict(group_side=0), "group_side")])
def test_invalid_params_raise_clear_value_error(bad, msg):
    with pytest.raises(ValueError, match=msg):
        DLGMDParams(**bad)
