"""The kernel compiler layer: quadrants and taichi run the same kernels, one per process."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cdnf_ti.taichi_runtime import (
    CACHE_ENV,
    COMPILER_ENV,
    COMPILERS,
    LANES_ENV,
    cache_folder,
    current_compiler,
    ensure_taichi,
    installed_compilers,
    select_compiler,
)

REPO = Path(__file__).resolve().parents[1]


def _run(args, compiler, code=None):
    env = dict(os.environ, **{COMPILER_ENV: compiler})
    cmd = [sys.executable, "-c", code] if code is not None else [sys.executable, "-m", "cdnf_ti.run", *args]
    return subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True)


def test_the_process_runs_the_compiler_it_was_asked_for():
    want = os.environ.get(COMPILER_ENV) or installed_compilers()[0]
    assert current_compiler() == want


def test_the_default_is_the_first_installed_of_taichi_then_quadrants():
    assert COMPILERS == ("taichi", "quadrants")
    assert installed_compilers() and set(installed_compilers()) <= set(COMPILERS)


def test_switching_compiler_inside_a_process_is_a_clear_error():
    other = [c for c in COMPILERS if c != current_compiler()][0]
    # the other compiler installed (Python <= 3.12): one per process; not installed (3.13): says so
    why = "start a new process" if other in installed_compilers() else "is not installed"
    with pytest.raises(ValueError, match=why):
        select_compiler(other)
    with pytest.raises(ValueError, match="unknown compiler"):
        ensure_taichi("cpu", "gcc")
    assert ensure_taichi("cpu", current_compiler()) == "cpu"  # naming the running one is fine


_CHECK = """
import numpy as np
from cdnf_ti import create_model, CDNFParams
from cdnf_ti.models import MODELS
from cdnf_ti.taichi_runtime import current_compiler
from cdnf_ti.stimuli.basic import basic_stimulus
st = basic_stimulus("dark_looming", height=64, width=72, start_half_size=1.2)
frames = list(st.frames())
for name in MODELS:
    a = create_model(name).run(frames)
    b = create_model(name, backend="numpy").run(frames)
    print(current_compiler(), name, float(np.max(np.abs(a.output - b.output))), bool(a.converged.all()))
