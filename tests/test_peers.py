"""The benchmark peers (SciPy, OpenCV+NumPy, PyTorch when installed) compute the same C-DNF as the reference."""
import importlib.util

import numpy as np
import pytest
from conftest import small_stimulus

from cdnf_ti import CDNF, CDNFParams
from cdnf_ti.bench.inputs import basic_frames, standin_video
from cdnf_ti.bench.peers import PeerCDNF, available_peers

# torch is the bench-only extra (pip install ".[bench]"); its peer is tested wherever it is installed
PEERS = ["scipy", "opencv"] + (["torch"] if importlib.util.find_spec("torch") is not None else [])


@pytest.mark.parametrize("peer", PEERS)
@pytest.mark.parametrize("border", ["replicate", "reflect", "zero"])
def test_peer_agrees_with_reference_on_a_basic_stimulus(peer, border):
    frames = list(small_stimulus("light_looming", size=70).frames())
    p = CDNFParams(border=border)
    a = PeerCDNF(peer, p).run(frames)
    b = CDNF(p, backend="numpy").run(frames)
    assert np.max(np.abs(a.output - b.output)) < 1e-4
    assert np.array_equal(a.spike, b.spike)
    assert a.converged.all()
    assert b.output.max() > 0.5 + p.epsilon  # the stimulus does alert


@pytest.mark.parametrize("peer", PEERS)
def test_peer_agrees_with_reference_on_dashcam_like_video(peer):
    frames = [f[::2, ::2] for f in standin_video(6, seed=2)]
    a = PeerCDNF(peer).run(frames)  # the peers run the paper's plain scheme from the previous solution
    b = CDNF(CDNFParams(scheme="plain", start="previous"), backend="numpy").run(frames)
    assert np.max(np.abs(a.output - b.output)) < 1e-4
    # same fixed-point schedule as the reference (previous-frame start, same stopping rule)
    assert np.max(np.abs(a.diagnostics["iterations_on"] - b.diagnostics["iterations_on"])) <= 1


def test_peers_needing_missing_libraries_are_a_clear_error():
    with pytest.raises(ValueError, match="not available"):
        PeerCDNF("no_such_peer")


def test_scipy_and_opencv_peers_are_available_here():
    assert {"scipy", "opencv"} <= set(available_peers())


def test_standin_video_is_deterministic_and_moves_everywhere():
    a = standin_video(3, height=60, width=80, seed=5)
    b = standin_video(3, height=60, width=80, seed=5)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert a[0].shape == (60, 80) and a[0].dtype == np.uint8
    moved = np.abs(a[1].astype(int) - a[0].astype(int)) > 0
    assert moved.mean() > 0.5  # camera ego-motion: most pixels change


def test_basic_frames_take_the_requested_size_and_count():
    fr = basic_frames("dark_looming", 4, height=48, width=64)
    assert len(fr) == 4 and fr[0].shape == (48, 64)


def test_bench_command_prints_one_row_per_model_and_peer(capsys):
    from cdnf_ti.run import main

    rc = main(["bench", "--quick", "--frames", "3", "--sizes", "48x40", "--no-reference"])
    out = capsys.readouterr().out
    assert rc == 0
    header = out.splitlines()[0]
    assert "frames/s" in header and "x opencv" in header and "x scipy" in header
    rows = [line for line in out.splitlines() if line.startswith("| cdnf")]
    # basic + real footage, each: C-DNF (Chebyshev and plain) under each compiler, and every peer
    from cdnf_ti.taichi_runtime import installed_compilers

    assert len(rows) == 2 * (2 * len(installed_compilers()) + len(available_peers()))
    assert sum("cdnf[opencv]" in r for r in rows) == 2
    assert all(c in out for c in installed_compilers())


class _TimedModel:
    """A stand-in model on a fake clock: frame k >= 1 takes k ms, 20 ms more on the first repeat
    and on frame 3 of the second (other work on the machine)."""

    clock = 0.0

    def __init__(self):
        self.repeat, self.t = -1, 0

    def reset(self):
        self.repeat, self.t = self.repeat + 1, 0

    def step(self, frame):
        from types import SimpleNamespace

        if self.t > 0 and self.repeat >= 0:
            noise = 0.02 if self.repeat == 0 or (self.repeat, self.t) == (1, 3) else 0.0
            _TimedModel.clock += 0.001 * self.t + noise
        self.t += 1
        return SimpleNamespace(output=float(frame[0, 0]), diagnostics={"iterations": float(self.t)})


def test_time_model_reports_the_median_and_the_best_of_each_frame_over_the_repeats(monkeypatch):
    from types import SimpleNamespace

    from cdnf_ti.bench import cli

    monkeypatch.setattr(cli, "time", SimpleNamespace(perf_counter=lambda: _TimedModel.clock))
    frames = [np.full((2, 2), k, np.uint8) for k in range(6)]
    tm = cli.time_model(_TimedModel, frames, repeats=3)
    # repeats take 115, 35 and 15 ms for 5 frames; the fastest of each frame sums to 1+2+3+4+5 = 15 ms
    assert tm.fps == pytest.approx(5 / 0.035) and tm.best_fps == pytest.approx(5 / 0.015)
    np.testing.assert_array_equal(tm.outputs, np.arange(6.0))
    np.testing.assert_array_equal(tm.diagnostics["iterations"], np.arange(2.0, 7.0))  # frame 0 excluded


