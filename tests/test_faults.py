"""Fault behaviour a batch user can trust (issue 12): interrupts, dead workers, missing devices, clashing
names, paths, output errors, size limits, locks. Each test is one fault; several run a real subprocess."""
from __future__ import annotations

import csv
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from cdnf_ti.run import main
from cdnf_ti.stimuli.basic import basic_stimulus

REPO = Path(__file__).resolve().parents[1]
TESTS = Path(__file__).resolve().parent
ENV = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), str(TESTS), os.environ.get("PYTHONPATH", "")]))
linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="uses /proc and Linux signals")


#: A child that was told to stop (signal, killed parent) and still runs after this long is hung; its slow
#: tasks (fault_tasks.SLOW_TASK_S) take far longer, so a pass never depends on how fast the machine is.
HUNG_S = 600


def _cli(*args: str, timeout: float | None = None, **kw) -> subprocess.CompletedProcess:
    """Run the command line in a child process; by default however long it takes (a slow machine is no fault)."""
    return subprocess.run([sys.executable, "-m", "cdnf_ti.run", *args], capture_output=True, text=True,
                          timeout=timeout, env=ENV, **kw)


#: Runs the command in argv[2:] as its own child and writes that child's peak resident memory (KiB on
#: Linux) to the file argv[1]. A small interpreter forks it, so the figure is the command's own: a child
#: forked straight from a test process that has grown (kernels, frames) starts at that process's size.
_PEAK_LAUNCHER = (
    "import os, subprocess, sys\n"
    "p = subprocess.Popen(sys.argv[2:])\n"
    "_, status, usage = os.wait4(p.pid, 0)\n"
    "open(sys.argv[1], 'w').write(str(usage.ru_maxrss))\n"
    "sys.exit(os.waitstatus_to_exitcode(status))\n"
)


def _cli_and_peak_memory(*args: str) -> tuple[subprocess.CompletedProcess, int | None]:
    """Run the command line in a child; also return its peak resident memory in bytes (None: not measurable here)."""
    cmd = [sys.executable, "-m", "cdnf_ti.run", *args]
    if not hasattr(os, "wait4"):
        return subprocess.run(cmd, capture_output=True, text=True, env=ENV), None
    with tempfile.TemporaryDirectory() as d:
        peak_file = Path(d) / "peak"
        proc = subprocess.run([sys.executable, "-c", _PEAK_LAUNCHER, str(peak_file), *cmd], capture_output=True,
                              text=True, env=ENV)
        kib = 1 if sys.platform == "darwin" else 1024  # ru_maxrss: bytes on macOS, KiB elsewhere
        return proc, int(peak_file.read_text()) * kib


def _children(pid: int) -> list[int]:
    kids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                kids.append(int(d.name))
    return kids


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.fixture
def looming_npy(tmp_path):
    s = basic_stimulus("dark_looming", height=48, width=48, start_half_size=0.8)
    path = tmp_path / "looming.npy"
    np.save(path, np.stack(list(s.frames())))
    return path


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory) -> Path:
    from cdnf_ti.experiments.synthetic import make_synthetic_dataset

    folder = tmp_path_factory.mktemp("faults_ds")
    make_synthetic_dataset(folder, size=48, clips=("dark_looming", "light_translating", "dark_receding"))
    return folder


# --- 1. Ctrl-C on parallel runs ---------------------------------------------------------------------------

def _start_slow_map() -> subprocess.Popen:
    code = "import fault_tasks\nif __name__ == '__main__':\n    fault_tasks.main_map_slow()\n"
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, env=ENV)
    first = p.stdout.readline()
    assert first.startswith("done 0"), first + p.stderr.read()
    return p


@linux_only
def test_sigint_cancels_pending_tasks_and_exits_130():
    p = _start_slow_map()
    p.send_signal(signal.SIGINT)
    rc = p.wait(timeout=HUNG_S)  # the slow tasks (an hour each) were not waited for
    assert rc == 130
    assert "interrupted" in p.stdout.read()


@linux_only
def test_second_sigint_exits_at_once():
    p = _start_slow_map()
    p.send_signal(signal.SIGINT)
    time.sleep(0.02)
    p.send_signal(signal.SIGINT)
    rc = p.wait(timeout=HUNG_S)
    assert rc == 130


