"""Kernels compiled with explicit vector types (``taichi_runtime.vector_kernel``, C-DNF's lane solves):
the lane helpers they use in place of ``.any()``/``ti.abs``, and the compile option they switch."""

import numpy as np

from cdnf_ti.taichi_runtime import dsl, kernels, scalar_kernel, vector_kernel

ti = dsl()


def _cases(lanes: int) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of lane vectors: equal, then differing in exactly one lane (each position once)."""
    rng = np.random.default_rng(lanes)
    a = rng.normal(size=(lanes + 1, lanes)).astype(np.float32)
    b = a.copy()
    for k in range(lanes):
        b[k + 1, k] += 0.5
    return a, b


def test_any_lane_sees_a_difference_in_any_single_lane():
    C = kernels("common")
    LANES, any_lane = C.LANES, C.any_lane

    V = ti.types.vector(LANES, ti.f32)

    @vector_kernel
    @ti.kernel
    def differs(a: ti.types.ndarray(dtype=V, ndim=1), b: ti.types.ndarray(dtype=V, ndim=1),
                out: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        for e in range(a.shape[0]):
            out[e] = ti.select(any_lane(a[e] != b[e]), 1, 0)

    a, b = _cases(LANES)
    xa, xb = ti.ndarray(V, a.shape[0]), ti.ndarray(V, a.shape[0])
    xa.from_numpy(a)
    xb.from_numpy(b)
    out = np.full(a.shape[0], -1, np.int32)
    differs(xa, xb, out)
    np.testing.assert_array_equal(out, (a != b).any(axis=1).astype(np.int32))  # [0, 1, 1, ..., 1]


def test_lane_abs_is_the_absolute_value_of_every_lane():
    C = kernels("common")
    LANES, lane_abs = C.LANES, C.lane_abs

    V = ti.types.vector(LANES, ti.f32)

    @vector_kernel
    @ti.kernel
    def absolute(a: ti.types.ndarray(dtype=V, ndim=1), out: ti.types.ndarray(dtype=V, ndim=1)):
        for e in range(a.shape[0]):
            out[e] = lane_abs(a[e])

    a, _ = _cases(LANES)
    xa, out = ti.ndarray(V, a.shape[0]), ti.ndarray(V, a.shape[0])
    xa.from_numpy(a)
    absolute(xa, out)
    np.testing.assert_array_equal(out.to_numpy(), np.abs(a))


def test_vector_kernel_restores_the_compile_option_for_the_kernels_compiled_after_it():
    """A kernel of the usual kind (a ``Vector.field``, unary minus and ``ti.abs`` on vectors: constructs
    that only compile scalarised) still compiles and runs after a vector kernel compiled."""
    LANES = kernels("common").LANES

    V = ti.types.vector(LANES, ti.f32)

    @vector_kernel
    @ti.kernel
    def scale(a: ti.types.ndarray(dtype=V, ndim=1), k: ti.template()):
        for e in range(a.shape[0]):
            a[e] = a[e] * k

    x = ti.ndarray(V, 3)
    x.fill(1.5)
    scale(x, 2)
    scale(x, 3)  # another instance (template value), compiled the same way
    scale(x, 2)
    np.testing.assert_array_equal(x.to_numpy(), np.full((3, LANES), 18.0, np.float32))
    assert ti.lang.impl.current_cfg().real_matrix_scalarize

    f = ti.Vector.field(4, ti.f32, shape=2)

    @ti.kernel
    def negate_abs():
        for i in f:
            f[i] = -ti.abs(f[i] - 1.0)

    negate_abs()
    np.testing.assert_array_equal(f.to_numpy(), np.full((2, 4), -1.0, np.float32))


def test_compiling_a_kernel_puts_back_the_compile_option_it_found():
    """``vector_kernel``/``scalar_kernel`` restore the option's previous value, not a fixed one."""
    LANES = kernels("common").LANES
    V = ti.types.vector(LANES, ti.f32)
    cfg = ti.lang.impl.current_cfg()

    @vector_kernel
    @ti.kernel
    def twice(a: ti.types.ndarray(dtype=V, ndim=1)):
        for e in range(a.shape[0]):
            a[e] = a[e] * 2.0

    @scalar_kernel
    @ti.kernel
    def add_one(a: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for e in range(a.shape[0]):
            a[e] = a[e] + 1.0

    before = cfg.real_matrix_scalarize
    try:
        cfg.real_matrix_scalarize = False
        x, y = ti.ndarray(V, 2), np.zeros(3, np.float32)
        x.fill(1.0)
        twice(x)
        assert cfg.real_matrix_scalarize is False
        add_one(y)  # compiled scalarised, and the option is False again after it
        assert cfg.real_matrix_scalarize is False
    finally:
        cfg.real_matrix_scalarize = before
    np.testing.assert_array_equal(x.to_numpy(), np.full((2, LANES), 2.0, np.float32))
    np.testing.assert_array_equal(y, np.ones(3, np.float32))
    assert twice.scalarize is False and add_one.scalarize is True


def test_two_threads_compile_vector_and_scalar_kernels_each_in_its_own_mode():
    """A scalar kernel compiled while another thread compiles vector kernels still compiles scalarised:
    unary minus on a vector, below, aborts the compilation of a vector kernel (tests/test_compiler_workarounds.py)."""
    import threading

    LANES = kernels("common").LANES
    V = ti.types.vector(LANES, ti.f32)
    V4 = ti.types.vector(4, ti.f32)

    @scalar_kernel
    @ti.kernel
    def negate(a: ti.types.ndarray(dtype=V4, ndim=1), k: ti.template()):
        for i in range(a.shape[0]):
            a[i] = -(a[i] + k)

    @vector_kernel
    @ti.kernel
    def scale(a: ti.types.ndarray(dtype=V, ndim=1), k: ti.template()):
        for e in range(a.shape[0]):
            a[e] = a[e] * k

    x, y = ti.ndarray(V, 2), ti.ndarray(V4, 2)
    x.fill(1.0)
    y.fill(0.0)
    errors = []

    def run(fn, count):
        try:
            for k in range(count):
                fn(k)
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=run, args=(lambda k: scale(x, k + 2), 4)),
               threading.Thread(target=run, args=(lambda k: negate(y, k), 4))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    np.testing.assert_array_equal(x.to_numpy(), np.full((2, LANES), 120.0, np.float32))  # 2 * 3 * 4 * 5
    np.testing.assert_array_equal(y.to_numpy(), np.full((2, 4), -2.0, np.float32))  # -(-(-(0+0)+1)+2)+3)
