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


def test_trace_time_and_fps_leave_out_the_slow_first_steps(monkeypatch):
    """The first steps allocate state and compile kernels (the LGMD family compiles its layers on
    frame 1): first steps that take 1000 s (on a stand-in clock) must not show in ``seconds`` or
    ``fps``; every later step must."""
    clock = SimpleNamespace(now=0.0)
    monkeypatch.setattr(base, "time", SimpleNamespace(perf_counter=lambda: clock.now))
    model = create_model("lgmd2")
    real_step, calls = model.step, []

    def step(frame):
        calls.append(len(calls))
        clock.now += 1000.0 if len(calls) <= base.WARMUP_STEPS else 0.25  # compiles, then a 4 frames/s model
        return real_step(frame)

    model.step = step
    tr = model.run(small_stimulus("dark_translating", size=48).frames())
    assert len(calls) == tr.n_frames > 2
    assert base.WARMUP_STEPS == 2
    assert tr.seconds == pytest.approx(0.25 * (tr.n_frames - 2))
    assert tr.fps == pytest.approx(4.0)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_every_registered_model_has_the_common_result_fields(name):
    model = create_model(name)
    r = model.step(np.zeros((32, 40), np.uint8))
    assert r.t == 0 and isinstance(r.output, float) and isinstance(r.spike, bool)
    assert isinstance(r.diagnostics, dict)
    model.step(np.full((32, 40), 200, np.uint8))
    fields = model.fields()
    assert fields and all(v.shape == (32, 40) for v in fields.values())
