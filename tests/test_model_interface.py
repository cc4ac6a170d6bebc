"""The shared model interface: registry, one-pass runs of several models, trace timing."""
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti.models import MODELS, base, create_model
from cdnf_ti.models.base import run_models


def test_one_pass_over_several_models_equals_separate_runs():
    frames = list(small_stimulus("light_looming", size=64).frames())
    names = list(MODELS)
    together = run_models([create_model(n) for n in names], iter(frames))
    for name, tr in zip(names, together):
        alone = create_model(name).run(frames)
        assert np.array_equal(tr.output, alone.output), name
        assert np.array_equal(tr.spike, alone.spike), name


class _Clock:
    """A stand-in clock: seconds advance only when a step says so."""

    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


class _LateCompiler(base.Model):
    """A test double of a model that compiles kernels on a later frame (as oLGMD does on its first
    active frame, index 2): building its backend takes 5 s, a compiling step 100 s, any other 0.25 s
    (a 4 frames/s model), all on a stand-in clock."""

    name = "late_compiler"
    BACKENDS = ("numpy",)

    def __init__(self, clock: _Clock, compile_at: tuple[int, ...]):
        self.clock, self.compile_at, self.compiled = clock, compile_at, 0
        super().__init__(backend="numpy")

    def _numpy_backend(self, shape):
        self.clock.now += 5.0
        return SimpleNamespace(shape=shape, load=lambda grey, first: None, reset=lambda: None, fields=dict)

    def compile_count(self) -> int:
        return self.compiled

    def _step(self, t, grey, loaded):
        if t in self.compile_at:
            self.compiled += 1
            self.clock.now += 100.0
        else:
            self.clock.now += 0.25
        return base.StepResult(t, 0.0, False)


@pytest.mark.parametrize("compile_at", [(0,), (2,), (1, 5)], ids=["first", "third", "second-and-sixth"])
def test_steps_that_compile_are_left_out_of_the_time_whenever_they_happen(compile_at):
    clock = _Clock()
    frames = [np.zeros((8, 8), np.uint8)] * 10
    (tr,) = run_models([_LateCompiler(clock, compile_at)], iter(frames), clock=clock)
    setup = {0, *compile_at}  # the first step builds the backend
    assert tr.timed_frames == 10 - len(setup)
    assert tr.seconds == pytest.approx(0.25 * tr.timed_frames)
    assert tr.fps == pytest.approx(4.0)
    assert tr.compile_seconds == pytest.approx(5.0 + 100.0 * len(compile_at) + 0.25 * (0 not in compile_at))


def test_a_trace_with_no_step_free_of_set_up_has_no_speed():
    clock = _Clock()
    (tr,) = run_models([_LateCompiler(clock, (0, 1))], iter([np.zeros((8, 8), np.uint8)] * 2), clock=clock)
    assert tr.timed_frames == 0 and np.isnan(tr.fps)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_every_registered_model_has_the_common_result_fields(name):
    model = create_model(name)
    r = model.step(np.zeros((32, 40), np.uint8))
    assert r.t == 0 and isinstance(r.output, float) and isinstance(r.spike, bool)
    assert isinstance(r.diagnostics, dict)
    model.step(np.full((32, 40), 200, np.uint8))
    fields = model.fields()
    assert fields and all(v.shape == (32, 40) for v in fields.values())
