"""oLGMD on the engine (cdnf_ti.models.olgmd): agreement with the float64 reference, and each quirk of
``variant="code"`` against ``variant="paper"``.

Tolerance: the engine's layers are float32 and its sums float64, the reference float64 throughout;
on the stimuli here the membrane potential ``K`` agrees to 1e-6 and the alert frame by frame.
A ``G`` cell within float32 round-off of the decay threshold ``0.5 G = 15`` could flip and move ``K``
by up to ``~30 / (0.6 N)``; none does on these stimuli.
"""
from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import model_checks as checks
import numpy as np
import pytest

from cdnf_ti.models import OLGMD, OLGMDParams
from cdnf_ti.olgmd_reference import OLGMDReference
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus
from cdnf_ti.stimuli.incoherent import IncoherentStimulus
from cdnf_ti.taichi_runtime import COMPILER_ENV, current_compiler, installed_compilers

REPO = Path(__file__).resolve().parents[1]
VARIANTS = ("code", "paper")
SIZE = 64
K_TOL = 1e-6
REAL_CLIPS = ("c02.mp4", "c38.mp4", "nc03.mp4")


PATHS = ("lanes", "generic")  # the fast CPU path (frames >= 2 lane vectors wide) and the generic kernels


def engine(variant: str, fps: float = 30.0, path: str = "lanes", **kw) -> OLGMD:
    model = OLGMD(OLGMDParams(variant=variant, **kw), fps=fps)
    model.fast = path == "lanes"
    return model


def compare(frames: list[np.ndarray], variant: str, fps: float = 30.0, path: str = "lanes") -> dict:
    """Engine and reference on ``frames``: largest differences and whether every alert is equal."""
    return checks.compare(engine(variant, fps, path), lambda h, w: OLGMDReference(h, w, variant=variant, fps=fps),
                          frames, "k", absolute=("k_raw", "spike_sum"), relative={"aim": 1e-9})


def assert_agrees(r: dict) -> None:
    checks.assert_agrees(r, k=K_TOL, k_raw=K_TOL, aim=1e-5)


@functools.cache
def stimulus(name: str, size: int = SIZE) -> tuple[tuple[np.ndarray, ...], float]:
    st = basic_stimulus(name, height=size, width=size)
    return tuple(st.frames()), float(st.fps)


# -- engine against the reference -------------------------------------------------------------------
@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("name", BASIC_STIMULI)
def test_engine_matches_reference_on_basic_stimulus(name, variant, path):
    frames, fps = stimulus(name)
    assert_agrees(compare(list(frames), variant, fps, path))


def test_frames_two_lane_vectors_wide_take_the_fast_path_and_narrower_ones_the_generic_kernels():
    from cdnf_ti.taichi_runtime import lanes

    for width, lane in ((2 * lanes(), True), (2 * lanes() - 1, False)):
        model = engine("code")
        model.step(np.zeros((8, width), np.uint8))
        assert model._be.lane is lane


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("variant", VARIANTS)
def test_engine_matches_reference_on_a_generated_incoherent_clip(variant, path):
    base = basic_stimulus("dark_looming", height=48, width=80)
    st = IncoherentStimulus(base, 0.5, seed=3, backend="numpy")
    assert_agrees(compare(list(st.frames()), variant, base.fps, path))


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("clip", REAL_CLIPS)
def test_engine_matches_reference_on_real_clip(shared_real, clip, variant, path):
    assert_agrees(compare(checks.clip_frames(shared_real, clip, 40), variant, 30.0, path))  # BGR, as their code


def test_engine_alerts_where_the_reference_does_on_a_real_collision(shared_real):
    r = compare(checks.clip_frames(shared_real, "c38.mp4", 20), "code")
    assert r["alerts"] > 0 and r["alerts_equal"]


_OTHER = """
import json, sys
sys.path.insert(0, {tests!r})
from test_olgmd import compare, stimulus
from cdnf_ti.taichi_runtime import current_compiler
out = {{}}
for variant in ("code", "paper"):
    for name in ("dark_looming", "light_receding"):
        frames, fps = stimulus(name)
        for path in ("lanes", "generic"):
            out[" ".join((variant, name, path))] = compare(list(frames), variant, fps, path)
print(json.dumps({{"compiler": current_compiler(), "results": out}}))
"""