def test_bench_table_shows_the_best_frames_per_second_next_to_the_median(capsys):
    from cdnf_ti.run import main
    from cdnf_ti.taichi_runtime import installed_compilers

    rc = main(["bench", "--quick", "--frames", "3", "--sizes", "48x40", "--no-reference", "--compiler",
               ",".join(installed_compilers())])
    out = capsys.readouterr().out
    assert rc == 0
    head = [c.strip() for c in out.splitlines()[0].split("|")]
    i, j = head.index("frames/s"), head.index("best frames/s")
    assert j == i + 1
    for line in (x for x in out.splitlines() if x.startswith("| cdnf")):
        cells = [c.strip() for c in line.split("|")]
        # the sum of each frame's fastest step is at most any repeat's total (child processes' rows too)
        assert float(cells[j]) >= float(cells[i]) > 0


def test_bench_command_appends_the_simd_report_when_asked(capsys, monkeypatch):
    import collections

    from cdnf_ti.bench import simd
    from cdnf_ti.run import main
    from cdnf_ti.taichi_runtime import current_compiler

    asked = []

    def fake_measure(compilers, progress=False):  # the real one compiles afresh per compiler (tests/test_compilers.py)
        asked.append(list(compilers))
        return [(c, "ON/OFF contrast solve", collections.Counter({1: 1, 8: 3})) for c in compilers]

    monkeypatch.setattr(simd, "measure_simd", fake_measure)
    here = current_compiler()
    rc = main(["bench", "--quick", "--frames", "3", "--sizes", "48x40", "--no-reference", "--compiler", here,
               "--simd"])
    out = capsys.readouterr().out
    assert rc == 0 and asked == [[here]]
    assert f"| {here} | ON/OFF contrast solve | 75 % | scalar: 1, 8 lanes: 3 |" in out.splitlines()


@pytest.mark.parametrize("bad", [["--sizes", "0x0"], ["--sizes", "abc"], ["--sizes", ""], ["--sizes", "20000x20000"],
                                 ["--frames", "0"], ["--repeats", "0"], ["--compiler", "nosuch"], ["--compiler", ","]])
def test_bench_command_rejects_bad_options_with_one_line(capsys, bad):
    from cdnf_ti.run import main

    rc = main(["bench", "--quick", "--no-reference", *bad])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith(f"error: {bad[0]}") and err.count("\n") == 1


def test_bench_command_rejects_a_missing_clip_with_one_line(capsys):
    from cdnf_ti.run import main

    rc = main(["bench", "--clip", "/nonexistent/clip.mp4"])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("error: /nonexistent/clip.mp4:") and err.count("\n") == 1


def test_startup_runs_each_compiler_cold_then_warm_in_a_fresh_cache_folder_of_its_own(monkeypatch):
    import subprocess
    from types import SimpleNamespace

    from cdnf_ti.bench import cli

    calls = []

    def fake_run(cmd, env, **kw):
        calls.append((env["CDNF_TI_COMPILER"], env["CDNF_TI_CACHE_DIR"]))
        return SimpleNamespace(returncode=0, stdout=f"1.5 {env['CDNF_TI_COMPILER'] == 'quadrants'}\n")

    monkeypatch.setattr(subprocess, "run", fake_run)
    rows = cli.measure_startup(["taichi", "quadrants"], size=(24, 40))
    assert [(r.compiler, r.cache, r.torch_imported) for r in rows] == [
        ("taichi", "cold", False), ("taichi", "warm", False), ("quadrants", "cold", True), ("quadrants", "warm", True)]
    assert [c for c, _ in calls] == ["taichi", "taichi", "quadrants", "quadrants"]
    assert calls[0][1] == calls[1][1] != calls[2][1] == calls[3][1]
    assert all(r.seconds > 0 for r in rows)


def test_startup_of_a_failed_child_is_nan_and_the_table_says_failed(monkeypatch):
    import subprocess
    from types import SimpleNamespace

    from cdnf_ti.bench import cli

    monkeypatch.setattr(subprocess, "run", lambda cmd, env, **kw: SimpleNamespace(returncode=1, stdout=""))
    rows = cli.measure_startup(["taichi"])
    assert all(np.isnan(r.seconds) and r.torch_imported is None for r in rows)
    assert cli.format_startup(rows).splitlines()[2:] == ["| taichi | cold | nan | failed |",
                                                         "| taichi | warm | nan | failed |"]


def test_the_startup_child_solves_a_frame_and_says_whether_pytorch_was_imported():
    import os
    import subprocess
    import sys

    from cdnf_ti.bench.cli import STARTUP_CODE
    from cdnf_ti.taichi_runtime import COMPILER_ENV, current_compiler

    env = dict(os.environ, **{COMPILER_ENV: current_compiler()})  # this process's compile cache: warm
    proc = subprocess.run([sys.executable, "-c", STARTUP_CODE.format(size=(24, 40))], env=env, capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    seconds, torch_imported = proc.stdout.split()
    assert float(seconds) > 0 and torch_imported in ("True", "False")
