"""Throughput of every registered model and of the C-DNF peers (pytest-benchmark).

Run with ``pytest bench/ --benchmark-only`` (``-k 426`` etc. to select). Each
benchmark steps a model through a prepared list of frames (decoded before
timing); ``extra_info`` holds frames/s and the iteration counts. The peers
run in the same session, so ratios can be read from one run; for a ready-made
table use ``python -m cdnf_ti.run bench``.

Inputs: a basic stimulus (dark looming) and real footage (the development dashcam
clip ``serial_vehicle_collision`` when present, else a
generated stand-in video), each at 426x240 and 600x600.

One process runs one kernel compiler: ``CDNF_TI_COMPILER=quadrants pytest bench/
--benchmark-only`` measures the other one (``extra_info["compiler"]`` says which).
"""
import warnings

import pytest

from cdnf_ti.bench.cli import bench_inputs
from cdnf_ti.bench.peers import PeerCDNF, available_peers
from cdnf_ti.models import MODELS, create_model
from cdnf_ti.models.base import NotConvergedWarning
from cdnf_ti.params import CDNFParams
from cdnf_ti.taichi_runtime import current_compiler, ensure_taichi

N_FRAMES = 12
INPUTS = {f"{label.split(':')[0]}-{res}": (label, frames) for label, res, frames in bench_inputs(N_FRAMES)}


def _stepper(model, frames):
    model.reset()
    model.step(frames[0])
    for f in frames[1:]:
        model.step(f)


def _bench(benchmark, model, frames):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotConvergedWarning)  # recorded per frame in "converged"
        _stepper(model, frames[:3])  # compile
        benchmark.pedantic(_stepper, args=(model, frames), rounds=3, iterations=1, warmup_rounds=0)
    n = len(frames)
    ensure_taichi("cpu")
    benchmark.extra_info["compiler"] = current_compiler()
    benchmark.extra_info["frames"] = n
    benchmark.extra_info["frames_per_s"] = n / benchmark.stats.stats.median


@pytest.mark.parametrize("input_key", list(INPUTS))
@pytest.mark.parametrize("model_name", list(MODELS))
def test_model_throughput(benchmark, model_name, input_key):
    label, frames = INPUTS[input_key]
    benchmark.group = input_key
    benchmark.extra_info["input"] = label
    _bench(benchmark, create_model(model_name, backend="taichi"), frames)


@pytest.mark.parametrize("input_key", list(INPUTS))
@pytest.mark.parametrize("peer", list(available_peers()))
def test_cdnf_peer_throughput(benchmark, peer, input_key):
    label, frames = INPUTS[input_key]
    benchmark.group = input_key
    benchmark.extra_info["input"] = label
    _bench(benchmark, PeerCDNF(peer), frames)


@pytest.mark.parametrize("input_key", list(INPUTS))
def test_cdnf_plain_scheme_throughput(benchmark, input_key):
    # the paper's scheme, the same one the peers run: compares the engines iteration for iteration
    label, frames = INPUTS[input_key]
    benchmark.group = input_key
    benchmark.extra_info["input"] = label
    _bench(benchmark, create_model("cdnf", CDNFParams(scheme="plain"), backend="taichi"), frames)