@pytest.mark.parametrize("compiler", [c for c in installed_compilers()])
def test_engine_matches_reference_under_each_compiler(compiler):
    if compiler == current_compiler():
        frames, fps = stimulus("dark_looming")
        for variant in VARIANTS:
            for path in PATHS:
                assert_agrees(compare(list(frames), variant, fps, path))
        return
    env = dict(os.environ, **{COMPILER_ENV: compiler})
    proc = subprocess.run([sys.executable, "-c", _OTHER.format(tests=str(REPO / "tests"))], cwd=REPO, env=env,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["compiler"] == compiler
    assert len(got["results"]) == 8
    for r in got["results"].values():
        assert_agrees(r)


def test_numpy_backend_is_the_reference():
    frames, fps = stimulus("dark_looming")
    tr = OLGMD(OLGMDParams(variant="paper"), backend="numpy", fps=fps).run(frames)
    ref = OLGMDReference(SIZE, SIZE, variant="paper", fps=fps).run(frames)
    np.testing.assert_array_equal(tr.output, ref["k"])
    np.testing.assert_array_equal(tr.spike, ref["alert"])


@pytest.mark.parametrize("variant", VARIANTS)
def test_streaming_after_reset_repeats_the_run(variant):
    frames, fps = stimulus("dark_looming")
    m = engine(variant, fps)
    a = m.run(frames)
    b = m.run(frames)
    np.testing.assert_array_equal(a.output, b.output)


@pytest.mark.parametrize("bad", [dict(variant="octave"), dict(t_on=(15.0, 30.0)), dict(a5=0.0)])
def test_bad_parameters_are_value_errors(bad):
    with pytest.raises(ValueError, match="OLGMDParams"):
        OLGMDParams(**bad)


def test_spike_sum_sweep_replays_the_alert():
    frames, fps = stimulus("dark_looming")
    tr = engine("code", fps).run(frames)
    (at_default,) = OLGMD.sweep_alerts(tr, [OLGMD.sweep_default()])
    np.testing.assert_array_equal(at_default, tr.spike)


# -- the quirks of variant="code" ------------------------------------------------------------------
def fields_per_frame(model: OLGMD, frames) -> tuple[list[dict], list]:
    """Step ``frames``, keeping every frame's fields and result."""
    model.reset()
    out, steps = [], []
    for f in frames:
        steps.append(model.step(f))
        out.append(model.fields())
    return out, steps


def test_code_variant_fixes_dt_at_53_ms_whatever_the_frame_rate():
    frames, _ = stimulus("dark_looming")
    code = [engine("code", fps).run(frames).output for fps in (10.0, 60.0)]
    paper = [engine("paper", fps).run(frames).output for fps in (10.0, 60.0)]
    np.testing.assert_array_equal(code[0], code[1])
    assert not np.array_equal(paper[0], paper[1])


@pytest.mark.parametrize("variant, conversion", [("code", cv2.COLOR_RGB2GRAY), ("paper", cv2.COLOR_BGR2GRAY)])
def test_colour_frames_are_made_grey_with_red_and_blue_swapped_in_code_only(variant, conversion):
    rng = np.random.default_rng(7)
    colour = [rng.integers(0, 256, (24, 40, 3), dtype=np.uint8) for _ in range(5)]
    a = engine(variant).run(colour)
    b = engine(variant).run([cv2.cvtColor(f, conversion) for f in colour])
    np.testing.assert_array_equal(a.output, b.output)
    np.testing.assert_array_equal(a.diagnostics["aim"], b.diagnostics["aim"])


def test_code_variant_drops_the_difference_of_frames_0_and_1():
    frames = [np.zeros((16, 32), np.uint8)] + [np.full((16, 32), 120, np.uint8)] * 4
    code = engine("code").run(frames).diagnostics["aim"]
    paper = engine("paper").run(frames).diagnostics["aim"]
    assert not code.any()
    assert paper[1] > 0


@pytest.mark.parametrize("variant", VARIANTS)
def test_persistence_of_p_follows_the_absolute_frame_index_in_code_only(variant):
    frames = [np.zeros((12, 40), np.uint8)] * 9 + [np.full((12, 40), 100, np.uint8)] * 2  # a step at frame 9
    fields, _ = fields_per_frame(engine(variant), frames)
    p9, p10 = fields[9]["P"][5, 20], fields[10]["P"][5, 20]
    assert p9 == 100.0
    a_1 = 1.0 / (1.0 + np.exp(9.0)) if variant == "code" else 1.0 / (1.0 + np.e)  # t = 10, i = 1
    assert p10 == pytest.approx(a_1 * p9, rel=1e-5)


@pytest.mark.parametrize("variant", VARIANTS)
def test_pm_off_is_driven_by_the_on_mean_in_code_only(variant):
    frames = [np.zeros((16, 32), np.uint8)] * 3 + [np.full((16, 32), 80, np.uint8)] * 2  # brightening only
    tr = engine(variant).run(frames)
    if variant == "code":
        np.testing.assert_allclose(tr.diagnostics["pm_off"][3], tr.diagnostics["pm_on"][3], rtol=1e-6)
        assert tr.diagnostics["pm_off"][3] > 0
    else:
        assert tr.diagnostics["pm_off"][3] == 0.0


@pytest.mark.parametrize("variant", VARIANTS)
def test_pm_smooths_the_raw_previous_mean_in_code_and_itself_in_paper(variant):
    frames, fps = stimulus("dark_looming")
    model = engine(variant, fps)
    fields, steps = fields_per_frame(model, frames)
    first = 2 if variant == "code" else 1
    pm = [s.diagnostics["pm_on"] for s in steps]
    mean = [f["ON"].astype(np.float64).mean() for f in fields]
    for t in range(first + 1, len(frames)):
        memory = mean[t - 1] if variant == "code" else pm[t - 1]
        assert pm[t] == pytest.approx(model.a4 * mean[t] + (1 - model.a4) * memory, rel=1e-5, abs=1e-9), t


def off_gate_frames() -> list[np.ndarray]:
    """A faint dimming (the OFF gate stays closed), then a dark square and a brightening band (it opens:
    ``variant="code"`` gates OFF on the ON mean)."""
    frames = [np.full((24, 72), 200, np.uint8)] * 3 + [np.full((24, 72), 199, np.uint8)]
    last = np.full((24, 72), 199, np.uint8)
    last[8:20, 8:20] = 20
    last[:4] = 255
    return frames + [last]


def spread(x: np.ndarray, centre: float, edge: float, diag: float, pad: str) -> np.ndarray:
    p = np.pad(x.astype(np.float64), 1, mode=pad)
    h, w = x.shape
    e = p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:]
    d = p[:-2, :-2] + p[:-2, 2:] + p[2:, :-2] + p[2:, 2:]
    return centre * p[1:-1, 1:-1] + edge * e + diag * d


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("variant", VARIANTS)
def test_delayed_excitation_is_zero_after_a_gated_frame_in_code_only(variant, path):
    model = engine(variant, path=path, th_on=1e9)  # the OFF channel alone
    fields, steps = fields_per_frame(model, off_gate_frames())
    d = steps[-1].diagnostics
    assert steps[-2].diagnostics["gate_off"] == 0 and d["gate_off"] == 1
    p, dt = model.params, model.dt
    a = [dt / (dt + tau) for tau in p.t_off]
    e_now, e_before = fields[-1]["OFF"], (0.0 if variant == "code" else fields[-2]["OFF"])
    inh = (spread(e_now, *(w * ai for w, ai in zip(p.w_off, a)), "edge")
           + spread(e_before * np.ones_like(e_now), *(w * (1 - ai) for w, ai in zip(p.w_off, a)), "edge"))
    s = np.maximum(e_now - d["w2"] * inh, 0.0)
    inner = (slice(1, -1), slice(1, -1))
    np.testing.assert_allclose(fields[-1]["S"][inner], s[inner], rtol=1e-5, atol=1e-3)


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("variant", VARIANTS)
def test_summation_border_is_zero_in_code_and_replicated_in_paper(variant, path):
    frames, fps = stimulus("dark_translating", 72)  # the bar crosses the frame, touching its top and bottom
    fields, _ = fields_per_frame(engine(variant, fps, path), frames)
    ring = [np.concatenate([f["S"][0], f["S"][-1], f["S"][:, 0], f["S"][:, -1]]) for f in fields]
    if variant == "code":
        assert max(r.max() for r in ring) == 0.0
    else:
        assert max(r.max() for r in ring) > 0.0


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("variant, pad", [("code", "reflect"), ("paper", "edge")])
def test_grouping_excitation_border_is_reflect_101_in_code_and_replicate_in_paper(variant, pad, path):
    frames, fps = stimulus("dark_looming", 72)
    fields, _ = fields_per_frame(engine(variant, fps, path), frames)
    f = max(fields, key=lambda x: x["S"].sum())  # the frame with the most summation
    assert f["S"].max() > 0
    np.testing.assert_allclose(f["Ce"], spread(f["S"], 1 / 9, 1 / 9, 1 / 9, pad), rtol=1e-5, atol=1e-4)


def test_olgmd_takes_no_event_bins_and_model_all_on_an_event_file_leaves_it_out(tmp_path, capsys):
    from event_encoders import random_events

    from cdnf_ti.errors import UserError
    from cdnf_ti.run import main

    with pytest.raises(UserError, match="does not take event input"):
        engine("code").step_on_off(np.zeros((8, 8)), np.zeros((8, 8)))
    f = tmp_path / "ev.npy"
    np.save(f, random_events(200, (64, 48), seed=4, duration_us=200_000))
    assert main([str(f), "--model", "all", "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "error:" not in err and "left out of --model all (no event input): olgmd" in err
    assert not (tmp_path / "out" / "ev.olgmd.csv").exists() and (tmp_path / "out" / "ev.lgmd2.csv").exists()
