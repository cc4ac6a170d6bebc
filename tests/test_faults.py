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


def _cli(*args: str, timeout: float = 300, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cdnf_ti.run", *args], capture_output=True, text=True,
                          timeout=timeout, env=ENV, **kw)


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
def test_sigint_cancels_pending_tasks_and_exits_130_within_seconds():
    p = _start_slow_map()
    t0 = time.monotonic()
    p.send_signal(signal.SIGINT)
    rc = p.wait(timeout=30)
    assert rc == 130
    assert time.monotonic() - t0 < 10  # the slow tasks (60 s each) were not waited for
    assert "interrupted" in p.stdout.read()


@linux_only
def test_second_sigint_exits_at_once():
    p = _start_slow_map()
    p.send_signal(signal.SIGINT)
    time.sleep(0.02)
    p.send_signal(signal.SIGINT)
    t0 = time.monotonic()
    rc = p.wait(timeout=30)
    assert rc == 130 and time.monotonic() - t0 < 10


@linux_only
def test_sigint_on_parallel_dataset_run_keeps_finished_clips_and_resume_skips_them(small_dataset, tmp_path):
    ds = tmp_path / "ds"
    shutil.copytree(small_dataset, ds)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "cdnf_ti.run", "dataset", str(ds), "--out", str(out), "--workers", "2",
           "--no-figures"]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    deadline = time.monotonic() + 240
    while not list(out.glob("traces/clean/*.json")) and time.monotonic() < deadline and p.poll() is None:
        time.sleep(0.05)
    p.send_signal(signal.SIGINT)
    t0 = time.monotonic()
    rc = p.wait(timeout=60)
    err = p.stderr.read()
    if rc == 0:
        pytest.skip("the run finished before the interrupt arrived (machine too fast for this test)")
    assert rc == 130, err
    assert time.monotonic() - t0 < 15
    assert "Traceback" not in err and "interrupted" in err
    kept = sorted(x.name for x in out.glob("traces/clean/*.json"))
    assert kept  # finished clips are kept
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
    deadline = time.monotonic() + 10
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
    proc = _cli(*args, "--arch", "gpu", timeout=120)
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
    t0 = time.monotonic()
    proc = _cli(str(looming_npy), "--out", str(ro), timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [proc.stderr.strip()]
    assert proc.stderr.startswith(f"error: {ro}: output folder is not writable")
    assert "frames" not in proc.stdout  # no model ran
    assert time.monotonic() - t0 < 60


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
                           "--out", str(out), "--no-progress"], capture_output=True, text=True, timeout=120,
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
    t0 = time.monotonic()
    proc = _cli(*argv, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    err = [ln for ln in proc.stderr.splitlines() if ln.strip() and not ln.startswith(("usage:", " "))]
    assert len(err) == 1 and "error:" in err[0] and "Traceback" not in proc.stderr  # (argparse adds usage)
    assert "MemoryError" not in proc.stderr
    assert time.monotonic() - t0 < 60


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
    assert p.wait(timeout=120) == 0
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
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=180, env=ENV)
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
