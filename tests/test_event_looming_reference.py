"""The float64 event-based looming detector reference (cdnf_ti.event_looming_reference), its event binning,
and the reader of the authors' event layout (t in ms beside sim_data.npz).

The authors' PyTorch model runs only when ``CDNF_TI_EVENT_LOOMING_REPO`` names a checkout of
FabianSchubert/Bio-Inspired-Event-Based-Looming-Object-Detection-for-Automotive-Collision-Avoidance and torch
is installed (docs/figures/compare_event_looming.py prints the full table).
"""
from __future__ import annotations

import functools
import importlib.util
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from cdnf_ti.errors import InputError, UserError
from cdnf_ti.event_looming_reference import (
    EventLoomingParams,
    EventLoomingReference,
    flow_kernels,
    frame_bins,
    signed_bins,
)
from cdnf_ti.events.readers import open_events
from cdnf_ti.events.types import EVENT_DTYPE
from cdnf_ti.stimuli.basic import basic_stimulus

SIZE = 96
REPO_ENV = "CDNF_TI_EVENT_LOOMING_REPO"


@functools.cache
def stimulus_bins(name: str) -> tuple:
    st = basic_stimulus(name, height=SIZE, width=SIZE)
    return tuple(frame_bins(st.frames(), st.fps))


@functools.cache
def response(name: str, variant: str = "code") -> dict:
    return EventLoomingReference(SIZE, SIZE, variant=variant).run(stimulus_bins(name))


def first_alert(r: dict):
    a = np.flatnonzero(r["alert"])
    return int(a[0]) if a.size else None


def events(rows) -> np.ndarray:
    """(t µs, x, y, p) rows -> an event chunk."""
    out = np.zeros(len(rows), dtype=EVENT_DTYPE)
    for i, (t, x, y, p) in enumerate(rows):
        out[i] = (t, x, y, p)
    return out


@pytest.mark.parametrize("variant", ["code", "paper"])
@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_looming_alerts_in_the_second_half_of_the_approach(variant, polarity):
    r = response(f"{polarity}_looming", variant)
    assert first_alert(r) is not None and first_alert(r) >= len(r["output"]) // 2


@pytest.mark.parametrize("variant", ["code", "paper"])
@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_receding_drives_both_halves_inwards_and_never_alerts(variant, polarity):
    r = response(f"{polarity}_receding", variant)
    assert first_alert(r) is None
    assert r["left"].min() < 0 and r["right"].min() < 0


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_translating_bar_never_alerts(polarity):
    assert first_alert(response(f"{polarity}_translating")) is None


def test_expansion_is_outward_on_both_halves():
    r = response("dark_looming")
    assert r["left"].max() > 0 and r["right"].max() > 0


def test_a_rightward_step_gives_positive_horizontal_flow():
    prev, cur = np.zeros((9, 9), np.int8), np.zeros((9, 9), np.int8)
    prev[4, 4], cur[4, 5] = 1, 1
    ref = EventLoomingReference(9, 9)
    ref.step(prev)
    ref.step(cur)
    assert ref.layers["vx"][4, 5] > 0 and ref.layers["vy"][4, 5] == pytest.approx(0.0, abs=1e-15)


def test_on_and_off_events_make_separate_flows():
    """An OFF event next to an earlier ON event is no motion: the polarities are not mixed."""
    prev, cur = np.zeros((9, 9), np.int8), np.zeros((9, 9), np.int8)
    prev[4, 4], cur[4, 5] = 1, -1
    ref = EventLoomingReference(9, 9)
    ref.step(prev)
    ref.step(cur)
    assert not ref.layers["vx"].any() and not ref.layers["vy"].any()


def test_flow_kernels_are_a_unit_gaussian_and_its_first_moments():
    k_n, k_x, k_y = flow_kernels(2, 0.3)
    assert k_n.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(k_x, -k_x[:, ::-1], atol=0)
    np.testing.assert_allclose(k_y, k_x.T, atol=0)
    assert k_x[2, 3] > 0  # one column to the right


def test_code_output_is_r_minus_the_threshold():
    r = EventLoomingReference(SIZE, SIZE, params=EventLoomingParams(out_th=0.5)).run(stimulus_bins("dark_looming"))
    np.testing.assert_allclose(r["output"], r["r"] - 0.5, rtol=0, atol=0)


def test_paper_output_is_the_leaky_integral_of_r():
    r = response("dark_looming", "paper")
    alpha, v = np.exp(-1.0 / 50.0), 0.0
    for t in range(len(r["r"])):
        v = alpha * v + (1 - alpha) * r["r"][t]
        assert r["output"][t] == pytest.approx(v, rel=1e-12, abs=1e-15)