"""


@pytest.mark.parametrize("compiler", installed_compilers())
def test_every_model_agrees_with_its_reference_under_each_compiler(compiler):
    # a fresh process per compiler: every kernel module compiles under it and matches float64
    proc = _run(None, compiler, code=_CHECK)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = [ln.split() for ln in proc.stdout.strip().splitlines()]
    assert len(lines) >= 5
    for comp, name, diff, conv in lines:
        assert comp == compiler
        assert float(diff) < 1e-4, (name, diff)
        assert conv == "True", name


def test_compiler_option_on_the_command_line(tmp_path):
    other = [c for c in installed_compilers() if c != current_compiler()]
    comp = other[0] if other else current_compiler()
    proc = _run(["stim:dark_looming?size=48", "--compiler", comp, "--out", str(tmp_path), "--no-progress"], "")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (tmp_path / "dark_looming.cdnf.csv").exists() or list(tmp_path.glob("*.cdnf.csv"))


def test_unknown_compiler_on_the_command_line_is_a_usage_error(tmp_path):
    proc = _run(["stim:dark_looming?size=48", "--compiler", "gcc", "--out", str(tmp_path)], "")
    assert proc.returncode == 2
    assert "--compiler" in proc.stderr


@pytest.mark.parametrize("compiler", installed_compilers())
def test_cuda_arch_runs_or_fails_with_one_line(compiler, tmp_path):
    # on a GPU machine the CUDA path runs; elsewhere it is a one-line error, exit code 2
    proc = _run(["stim:dark_looming?size=48", "--arch", "cuda", "--out", str(tmp_path), "--no-progress"], compiler)
    if proc.returncode == 0:
        assert list(tmp_path.glob("*.cdnf.csv"))
    else:
        assert proc.returncode == 2
        err = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert len(err) == 1 and err[0].startswith("error:") and "cuda" in err[0], proc.stderr


def test_kernel_modules_are_built_for_the_runtimes_dsl():
    from cdnf_ti.kernels import common
    from cdnf_ti.models import MODELS
    from cdnf_ti.taichi_runtime import dsl, kernels

    for name in sorted({m.kernels for m in MODELS.values() if isinstance(m.kernels, str)}) + ["common", "stimuli"]:
        built = kernels(name)
        dsl_of = built.engine.ti if hasattr(built, "engine") else built.ti  # a model on the engine core: its engine's
        assert dsl_of is dsl() and kernels(name) is built  # built once per process
    assert np.isfinite(float(common.MAX_STEPS))  # the constants need no compiler


@pytest.mark.parametrize("compiler", installed_compilers())
def test_limit_cpu_threads_sizes_the_pool_under_each_compiler(compiler):
    # taichi reads TI_CPU_MAX_NUM_THREADS, quadrants QD_CPU_MAX_NUM_THREADS: worker processes set both
    from cdnf_ti.taichi_runtime import THREADS_ENV

    code = ("from cdnf_ti.taichi_runtime import cpu_threads, ensure_taichi, limit_cpu_threads\n"
            "limit_cpu_threads(3)\nensure_taichi('cpu')\nprint(cpu_threads())")
    env = {k: v for k, v in os.environ.items() if k not in THREADS_ENV}
    env[COMPILER_ENV] = compiler
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split()[-1] == "3"


def test_a_kernel_compile_error_still_names_the_file_and_line():
    # taichi's parser notes positions as one line (taichi_runtime._one_line_source_positions)
    ensure_taichi("cpu")
    from cdnf_ti.taichi_runtime import dsl

    ti = dsl()

    @ti.kernel
    def broken(x: ti.f32) -> ti.f32:
        return x + not_defined_anywhere  # noqa: F821

    source = Path(__file__).read_text().splitlines()
    line = 1 + next(k for k, text in enumerate(source) if text.strip().startswith("return x + not_defined_anywhere"))
    with pytest.raises(Exception) as err:
        broken(1.0)
    msg = str(err.value)
    assert "not_defined_anywhere" in msg and f'test_compilers.py", line {line}' in msg


def test_the_compile_cache_keeps_a_gigabyte_of_kernels_before_it_evicts_any():
    # both compilers default to 100 MiB, less than the kernels of the five models at a few sizes
    from cdnf_ti.taichi_runtime import CACHE_MAX_BYTES, dsl

    ensure_taichi("cpu")
    cfg = dsl().lang.impl.current_cfg()
    assert cfg.offline_cache and cfg.offline_cache_max_size_of_files == CACHE_MAX_BYTES >= 1 << 30


def test_the_compile_cache_is_cdnf_tis_own_folder_in_the_user_cache(monkeypatch, tmp_path):
    monkeypatch.delenv(CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_folder("taichi") == str(tmp_path / "xdg" / "cdnf_ti" / "taichi")
    assert cache_folder("quadrants") == str(tmp_path / "xdg" / "cdnf_ti" / "quadrants")
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert cache_folder("taichi") == str(tmp_path / ".cache" / "cdnf_ti" / "taichi")


def test_cdnf_ti_cache_dir_names_the_compile_cache_folder(monkeypatch, tmp_path):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "kernels"))
    assert cache_folder("taichi") == cache_folder("quadrants") == str(tmp_path / "kernels")


def test_the_runtime_keeps_its_kernels_in_cdnf_tis_cache_folder():
    from cdnf_ti.taichi_runtime import dsl

    ensure_taichi("cpu")
    folder = dsl().lang.impl.current_cfg().offline_cache_file_path
    assert os.path.abspath(folder) == cache_folder(current_compiler())


_KERNELS = """
@ti.kernel
def fill(a: ti.types.ndarray(), c: ti.template()):
    for i in a:
        a[i] = i * c
a = np.zeros(8, np.float32)
for c in range(N):
    fill(a, c)
