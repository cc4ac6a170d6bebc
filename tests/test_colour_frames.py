"""Colour frames for the models that take them (``Model.frame_colour``): every command decodes a frame once,
makes it grey once, and hands each model the form it takes. EMD-LPLC2's real variant takes colour (folder 7
reads the green channel); every other model takes grey.

The input is a small generated colour video (lossless FFV1 AVI): a looming dark square in the green
channel, its negative in the red one and a fixed seeded noise in the blue one, so the green channel and
the grey (BT.601 luma) differ everywhere.
"""
from __future__ import annotations

import csv
import functools
import json

import cv2
import numpy as np
import pytest

from cdnf_ti.experiments.clip_tasks import ClipTask
from cdnf_ti.frames import ColourFrame, iter_frames, open_source, to_grey
from cdnf_ti.lplc2_reference import LPLC2Reference
from cdnf_ti.models import LPLC2, MODELS, LPLC2Params, get_model_class
from cdnf_ti.models.base import Trace
from cdnf_ti.run import main
from cdnf_ti.stimuli.basic import basic_stimulus
from cdnf_ti.video import write_video

SIZE = 320  #: px before the real variant's shrink (an 80x80 array, as tests/test_lplc2_real.py)
REAL = LPLC2Params(variant="real")


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    """The colour video's path (``looming.avi``, in a folder of its own with a labels.csv)."""
    folder = tmp_path_factory.mktemp("colour")
    st = basic_stimulus("dark_looming", height=SIZE, width=SIZE)
    blue = np.random.default_rng(7).integers(0, 256, (SIZE, SIZE), dtype=np.uint8)
    frames = []
    for g in st.frames():
        green = np.floor(g * 255.0 + 0.5).astype(np.uint8)
        frames.append(np.dstack([blue, green, 255 - green]))
    path = folder / "looming.avi"
    write_video(path, frames, fps=st.fps)
    (folder / "labels.csv").write_text(f"clip,label,window_start,window_end\nlooming,collision,30,{len(frames) - 1}\n")
    return path


@functools.cache
def decoded(path: str) -> tuple[list[np.ndarray], float]:
    """The video's frames as decoded (BGR uint8) and its frame rate."""
    src = open_source(path)
    return list(src), src.fps


@functools.cache
def stepped(path: str, colour: bool) -> Trace:
    """The real variant run from Python on the decoded colour frames (``colour``) or on their grey."""
    frames, fps = decoded(path)
    return LPLC2(REAL, fps=fps).run(frames if colour else [to_grey(f) for f in frames])


def run_cli(tmp_path, video, *args) -> tuple[int, dict]:
    """``python -m cdnf_ti.run run VIDEO ARGS --out tmp_path/out``: the exit code and the summary rows by model."""
    out = tmp_path / "out"
    code = main(["run", str(video), "--out", str(out), "--no-progress", *args])
    with open(out / "summary.csv", newline="") as f:
        return code, {r["model"]: r for r in csv.DictReader(f)}


def assert_same_trace(csv_path, want: Trace) -> None:
    """The trace file holds ``want``, every column (output, spike and the diagnostics), as ``to_csv`` writes it."""
    assert csv_path.read_text() == want.to_csv_text()


def test_every_model_takes_grey_frames_but_the_real_lplc2_variant():
    takes = {name: get_model_class(name).frame_colour(None) for name in MODELS}
    assert set(takes.values()) == {"grey"}
    assert LPLC2.frame_colour(REAL) == "bgr" and LPLC2.frame_colour(LPLC2Params()) == "grey"


def test_a_colour_frame_holds_the_decoded_frame_and_its_grey():
    bgr = np.random.default_rng(0).integers(0, 256, (6, 8, 3), dtype=np.uint8)
    frame = ColourFrame.of(bgr)
    np.testing.assert_array_equal(frame.bgr, bgr)
    np.testing.assert_array_equal(frame.grey, to_grey(bgr))
    assert frame.shape == (6, 8)
    grey = np.full((6, 8), 0.5, np.float32)
    np.testing.assert_array_equal(ColourFrame.of(grey).bgr, grey)  # a grey input's colour form is its grey


def test_a_grey_pass_decodes_grey_frames_as_before(video):
    src = open_source(video)
    for got, want in zip(iter_frames(src, False), src):
        assert not isinstance(got, ColourFrame)
        np.testing.assert_array_equal(got, to_grey(want))


def test_the_colour_and_grey_inputs_differ_for_the_real_variant(video):
    """The video tells the two apart: the real variant's arms differ between its green channel and its grey."""
    a, b = stepped(str(video), True), stepped(str(video), False)
    assert not np.allclose(a.diagnostics["arm_left"], b.diagnostics["arm_left"])


def test_run_hands_the_real_variant_the_colour_frames(tmp_path, video):
    code, rows = run_cli(tmp_path, video, "--model", "lplc2", "--param", "variant=real")
    assert code == 0
    assert_same_trace(tmp_path / "out" / rows["lplc2"]["trace"], stepped(str(video), True))


