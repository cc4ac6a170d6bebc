"""Field movies: render writes a playable MP4 (read back with OpenCV), and dataset --render makes one per clip."""
from __future__ import annotations

import subprocess
import sys

import cv2
import numpy as np
import pytest

from cdnf_ti.experiments.synthetic import make_synthetic_dataset
from cdnf_ti.models import MODELS
from cdnf_ti.video import write_video


def _read_all(path):
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(f)
    n, w, h = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), \
        int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    cap.release()
    return frames, n, w, h


def test_render_writes_a_playable_mp4_with_one_frame_per_input_frame(tmp_path):
    out = tmp_path / "movie.mp4"
    p = subprocess.run([sys.executable, "-m", "cdnf_ti.run", "render", "stim:dark_looming?size=64", "--model", "cdnf",
                        "--out", str(out), "--no-progress"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    frames, n, w, h = _read_all(out)
    from cdnf_ti.inputs import resolve_input

    n_in = resolve_input("stim:dark_looming?size=64").n_frames
    assert len(frames) == n == n_in
    from cdnf_ti.render import CBAR_W, TRACE_H

    # four 64x64 panels (2 x 2), each with its colour bar on the right, above the trace panel
    assert (w, h) == (2 * (64 + CBAR_W), 128 + TRACE_H) and frames[0].shape == (h, w, 3)
    # the fields change as the square looms: the last frame's field panels differ from the first's
    assert np.abs(frames[-1][:128].astype(int) - frames[1][:128].astype(int)).mean() > 1.0


def test_unknown_movie_suffix_is_a_one_line_error_before_any_work(tmp_path):
    p = subprocess.run([sys.executable, "-m", "cdnf_ti.run", "render", "stim:dark_looming?size=32",
                        "--out", str(tmp_path / "m.gif")], capture_output=True, text=True)
    assert p.returncode == 2
    assert p.stderr.strip().count("\n") == 0 and "m.gif" in p.stderr and ".mp4" in p.stderr


@pytest.mark.parametrize("window", ["5:2", "-3:2", "0:100000"])
def test_an_impossible_window_is_a_one_line_error_before_any_work(tmp_path, capsys, window):
    from cdnf_ti.run import main

    out = tmp_path / "m.mp4"
    rc = main(["render", "stim:dark_looming?size=32", "--out", str(out), f"--window={window}", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("error: ") and window in err and err.count("\n") == 1
    assert not out.exists()


def test_render_video_itself_rejects_a_reversed_window(tmp_path):
    from cdnf_ti.errors import UserError
    from cdnf_ti.render import render_video

    with pytest.raises(UserError, match="window 5:2 must satisfy 0 <= START <= END"):
        render_video("stim:dark_looming?size=32", "cdnf", tmp_path / "m.mp4", window=(5, 2))
    assert not (tmp_path / "m.mp4").exists()


def test_the_one_writer_stores_every_frame_losslessly_in_avi(tmp_path):
    frames = [np.full((24, 32), k * 10, np.uint8) for k in range(9)]
    assert write_video(tmp_path / "a.avi", frames, 25.0) == 9
    back, n, w, h = _read_all(tmp_path / "a.avi")
    assert n == 9 and (w, h) == (32, 24)
    assert all(np.array_equal(b[:, :, 0], f) for b, f in zip(back, frames))


def test_dataset_render_makes_a_movie_per_clip(tmp_path):
    make_synthetic_dataset(tmp_path / "ds", size=32, clips=("dark_looming", "light_translating"))
    ds = tmp_path / "ds"
    out = tmp_path / "out"
    p = subprocess.run([sys.executable, "-m", "cdnf_ti.run", "dataset", str(ds), "--out", str(out), "--workers", "0",
                        "--render", "--no-progress", "--no-figures"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    for clip in ("dark_looming", "light_translating"):
        frames, n, _w, _h = _read_all(out / "movies" / f"{clip}.cdnf.mp4")
        assert n == len(frames) == 46


@pytest.mark.parametrize("model", [name for name in MODELS if name != "cdnf"])
def test_every_other_registered_model_renders_too(tmp_path, model):
    from cdnf_ti.render import render_video

    n = render_video("stim:dark_looming?size=32", model, tmp_path / "m.mp4", backend="numpy")
    frames, m, _w, _h = _read_all(tmp_path / "m.mp4")
    assert n == m == len(frames) > 10


def test_render_makes_one_movie_per_model_and_condition(tmp_path, capsys):
    from cdnf_ti.run import main

    rc = main(["render", "stim:dark_looming?size=32", "--model", "cdnf,lgmd2", "--rain", "both", "--rain-drops", "10",
               "--out", str(tmp_path), "--no-progress"])
    assert rc == 0
    names = sorted(p.name for p in tmp_path.glob("*.mp4"))
    assert names == ["dark_looming_size32.cdnf.mp4", "dark_looming_size32.cdnf.rain.mp4",
                     "dark_looming_size32.lgmd2.mp4", "dark_looming_size32.lgmd2.rain.mp4"]


def test_render_out_names_a_movie_file_only_when_one_movie_is_made(tmp_path, capsys):
    from cdnf_ti.run import main

    rc = main(["render", "stim:dark_looming?size=32", "--model", "cdnf,lgmd2", "--out", str(tmp_path / "m.mp4"),
               "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("error: ") and "give a folder" in err and err.count("\n") == 1
    assert not (tmp_path / "m.mp4").exists()


def test_render_rejects_an_unknown_param_before_any_work(tmp_path, capsys):
    from cdnf_ti.run import main

    rc = main(["render", "stim:dark_looming?size=32", "--param", "nosuch=1", "--out", str(tmp_path / "o"),
               "--no-progress"])
    assert rc == 2 and "nosuch" in capsys.readouterr().err and not (tmp_path / "o").exists()


def test_colour_bars_keep_one_scale_through_the_movie(tmp_path):
    from cdnf_ti.render import CBAR_W, render_video

    out = tmp_path / "m.avi"  # lossless: the pixels read back are the pixels drawn
    render_video("stim:dark_looming?size=48", "cdnf", out, backend="numpy")
    frames, _n, _w, _h = _read_all(out)
    # the bar of the Summation panel (bottom right): its colours and labels are the same in every frame
    bars = [f[48:96, 2 * 48 + CBAR_W:] for f in frames]
    assert all(np.array_equal(bars[0], b) for b in bars[1:])
    assert bars[0].std() > 10  # it is a bar, not an empty strip


def test_field_ranges_hold_the_values_of_every_frame():
    from cdnf_ti.frames import iter_grey
    from cdnf_ti.inputs import resolve_input
    from cdnf_ti.models import create_model
    from cdnf_ti.render import TRACE_KEY, field_ranges, robust_range

    src = resolve_input("stim:dark_looming?size=32")
    model = create_model("cdnf", backend="numpy")
    ranges = field_ranges(model, iter_grey(src))
    model.reset()
    for frame in iter_grey(src):
        res = model.step(frame)
        for key, (lo, hi) in ranges.items():
            if key == TRACE_KEY:  # the trace panel's y range: the output and the threshold
                assert lo <= min(res.output, model.threshold) and max(res.output, model.threshold) <= hi
                continue
            flo, fhi = robust_range(model.fields()[key])
            assert lo <= flo and fhi <= hi


# -- colour maps, the trace's axis and its legend -----------------------------------------------------------

def _ramp(scale, n: int = 9) -> np.ndarray:
    """The colours of ``n`` values evenly from the scale's low to its high end, (n, 3) BGR as int."""
    lo, hi = scale.limits
    return scale(np.linspace(lo, hi, n, dtype=np.float32)[None, :])[0].astype(int)


def test_a_signed_field_has_a_diverging_map_white_at_zero():
    from cdnf_ti.render import FieldScale

    colours = _ramp(FieldScale(-2.0, 1.0))  # symmetric: -2 .. 2, 0 in the middle
    neg, zero, pos = colours[0], colours[4], colours[-1]
    assert zero.min() > 230  # white at zero
    assert neg[0] > neg[2] + 80 and pos[2] > pos[0] + 80  # blue below zero, red above: +max and -max differ
    luminance = colours.sum(axis=1)
    assert all(np.diff(luminance[:5]) > 0) and all(np.diff(luminance[4:]) < 0)  # lighter towards zero


def test_a_non_negative_field_has_a_sequential_map_dark_at_zero():
    from cdnf_ti.render import FieldScale

    grey = cv2.cvtColor(_ramp(FieldScale(0.0, 3.0)).astype(np.uint8)[None], cv2.COLOR_BGR2GRAY)[0].astype(int)
    assert all(np.diff(grey) > 0)


def test_each_panel_gets_the_map_of_its_fields_sign():
    """EMD-LPLC2's opponent motion (left - right) is signed, its LPLC2 response non-negative."""
    from cdnf_ti.models import create_model
    from cdnf_ti.render import DIVERGING, SEQUENTIAL, FieldScale, field_ranges
    from cdnf_ti.stimuli.basic import basic_stimulus

    frames = basic_stimulus("dark_looming", height=96, width=128, fps=100.0, duration=0.5).frames()
    ranges = field_ranges(create_model("lplc2", backend="numpy", fps=100.0), frames)
    assert FieldScale(*ranges["horizontal"])._cmap() is DIVERGING
    assert FieldScale(*ranges["vertical"])._cmap() is DIVERGING
    assert FieldScale(*ranges["lplc2"])._cmap() is SEQUENTIAL


def test_the_trace_keeps_one_y_axis_while_the_movie_plays():
    from cdnf_ti.models import create_model
    from cdnf_ti.render import TRACE_H, field_ranges, render_frames
    from cdnf_ti.stimuli.basic import basic_stimulus

    stim = basic_stimulus("dark_looming", height=48, width=48)
    model = create_model("cdnf", backend="numpy")
    ranges = field_ranges(model, stim.frames())
    movie = list(render_frames(model, stim.frames(), stim.fps, stim.n_frames, ranges=ranges))
    axis = [m[-TRACE_H:, :44] for m in movie]  # the y axis's labels, left of the plot
    assert all(np.array_equal(a, axis[0]) for a in axis)


def test_the_window_legend_names_the_bands_colour_only_with_a_window():
    from cdnf_ti.render import TRACE_H, WINDOW_BGR, WINDOW_COLOUR, _trace_panel, window_legend

    assert window_legend(None) is None
    assert window_legend((3, 7)).startswith(f"{WINDOW_COLOUR}: labelled window")
    b, g, r = WINDOW_BGR
    assert WINDOW_COLOUR == "pink" and r > b > g  # pink: red, then blue, little green
    img = _trace_panel(320, 9, 20, [0.5] * 10, [None] * 10, [False] * 10, "m I", 30.0, (3, 7))
    assert (img[TRACE_H // 2, 46 + (320 - 54) * 5 // 19] == WINDOW_BGR).all()  # the band, mid-window


def test_render_prints_what_it_wrote_on_stdout(tmp_path, capsys):
    from cdnf_ti.run import main

    assert main(["render", "stim:dark_looming?size=32", "--backend", "numpy", "--out", str(tmp_path / "m.mp4"),
                 "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert f"{tmp_path / 'm.mp4'}: " in out and str(tmp_path / "m.mp4") not in err


def test_the_trace_panel_draws_the_value_the_alert_rule_compares_and_its_level():
    """EMD-LPLC2 alerts on V before a spike's reset (``V_peak``) above ``v_threshold``: the panel draws that
    and the level, not the frame-end V, which a spike resets below the level."""
    from cdnf_ti.models import LPLC2
    from cdnf_ti.models.base import StepResult
    from cdnf_ti.render import _trace_values

    model = LPLC2(fps=30.0)
    res = StepResult(5, -70.0, True, True, {"V_peak": -48.5})
    assert _trace_values(model, res, None) == (-48.5, model.params.v_threshold)
