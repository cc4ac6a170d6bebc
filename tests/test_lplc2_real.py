"""EMD-LPLC2's real-environment variant on the engine (``LPLC2Params(variant="real")``) against its float64
reference (``LPLC2Reference(variant="real")``): the 3-of-4 unit rule of the authors' folders 5-7 and folder 7's
input (the green channel of a colour frame, shrunk to a quarter as MATLAB's ``imresize(.., 0.25)``).

Tolerances (the brief of the variant): the giant fibre's spikes, spike count and active-unit count equal on every
frame, the membrane ``V`` within 1e-4 mV; the arms and response maps as in ``tests/test_lplc2.py`` (float32
sums against float64).
"""
from __future__ import annotations

import ast
import functools
import io
import os
import subprocess
import sys
import tokenize
from pathlib import Path

import numpy as np
import pytest

from cdnf_ti.errors import UserError
from cdnf_ti.lplc2_reference import LPLC2Reference, matlab_imresize
from cdnf_ti.models import LPLC2, LPLC2Params
from cdnf_ti.models.lplc2 import imresize_matrix
from cdnf_ti.stimuli.basic import BASIC_STIMULI, basic_stimulus
from cdnf_ti.taichi_runtime import COMPILER_ENV, installed_compilers

SIZE = 320  #: basic stimuli before the shrink: an 80x80 frame (the lane layout), a 79x79 unit array
REPO = Path(__file__).resolve().parents[1]
REAL = LPLC2Params(variant="real")
CLIPS = ("c02.mp4", "serial_vehicle_collision.mp4")


@functools.cache
def stimulus(name: str) -> tuple:
    st = basic_stimulus(name, height=SIZE, width=SIZE)
    return tuple(st.frames()), st.fps


def run_both(frames, fps: float, generic: bool = False):
    """The compiled real variant's trace (the lane layout, or the pixel layout where ``generic``), the model,
    and the reference's per-frame outputs on ``frames``."""
    model = LPLC2(REAL, fps=fps)
    model.fast = not generic
    trace = model.run(frames)
    assert model._be.lane is not generic
    ref = LPLC2Reference(*np.shape(frames[0])[:2], fps=fps, variant="real")
    return trace, model, ref, ref.run(frames)


def assert_agrees(trace, ref: dict) -> None:
    """Alerts, spike and active-unit counts equal frame by frame; V within 1e-4 mV."""
    np.testing.assert_array_equal(trace.spike, ref["alert"])
    np.testing.assert_array_equal(trace.diagnostics["spikes"], ref["spikes"])
    np.testing.assert_array_equal(trace.diagnostics["active"], ref["active"])
    np.testing.assert_allclose(trace.output, ref["v"], atol=1e-4, rtol=0)


@pytest.mark.parametrize("stim", BASIC_STIMULI)
def test_real_variant_matches_reference_on_basic_stimulus(stim):
    trace, _, _, ref = run_both(*stimulus(stim))
    assert_agrees(trace, ref)


@pytest.mark.parametrize("stim", ["dark_looming", "light_looming"])
def test_real_variant_pixel_layout_matches_reference_on_basic_stimulus(stim):
    trace, _, _, ref = run_both(*stimulus(stim), generic=True)
    assert_agrees(trace, ref)


@pytest.fixture(scope="module", params=CLIPS)
def clip(request, shared_real):
    """A development dashcam clip's grey frames (what ``run`` hands a grey model) and its fps."""
    if shared_real is None or not (shared_real / request.param).exists():
        pytest.skip("the development dashcam clips are not present (the basic stimuli cover the variant)")
    from cdnf_ti.frames import iter_grey, open_source

    src = open_source(shared_real / request.param)
    return list(iter_grey(src)), src.fps


def test_real_variant_matches_reference_on_real_clip(clip):
    trace, _, _, ref = run_both(*clip)
    assert ref["active"].max() > 0  # the clip drives the array
    assert_agrees(trace, ref)


def test_real_variant_maps_match_reference_maps_on_real_clip(clip):
    _, model, ref, _ = run_both(*clip)
    fields = model.fields()
    maps = dict(left=ref.arm_maps[0], right=ref.arm_maps[1], up=ref.arm_maps[2], down=ref.arm_maps[3],
                lplc2=ref.lplc2)
    for name, want in maps.items():
        scale = max(1.0, float(np.abs(want).max()))
        np.testing.assert_allclose(fields[name][:-1, :-1], want, atol=(1e-4 if name == "lplc2" else 2e-5) * scale,
                                   rtol=0, err_msg=name)


def test_colour_frames_are_seen_through_their_green_channel():
    grey, fps = stimulus("dark_looming")
    rng = np.random.default_rng(0)
    frames = []
    for g in grey:  # the stimulus in the green channel, independent noise in blue and red
        bgr = rng.integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8)
        bgr[:, :, 1] = np.floor(g * 255.0 + 0.5).astype(np.uint8)
        frames.append(bgr)
    trace, _, _, ref = run_both(frames, fps)
    assert ref["alert"].any()
    assert_agrees(trace, ref)


def test_fields_are_at_the_shrunk_size_rounded_up():
    model = LPLC2(REAL, fps=30.0)
    model.run([np.zeros((241, 426), np.uint8)] * 2)
    assert {f.shape for f in model.fields().values()} == {(61, 107)}