"""


@pytest.mark.parametrize("compiler", installed_compilers())
def test_another_taichi_program_with_a_small_cache_evicts_none_of_cdnf_tis_kernels(compiler, tmp_path):
    # every runtime trims the folder it uses to its own size limit (least recently used first, a quarter at a time)
    env = {k: v for k, v in os.environ.items() if k not in (CACHE_ENV, "XDG_CACHE_HOME")}
    env.update({COMPILER_ENV: compiler, "HOME": str(tmp_path)})
    ours = ("import numpy as np\nfrom cdnf_ti.taichi_runtime import dsl, ensure_taichi\n"
            "ensure_taichi('cpu')\nti = dsl()\nN = 8\n" + _KERNELS)
    other = (f"import numpy as np\nimport {compiler} as ti\n"
             "ti.init(arch=ti.cpu, offline_cache=True, offline_cache_max_size_of_files=1)\nN = 12\n" + _KERNELS)
    folder = tmp_path / ".cache" / "cdnf_ti" / compiler

    def files(root):
        return sorted(p.relative_to(root) for p in root.rglob("*") if p.is_file())

    # the other program runs twice: a runtime trims what it found in its folder, not what it just added
    for name, code in (("ours.py", ours), ("other.py", other), ("other.py", other)):  # kernels need a file
        (tmp_path / name).write_text(code)
        proc = subprocess.run([sys.executable, str(tmp_path / name)], cwd=REPO, env=env, capture_output=True,
                              text=True)
        assert proc.returncode == 0, proc.stderr[-2000:]
        if code is ours:
            kept = files(folder)
    theirs = files(tmp_path / ".cache" / compiler)
    assert len(kept) > 8 and files(folder) == kept
    assert 0 < len(theirs) < 12  # the other program's own folder was trimmed


@pytest.mark.parametrize("compiler", installed_compilers())
def test_the_lane_width_of_the_fast_path_suits_the_compiler(compiler):
    # both compilers run the lane kernels fastest with 32 lanes
    # (docs/PERFORMANCE.md, "Design decisions that still hold")
    code = ("from cdnf_ti.taichi_runtime import ensure_taichi\nensure_taichi('cpu')\n"
            "from cdnf_ti.taichi_runtime import kernels\n"
            "print(kernels('common').LANES, kernels('cdnf').engine.LANES, kernels('olgmd').engine.LANES)")
    env = dict(os.environ, **{COMPILER_ENV: compiler})
    env.pop(LANES_ENV, None)
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    want = {"taichi": 32, "quadrants": 32}[compiler]
    assert proc.stdout.split()[-3:] == [str(want)] * 3


_LANES_CHILD = """
import numpy as np
from cdnf_ti import CDNF
from cdnf_ti.bench.inputs import standin_video
from cdnf_ti.taichi_runtime import kernels
frames = [f[::2, ::2] for f in standin_video(6, seed=2)]
fast = CDNF()
a = fast.run(frames)
b = CDNF(backend="numpy").run(frames)
print(kernels('common').LANES, fast._be.lane, np.max(np.abs(a.output - b.output)))
"""


def test_the_lane_count_can_be_set_for_another_cpu_and_gives_the_same_output():
    compiler = current_compiler()
    env = dict(os.environ, **{COMPILER_ENV: compiler, LANES_ENV: "8"})  # not the default of either compiler
    proc = subprocess.run([sys.executable, "-c", _LANES_CHILD], cwd=REPO, env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lanes, lane_path, max_diff = proc.stdout.split()[-3:]
    assert (lanes, lane_path) == ("8", "True")
    assert float(max_diff) < 1e-4  # same equations on dashcam-like video, against the float64 reference


def test_an_unsupported_lane_count_is_a_one_line_error(tmp_path):
    env = dict(os.environ, **{LANES_ENV: "12"})
    proc = subprocess.run([sys.executable, "-m", "cdnf_ti.run", "demo", "--size", "64"], cwd=tmp_path, env=env,
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.startswith(f"error: ${LANES_ENV}='12':") and proc.stderr.count("\n") == 1


_IR = """
define void @run_lanes_c86_0_kernel_0_serial(ptr %context) {
  %a = fadd float %x, 1.000000e+00
  %b = fmul reassoc ninf nsz afn <8 x float> %v, %w
  %c = fadd <8 x float> %b, %b
  %d = fsub <4 x float> %u, %u
  %e = add i32 1, 2
  %f = fadd double %y, 1.000000e+00
  %g = fneg float %a
  %h = load <8 x float>, ptr %context, align 4
  store <8 x float> %c, ptr %context, align 4
  ret void
}
"""


def test_the_simd_report_counts_float_arithmetic_by_vector_width():
    from cdnf_ti.bench.simd import float_arith_widths, vector_share

    widths = float_arith_widths(_IR)  # loads, stores, integer and double arithmetic are not counted
    assert widths == {1: 2, 8: 2, 4: 1}
    assert vector_share(widths) == pytest.approx(0.6)


def test_the_simd_report_reads_only_the_solve_launches(tmp_path):
    from cdnf_ti.bench.simd import kernel_widths

    (tmp_path / "x_kernel_cpu_llvm_ir_optimized_0000.ll").write_text(_IR)
    other = _IR.replace("run_lanes", "run_pixels")  # a launch that is not on the lane layout
    (tmp_path / "x_kernel_cpu_llvm_ir_optimized_0001.ll").write_text(other)
    assert kernel_widths(str(tmp_path)) == {"lane launches (solves among them)": {1: 2, 8: 2, 4: 1}}


@pytest.mark.parametrize("compiler", installed_compilers())
def test_the_simd_report_inspects_both_solve_launches_under_each_compiler(compiler):
    from cdnf_ti.bench.simd import SOLVE_KERNELS, measure_simd, vector_share
    from cdnf_ti.kernels.common import lane_count

    rows = measure_simd([compiler], size=(48, 100))
    assert [(c, label) for c, label, _ in rows] == [(compiler, label) for _, label in SOLVE_KERNELS]
    assert all(sum(w.values()) > 50 for _, _, w in rows)  # the whole update loop, not a stub
    # the solves compile with explicit vector types (taichi_runtime.vector_kernel): their arithmetic stays
    # in whole lane vectors, which the code generator lowers to the host's widest registers
    for _, _, widths in rows:
        assert max(widths, key=widths.get) == lane_count(compiler)
        lanes_done = {w: w * n for w, n in widths.items()}  # float operations, each lane counted
        assert vector_share(lanes_done) > 0.95  # the scalar rest: per-row bookkeeping
