"""kernels/pooling.py: window sums along columns and rows, and the separable box sum, against NumPy."""
from __future__ import annotations

import numpy as np
import pytest

from cdnf_ti.taichi_runtime import dsl, kernels


def numpy_box_sum(x: np.ndarray, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    """``out(y, x) = sum x(y + r0 .. y + r1, x + c0 .. x + c1)``, zero outside, by explicit float64 loops."""
    h, w = x.shape
    out = np.zeros((h, w))
    for y in range(h):
        for c in range(w):
            rows = slice(max(y + r0, 0), max(min(y + r1, h - 1) + 1, 0))
            cols = slice(max(c + c0, 0), max(min(c + c1, w - 1) + 1, 0))
            out[y, c] = x[rows, cols].astype(np.float64).sum()
    return out


def engine_box_sum(x: np.ndarray, r0: int, r1: int, c0: int, c1: int, sign: float = 1.0) -> np.ndarray:
    ti = dsl()
    src, tmp, dst = (ti.ndarray(ti.f32, x.shape) for _ in range(3))
    src.from_numpy(x.astype(np.float32))
    kernels("pooling").box_sum(src, tmp, dst, r0, r1, c0, c1, sign)
    return dst.to_numpy()


@pytest.mark.parametrize("window", [(-19, 20, -49, 0), (-19, 20, 1, 50), (-49, 0, -19, 20), (1, 50, -19, 20)])
def test_half_plane_windows_match_numpy_sums(window):
    x = np.random.default_rng(3).normal(size=(37, 61)).astype(np.float32)
    np.testing.assert_allclose(engine_box_sum(x, *window), numpy_box_sum(x, *window), rtol=0, atol=2e-5)


def test_a_window_wider_than_the_array_sums_the_whole_line():
    x = np.random.default_rng(4).random((5, 7)).astype(np.float32)
    np.testing.assert_allclose(engine_box_sum(x, -9, 9, -9, 9), np.full(x.shape, x.astype(np.float64).sum()),
                               rtol=1e-6)


def test_a_window_entirely_outside_the_array_is_zero():
    x = np.ones((6, 8), np.float32)
    assert not engine_box_sum(x, 0, 0, 8, 12).any()
    assert not engine_box_sum(x, -12, -6, 0, 0).any()


def test_the_sign_scales_the_sum():
    x = np.random.default_rng(5).random((9, 11)).astype(np.float32)
    np.testing.assert_allclose(engine_box_sum(x, -1, 2, 0, 3, -1.0), -numpy_box_sum(x, -1, 2, 0, 3), atol=1e-6)


def test_a_small_window_beside_large_values_keeps_its_digits():
    # a float32 prefix sum would lose the unit window's value against the 1e6 total before it
    x = np.zeros((4, 300), np.float32)
    x[:, :100] = 1.0e4
    x[:, 250] = 1.0e-3
    out = engine_box_sum(x, 0, 0, -2, 2)
    np.testing.assert_allclose(out[:, 248:253], 1.0e-3, rtol=1e-6)


def engine_lane_box_sum(x: np.ndarray, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    from cdnf_ti.kernels.pooling import ghost_elements, lane_layout
    from cdnf_ti.taichi_runtime import lanes

    L = lanes()
    C, P = kernels("common"), kernels("pooling")
    h, w = x.shape
    g = ghost_elements(max(abs(c0), abs(c1)) + 1, L)
    e1, nb = lane_layout(w, L, g)
    flat = np.zeros((h, nb * L), np.float32)
    flat[:, g * L: g * L + w] = x
    src, tmp, lp, dst = (C.lane_array(H=h, NB=nb) for _ in range(4))
    src.from_numpy(flat.reshape(h, nb, L))
    P.lane_box_sum(src, tmp, lp, dst, r0, r1, c0, c1, g)
    return dst.to_numpy().reshape(h, nb * L)[:, g * L: g * L + w]


@pytest.mark.parametrize("window", [(-19, 20, -49, 0), (-19, 20, 1, 50), (-49, 0, -19, 20), (1, 50, -19, 20),
                                    (0, 0, -3, 70), (-2, 1, -64, -33)])
@pytest.mark.parametrize("width", [5, 61, 130])
def test_lane_windows_match_numpy_sums(window, width):
    x = np.random.default_rng(width).normal(size=(23, width)).astype(np.float32)
    np.testing.assert_allclose(engine_lane_box_sum(x, *window), numpy_box_sum(x, *window), rtol=0, atol=2e-4)


def test_a_small_lane_window_beside_large_values_keeps_its_digits():
    x = np.zeros((3, 300), np.float32)
    x[:, :100] = 1.0e4
    x[:, 250] = 1.0e-3
    out = engine_lane_box_sum(x, 0, 0, -2, 2)
    np.testing.assert_allclose(out[:, 248:253], 1.0e-3, rtol=1e-6)
