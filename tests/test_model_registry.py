"""A new model is one class and @register_model: the base class runs its skeleton.

The tiny model below (mean absolute luminance change, alert above a level) is
defined here, in the test file, to show that nothing else in the package has to
change for a model to work with ``create_model``, ``run_models``, the CLI's
``--models`` and the threshold sweep.
"""
from dataclasses import dataclass

import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti.models import (
    MODELS,
    Model,
    ModelBackend,
    StepResult,
    Sweepable,
    create_model,
    get_model_class,
    register_model,
)
from cdnf_ti.models.base import run_models


@dataclass(frozen=True)
class TinyParams:
    level: float = 0.01


class NumpyTinyBackend:
    """The tiny model's per-pixel state: the previous frame and the change ``P``."""

    name = "numpy"

    def __init__(self, shape):
        self.shape = tuple(shape)
        self.reset()

    def reset(self):
        self.L = np.zeros(self.shape)
        self.P = np.zeros(self.shape)

    def load(self, grey, first):
        g = grey.astype(np.float64) / (255.0 if grey.dtype == np.uint8 else 1.0)
        self.P = np.zeros(self.shape) if first else g - self.L
        self.L = g
        return float(np.abs(self.P).mean())

    def fields(self):
        return {"P": self.P.copy()}


@pytest.fixture
def tiny():
    """Register the tiny model for one test, then remove it from the registry."""

    @register_model
    class Tiny(Model):
        name = "tiny_change"
        output_name = "mean_abs_P"
        params_type = TinyParams
        BACKENDS = ("numpy",)

        def _numpy_backend(self, shape):
            return NumpyTinyBackend(shape)

        def _step(self, t, grey, mean_abs_p):
            return StepResult(t, mean_abs_p, mean_abs_p > self.params.level)

    try:
        yield Tiny
    finally:
        MODELS.pop("tiny_change", None)


def mean_abs_change(frames):
    prev, out = None, []
    for f in frames:
        g = f.astype(np.float64) / (255.0 if f.dtype == np.uint8 else 1.0)
        out.append(0.0 if prev is None else float(np.abs(g - prev).mean()))
        prev = g
    return np.array(out)


def test_a_registered_model_is_created_by_name_and_runs(tiny):
    frames = list(small_stimulus("dark_looming", size=48).frames())
    model = create_model("Tiny-Change", backend="numpy")
    assert isinstance(model, tiny) and get_model_class("tiny_change") is tiny
    trace = model.run(frames)
    expected = mean_abs_change(frames)
    np.testing.assert_allclose(trace.output, expected, rtol=1e-12, atol=1e-15)
    assert np.array_equal(trace.spike, expected > 0.01)
    assert trace.model == "tiny_change" and trace.output_name == "mean_abs_P"
    assert model.fields()["P"].shape == (48, 48)


def test_a_registered_model_runs_in_one_pass_with_the_built_in_models(tiny):
    frames = list(small_stimulus("light_looming", size=40).frames())
    together = run_models([create_model("tiny_change", backend="numpy"), create_model("lgmd2", backend="numpy")],
                          iter(frames))
    alone = create_model("tiny_change", backend="numpy").run(frames)
    assert np.array_equal(together[0].output, alone.output)


def test_the_base_class_checks_the_frame_size_and_resets(tiny):
    model = tiny(backend="numpy")
    assert model.fields() == {}
    model.step(np.zeros((20, 30), np.uint8))
    with pytest.raises(ValueError, match="30x20"):
        model.step(np.zeros((21, 30), np.uint8))
    model.reset()
    first = model.step(np.full((20, 30), 255, np.uint8))
    assert first.t == 0 and first.output == 0.0  # no previous frame after reset


def test_a_model_without_that_backend_is_refused_with_a_clear_error(tiny):
    with pytest.raises(ValueError, match="unknown backend 'taichi'"):
        create_model("tiny_change")


def test_the_command_line_runs_a_registered_model(tiny, tmp_path, capsys):
    from cdnf_ti.run import main, parse_models

    assert parse_models("tiny_change") == ["tiny_change"]
    assert "tiny_change" in parse_models("all")
    out = tmp_path / "out"
    rc = main(["stim:dark_looming?size=40", "--models", "tiny_change,lgmd2", "--backend", "numpy",
               "--out", str(out), "--no-progress"])
    assert rc == 0
    assert "[tiny_change]" in capsys.readouterr().out
    csv_files = sorted(p.name for p in out.glob("*.tiny_change.csv"))
    assert len(csv_files) == 1


def test_a_model_without_sweep_alerts_is_not_sweepable(tiny):
    assert not isinstance(tiny, Sweepable)


def test_register_model_refuses_a_class_that_is_not_a_model():
    with pytest.raises(TypeError):
        register_model(TinyParams)


def test_register_model_refuses_a_model_without_a_name():
    class Nameless(Model):
        pass

    with pytest.raises(ValueError, match="no registry name"):
        register_model(Nameless)


def test_register_model_refuses_a_name_already_taken():
    class Impostor(Model):
        name = "LGMD-2"

    with pytest.raises(ValueError, match="taken"):
        register_model(Impostor)
    assert MODELS["lgmd2"].__name__ == "LGMD2"


@pytest.mark.parametrize("backend", ["numpy", "taichi"])
@pytest.mark.parametrize("name", sorted(MODELS))
def test_every_built_in_backend_meets_the_backend_contract(name, backend):
    model = create_model(name, backend=backend)
    model.step(np.zeros((24, 40), np.uint8))
    be = model._be
    assert isinstance(be, ModelBackend)
    assert be.name == backend and tuple(be.shape) == (24, 40)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_every_built_in_model_has_its_own_threshold_sweep(name):
    cls = get_model_class(name)
    assert isinstance(cls, Sweepable)
    assert len(cls.sweep_values) > 1 and cls.sweep_default() in cls.sweep_values
