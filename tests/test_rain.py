"""Synthetic rain: droplet statistics measured from generated layers, blend, SNR, determinism, kernels vs NumPy."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from cdnf_ti.stimuli.rain import (
    RainParams,
    RainyFrames,
    blur_numpy,
    draw_drops,
    rain_frame_numpy,
    snr_db,
    streak_layer_numpy,
)

SHAPE = (240, 426)


def components(layer: np.ndarray):
    """Connected streaks (8-connectivity) of an unblurred layer: (count, stats)."""
    n, _, stats, _ = cv2.connectedComponentsWithStats((layer > 0).astype(np.uint8), connectivity=8)
    return n - 1, stats[1:]


def test_default_droplet_count_is_500_at_426x240_and_scales_with_area():
    p = RainParams()
    assert p.drops_for((240, 426)) == 500
    assert p.drops_for((480, 852)) == 2000
    assert p.drops_for((120, 213)) == 125
    assert RainParams(drops=37).drops_for((240, 426)) == 37


def test_droplet_count_measured_from_layer():
    # sparse rain: streaks rarely touch, so connected components count droplets
    p = RainParams(drops=60)
    layer = next(RainyFrames([], p, seed=3).layers(SHAPE, blur=False))
    drops = draw_drops(SHAPE, p, 3, 0)
    inside = drops.row0 + p.length <= SHAPE[0]
    n, _ = components(layer)
    assert n <= 60 and n >= 60 - 4
    # every droplet drew its own pixels: total pixels = 8 per full streak (no overlap at this density)
    full = int(inside.sum())
    assert np.count_nonzero(layer) >= 8 * full - 8 * (60 - n)


def test_streaks_are_8px_long_1px_wide_and_within_the_angle_range():
    p = RainParams(drops=40, max_angle_deg=10.0)
    layer = next(RainyFrames([], p, seed=11).layers(SHAPE, blur=False))
    n, stats = components(layer)
    full = [s for s in stats if s[cv2.CC_STAT_TOP] + s[cv2.CC_STAT_HEIGHT] < SHAPE[0]]
    singles = [s for s in full if s[cv2.CC_STAT_AREA] == p.length]  # isolated full streaks
    assert len(singles) >= 30
    max_dx = math.tan(math.radians(10.0)) * (p.length - 1)
    for s in singles:
        assert s[cv2.CC_STAT_HEIGHT] == p.length  # 8 rows downward
        assert s[cv2.CC_STAT_WIDTH] <= 1 + math.ceil(max_dx)  # 1 px per row, slight slant
    # 1 px wide: each row of a streak holds one pixel
    lab = cv2.connectedComponentsWithStats((layer > 0).astype(np.uint8), connectivity=8)[1]
    for idx, s in enumerate(stats, start=1):
        if s[cv2.CC_STAT_AREA] == p.length and s[cv2.CC_STAT_HEIGHT] == p.length:
            rows = np.nonzero(lab == idx)[0]
            assert np.all(np.bincount(rows)[rows.min():] == 1)


def test_droplet_angles_are_uniform_within_the_slight_deviation():
    p = RainParams()
    angles = np.concatenate([draw_drops(SHAPE, p, 0, k).angle_deg for k in range(4)])
    assert angles.min() >= -p.max_angle_deg and angles.max() <= p.max_angle_deg
    assert angles.min() < -0.9 * p.max_angle_deg and angles.max() > 0.9 * p.max_angle_deg
    assert abs(angles.mean()) < 1.0


def test_start_points_are_uniform_over_the_frame():
    d = draw_drops(SHAPE, RainParams(), 5, 0)
    assert d.row0.min() >= 0 and d.row0.max() < SHAPE[0]
    assert d.col0.min() >= 0 and d.col0.max() < SHAPE[1]
    # quadrant counts within 5 sigma of 125 each
    q = np.histogram2d(d.row0, d.col0, bins=2, range=[[0, SHAPE[0]], [0, SHAPE[1]]])[0]
    assert np.all(np.abs(q - 125) < 5 * math.sqrt(125 * 0.75))


def test_streak_pixels_are_grey():
    p = RainParams(drops=50)
    layer = next(RainyFrames([], p, seed=1).layers(SHAPE, blur=False))
    vals = np.unique(layer)
    np.testing.assert_allclose(vals, [0.0, np.float32(p.grey)])


def test_blur_is_a_normalised_gaussian_that_keeps_the_rain_mass():
    p = RainParams(drops=100)
    r = RainyFrames([], p, seed=2)
    raw = next(r.layers(SHAPE, blur=False))
    blurred = next(RainyFrames([], p, seed=2).layers(SHAPE, blur=True))
    # mirrored borders keep the total up to streaks touching the edge
    assert blurred.sum() == pytest.approx(raw.sum(), rel=0.05)
    assert blurred.max() < raw.max()
    g = p.blur_kernel()
    assert g.sum() == pytest.approx(1.0) and g.size == 7 and np.argmax(g) == 3


def test_blend_weight_is_half_on_a_black_frame():
    # on black the clip never acts: out = 0.5 * rain exactly
    p = RainParams()
    black = np.zeros(SHAPE, np.float32)
    out = next(iter(RainyFrames([black], p, seed=9)))
    layer = next(RainyFrames([], p, seed=9).layers(SHAPE))
    np.testing.assert_allclose(out, p.weight * layer, atol=1e-6)


def test_blend_clips_to_one():
    white = np.ones((32, 48), np.float32)
    out = next(iter(RainyFrames([white], RainParams(drops=30), seed=0)))
    assert out.max() <= 1.0 and np.all(out == 1.0)


def test_snr_on_a_known_case():
    clean = np.full((10, 10), 0.5)
    rainy = clean.copy()
    rainy[0, :4] += 0.25  # noise energy 4 * 0.0625 = 0.25; signal 100 * 0.25 = 25
    assert snr_db(clean, rainy) == pytest.approx(20.0)
    u8 = (clean * 255).round().astype(np.uint8)
    assert snr_db(u8, u8) == math.inf


def test_per_frame_snr_matches_snr_db_and_video_snr_is_their_mean():
    rng = np.random.default_rng(0)
    frames = [rng.uniform(0.2, 0.6, size=(60, 80)).astype(np.float32) for _ in range(3)]
    r = RainyFrames(frames, RainParams(drops=40), seed=4)
    outs = list(r)
    expect = [snr_db(f, o) for f, o in zip(frames, outs)]
    np.testing.assert_allclose(r.snr_per_frame, expect, rtol=1e-5)
    assert r.snr_db == pytest.approx(np.mean(expect), rel=1e-6)


def test_frames_with_no_visible_rain_are_left_out_of_the_mean_snr():
    white = np.ones((32, 48), np.float32)
    grey = np.full((32, 48), 0.4, np.float32)
    r = RainyFrames([white, grey], RainParams(drops=30), seed=0)
    list(r)
    assert r.snr_per_frame[0] == math.inf and math.isfinite(r.snr_per_frame[1])
    assert r.snr_db == r.snr_per_frame[1]


def test_same_seed_same_rain_different_seed_different_rain():
    frame = np.full(SHAPE, 0.3, np.float32)
    a = list(RainyFrames([frame, frame], seed=5))
    b = list(RainyFrames([frame, frame], seed=5))
    c = list(RainyFrames([frame, frame], seed=6))
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[0], c[0])
    assert not np.array_equal(a[0], a[1])  # a fresh layer per frame


def test_taichi_rain_matches_numpy_reference_on_stimulus_and_video_like_frames():
    from conftest import small_stimulus

    stim = small_stimulus("light_looming", size=120)
    rng = np.random.default_rng(1)
    video = [cv2.GaussianBlur(rng.integers(0, 256, (90, 160), dtype=np.uint8), (9, 9), 3) for _ in range(2)]
    for frames in ([stim.frame(0), stim.frame(40)], video):
        p = RainParams(drops=300)
        tk = list(RainyFrames(frames, p, seed=2))
        ref = list(RainyFrames(frames, p, seed=2, backend="numpy"))
        for k, (f, g) in enumerate(zip(tk, ref)):
            np.testing.assert_allclose(f, g, atol=2e-6)
            np.testing.assert_allclose(f, rain_frame_numpy(frames[k], p, 2, k), atol=2e-6)


def test_streak_and_blur_kernels_match_numpy_reference():
    p = RainParams(drops=200, width=2, max_angle_deg=20)
    r = RainyFrames([], p, seed=8)
    raw = next(r.layers(SHAPE, blur=False))
    ref = streak_layer_numpy(SHAPE, draw_drops(SHAPE, p, 8, 0), p)
    np.testing.assert_array_equal(raw, ref.astype(np.float32))
    blurred = next(RainyFrames([], p, seed=8).layers(SHAPE))
    np.testing.assert_allclose(blurred, blur_numpy(ref, p), atol=1e-6)


def test_bgr_uint8_input_is_converted_to_grey():
    bgr = np.zeros((40, 60, 3), np.uint8)
    bgr[..., 1] = 100
    out = next(iter(RainyFrames([bgr], RainParams(drops=0))))
    np.testing.assert_allclose(out, np.full((40, 60), round(100 * 0.587) / 255, np.float32), atol=1 / 255)


def test_rain_params_reject_bad_values():
    for kw in ({"drops": -1}, {"length": 0}, {"width": 0}, {"max_angle_deg": 95}, {"grey": 2}, {"weight": -1}):
        with pytest.raises(ValueError):
            RainParams(**kw)


def test_default_rain_snr_on_real_clip_is_near_20_db(shared_real):
    if shared_real is None:
        pytest.skip("the development dashcam clips are not present")
    from cdnf_ti.frames import iter_grey, open_source

    src = open_source(shared_real / "nc03.mp4")
    r = RainyFrames(iter_grey(src), seed=0)
    for _ in r:
        pass
    assert 15.0 < r.snr_db < 25.0
