"""The local start (``CDNFParams.start = "local"``): each frame's iteration starts every pixel at
the stationary level of its own input, in the NumPy reference and in both layouts of the engine."""
import numpy as np
import pytest
from cdnf_engine import Driver

from cdnf_ti import CDNF, CDNFParams
from cdnf_ti.bench.inputs import standin_video
from cdnf_ti.params import kernel_gains, resting_level, stationary_level, vartheta
from cdnf_ti.reference import NumpyCDNFBackend
from cdnf_ti.solver import cdnf_local_starts, local_start

BACKENDS = {"lanes": True, "generic": False}  # the engine's lane layout, or its pixel layout


def _dashcam(n=3):
    return [np.ascontiguousarray(f[::2, ::3]) for f in standin_video(n, seed=3)]  # 120 x 142, all moving


@pytest.mark.parametrize("gain", [1.0, -1.55, 0.4])
def test_stationary_level_solves_the_uniform_field_equation(gain):
    x = np.linspace(0.0, 1.3, 27)
    u = stationary_level(x, 0.2, gain)
    assert np.max(np.abs(x - 0.2 + vartheta(gain * u) - u)) < 1e-12


def test_stationary_level_of_no_input_is_the_resting_level():
    for gain in kernel_gains(CDNFParams()):
        assert abs(stationary_level(0.0, 0.2, gain) - resting_level(0.2, gain)) < 1e-12


@pytest.mark.parametrize("params", [CDNFParams(), CDNFParams(h=0.1, alpha_on=0.9), CDNFParams(sigma_1=0.5, B=0.3)],
                         ids=["defaults", "h0.1-alpha0.9", "other-dog"])
def test_the_fitted_start_is_exact_at_rest_and_close_to_the_stationary_level_elsewhere(params):
    coefs = cdnf_local_starts(params)
    for row, gain, atol in ((0, kernel_gains(params)[0], 2e-3), (1, kernel_gains(params)[1], 2e-3)):
        x = np.linspace(0.0, coefs[row, 1], 2001)
        fit = local_start(x, coefs[row])
        assert fit[0] == resting_level(params.h, gain)
        assert np.max(np.abs(fit - stationary_level(x, params.h, gain))) < atol


def test_inputs_beyond_the_fitted_range_start_at_its_end():
    coefs = cdnf_local_starts(CDNFParams())[0]
    assert local_start(np.array([1.0, 3.0]), coefs)[1] == local_start(np.array([1.0]), coefs)[0]


def test_a_uniform_luminance_step_starts_at_its_fixed_point():
    # A uniform input is solved by the start itself (up to the fit): the first residual is tiny.
    first = {}
    for start in ("local", "previous"):
        be = NumpyCDNFBackend(CDNFParams(start=start), (24, 30))
        be.load(np.full((24, 30), 0.2), True)
        be.load(np.full((24, 30), 0.7), False)
        first[start] = max(be.contrast_iterate(1.0))
    assert first["local"] < 1e-3
    assert first["previous"] > 0.3


def _loaded_pair(kind):
    """A Taichi backend of ``kind`` and the NumPy reference, both after loading two dashcam-like frames."""
    frames = _dashcam(2)
    be = Driver(CDNFParams(), frames[0].shape, fast=BACKENDS[kind])
    ref = NumpyCDNFBackend(CDNFParams(), frames[0].shape)
    for b in (be, ref):
        b.load(frames[0], True)
        b.load(frames[1], False)
    return be, ref


@pytest.mark.parametrize("kind", BACKENDS)
def test_kernels_set_the_reference_start_when_a_frame_loads(kind):
    be, ref = _loaded_pair(kind)
    a, r = be.fields(), ref.fields()
    assert np.max(np.abs(r["u_on"] - local_start(np.maximum(r["P"], 0.0), cdnf_local_starts(CDNFParams())[0]))) == 0
    for name in ("u_on", "u_off"):
        assert np.max(np.abs(a[name] - r[name])) < 2e-6, name


@pytest.mark.parametrize("kind", BACKENDS)
def test_kernels_set_the_reference_start_with_the_summation_input(kind):
    be, ref = _loaded_pair(kind)
    for b in (be, ref):
        for _ in range(12):
            b.contrast_iterate(1.0)
        b.summation_input()
    a, r = be.fields(), ref.fields()
    assert np.ptp(r["v"]) > 0.1  # the start is not uniform
    assert np.max(np.abs(a["v"] - r["v"])) < 5e-6


@pytest.mark.parametrize("start", ["previous", "rest"])
def test_other_starts_leave_the_fields_as_they_are_when_a_frame_loads(start):
    frames = _dashcam(2)
    be = Driver(CDNFParams(start=start), frames[0].shape)
    before = be.fields()
    be.load(frames[1], False)
    after = be.fields()
    assert np.array_equal(before["u_on"], after["u_on"]) and np.array_equal(before["u_off"], after["u_off"])


def test_the_local_start_needs_fewer_updates_on_dashcam_like_video():
    frames = _dashcam(10)
    local = CDNF(CDNFParams(start="local")).run(frames).diagnostics
    previous = CDNF(CDNFParams(start="previous")).run(frames).diagnostics
    for name in ("iterations_on", "iterations_sum"):
        assert local[name][1:].sum() < previous[name][1:].sum(), name


@pytest.mark.parametrize("border", ["zero", "reflect"])
def test_the_resting_state_is_still_solved_with_the_local_start(border):
    # Off a replicate border the resting state is not uniform: the start must not replace it.
    frame = np.full((40, 80), 0.5, np.float32)
    fast, ref = CDNF(CDNFParams(border=border)), CDNF(CDNFParams(border=border), backend="numpy")
    for m in (fast, ref):
        m.run([frame])
    a, r = fast._be.fields(), ref._be.fields()
    for name in ("u_on", "v"):
        assert np.max(np.abs(a[name] - r[name])) < 2e-5, name


def test_an_unknown_start_is_a_clear_error():
    with pytest.raises(ValueError, match="start must be one of"):
        CDNFParams(start="cold")
