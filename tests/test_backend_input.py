"""The one backend's input: every launch of a frame reads the same array, and stepping keeps nothing alive
per frame, even when the caller holds every frame (a benchmark does), under either compiler."""
import gc

import numpy as np

from cdnf_ti import create_model


def _frames(n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, (48, 64), dtype=np.uint8) for _ in range(n)]


def _objects_kept(step, inputs) -> int:
    """Objects alive after ``step`` over ``inputs`` that were not before (garbage collected both times)."""
    gc.collect()
    before = len(gc.get_objects())
    for x in inputs:
        step(x)
    gc.collect()
    return len(gc.get_objects()) - before


def test_stepping_frames_the_caller_holds_keeps_no_object_per_frame():
    model, frames = create_model("lgmd1"), _frames(60)
    for f in frames[:10]:
        model.step(f)  # compiled, warmed up
    assert _objects_kept(model.step, frames[10:]) < 10  # 50 frames held: not one object each


def test_stepping_event_bins_the_caller_holds_keeps_no_object_per_bin():
    model, bins = create_model("lgmd1"), [(f / 255.0, f[::-1] / 255.0) for f in _frames(60, seed=1)]
    for b in bins[:10]:
        model.step_on_off(*b)
    assert _objects_kept(lambda b: model.step_on_off(*b), bins[10:]) < 10


def test_a_frame_changed_after_its_step_does_not_change_the_trace():
    frames = _frames(12, seed=2)
    held, copied = create_model("lgmd1"), create_model("lgmd1")
    out_held = []
    for f in frames:
        out_held.append(held.step(f).output)
        f[:] = 0  # the caller reuses its buffer
    out_copied = [copied.step(f.copy()).output for f in _frames(12, seed=2)]
    assert out_held == out_copied


def test_the_runtime_says_whether_the_compiler_keeps_an_entry_per_new_launch_array():
    from cdnf_ti.taichi_runtime import caches_launch_arguments, dsl, ensure_taichi

    ensure_taichi("cpu")
    ti = dsl()

    @ti.kernel
    def total(a: ti.types.ndarray()) -> ti.f32:
        s = 0.0
        for i in range(a.shape[0]):
            s += a[i]
        return s

    arrays = [np.full(8, k, np.float32) for k in range(40)]  # held, as a benchmark holds its frames
    total(arrays[0])  # compiled
    kept = _objects_kept(total, arrays[1:])
    assert (kept >= len(arrays) - 1) == caches_launch_arguments()
