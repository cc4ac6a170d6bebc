"""The shared model interface: registry, one-pass runs of several models, trace timing."""
import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti.models import MODELS, create_model
from cdnf_ti.models.base import run_models


def test_one_pass_over_several_models_equals_separate_runs():
    frames = list(small_stimulus("light_looming", size=64).frames())
    names = list(MODELS)
    together = run_models([create_model(n) for n in names], iter(frames))
    for name, tr in zip(names, together):
        alone = create_model(name).run(frames)
        assert np.array_equal(tr.output, alone.output), name
        assert np.array_equal(tr.spike, alone.spike), name


def test_trace_fps_excludes_the_first_frame():
    tr = create_model("lgmd2").run(small_stimulus("dark_translating", size=48).frames())
    assert tr.seconds > 0
    assert tr.fps == pytest.approx((tr.n_frames - 1) / tr.seconds)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_every_registered_model_has_the_common_result_fields(name):
    model = create_model(name)
    r = model.step(np.zeros((32, 40), np.uint8))
    assert r.t == 0 and isinstance(r.output, float) and isinstance(r.spike, bool)
    assert isinstance(r.diagnostics, dict)
    model.step(np.full((32, 40), 200, np.uint8))
    fields = model.fields()
    assert fields and all(v.shape == (32, 40) for v in fields.values())