def test_a_frame_of_another_size_is_refused_in_one_line():
    model = LPLC2(REAL, fps=30.0)
    model.step(np.zeros((240, 432), np.uint8))
    with pytest.raises(ValueError, match="432x240") as e:
        model.step(np.zeros((240, 431), np.uint8))  # the same shrunk size (108x60)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("n", [1, 5, 17, 240, 241, 426])
def test_resize_matrix_equals_matlab_imresize_of_the_reference(n):
    img = np.random.default_rng(n).random((n, 9))
    np.testing.assert_allclose(imresize_matrix(n, 0.25) @ img @ imresize_matrix(9, 0.25).T,
                               matlab_imresize(img, 0.25), rtol=0, atol=1e-12)


def test_event_bins_are_refused_with_one_user_error_line():
    with pytest.raises(UserError) as e:
        LPLC2(REAL).step_on_off(np.zeros((64, 64), np.float32), np.zeros((64, 64), np.float32))
    assert "\n" not in str(e.value)


def test_the_numpy_backend_refuses_the_real_variant():
    with pytest.raises(UserError, match="variant=arena only"):
        LPLC2(REAL, backend="numpy").step(np.zeros((64, 64), np.uint8))


def test_an_unknown_variant_is_refused():
    with pytest.raises(ValueError, match="variant"):
        LPLC2Params(variant="outdoor")


def test_run_takes_the_variant_as_a_string_parameter(tmp_path):
    import csv

    from cdnf_ti.run import main

    frames, fps = stimulus("dark_looming")
    np.save(tmp_path / "looming.npy", np.stack(frames))
    out = tmp_path / "o"
    assert main(["run", str(tmp_path / "looming.npy"), "--model", "lplc2", "--param", "variant=real", "--out",
                 str(out), "--no-progress"]) == 0
    row = next(csv.DictReader(open(out / "summary.csv")))
    trace = list(csv.DictReader(open(out / row["trace"])))
    expected = LPLC2(REAL, fps=float(row["video_fps"])).run(frames)
    assert row["params"] == "variant=real" and expected.spike.any()
    np.testing.assert_array_equal([int(r["spike"]) for r in trace], expected.spike.astype(int))
    np.testing.assert_allclose([float(r["V"]) for r in trace], expected.output, atol=1e-6, rtol=0)


def test_run_refuses_an_unknown_variant_in_one_error_line(tmp_path, capsys):
    from cdnf_ti.run import main

    np.save(tmp_path / "looming.npy", np.stack(stimulus("dark_looming")[0][:3]))
    code = main(["run", str(tmp_path / "looming.npy"), "--model", "lplc2", "--param", "variant=outdoor", "--out",
                 str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1 and err[0].startswith("error:") and "variant" in err[0]


_OTHER_COMPILER = """
import numpy as np
from cdnf_ti.models import LPLC2, LPLC2Params
from cdnf_ti.lplc2_reference import LPLC2Reference
from cdnf_ti.stimuli.basic import basic_stimulus
from cdnf_ti.taichi_runtime import current_compiler
st = basic_stimulus("dark_looming", height=320, width=320)
frames = list(st.frames())
t = LPLC2(LPLC2Params(variant="real"), fps=st.fps).run(frames)
r = LPLC2Reference(320, 320, fps=st.fps, variant="real").run(frames)
print(current_compiler(), int(r["alert"].sum()), bool(np.array_equal(t.spike, r["alert"])),
      bool(np.array_equal(t.diagnostics["active"], r["active"])), float(np.abs(t.output - r["v"]).max()))
"""


@pytest.mark.parametrize("compiler", installed_compilers())
def test_real_variant_matches_reference_under_each_compiler(compiler):
    env = dict(os.environ, **{COMPILER_ENV: compiler})
    proc = subprocess.run([sys.executable, "-c", _OTHER_COMPILER], cwd=REPO, env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    comp, alerts, spikes_equal, active_equal, dv = proc.stdout.split()
    assert comp == compiler and int(alerts) > 0
    assert spikes_equal == "True" and active_equal == "True" and float(dv) < 1e-4


def code_lines(path: Path) -> int:
    """Lines holding code: not blank, not only a comment, not part of a docstring."""
    src = path.read_text()
    docs = set()
    for node in ast.walk(ast.parse(src)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(getattr(first.value, "value", None), str):
                docs.update(range(first.lineno, first.end_lineno + 1))
    skip = (tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT, tokenize.ENDMARKER)
    lines = set()
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type not in skip:
            lines.update(range(tok.start[0], tok.end[0] + 1))
    return len(lines - docs)


def test_code_lines_counts_code_only(tmp_path):
    path = tmp_path / "sample.py"
    path.write_text('"""Doc."""\n\n# a comment\nx = 1  # trailing\n\n\ndef f():\n    """Doc\n    more."""\n'
                    '    return (x +\n            1)\n')
    assert code_lines(path) == 4  # x = 1; def f(); the two lines of the return


def test_the_model_and_its_kernels_are_at_most_300_code_lines():
    assert code_lines(REPO / "kernels" / "lplc2.py") + code_lines(REPO / "cdnf_ti" / "models" / "lplc2.py") <= 300
