"""Small and odd frame sizes: the comparison models match their float64 references on frames a few
columns wide (single border columns, the smallest 2x2 frames), which run on the pixel layout."""

import numpy as np
import pytest

from cdnf_ti.models import MODELS, create_model

SIZES = [(2, 2), (2, 3), (5, 17), (4, 18), (3, 21), (6, 37), (9, 70)]


def moving_noise(h: int, w: int, seed: int, n: int = 6) -> list[np.ndarray]:
    """A bright square growing from the top-left corner over faint noise: every pixel changes,
    the border columns and rows included."""
    rng = np.random.default_rng(seed)
    frames = []
    for t in range(n):
        g = rng.normal(110, 3, (h, w))
        g[: t + 1, : 2 * t + 1] += 120
        frames.append(np.clip(np.rint(g), 0, 255).astype(np.uint8))
    return frames


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[1]}x{s[0]}")
@pytest.mark.parametrize("model", ["lgmd1", "lgmd2", "sdnf", "flgmd_onn"])
def test_taichi_matches_numpy_reference_at_every_frame_size(model, size):
    frames = moving_noise(*size, seed=sum(size))
    params = None
    if model in ("lgmd1", "flgmd_onn"):  # no FFI hold: the per-pixel layers run on every frame
        params = MODELS[model].params_type(t_ffi=1e9)
    a, b = create_model(model, params, backend="taichi"), create_model(model, params, backend="numpy")
    ta, nu = a.run(frames), b.run(frames)
    if "held" in nu.diagnostics:
        assert nu.diagnostics["held"].max() == 0  # the layers really run
    np.testing.assert_allclose(ta.output, nu.output, atol=1e-5, rtol=0)
    fa, fb = a.fields(), b.fields()
    for k in fb:
        scale = max(1.0, float(np.abs(fb[k]).max()))
        np.testing.assert_allclose(fa[k], fb[k], atol=1e-4 * scale, rtol=0, err_msg=k)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 7, 16, 32])
def test_run_max_is_the_largest_value_and_leaves_its_argument_unchanged(n):
    """``run_max`` (a tree of pairwise maxima, also the lane vectors' reduction) equals NumPy's max
    wherever the largest value sits, negatives and ties included, and its caller's vector is not changed."""
    from cdnf_ti.taichi_runtime import dsl, kernels

    run_max = kernels("common").run_max

    ti = dsl()

    @ti.kernel
    def reduce_rows(values: ti.types.ndarray(dtype=ti.f32, ndim=2), out: ti.types.ndarray(dtype=ti.f32, ndim=1),
                    after: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        for r in range(values.shape[0]):
            v = ti.Vector([values[r, c] for c in ti.static(range(n))], dt=ti.f32)
            out[r] = run_max(v, n)
            for c in ti.static(range(n)):
                after[r, c] = v[c]

    rng = np.random.default_rng(n)
    rows = [np.full(n, -1.0)] + [np.where(np.arange(n) == k, 2.5, -rng.random(n)) for k in range(n)]
    rows += [rng.normal(size=n) for _ in range(8)] + [np.full(n, 0.25)]
    values = np.array(rows, dtype=np.float32)
    out = np.zeros(len(values), np.float32)
    after = np.zeros_like(values)
    reduce_rows(values, out, after)
    np.testing.assert_array_equal(out, values.max(axis=1))
    np.testing.assert_array_equal(after, values)
