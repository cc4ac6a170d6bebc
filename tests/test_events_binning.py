"""Binning events into per-bin ON/OFF counts, the problems it reports, and the counts-to-contrast mapping."""
from __future__ import annotations

import numpy as np
import pytest
from event_encoders import random_events

from cdnf_ti.events import EventReport, bin_events, checked, contrast_input
from cdnf_ti.events.types import EVENT_DTYPE

SIZE = (40, 30)


def chunked(ev: np.ndarray, n: int):
    return [ev[i:i + n] for i in range(0, ev.size, n)]


def histogram(ev: np.ndarray, size, bin_ms: float, n_bins: int, t0: float) -> np.ndarray:
    """Independent reference: np.add.at, one event at a time."""
    w, h = size
    out = np.zeros((n_bins, 2, h, w), dtype=np.int64)
    k = np.floor((ev["t"] - t0) / (bin_ms * 1000)).astype(int)
    np.add.at(out, (k, ev["p"].astype(int), ev["y"].astype(int), ev["x"].astype(int)), 1)
    return out


def test_bin_counts_equal_a_per_event_histogram_whatever_the_chunking():
    ev = random_events(20000, SIZE, duration_us=1_000_000, seed=0)
    t0 = np.floor(ev["t"][0] / 10_000) * 10_000
    n_bins = int((ev["t"][-1] - t0) // 10_000) + 1
    want = histogram(ev, SIZE, 10.0, n_bins, t0)
    for chunk in (97, 5000, ev.size):
        got = np.stack(list(bin_events(chunked(ev, chunk), SIZE, bin_ms=10.0)))
        np.testing.assert_array_equal(got, want)


def test_bins_start_at_multiples_of_the_bin_length_and_empty_bins_are_zero():
    ev = np.zeros(3, dtype=EVENT_DTYPE)
    ev["t"] = [70_000, 75_000, 175_000]  # bins of 33.333 ms: #2, #2, #5 on the clock -> 0, 0, 3 here
    ev["x"], ev["y"], ev["p"] = [1, 2, 3], [0, 0, 0], [1, 0, 1]
    bins = list(bin_events([ev], SIZE, bin_ms=100 / 3))
    assert len(bins) == 4
    assert [int(b.sum()) for b in bins] == [2, 0, 0, 1]
    assert bins[0][1, 0, 1] == 1 and bins[0][0, 0, 2] == 1 and bins[3][1, 0, 3] == 1


def test_events_outside_the_sensor_are_left_out_and_reported():
    ev = random_events(1000, SIZE, seed=1)
    ev["x"][10] = SIZE[0] + 5
    ev["y"][20] = SIZE[1]
    report = EventReport()
    total = sum(int(b.sum()) for b in bin_events(checked(chunked(ev, 300), SIZE, report), SIZE))
    assert total == ev.size - 2
    assert report.n_outside == 2 and report.first_outside == (10, SIZE[0] + 5, int(ev["y"][10]))
    assert "2 event(s) outside the 40x30 sensor" in report.problems()[0]


def test_timestamps_going_backwards_are_reported_and_binned_in_the_open_bin():
    ev = np.zeros(4, dtype=EVENT_DTYPE)
    ev["t"] = [0, 50_000, 10_000, 60_000]  # event 2 belongs to bin 0, which is closed when it arrives
    ev["x"] = [0, 1, 2, 3]
    report = EventReport()
    bins = list(bin_events(checked(chunked(ev, 2), SIZE, report), SIZE, bin_ms=40.0))
    assert report.n_backwards == 1 and report.first_backwards == (2, 10_000, 50_000)
    assert bins[0].sum() == 1 and bins[1].sum() == 3  # counted, in the bin being filled
    assert "timestamp earlier" in report.problems()[0]


def test_a_clean_recording_reports_no_problem():
    report = EventReport()
    ev = random_events(500, SIZE, seed=2)
    list(bin_events(checked([ev], SIZE, report), SIZE))
    assert report.problems() == [] and report.n_events == ev.size
    assert report.n_on == int(ev["p"].sum())


def test_contrast_is_threshold_times_count_capped_at_one():
    counts = np.zeros((2, 2, 3), dtype=np.int64)
    counts[1, 0, :] = [1, 3, 20]  # ON
    counts[0, 1, :] = [2, 0, 7]  # OFF
    p_on, p_off = contrast_input(counts, 0.15)
    np.testing.assert_allclose(p_on[0], [0.15, 0.45, 1.0])
    np.testing.assert_allclose(p_off[1], [0.30, 0.0, 1.0])
    assert not p_on[1].any() and not p_off[0].any()


def test_contrast_refuses_a_non_positive_threshold():
    with pytest.raises(ValueError):
        contrast_input(np.zeros((2, 2, 2)), 0.0)


def test_bins_of_a_numpy_recording_start_at_its_clock_zero(tmp_path):
    from cdnf_ti.events import open_event_source

    ev = random_events(200, SIZE, duration_us=400_000, seed=3)
    ev["t"] += 500_000  # a quiet first half second
    np.save(tmp_path / "ev.npy", ev)
    src = open_event_source(tmp_path / "ev.npy", SIZE, bin_ms=100.0)
    bins = list(src.counts())
    assert len(bins) == int(ev["t"][-1] // 100_000) + 1 and bins[0].sum() == 0
