"""On a GPU (Taichi's CUDA backend) every model agrees with its float64 reference.

A process runs one kernel runtime, and the test session's runs on the CPU, so each CUDA check
starts a child process per compiler that initialises it with ``arch="cuda"``. CI has no GPU:
there the child reports that no CUDA device exists and those two tests skip with that reason
(the one-line error for a missing GPU is tested here for the bench, and in
``test_compilers.py`` and ``test_cli.py``). On a machine with an NVIDIA GPU they run.

What a GPU runs differently from the CPU is tested everywhere: the generic model and stimulus kernels with the
GPU's work partition (one work item per run of 16 columns) run here on the CPU against the
references.
"""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cdnf_ti import create_model
from cdnf_ti.bench.inputs import standin_video
from cdnf_ti.models import MODELS
from cdnf_ti.taichi_runtime import COMPILER_ENV, installed_compilers

REPO = Path(__file__).resolve().parents[1]
NO_GPU = "NO_CUDA_DEVICE"

_CHECK = f"""
import sys
import numpy as np
from cdnf_ti import create_model
from cdnf_ti.bench.inputs import real_or_standin
from cdnf_ti.models import MODELS
from cdnf_ti.stimuli.basic import basic_stimulus
from cdnf_ti.taichi_runtime import BackendUnavailableError, current_compiler, ensure_taichi
try:
    arch = ensure_taichi("cuda")
except BackendUnavailableError:
    print("{NO_GPU}")
    sys.exit(0)
looming = list(basic_stimulus("dark_looming", height=96, width=128, start_half_size=1.2).frames())
label, video = real_or_standin(24, start=60)  # the shared dashcam clip when present, else its stand-in
for in_label, frames in (("dark_looming", looming), (label.replace(" ", "_"), video)):
    for name in MODELS:
        gpu = create_model(name, arch="cuda").run(frames)
        ref = create_model(name, backend="numpy").run(frames)
        same_alerts = bool(np.array_equal(gpu.spike, ref.spike))
        print(arch, current_compiler(), in_label, name, float(np.max(np.abs(gpu.output - ref.output))),
              bool(gpu.converged.all()), same_alerts, flush=True)
"""


def _child(compiler: str, code: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, **{COMPILER_ENV: compiler})
    return subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True)


@pytest.mark.slow
@pytest.mark.parametrize("compiler", installed_compilers())
def test_every_model_on_cuda_agrees_with_its_reference(compiler):
    proc = _child(compiler, _CHECK)
    assert proc.returncode == 0, proc.stderr[-3000:]
    if NO_GPU in proc.stdout:
        pytest.skip("no CUDA device on this machine")
    rows = [ln.split() for ln in proc.stdout.strip().splitlines()]
    assert len(rows) == 2 * len(MODELS), proc.stdout  # two inputs x every registered model
    for arch, comp, in_label, name, diff, converged, same_alerts in rows:
        assert (arch, comp) == ("cuda", compiler)
        assert float(diff) < 1e-4, (in_label, name, diff)
        assert converged == "True", (in_label, name)
        assert same_alerts == "True", (in_label, name)


@pytest.mark.parametrize("compiler", installed_compilers())
def test_bench_on_cuda_runs_or_fails_with_one_line(compiler):
    args = ["bench", "--arch", "cuda", "--quick", "--frames", "4", "--sizes", "64x48", "--compiler", compiler]
    proc = subprocess.run([sys.executable, "-m", "cdnf_ti.run", *args], cwd=REPO, capture_output=True, text=True,
                          env=dict(os.environ, **{COMPILER_ENV: compiler}))
    if proc.returncode == 2:  # no GPU here: one line naming the backend
        err = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert len(err) == 1 and err[0].startswith("error:") and "'cuda' is not available" in err[0], proc.stderr
        return
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = [ln for ln in proc.stdout.splitlines() if ln.startswith("| cdnf |")]
    assert rows and all(f"{compiler} (cuda)" in r for r in rows), proc.stdout


def test_a_gpu_gets_one_work_item_per_run_of_columns():
    from cdnf_ti.kernels.stimuli import CHUNK, COLUMN_BLOCKS, column_blocks

    assert column_blocks(426, "cpu") == COLUMN_BLOCKS
    assert column_blocks(426, "cuda") == -(-426 // CHUNK) == 27  # 240 x 27 = 6480 GPU threads at 426x240
    assert column_blocks(8, "cuda") == 1


@pytest.mark.parametrize("name", MODELS)
def test_the_gpu_work_partition_computes_the_reference_result(name, monkeypatch):
    # the generic kernels with the GPU's work items (one per run of columns), run here on the CPU
    from cdnf_ti.kernels import stimuli

    cpu_blocks = stimuli.column_blocks
    monkeypatch.setattr(stimuli, "column_blocks", lambda width, arch: cpu_blocks(width, "cuda"))
    frames = [np.ascontiguousarray(f[::2, ::3][:, :70]) for f in standin_video(8, seed=3)]  # 120 x 70
    model = create_model(name)
    model.fast = False  # the generic kernels, which GPUs run
    got = model.run(frames)
    if model.kernels is not None:  # the engine's pixel layout: one work item per pixel
        assert model._be.lane is False
    else:
        assert model._be.blocks == 5  # 70 px: five runs of 16 columns, the last one partial
    ref = create_model(name, backend="numpy").run(frames)
    assert np.max(np.abs(got.output - ref.output)) < 1e-4
    assert np.array_equal(got.spike, ref.spike) and got.converged.all()


def _stimulus_pairs():
    """(taichi frames, numpy frames) of each procedural stimulus at 56 x 70 (five work items per row on a GPU)."""
    from cdnf_ti.stimuli.basic import basic_stimulus
    from cdnf_ti.stimuli.grating import GratingStimulus
    from cdnf_ti.stimuli.incoherent import incoherent_stimulus
    from cdnf_ti.stimuli.rain import RainParams, RainyFrames

    size = dict(height=56, width=70)
    yield "looming", *(list(basic_stimulus("dark_looming", backend=b, **size).frames()) for b in ("taichi", "numpy"))
    yield "incoherent", *(list(incoherent_stimulus("dark_looming", 0.4, 3, backend=b, **size).frames())
                          for b in ("taichi", "numpy"))
    grating = dict(period=10, bar_width=3, speed=-77.0, seed=5, **size)
    yield "grating", *(list(GratingStimulus(backend=b, **grating).frames()) for b in ("taichi", "numpy"))
    video = [np.ascontiguousarray(f[::2, ::3][:56, :70]) for f in standin_video(3, seed=7)]
    yield "rain", *(list(RainyFrames(video, RainParams(drops=60), seed=2, backend=b)) for b in ("taichi", "numpy"))


def test_the_gpu_work_partition_renders_the_reference_stimuli(monkeypatch):
    # the stimulus kernels with the GPU's work items, run here on the CPU, against the NumPy renderings
    from cdnf_ti.kernels import stimuli

    cpu_blocks = stimuli.column_blocks
    monkeypatch.setattr(stimuli, "column_blocks", lambda width, arch: cpu_blocks(width, "cuda"))
    for name, got, ref in _stimulus_pairs():
        assert len(got) == len(ref) > 1, name
        for k, (a, b) in enumerate(zip(got, ref)):
            np.testing.assert_allclose(a, b, atol=2e-6, err_msg=f"{name} frame {k}")