@linux_only
def test_sigint_on_parallel_dataset_run_keeps_finished_clips_and_resume_skips_them(small_dataset, tmp_path):
    ds = tmp_path / "ds"
    shutil.copytree(small_dataset, ds)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "cdnf_ti.run", "dataset", str(ds), "--out", str(out), "--workers", "2",
           "--no-figures"]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    while not list(out.glob("traces/clean/*.json")) and p.poll() is None:  # until a clip has finished
        time.sleep(0.05)
    finished = sorted(x.name for x in out.glob("traces/clean/*.json"))
    p.send_signal(signal.SIGINT)
    rc = p.wait(timeout=HUNG_S)
    err = p.stderr.read()
    if rc == 0:
        pytest.skip("the run finished before the interrupt arrived (machine too fast for this test)")
    assert rc == 130, err
    assert finished, "no clip finished before the run ended"
    assert "Traceback" not in err and "interrupted" in err
    kept = sorted(x.name for x in out.glob("traces/clean/*.json"))
    assert set(finished) <= set(kept)  # the clips finished before the interrupt are kept
    assert not list(out.rglob("*.tmp*"))
    proc = _cli("dataset", str(ds), "--out", str(out), "--workers", "0", "--no-figures", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert f"{len(kept)} reused" in proc.stdout


# --- 5. dead workers and orphans ---------------------------------------------------------------------------

def test_dead_worker_task_is_retried_once_then_recorded_as_failed():
    from fault_tasks import die_on

    from cdnf_ti.experiments.parallel import TaskFailed, map_tasks

    res = dict(map_tasks(die_on, ["a", "die", "b", "c"], workers=2, arch=None))
    assert [res[i] for i in (0, 2, 3)] == ["a", "b", "c"]  # the other tasks are not lost
    assert isinstance(res[1], TaskFailed) and "died" in str(res[1]) and "2 times" in str(res[1])


def test_task_whose_worker_died_once_succeeds_on_retry(tmp_path):
    from fault_tasks import die_first_time

    from cdnf_ti.experiments.parallel import map_tasks

    res = dict(map_tasks(die_first_time, [None, str(tmp_path / "m1"), None], workers=2, arch=None))
    assert res == {0: "ok", 1: "ok", 2: "ok"}
    assert (tmp_path / "m1").read_text() == "died once"


@linux_only
def test_killing_the_main_process_leaves_no_orphan_workers():
    p = _start_slow_map()
    workers = [k for k in _children(p.pid) if "multiprocessing" in Path(f"/proc/{k}/cmdline").read_text()]
    assert workers
    p.kill()
    p.wait()
    deadline = time.monotonic() + HUNG_S  # the workers' tasks sleep far longer: alive then means orphaned
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(_alive(w) for w in workers)


def test_dataset_headline_states_scored_and_failed_clips(small_dataset, tmp_path):
    ds = tmp_path / "ds"
    shutil.copytree(small_dataset, ds)
    (ds / "broken.avi").write_bytes(b"not a video" * 100)
    with open(ds / "labels.csv", "a") as f:
        f.write("broken,non-collision,,,,,corrupt\n")
    proc = _cli("dataset", str(ds), "--out", str(tmp_path / "o"), "--workers", "0", "--no-figures",
                "--no-progress")
    assert proc.returncode == 1
    assert "cdnf, clean: accuracy" in proc.stdout
    assert "over 3 scored clip(s) of 4; 1 failed (not scored)" in proc.stdout


# --- 2. unavailable arch -----------------------------------------------------------------------------------

@pytest.mark.parametrize("command", ["run", "demo", "dataset", "experiment"])
def test_unavailable_arch_is_one_line_and_exit_2(command, looming_npy, small_dataset, tmp_path):
    from cdnf_ti.taichi_runtime import BackendUnavailableError, check_arch

    try:
        check_arch("gpu")
        pytest.skip("a GPU backend is available here; the error path cannot be exercised")
    except BackendUnavailableError:
        pass
    out = str(tmp_path / "o")
    args = {"run": [str(looming_npy), "--out", out],
            "demo": ["demo", "--size", "32", "--no-progress"],
            "dataset": ["dataset", str(small_dataset), "--out", out, "--workers", "2"],
            "experiment": ["experiment", "table1", "--out", out, "--size", "32", "--workers", "2"]}[command]
    proc = _cli(*args, "--arch", "gpu")
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "BrokenProcessPool" not in proc.stderr
    assert proc.stderr.strip().splitlines() == [
        "error: Taichi backend 'gpu' is not available on this machine (no driver/device found); use --arch cpu"]
    assert not (tmp_path / "o" / "results.csv").exists() and not (tmp_path / "o" / "table1.md").exists()


# --- 3. inputs sharing a stem ------------------------------------------------------------------------------

def test_inputs_sharing_a_stem_get_distinct_output_names(looming_npy, tmp_path, capsys):
    for d in ("A", "B"):
        (tmp_path / d).mkdir()
    shutil.copy(looming_npy, tmp_path / "A" / "clip.npy")
    frames = np.load(looming_npy)
    np.save(tmp_path / "B" / "clip.npy", frames[:20])  # a different clip with the same stem
    out = tmp_path / "o"
    assert main([str(tmp_path / "A" / "clip.npy"), str(tmp_path / "B" / "clip.npy"), "--out", str(out),
                 "--no-progress"]) == 0
    a = list(csv.DictReader(open(out / "A_clip.cdnf.csv")))
    b = list(csv.DictReader(open(out / "B_clip.cdnf.csv")))
    assert (len(a), len(b)) == (len(frames), 20)
    assert not (out / "clip.cdnf.csv").exists()
    assert [r["clip"] for r in csv.DictReader(open(out / "summary.csv"))] == ["A_clip", "B_clip"]


def test_unique_names_numbers_names_that_still_clash():
    from cdnf_ti.run import unique_names

    assert unique_names(["x/a.mp4", "y/b.mp4"], ["a", "b"]) == ["a", "b"]
    assert unique_names(["A/clip.mp4", "B/clip.avi"], ["clip", "clip"]) == ["A_clip", "B_clip"]
    assert unique_names(["A/clip.mp4", "A/clip.avi", "B/Clip.npy"], ["clip", "clip", "Clip"]) == [
        "A_clip", "A_clip-2", "B_Clip"]
    assert unique_names(["stim:a", "stim:a"], ["a", "a"]) == ["a", "a-2"]


# --- 4. paths ----------------------------------------------------------------------------------------------

def test_resume_recognises_the_same_input_given_relative_or_absolute(small_dataset, tmp_path, monkeypatch):
    from cdnf_ti.experiments.dataset import run_dataset

    shutil.copytree(small_dataset, tmp_path / "ds")
    monkeypatch.chdir(tmp_path)
    first = run_dataset("ds", None, "out", models=["cdnf"], workers=0, progress=False, figures=False)
    assert first.ran == 3
    again = run_dataset(tmp_path / "ds", None, tmp_path / "out", models=["cdnf"], workers=0, progress=False,
                        figures=False)
    assert (again.ran, again.skipped) == (0, 3)


def test_paths_sent_to_workers_are_absolute(small_dataset, tmp_path, monkeypatch):
    from cdnf_ti.experiments import dataset as ds_mod

    shutil.copytree(small_dataset, tmp_path / "ds")
    monkeypatch.chdir(tmp_path)
    seen = []

    def fake_map(fn, tasks, **kw):
        seen.extend(tasks)
        return iter(())

    monkeypatch.setattr("cdnf_ti.experiments.parallel.map_tasks", fake_map)
    ds_mod.run_dataset("ds", None, "out", models=["cdnf"], workers=2, progress=False, figures=False)
    assert seen and all(os.path.isabs(t.path) and os.path.isabs(t.out) for t in seen)
    assert all(Path(t.path).is_file() for t in seen)


def test_dask_worker_in_another_folder_runs_relative_paths(small_dataset, tmp_path, monkeypatch):
    distributed = pytest.importorskip("distributed")
    from cdnf_ti.experiments.dataset import run_dataset

    shutil.copytree(small_dataset, tmp_path / "ds")
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")  # the workers start here ...
    with distributed.LocalCluster(n_workers=1, processes=True, threads_per_worker=1, dashboard_address=None,
                                  silence_logs=40) as cluster:
        monkeypatch.chdir(tmp_path)  # ... and the run is given paths relative to here
        run = run_dataset("ds", None, "out", models=["cdnf"], scheduler=cluster.scheduler_address,
                          progress=False, figures=False)
    assert run.ran == 3 and not run.failed


# --- 6. output errors --------------------------------------------------------------------------------------

def test_unwritable_output_folder_fails_before_any_work(looming_npy, tmp_path):
    if os.geteuid() == 0:
        ro = Path("/sys/fs")  # root may write anywhere a chmod forbids; sysfs refuses even root
        if not ro.is_dir():
            pytest.skip("no read-only folder available to root here")
    else:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
    proc = _cli(str(looming_npy), "--out", str(ro))
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [proc.stderr.strip()]
    assert proc.stderr.startswith(f"error: {ro}: output folder is not writable")
    assert "frames" not in proc.stdout  # no model ran


def test_write_error_names_the_path(tmp_path, monkeypatch):
    import errno

    from cdnf_ti.atomic import atomic_write_text
    from cdnf_ti.errors import OutputError

    def full(*a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "replace", full)
    target = tmp_path / "results.csv"
    with pytest.raises(OutputError) as e:
        atomic_write_text(target, "x")
    assert str(e.value) == f"{target}: No space left on device"
    assert not list(tmp_path.iterdir())  # no temporary file left behind


def _file_size_limit(limit: int):
    def apply() -> None:
        import resource

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes past the limit fail instead of killing us
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return apply


@linux_only
def test_generate_on_a_full_disk_names_the_file_and_not_the_frame_rate(tmp_path):
    out = tmp_path / "loom.avi"
    proc = subprocess.run([sys.executable, "-m", "cdnf_ti.run", "generate", "dark_looming", "--size", "200",
                           "--out", str(out), "--no-progress"], capture_output=True, text=True,
                          env=ENV, preexec_fn=_file_size_limit(8_000))
    assert proc.returncode == 2, proc.stderr
    assert "frame rate" not in proc.stderr and "PNG" not in proc.stderr
    assert proc.stderr.startswith(f"error: {out}: ") and "Traceback" not in proc.stderr
    assert not out.exists()


# --- 7. size and drop-count limits -------------------------------------------------------------------------

@pytest.mark.parametrize("args", [
    ["demo", "--size", "20000"],
    ["generate", "dark_looming", "--size", "20000", "--out", "{tmp}/x.avi"],
    ["stim:dark_looming?size=20000", "--out", "{tmp}/o"],
    ["stim:dark_looming?height=6000&width=90000", "--out", "{tmp}/o"],
    ["{npy}", "--rain", "--rain-drops", "100000000", "--out", "{tmp}/o"],
    ["{npy}", "--rain", "--rain-drops", "1e8", "--out", "{tmp}/o"],
    ["{npy}", "--rain", "--rain-drops", "50000", "--out", "{tmp}/o"],  # more drops than the 48x48 frame has px
])
def test_impossible_sizes_and_drop_counts_are_rejected_up_front(args, looming_npy, tmp_path):
    argv = [a.format(tmp=tmp_path, npy=looming_npy) for a in args]
    proc, peak_bytes = _cli_and_peak_memory(*argv)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    err = [ln for ln in proc.stderr.splitlines() if ln.strip() and not ln.startswith(("usage:", " "))]
    assert len(err) == 1 and "error:" in err[0] and "Traceback" not in proc.stderr  # (argparse adds usage)
    assert "MemoryError" not in proc.stderr
    if peak_bytes is not None:  # rejected before any frame was made (one 20000 x 20000 float32 frame: 1.6 GB)
        assert peak_bytes < 1 << 30, f"peak memory {peak_bytes / 2**20:.0f} MiB"


def test_limits_allow_ordinary_sizes():
    from cdnf_ti.limits import check_drops, check_frame_size

    check_frame_size(1080, 1920, n_models=5)
    check_drops(500, (240, 426))
    check_drops(None, (2, 2))


# --- 8. smaller defects ------------------------------------------------------------------------------------

@pytest.mark.parametrize("value", ["inf", "nan", "-inf"])
def test_non_finite_epsilon_is_rejected(value, looming_npy, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main([str(looming_npy), "--epsilon", value, "--out", str(tmp_path / "o")])
    assert e.value.code == 2
    assert "--epsilon" in capsys.readouterr().err


def test_one_frame_input_prints_no_nan_fps(tmp_path, capsys):
    one = tmp_path / "one.npy"
    np.save(one, np.full((1, 32, 32), 0.5, np.float32))
    assert main([str(one), "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "nan" not in out.lower() and "n/a fps" in out
    assert "nan" not in (tmp_path / "o" / "summary.csv").read_text().lower()


def test_json_files_never_hold_infinity_or_nan(tmp_path):
    from cdnf_ti.atomic import atomic_write_json

    atomic_write_json(tmp_path / "x.json", {"fps": float("inf"), "snr": [float("nan"), np.float32(2.5)]})
    text = (tmp_path / "x.json").read_text()
    assert "Infinity" not in text and "NaN" not in text
    assert json.loads(text) == {"fps": None, "snr": [None, 2.5]}


def test_videos_without_a_label_are_noted(small_dataset, tmp_path):
    ds = tmp_path / "ds"
    shutil.copytree(small_dataset, ds)
    shutil.copy(ds / "dark_looming.avi", ds / "extra_clip.avi")
    proc = _cli("dataset", str(ds), "--out", str(tmp_path / "o"), "--workers", "0", "--no-figures",
                "--no-progress")
    assert proc.returncode == 0, proc.stderr
    notes = [ln for ln in proc.stderr.splitlines() if ln.startswith("note:")]
    assert len(notes) == 1 and "1 video(s)" in notes[0] and "extra_clip.avi" in notes[0]


def test_rgb_colour_order_option_for_npy_arrays(tmp_path):
    from cdnf_ti.frames import iter_grey, open_source

    rgb = np.zeros((2, 8, 8, 3), np.uint8)
    rgb[..., 0] = 255  # pure red in RGB order
    np.save(tmp_path / "red.npy", rgb)
    as_rgb = next(iter(iter_grey(open_source(tmp_path / "red.npy", color_order="rgb"), prefetch=0)))
    as_bgr = next(iter(iter_grey(open_source(tmp_path / "red.npy"), prefetch=0)))
    assert as_rgb[0, 0] == 76  # BT.601: 0.299 * 255 (red)
    assert as_bgr[0, 0] == 29  # 0.114 * 255: the same array read as BGR is blue


def test_fps_option_sets_the_frame_rate_of_image_folders_and_npy(looming_npy, tmp_path, capsys):
    import cv2

    from cdnf_ti.frames import open_source

    folder = tmp_path / "frames"
    folder.mkdir()
    for t, f in enumerate(np.load(looming_npy)[:3]):
        cv2.imwrite(str(folder / f"{t:03d}.png"), (f * 255).astype(np.uint8))
    assert open_source(folder).fps == 30.0 and open_source(folder, fps=12.5).fps == 12.5
    assert open_source(looming_npy, fps=60).fps == 60
    assert main([str(looming_npy), "--fps", "60", "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    line = capsys.readouterr().out
    fa = int(line.split("first alert ")[1].split()[0])
    assert f"({fa / 60:.2f} s)" in line


def test_second_run_into_a_locked_output_folder_waits_then_runs(looming_npy, tmp_path):
    from cdnf_ti.atomic import output_lock

    out = tmp_path / "o"
    out.mkdir()
    with output_lock(out):
        p = subprocess.Popen([sys.executable, "-m", "cdnf_ti.run", str(looming_npy), "--out", str(out),
                              "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
        line = p.stderr.readline()
        assert line.startswith("note: ") and "another cdnf_ti run" in line and "waiting" in line
        time.sleep(0.5)
        assert p.poll() is None and not (out / "looming.cdnf.csv").exists()  # it waits, writes nothing
    assert p.wait() == 0
    assert (out / "looming.cdnf.csv").exists()


def test_gitignore_lists_the_default_output_folders():
    lines = (REPO / ".gitignore").read_text().splitlines()
    assert "cdnf_out/" in lines and "cdnf_experiments/" in lines


# --- error handling ----------------------------------------------------------------------------------------

def test_user_error_is_one_line_exit_2(monkeypatch, capsys):
    from cdnf_ti import run
    from cdnf_ti.errors import UserError

    def bad(argv):
        raise UserError("clip.mp4: something the user can fix")

    monkeypatch.setattr(run, "run_videos", bad)
    assert main(["x.mp4"]) == 2
    assert capsys.readouterr().err == "error: clip.mp4: something the user can fix\n"


def test_bug_keeps_its_traceback(monkeypatch):
    from cdnf_ti import run

    def bug(argv):
        raise ValueError("internal inconsistency")

    monkeypatch.setattr(run, "run_videos", bug)
    with pytest.raises(ValueError, match="internal inconsistency"):
        main(["x.mp4"])


def test_one_failing_model_gives_an_error_row_for_that_model_only(small_dataset, tmp_path):
    from cdnf_ti.experiments.dataset import run_dataset
    from cdnf_ti.models import MODELS, register_model
    from cdnf_ti.models.sdnf import SDNF

    class Broken(SDNF):
        name = "broken_for_test"

        def step(self, frame):
            raise RuntimeError("model bug")

    register_model(Broken)
    try:
        run = run_dataset(small_dataset, None, tmp_path / "o", models=["cdnf", "broken_for_test"], workers=0,
                          progress=False, figures=False)
    finally:
        MODELS.pop("broken_for_test", None)
    errs = {(r["clip"], r["model"]) for r in run.rows if r["error"]}
    assert errs == {(c, "broken_for_test") for c in ("dark_looming", "light_translating", "dark_receding")}
    assert all(r["outcome"] for r in run.rows if r["model"] == "cdnf")
    assert "model bug" in run.rows[1]["error"]


# --- embedding hazards -------------------------------------------------------------------------------------

def test_atomic_writer_never_changes_the_process_umask(tmp_path, monkeypatch):
    from cdnf_ti.atomic import atomic_write_text

    def no(*a):
        raise AssertionError("os.umask called")

    monkeypatch.setattr(os, "umask", no)
    atomic_write_text(tmp_path / "a.txt", "x")
    assert (tmp_path / "a.txt").read_text() == "x"


def test_library_adopts_a_host_programs_taichi_runtime():
    code = (
        "import taichi as ti\n"
        "ti.init(arch=ti.cpu, log_level=ti.WARN)\n"
        "x = ti.field(ti.f32, shape=4)\n"
        "x[2] = 7.0\n"
        "import numpy as np\n"
        "from cdnf_ti import CDNF\n"
        "from cdnf_ti.taichi_runtime import ensure_taichi\n"
        "assert ensure_taichi('cpu') == 'cpu'\n"
        "CDNF().run(np.random.default_rng(0).random((3, 32, 32), dtype=np.float32))\n"
        "print('kept', x[2])\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV)
    assert proc.returncode == 0, proc.stderr
    assert "kept 7.0" in proc.stdout


def test_progress_outside_a_terminal_is_one_line_per_task_and_a_summary(capsys):
    from fault_tasks import sleep_then_pid

    from cdnf_ti.experiments.parallel import map_tasks

    list(map_tasks(sleep_then_pid, [0.0, 0.0, 0.0], workers=0, progress="clips",
                   describe=lambda t, r: f"clip{t} [cdnf, clean]" + ("" if r is None else ": 0.0 s")))
    err = capsys.readouterr().err.splitlines()
    assert err[:3] == [f"[{k}/3] clip0.0 [cdnf, clean]: 0.0 s" for k in (1, 2, 3)]
    assert err[3].startswith("clips: 3 of 3 tasks finished, 0 failed, ") and len(err) == 4


def test_failed_task_is_reported_in_the_log(capsys):
    from cdnf_ti.experiments.parallel import map_tasks

    list(map_tasks(math.sqrt, [4.0, -1.0], workers=0, progress="t"))
    err = capsys.readouterr().err
    assert "[2/2] task 2" in err and "error: ValueError: math domain error" in err
    assert "1 failed" in err


def test_table1_shows_error_for_a_failed_run_not_none():
    from cdnf_ti.demo import format_table1
    from cdnf_ti.stimuli.basic import BASIC_STIMULI

    res = {"cdnf": {s: {"alert": 1 if "looming" in s or "receding" in s else 0} for s in BASIC_STIMULI}}
    res["cdnf"]["dark_looming"] = {"alert": None, "error": "its worker process died"}
    table = format_table1(res)
    assert "None" not in table
    assert "| Dark approaching | error |" in table


def test_temporary_files_of_dead_writers_are_removed(tmp_path):
    from cdnf_ti.atomic import _new_temp, remove_stale_temps

    (tmp_path / "traces").mkdir()
    live = Path(_new_temp(tmp_path / "traces" / "a.csv"))  # this process: still writing
    dead = tmp_path / "traces" / ".b.csv.999999999.0123abcd.tmp.csv"  # no such process
    dead.write_text("half a trace")
    (tmp_path / "traces" / "c.csv").write_text("finished")
    assert remove_stale_temps(tmp_path) == 1
    assert live.exists() and not dead.exists() and (tmp_path / "traces" / "c.csv").exists()


def test_one_failing_model_in_run_gives_an_error_line_for_that_model_only(looming_npy, tmp_path, capsys):
    from cdnf_ti.models import MODELS, register_model
    from cdnf_ti.models.sdnf import SDNF

    class Broken(SDNF):
        name = "broken_for_run_test"

        def step(self, frame):
            raise RuntimeError("model bug")

    register_model(Broken)
    try:
        code = main([str(looming_npy), "--model", "cdnf,broken_for_run_test", "--out", str(tmp_path / "o"),
                     "--no-progress"])
    finally:
        MODELS.pop("broken_for_run_test", None)
    captured = capsys.readouterr()
    assert code == 1
    assert (tmp_path / "o" / "looming.cdnf.csv").exists()
    assert not (tmp_path / "o" / "looming.broken_for_run_test.csv").exists()
    errors = [ln for ln in captured.err.splitlines() if ln.startswith("error")]
    assert errors == [f"error: {looming_npy} [broken_for_run_test]: RuntimeError: model bug"]
    rows = list(csv.DictReader(open(tmp_path / "o" / "summary.csv")))
    assert [(r["model"], r["status"]) for r in rows] == [("cdnf", "ok"),
                                                          ("broken_for_run_test", "error: RuntimeError: model bug")]


# --- issue 37: names from data stay inside their folders ---------------------------------------------------

def _listing(root: Path, skip: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``root`` but those under ``skip``: relative name -> (size, mtime_ns)."""
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")
            if p.is_file() and skip not in p.parents}


@pytest.mark.parametrize("clip", ["../../../victim", "{victim}", "/etc/passwd"])
def test_clip_name_leaving_the_dataset_folder_is_rejected_naming_the_row(clip, small_dataset, tmp_path):
    top = tmp_path / "top"
    ds = top / "a" / "b" / "ds"  # ../../../victim from ds is top/victim
    shutil.copytree(small_dataset, ds)
    shutil.copy(ds / "dark_looming.avi", top / "victim.avi")  # a video outside the folder
    name = clip.format(victim=top / "victim.avi")
    with open(ds / "labels.csv", "a") as f:
        f.write(f"{name},non-collision,,,\n")
    out = top / "a" / "b" / "out"
    before = _listing(top, ds)
    proc = _cli("dataset", str(ds), "--out", str(out), "--workers", "0", "--no-progress", timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines() == [proc.stderr.strip()]
    assert proc.stderr.startswith(f"error: {ds / 'labels.csv'}: row 5 ({name}): clip name ")
    assert _listing(top, ds) == before  # nothing written outside the dataset folder (no --out work either)
    assert not list(top.rglob("victim.*.csv")) and not list(top.rglob("*victim*.png"))


@pytest.mark.parametrize("name", ["..", ".", "a/b", "a\\b", "/etc/passwd", "C:x", "", "x\0y"])
def test_a_name_that_is_not_plain_has_a_problem(name):
    from cdnf_ti.paths import name_problem

    assert name_problem(name) is not None


@pytest.mark.parametrize("name", ["clip", "clip.avi", "a..b", ".hidden", "my clip (1)"])
def test_a_plain_name_has_no_problem(name):
    from cdnf_ti.paths import name_problem

    assert name_problem(name) is None


@pytest.mark.parametrize("name", ["../x.csv", "/tmp/x.csv", "traces/../../x.csv"])
def test_output_path_built_from_a_name_that_leaves_its_folder_is_refused(name, tmp_path):
    from cdnf_ti.paths import PathEscapeError, inside

    with pytest.raises(PathEscapeError, match="must stay inside"):
        inside(tmp_path, name)
    assert inside(tmp_path, "traces/clean/c.cdnf.csv") == tmp_path / "traces" / "clean" / "c.cdnf.csv"


def test_trace_of_a_clip_named_with_dots_cannot_leave_the_output_folder(tmp_path):
    from cdnf_ti.experiments.layout import trace_path
    from cdnf_ti.paths import PathEscapeError

    with pytest.raises(PathEscapeError):
        trace_path(tmp_path, "clean", "../../victim", "cdnf")


# --- issue 37: content, not modification time ---------------------------------------------------------------

def test_video_changed_in_place_with_size_and_mtime_kept_is_recomputed_with_a_note(small_dataset, tmp_path,
                                                                                    capsys):
    from cdnf_ti.experiments.dataset import run_dataset

    ds = tmp_path / "ds"
    shutil.copytree(small_dataset, ds)
    clip = ds / "dark_looming.avi"
    old, new = clip.read_bytes(), (ds / "dark_receding.avi").read_bytes()
    size = max(len(old), len(new))  # both padded to one size (the AVI reader ignores trailing bytes)
    clip.write_bytes(old.ljust(size, b"\0"))
    kw = dict(models=["cdnf"], workers=0, progress=False, figures=False)
    assert run_dataset(ds, None, tmp_path / "out", **kw).ran == 3
    st = clip.stat()
    with open(clip, "r+b") as f:  # another video in place, as cp -p or rsync -t leave it
        f.write(new.ljust(size, b"\0"))
    os.utime(clip, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert (clip.stat().st_size, clip.stat().st_mtime_ns) == (st.st_size, st.st_mtime_ns)
    capsys.readouterr()
    again = run_dataset(ds, None, tmp_path / "out", **kw)
    assert (again.ran, again.skipped) == (1, 2)
    note = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("note: ")]
    assert len(note) == 1 and "dark_looming.cdnf [clean]: input file content" in note[0]


def test_content_digest_reads_both_ends_of_a_large_file(tmp_path):
    from cdnf_ti.provenance import CONTENT_SPAN, content_digest

    f = tmp_path / "big.bin"
    data = bytearray(3 * CONTENT_SPAN)
    f.write_bytes(data)
    digests = {content_digest(f)}
    for at in (0, len(data) - 1):
        changed = bytearray(data)
        changed[at] = 1
        f.write_bytes(changed)
        digests.add(content_digest(f))
    assert len(digests) == 3


# --- issue 37: frame size changes mid-video -----------------------------------------------------------------

def test_video_whose_frame_size_changes_mid_stream_is_rejected_naming_the_frame(tmp_path):
    from mjpeg_avi import mjpeg_avi, ramp_frames

    video = tmp_path / "resized.avi"
    video.write_bytes(mjpeg_avi(ramp_frames(5, 48, 64) + ramp_frames(5, 96, 80)))
    proc = _cli(str(video), "--out", str(tmp_path / "o"), "--no-progress", timeout=300)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    assert [ln for ln in proc.stderr.splitlines() if ln.startswith("error")] == [
        f"error: {video}: frame 5 is 80x96, the video states 64x48 (frame size changed mid-video)"]


def test_video_of_one_frame_size_reads_every_frame(tmp_path):
    from mjpeg_avi import mjpeg_avi, ramp_frames

    from cdnf_ti.frames import iter_grey, open_source

    video = tmp_path / "steady.avi"
    video.write_bytes(mjpeg_avi(ramp_frames(6, 48, 64)))
    frames = list(iter_grey(open_source(video), prefetch=0))
    assert len(frames) == 6 and frames[0].shape == (48, 64)


def test_jpeg_size_is_read_from_the_start_of_frame_marker():
    import cv2

    from cdnf_ti.frames import jpeg_size

    data = cv2.imencode(".jpg", np.zeros((37, 53), np.uint8))[1].tobytes()
    assert jpeg_size(data) == (53, 37)
    assert jpeg_size(data[:20]) is None and jpeg_size(b"not a jpeg") is None


# --- issue 37: signals ----------------------------------------------------------------------------------------

def _read_until(stream, text: str) -> list[str]:
    """Lines of ``stream`` up to and including the first that contains ``text`` (all of them at EOF)."""
    lines = []
    for line in stream:
        lines.append(line)
        if text in line:
            break
    return lines


def _wchan(pid: int) -> str:
    """What the main thread of process ``pid`` waits on in the kernel (``futex_do_wait``, ...)."""
    try:
        return Path(f"/proc/{pid}/wchan").read_text()
    except OSError:
        return ""


def _signal_process(p: subprocess.Popen) -> None:
    """Ctrl-C at the process ``p`` alone."""
    p.send_signal(signal.SIGINT)


def _terminate_process_group(p: subprocess.Popen) -> None:
    """SIGTERM at ``p``'s whole process group, as ``timeout`` or a job scheduler sends it."""
    os.killpg(p.pid, signal.SIGTERM)


@linux_only
@pytest.mark.parametrize("interrupt", [_signal_process, _terminate_process_group], ids=["ctrl-c", "group-sigterm"])
def test_an_interrupt_while_native_code_holds_the_interpreter_ends_the_run_and_keeps_finished_results(
        looming_npy, tmp_path, interrupt):
    stall = tmp_path / "stall.npy"  # stands for an input whose kernels compile: see fault_tasks
    shutil.copy(looming_npy, stall)
    out = tmp_path / "o"
    code = "import fault_tasks\nfault_tasks.main_run_with_native_stall()\n"
    p = subprocess.Popen([sys.executable, "-c", code, str(looming_npy), str(stall), "--backend", "numpy",
                          "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
                         start_new_session=True)  # its own process group
    try:
        lines = _read_until(p.stdout, "stalling")
        assert lines and "stalling" in lines[-1], "".join(lines) + p.stderr.read()
        finished = (out / "looming.cdnf.csv").read_bytes()
        deadline = time.monotonic() + 120
        while "futex" not in _wchan(p.pid) and time.monotonic() < deadline:  # until it waits in native code
            time.sleep(0.05)
        assert "futex" in _wchan(p.pid)
        interrupt(p)
        rc = p.wait(timeout=30)  # the stall never ends
    finally:
        p.kill()
        p.wait()
    err = p.stderr.read()
    assert rc != 0 and "Traceback" not in err and "Exception ignored" not in err
    assert "interrupted while native code (a kernel compile) holds the interpreter" in err
    assert (out / "looming.cdnf.csv").read_bytes() == finished
    assert not (out / "stall.cdnf.csv").exists()


def test_sweep_removes_temporary_files_of_dead_writers_on_start(small_dataset, tmp_path):
    from cdnf_ti.experiments.paramsweep import run_param_sweep

    out = tmp_path / "sweep"
    stale = out / "settings" / "x" / "traces" / "clean" / ".c.cdnf.json.999999999.0123abcd.tmp.json"
    stale.parent.mkdir(parents=True)
    stale.write_text("half a record")  # as a sweep stopped by Ctrl-C leaves it (its writer is gone)
    run_param_sweep(small_dataset, None, out, "cdnf", ["h=0.1,0.2"], workers=0, progress=False, figures=False,
                    html=False, backend="numpy")
    assert not stale.exists()
    assert not list(out.rglob("*.tmp*"))


@linux_only
@pytest.mark.parametrize("command", [["dataset"], ["experiment", "sweep"]])
def test_sigterm_stops_a_parallel_batch_run_like_ctrl_c(command, small_dataset, tmp_path):
    ds = tmp_path / "ds"
    shutil.copytree(small_dataset, ds)
    out = tmp_path / "out"
    extra = ["--model", "cdnf", "--param", "h=0.1,0.2,0.3"] if command[-1] == "sweep" else []
    p = subprocess.Popen([sys.executable, "-m", "cdnf_ti.run", *command, str(ds), *extra, "--out", str(out),
                          "--workers", "2", "--no-figures", "--no-progress"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    deadline = time.monotonic() + 120
    while len(_children(p.pid)) < 3 and time.monotonic() < deadline and p.poll() is None:  # the pool is up
        time.sleep(0.05)
    p.send_signal(signal.SIGTERM)
    rc = p.wait(timeout=60)
    err = p.stderr.read()  # until the resource tracker, which shares stderr, has ended too
    if rc == 0:
        pytest.skip("the run finished before the signal arrived (machine too fast for this test)")
    assert rc == 130, err
    assert "Traceback" not in err and "interrupted" in err
    assert "leaked semaphore" not in err and "resource_tracker" not in err
    assert not (out / ".cdnf_ti.lock").exists()
    assert not list(out.rglob("*.tmp*"))


#: A batch whose SIGTERM lands while ``spawn`` starts a worker: after the child is launched and before it has
#: been sent its start-up data (the race that once left a child printing "Ran out of input").
_SIGNAL_DURING_SPAWN = r"""
import multiprocessing.util, os, signal, sys
from cdnf_ti.experiments import parallel
from fault_tasks import SLOW_TASK_S, sleep_then_pid
launch = multiprocessing.util.spawnv_passfds
def launch_then_signal(path, args, passfds):
    pid = launch(path, args, passfds)
    if any("spawn_main" in str(a) for a in args):  # a worker, not the resource tracker
        os.kill(os.getpid(), signal.SIGTERM)
    return pid
multiprocessing.util.spawnv_passfds = launch_then_signal
parallel.handle_sigterm_as_interrupt()
try:
    list(parallel.map_tasks(sleep_then_pid, [SLOW_TASK_S] * 2, workers=2, arch=None))
except KeyboardInterrupt:
    print("interrupted", file=sys.stderr)
    sys.exit(130)
"""


@linux_only
def test_sigterm_while_a_worker_is_being_spawned_stops_that_worker_too():
    p = subprocess.run([sys.executable, "-c", _SIGNAL_DURING_SPAWN], capture_output=True, text=True, env=ENV,
                       timeout=120)  # stderr is read to its end: until every child that shares it has ended
    assert p.returncode == 130, p.stderr
    assert p.stderr.strip() == "interrupted"  # no traceback from a half-started worker


def test_second_signal_during_the_clean_stop_of_live_record_leaves_a_playable_recording(tmp_path, monkeypatch):
    import cv2

    from cdnf_ti.live import Recorder, _Signals
    from cdnf_ti.live_sources import Frame

    exits = []
    monkeypatch.setattr(os, "_exit", exits.append)  # the process would end here
    path = tmp_path / "rec.avi"
    recorder = Recorder(path, fps=30.0, backlog=512)
    image = np.zeros((64, 64), np.uint8)
    result = {"model": "cdnf", "output_name": "I_v", "value": 0.5, "alert": False, "latency_ms": 1.0}
    for t in range(300):  # a backlog the clean stop would still be writing
        recorder.put(Frame(t, image, 0.0, t / 30.0), [result])
    deadline = time.monotonic() + 120
    while recorder._queue.qsize() > 297 and time.monotonic() < deadline:  # the writer has taken 3 frames
        time.sleep(0.01)
    signals = _Signals(threading.Event(), recorder.finish_now)
    signals._handle(signal.SIGINT, None)  # Ctrl-C: the clean stop begins
    signals._handle(signal.SIGINT, None)  # Ctrl-C again: the process ends now
    assert exits == [130]
    cap = cv2.VideoCapture(str(path))
    frames = 0
    while cap.read()[0]:
        frames += 1
    cap.release()
    assert frames > 0
    assert not [p for p in tmp_path.iterdir() if p.name != "rec.avi"]  # no hidden temporary file left


@pytest.mark.parametrize("existing", [False, True], ids=["new-folder", "existing-folder"])
def test_a_run_whose_every_input_failed_leaves_the_output_folder_as_it_was(looming_npy, tmp_path, capsys, existing):
    from cdnf_ti.models import MODELS, register_model
    from cdnf_ti.models.sdnf import SDNF

    class Broken(SDNF):
        name = "broken_for_empty_run_test"

        def step(self, frame):
            raise RuntimeError("model bug")

    out = tmp_path / "o"
    if existing:
        out.mkdir()
        (out / "summary.csv").write_text("input,clip,model\nearlier,earlier,cdnf\n")
    before = sorted((p.name, p.read_bytes()) for p in out.iterdir()) if existing else None
    register_model(Broken)
    try:
        code = main([str(looming_npy), "--model", "broken_for_empty_run_test", "--backend", "numpy", "--out",
                     str(out), "--no-progress"])
    finally:
        MODELS.pop("broken_for_empty_run_test", None)
    assert code == 2
    assert "error:" in capsys.readouterr().err
    if existing:
        assert sorted((p.name, p.read_bytes()) for p in out.iterdir()) == before
    else:
        assert not out.exists()