def test_signed_bins_keep_each_pixel_s_last_event_and_yield_empty_bins():
    ev = events([(100, 1, 0, 1), (900, 1, 0, 0), (950, 2, 0, 1), (2500, 0, 1, 0), (2600, 5, 5, 1)])
    bins = list(signed_bins([ev], (2, 3), 1000.0))
    assert len(bins) == 3
    np.testing.assert_array_equal(bins[0], [[0, -1, 1], [0, 0, 0]])  # (5, 5) is outside the sensor
    np.testing.assert_array_equal(bins[1], 0)
    np.testing.assert_array_equal(bins[2], [[0, 0, 0], [-1, 0, 0]])


def test_signed_bins_stop_at_n_bins():
    ev = events([(t * 1000, 0, 0, 1) for t in range(10)])
    assert len(list(signed_bins([ev], (1, 1), 1000.0, n_bins=4))) == 4


def test_frame_bins_give_one_map_per_frame_the_first_empty():
    st = basic_stimulus("dark_looming", height=SIZE, width=SIZE)
    bins = stimulus_bins("dark_looming")
    assert len(bins) == len(list(st.frames()))
    assert not bins[0].any() and bins[-1].any()
    assert set(np.unique(bins[-1])) <= {-1, 0, 1}


def test_their_layout_reads_with_t_in_ms(tmp_path):
    a = np.zeros(3, dtype=[("t", "<u4"), ("x", "<u2"), ("y", "<u2"), ("p", "<u2")])
    a["t"], a["x"], a["y"], a["p"] = [0, 10, 25], [1, 2, 3], [4, 5, 6], [0, 1, 1]
    np.save(tmp_path / "events.npy", a)
    plain = np.concatenate(list(open_events(tmp_path / "events.npy").chunks()))
    np.savez(tmp_path / "sim_data.npz", coll_type=np.array("cars"), t_end=np.array(30.0), dt=np.array(10.0))
    ev = np.concatenate(list(open_events(tmp_path / "events.npy").chunks()))
    np.testing.assert_array_equal(plain["t"], [0, 10, 25])  # without the sidecar: µs, as before
    np.testing.assert_array_equal(ev["t"], [0, 10_000, 25_000])
    np.testing.assert_array_equal(ev["p"], [0, 1, 1])
    np.testing.assert_array_equal(ev["x"], a["x"])


def test_a_sidecar_without_t_end_and_dt_leaves_t_in_us(tmp_path):
    a = np.zeros(1, dtype=[("t", "<u4"), ("x", "<u2"), ("y", "<u2"), ("p", "<u2")])
    a["t"] = 7
    np.save(tmp_path / "events.npy", a)
    np.savez(tmp_path / "sim_data.npz", other=np.array(1))
    assert np.concatenate(list(open_events(tmp_path / "events.npy").chunks()))["t"][0] == 7


def test_streaming_after_reset_repeats_the_run():
    ref = EventLoomingReference(SIZE, SIZE, variant="paper")
    first = ref.run(stimulus_bins("dark_looming"))
    ref.reset()
    second = ref.run(stimulus_bins("dark_looming"))
    for name in first:
        np.testing.assert_array_equal(first[name], second[name])


def test_a_bin_output_does_not_depend_on_later_bins():
    prefix = EventLoomingReference(SIZE, SIZE).run(stimulus_bins("dark_looming")[:30])
    np.testing.assert_array_equal(prefix["output"], response("dark_looming")["output"][:30])


def test_bad_bins_are_one_line_input_errors_naming_the_bin():
    with pytest.raises(InputError, match="bin 0") as e:
        EventLoomingReference(SIZE, SIZE).step(np.zeros((SIZE, SIZE + 1)))
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("kw", [dict(variant="nope"), dict(height=1), dict(params=EventLoomingParams(dt=0.0))])
def test_bad_arguments_are_user_errors(kw):
    with pytest.raises(UserError):
        EventLoomingReference(**(dict(height=SIZE, width=SIZE) | kw))


@pytest.mark.skipif(not os.environ.get(REPO_ENV) or importlib.util.find_spec("torch") is None,
                    reason=f"{REPO_ENV} does not name a checkout of the authors' code, or torch is missing")
@pytest.mark.parametrize("name", ["dark_looming", "light_receding"])
def test_code_variant_equals_the_authors_pytorch_model(name):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "docs" / "figures"))
    import compare_event_looming as oracle

    theirs = oracle.load_authors(Path(os.environ[REPO_ENV]))
    bins = list(stimulus_bins(name))
    r = oracle.compare_bins(theirs, bins, bins)
    assert r["output"] < 1e-5 and r["lr_rel"] < 1e-5  # their model is float32
    assert r["first_theirs"] == r["first_ours"]