def test_run_of_the_real_variant_matches_the_float64_reference_on_the_green_channel(tmp_path, video):
    code, rows = run_cli(tmp_path, video, "--model", "lplc2", "--param", "variant=real")
    trace = Trace.from_csv(tmp_path / "out" / rows["lplc2"]["trace"])
    frames, fps = decoded(str(video))
    ref = LPLC2Reference(SIZE, SIZE, fps=fps, variant="real").run([f[:, :, 1] for f in frames])
    assert ref["alert"].any()  # the square looms into an alert
    np.testing.assert_array_equal(trace.spike, ref["alert"])
    np.testing.assert_array_equal(trace.diagnostics["active"], ref["active"])
    np.testing.assert_allclose(trace.output, ref["v"], atol=1e-4, rtol=0)


def test_a_grey_model_gives_the_same_trace_beside_a_colour_model(tmp_path, video):
    _, alone = run_cli(tmp_path / "alone", video, "--model", "cdnf")
    _, mixed = run_cli(tmp_path / "mixed", video, "--model", "cdnf,lplc2", "--param", "lplc2.variant=real")
    text = [(tmp_path / sub / "out" / rows["cdnf"]["trace"]).read_text() for sub, rows in
            (("alone", alone), ("mixed", mixed))]
    assert text[0] == text[1]


def test_summary_settings_say_which_model_took_colour_frames(tmp_path, video):
    _, rows = run_cli(tmp_path, video, "--model", "cdnf,lplc2", "--param", "lplc2.variant=real")
    assert "frames=bgr" in rows["lplc2"]["settings"].split(";")
    assert "frames=bgr" not in rows["cdnf"]["settings"]


def test_a_rerun_over_a_result_made_from_grey_frames_says_the_input_changed(tmp_path, video, capsys):
    run_cli(tmp_path, video, "--model", "lplc2", "--param", "variant=real")
    summary = tmp_path / "out" / "summary.csv"
    summary.write_text(summary.read_text().replace(";frames=bgr", ""))  # as a run before colour frames wrote it
    capsys.readouterr()
    run_cli(tmp_path, video, "--model", "lplc2", "--param", "variant=real")
    assert "frames (not recorded) -> bgr" in capsys.readouterr().err


def test_rainy_frames_reach_a_colour_model_grey(tmp_path, video):
    code, rows = run_cli(tmp_path, video, "--model", "lplc2", "--param", "variant=real", "--rain", "on")
    assert code == 0
    assert "frames=bgr" not in rows["lplc2"]["settings"]


def test_dataset_fingerprint_names_colour_frames_for_a_colour_model_only(video):
    task = ClipTask("looming", str(video), "clean", ("lplc2",), "out", params={"lplc2": REAL})
    assert task.fingerprint("lplc2")["options"]["frames"] == "bgr"
    arena = ClipTask("looming", str(video), "clean", ("lplc2",), "out")
    assert "frames" not in arena.fingerprint("lplc2").get("options", {})
    rain = ClipTask("looming", str(video), "rain", ("lplc2",), "out", params={"lplc2": REAL})
    assert "frames" not in rain.fingerprint("lplc2").get("options", {})


def test_a_sweep_setting_of_the_real_variant_takes_colour_frames(video):
    task = ClipTask("looming", str(video), "clean", ("lplc2",), "out", setting=(("variant", "real"),), key="k")
    assert task.colour_frames("lplc2")


def test_dataset_hands_the_real_variant_the_colour_frames(tmp_path, video):
    code = main(["dataset", str(video.parent), "--models", "lplc2", "--param", "variant=real", "--out",
                 str(tmp_path / "ds"), "--workers", "0", "--no-progress", "--no-figures"])
    assert code == 0
    assert_same_trace(tmp_path / "ds" / "traces" / "clean" / "looming.lplc2.csv", stepped(str(video), True))


def test_render_feeds_and_shows_the_colour_frames(tmp_path, video):
    out = tmp_path / "movie.avi"
    assert main(["render", str(video), "--model", "lplc2", "--param", "variant=real", "--out", str(out),
                 "--no-progress"]) == 0
    cap = cv2.VideoCapture(str(out))
    ok, movie = cap.read()
    cap.release()
    assert ok
    panel = movie[40:SIZE, :SIZE].astype(int)  # the input panel, below its label
    assert np.abs(panel[:, :, 0] - panel[:, :, 1]).mean() > 20  # colour: blue noise beside the green channel


def test_live_hands_the_real_variant_the_colour_frames(video, capsys):
    from cdnf_ti.live import main as live_main

    assert live_main([str(video), "--model", "lplc2", "--param", "variant=real", "--diagnostics", "--queue", "64",
                      "--no-progress"]) == 0
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    frames = [r for r in records if r["event"] == "frame"]
    want = stepped(str(video), True)
    assert len(frames) == want.n_frames  # a queue that holds the whole file: nothing dropped
    np.testing.assert_allclose([r["diagnostics"]["arm_left"] for r in frames], want.diagnostics["arm_left"],
                               rtol=1e-6, atol=0)
    np.testing.assert_array_equal([r["alert"] for r in frames], want.spike)

