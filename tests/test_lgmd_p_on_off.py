"""LGMD_P_ON_OFF on the engine (cdnf_ti.models.lgmd_p_on_off): agreement with the float64 reference.

The engine's layers are float32 and its sums float64, the reference float64 throughout. A ``G`` cell
within float32 round-off of the threshold ``0.5 G = 0.7`` could flip and move ``sum G`` by at most
``~1.4`` and ``mp`` by ``~1.4 / (4 * 0.1 N)``: below 1e-4 at these sizes. The suite runs once per
compiler (``CDNF_TI_COMPILER``); every comparison here runs on both layouts, the lane path and the
pixel layout (``fast=False``).
"""
from __future__ import annotations

import functools

import model_checks as checks
import numpy as np
import pytest

from cdnf_ti.errors import UserError
from cdnf_ti.lgmd_p_on_off_reference import LGMDPOnOffReference
from cdnf_ti.models import MODELS, LGMDPOnOff, LGMDPOnOffParams
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus
from cdnf_ti.taichi_runtime import lanes

MP_TOL = 1e-4
SIZE = 64  #: two lane vectors: the lane path applies
#: Real clips and the frames compared: c38 alerts at 99 (its collision), nc03 peaks at 0.89 (no alert).
REAL_CLIPS = {"c38.mp4": (84, 112), "nc03.mp4": (60, 90)}
LAYOUTS = {"lanes": True, "pixels": False}


def engine(layout: str, **params) -> LGMDPOnOff:
    model = LGMDPOnOff(LGMDPOnOffParams(**params))
    model.fast = LAYOUTS[layout]
    return model


def compare(frames: list, layout: str, **params) -> dict:
    """Engine and reference on ``frames`` (or event bins): largest ``mp`` difference, alerts equal, alerts."""
    model = engine(layout, **params)
    r = checks.compare(model, lambda h, w: LGMDPOnOffReference(h, w, variant=model.params.variant,
                                                               params=model.params), frames, "mp", peak="mp")
    assert model._be.lane is LAYOUTS[layout]
    return r


def assert_agrees(r: dict) -> None:
    checks.assert_agrees(r, mp=MP_TOL)


@functools.cache
def stimulus(name: str) -> tuple:
    return tuple(basic_stimulus(name, height=SIZE, width=SIZE).frames())


@functools.cache
def real_frames(folder, clip: str) -> tuple:
    """Frames ``REAL_CLIPS[clip]`` of a development clip, BGR uint8 as read."""
    start, stop = REAL_CLIPS[clip]
    return tuple(checks.clip_frames(folder, clip, stop, start))


def event_bins(n: int, shape: tuple[int, int], seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` bins of ``(p_on, p_off)``: OFF events on the ring a dark square's edge swept in the bin (half-size
    ``3 + k^2 / 4`` px at bin ``k``, an accelerating approach) over sparse random ON/OFF events at threshold
    0.2, so some pixels have both polarities in one bin."""
    rng = np.random.default_rng(seed)
    h, w = shape

    def square(r: int) -> np.ndarray:
        box = np.zeros(shape, bool)
        box[max(h // 2 - r, 0):h // 2 + r, max(w // 2 - r, 0):w // 2 + r] = True
        return box

    out = []
    for k in range(n):
        on, off = (0.2 * rng.integers(0, 3, shape) * (rng.random(shape) < 0.05) for _ in "ab")
        ring = square(3 + k * k // 4) & ~square(3 + (k - 1) * (k - 1) // 4 if k else 3)
        out.append((on, np.minimum(off + 0.6 * ring, 1.0)))
    return out


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("name", BASIC_STIMULI)
def test_engine_matches_reference_on_basic_stimulus(name, layout):
    assert_agrees(compare(list(stimulus(name)), layout))


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("clip", REAL_CLIPS)
def test_engine_matches_reference_on_real_clip(shared_real, clip, layout):
    assert_agrees(compare(list(real_frames(shared_real, clip)), layout))


def test_engine_alerts_where_the_reference_does_on_a_real_collision(shared_real):
    r = compare(list(real_frames(shared_real, "c38.mp4")), "lanes")
    assert r["alerts"] > 0 and r["alerts_equal"], r


@pytest.mark.parametrize("layout", LAYOUTS)
def test_paper_variant_matches_reference_on_colour_frames(shared_real, layout):
    """``variant="paper"`` makes colour frames grey with ``COLOR_BGR2GRAY`` and outputs 0.5 at frame 0."""
    frames = list(real_frames(shared_real, "nc03.mp4"))
    assert_agrees(compare(frames, layout, variant="paper"))
    assert engine(layout, variant="paper").run(frames[:1]).output[0] == 0.5


@pytest.mark.parametrize("layout", LAYOUTS)
def test_engine_matches_reference_on_event_bins(layout):
    r = compare(event_bins(12, (48, 2 * lanes() + 6), seed=4), layout)
    assert_agrees(r)
    assert r["alerts"] > 0  # the approach's bins alert


def test_every_event_bin_is_a_full_step_including_bin_0():
    on, off = event_bins(1, (48, 2 * lanes()), seed=5)[0]
    trace = engine("lanes").run([(on, off)])
    assert trace.n_frames == 1 and trace.diagnostics["sum_G"][0] > 0 and trace.output[0] > 0.5


def test_frame_0_outputs_zero_as_the_authors_code():
    assert engine("lanes").run(list(stimulus("dark_looming"))[:1]).output[0] == 0.0


@pytest.mark.parametrize("layout", LAYOUTS)
def test_engine_follows_changed_parameters(layout):
    """A narrower normalisation Gaussian (a compile-time radius) and no contrast pathway, as the reference."""
    assert_agrees(compare(list(stimulus("dark_translating")), layout, gauss_size=5, gauss_sigma=2.0, alpha_3=0.0))


def test_a_frame_smaller_than_the_gaussian_is_refused():
    with pytest.raises(UserError, match="at least 9x9"):
        engine("lanes").step(np.zeros((8, 70), np.uint8))


def test_model_is_registered_by_its_class():
    assert MODELS["lgmd_p_on_off"] is LGMDPOnOff
    assert LGMDPOnOff().alert_rule().rule == "mp >= 0.9"
