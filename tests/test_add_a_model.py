"""Adding a model touches no engine file: a complete model, declared here, runs through ``run``, ``render``
and ``bench`` on the engine's one backend, in both layouts, against its own float64 NumPy reference.

The model between the ``# -- model`` markers is the "add a model" example of docs/ARCHITECTURE.md, word
for word (a test checks it).
"""

from pathlib import Path

import numpy as np
import pytest

from cdnf_ti.models import MODELS

ROOT = Path(__file__).resolve().parents[1]

# -- model
from dataclasses import dataclass  # noqa: E402

from cdnf_ti.kernels.engine import Coefs, Launch, Planes, Scalars, Stage, model  # noqa: E402
from cdnf_ti.models import Model, StepResult, register_model  # noqa: E402

PLANES, COEFS, SCALARS = Planes("L P E"), Coefs(a=1), Scalars("scale keep")


def build(ti, lanes):
    """The stage, written once: ``P = keep (g - L)``, ``E = a E + (1 - a) |P|`` and its 3x3 mean, summed."""
    from cdnf_ti.kernels import engine

    L, P, E = PLANES

    @ti.func
    def ema(a: ti.template()):
        g = a.grey() * a.value(SCALARS.scale)
        p = a.value(SCALARS.keep) * (g - a.at(L))
        a.put(L, g)
        a.put(P, p)
        a.put(E, a.coef(COEFS.a) * a.at(E) + (1.0 - a.coef(COEFS.a)) * ti.max(p, 0.0 - p))

    @ti.func
    def smooth(a: ti.template()):
        centre, edge, diag = a.window3(E)
        return (centre + edge + diag) / 9.0

    step = Launch("step", Stage(ema, ghosts=(E,)), Stage(smooth, sums="sum_E"))
    return model(PLANES, COEFS, SCALARS, engine.build(ti, lanes), step)


@dataclass(frozen=True)
class EmaParams:
    a: float = 0.8  # the persistence of E
    level: float = 0.01  # the alert level of the output


@register_model
class Ema(Model):
    """A toy model: the mean of the 3x3-smoothed EMA of ``|P|``; alert above ``level``."""

    name, output_name, params_type = "toy_ema", "mean_E", EmaParams
    kernels = staticmethod(build)
    panels = (("E", "EMA of |P|"),)

    def coefficients(self):
        return {"a": self.params.a}

    def _numpy_backend(self, shape):
        return EmaReference(self, shape)

    def _step(self, t, grey, loaded):
        if loaded is None:  # the engine: launch the stages
            scale = 1.0 / 255.0 if grey.dtype == np.uint8 else 1.0
            (total,) = self._be.launch("step", scale=scale, keep=float(t > 0))
            loaded = total / grey.size
        return StepResult(t, loaded, loaded > self.params.level)
# -- model
MODELS.pop(Ema.name)  # registered for this file's tests only (the fixture)


class EmaReference:
    """The float64 oracle, written from the equations (NumPy, replicate border)."""

    name = "numpy"

    def __init__(self, m, shape):
        self.a, self.shape = m.params.a, tuple(shape)
        self.reset()

    def reset(self):
        self.L, self.E = np.zeros(self.shape), np.zeros(self.shape)
        self.first = True

    def load(self, grey, first):
        g = grey.astype(np.float64) / (255.0 if grey.dtype == np.uint8 else 1.0)
        p = np.zeros(self.shape) if first else g - self.L
        self.L = g
        self.E = self.a * self.E + (1 - self.a) * np.abs(p)
        q = np.pad(self.E, 1, mode="edge")
        h, w = self.shape
        return float(sum(q[i:i + h, j:j + w] for i in range(3) for j in range(3)).mean() / 9.0)

    def fields(self):
        return {"E": self.E}


@pytest.fixture
def toy():
    MODELS[Ema.name] = Ema
    try:
        yield Ema
    finally:
        MODELS.pop(Ema.name, None)


def frames(width: int) -> list[np.ndarray]:
    from cdnf_ti.stimuli.basic import basic_stimulus

    return list(basic_stimulus("dark_looming", height=40, width=width, backend="numpy").frames())[-14:]


@pytest.mark.parametrize("width", [80, 40])  # the lane layout (>= 2 lane vectors), the pixel layout
def test_a_model_declared_in_a_test_file_matches_its_float64_reference_in_both_layouts(toy, width):
    from cdnf_ti.taichi_runtime import lanes

    f = frames(width)
    model = toy()
    got = model.run(f)
    assert model._be.lane is (width >= 2 * lanes())
    want = toy(backend="numpy").run(f)
    assert np.abs(want.output).max() > 1e-3
    np.testing.assert_allclose(got.output, want.output, rtol=1e-5, atol=1e-7)


def test_a_model_declared_in_a_test_file_runs_through_run_render_and_bench(toy, tmp_path):
    from cdnf_ti.bench.cli import run_bench
    from cdnf_ti.run import main
    from cdnf_ti.taichi_runtime import current_compiler

    assert main(["stim:dark_looming?size=32", "--model", "toy_ema", "--out", str(tmp_path / "o"),
                 "--no-progress"]) == 0
    assert (tmp_path / "o" / "dark_looming_size32.toy_ema.csv").exists()
    assert main(["render", "stim:dark_looming?size=32", "--model", "toy_ema", "--out", str(tmp_path / "r.mp4"),
                 "--no-progress"]) == 0
    assert (tmp_path / "r.mp4").stat().st_size > 0
    rows = run_bench(["toy_ema"], n_frames=4, repeats=1, progress=False, resolutions=((24, 72),),
                     compilers=[current_compiler()])
    assert rows and all(r.model == "toy_ema" and r.fps > 0 for r in rows)


def test_the_architecture_guide_shows_this_model_word_for_word():
    source = (ROOT / "tests" / "test_add_a_model.py").read_text(encoding="utf-8")
    code = source.split("# -- model\n")[1].replace("  # noqa: E402", "")
    guide = (ROOT / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    assert code.strip() in guide
