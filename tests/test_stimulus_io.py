"""Lossless stimulus files: FFV1 AVI / PNG folders, sidecars, read-back, generated inputs."""
from __future__ import annotations

import numpy as np
import pytest

from cdnf_ti.errors import InputError
from cdnf_ti.inputs import GeneratedSource, parse_stim_spec, resolve_input
from cdnf_ti.stimuli.incoherent import incoherent_stimulus
from cdnf_ti.stimuli.io import (
    output_format,
    read_frames,
    read_frames_uint8,
    read_sidecar,
    sidecar_path,
    to_uint8,
    write_frames,
    write_sidecar,
)
from cdnf_ti.stimuli.rain import RainParams, RainyFrames


def _stim():
    return incoherent_stimulus("dark_looming", 0.3, seed=2, height=64, width=80, start_half_size=1.2)


@pytest.mark.parametrize("out", ["s.avi", "s_png"])
def test_binary_stimulus_reads_back_exactly(tmp_path, out):
    s = _stim()
    n = write_frames(s.frames(), tmp_path / out, fps=s.fps)
    assert n == s.n_frames
    back = list(read_frames(tmp_path / out))
    assert len(back) == s.n_frames
    for f, g in zip(s.frames(), back):
        np.testing.assert_array_equal(f, g)


@pytest.mark.parametrize("out", ["r.avi", "r_png"])
def test_rainy_frames_read_back_as_the_same_8bit_frames(tmp_path, out):
    s = _stim()
    rain = RainyFrames(s.frames(), RainParams(drops=40), seed=1)
    write_frames(rain, tmp_path / out, fps=s.fps)
    again = RainyFrames(s.frames(), RainParams(drops=40), seed=1)
    for f, g in zip(again, read_frames_uint8(tmp_path / out)):
        np.testing.assert_array_equal(to_uint8(f), g)


def test_avi_keeps_the_frame_rate(tmp_path):
    from cdnf_ti.frames import open_source

    s = incoherent_stimulus("light_translating", 0.5, height=32, width=40, fps=25.0, duration=0.4)
    write_frames(s.frames(), tmp_path / "t.avi", fps=s.fps)
    assert open_source(tmp_path / "t.avi").fps == pytest.approx(25.0)


def test_sidecar_round_trip_and_location(tmp_path):
    meta = {"stimulus": "dark_looming", "coherence": 0.3, "seed": 2}
    assert sidecar_path(tmp_path / "a.avi") == tmp_path / "a.json"
    assert sidecar_path(tmp_path / "folder") == tmp_path / "folder" / "sidecar.json"
    write_sidecar(tmp_path / "a.avi", meta)
    assert read_sidecar(tmp_path / "a.avi") == meta


def test_png_folder_with_sidecar_still_opens_as_frames(tmp_path):
    s = _stim()
    write_frames(s.frames(), tmp_path / "p", fps=s.fps)
    write_sidecar(tmp_path / "p", {"seed": 2})
    assert sum(1 for _ in read_frames(tmp_path / "p")) == s.n_frames


def test_unsupported_output_suffix_is_rejected():
    with pytest.raises(ValueError, match=r"\.avi"):
        output_format("x.mp4")


def test_failed_write_leaves_no_output(tmp_path):
    def frames():
        yield np.zeros((16, 16), np.float32)
        raise RuntimeError("generator broke")

    for out in ("bad.avi", "bad_png"):
        with pytest.raises(RuntimeError):
            write_frames(frames(), tmp_path / out)
        assert not (tmp_path / out).exists()
    assert [p.name for p in tmp_path.iterdir()] == []


def test_to_uint8_rounds_to_nearest():
    np.testing.assert_array_equal(to_uint8(np.array([0.0, 0.5, 1.0, 0.002])), [0, 128, 255, 1])


def test_resolve_input_generates_named_stimulus():
    src = resolve_input("stim:light_translating?coherence=0.2&seed=3&size=48&fps=30")
    assert isinstance(src, GeneratedSource)
    assert src.shape == (48, 48) and src.fps == 30.0 and src.n_frames == 46
    assert src.name == "light_translating_c0.2_s3_fps30_size48"
    ref = incoherent_stimulus("light_translating", 0.2, 3, height=48, width=48, start_half_size=0.8)
    for f, g in zip(src, ref.frames()):
        np.testing.assert_array_equal(f, g)
    # re-iterable: a second pass gives the same frames
    np.testing.assert_array_equal(next(iter(src)), next(iter(src)))


def test_resolve_input_static_scatter_builds_the_static_construction():
    src = resolve_input("stim:dark_translating?coherence=0.5&seed=2&size=40&scatter=static")
    assert src.stimulus.scatter == "static" and "scatterstatic" in src.name
    ref = incoherent_stimulus("dark_translating", 0.5, 2, scatter="static", height=40, width=40)
    flicker = incoherent_stimulus("dark_translating", 0.5, 2, height=40, width=40)
    frames = list(src)
    for f, g in zip(frames, ref.frames()):
        np.testing.assert_array_equal(f, g)
    assert any(not np.array_equal(f, g) for f, g in zip(frames, flicker.frames()))


def test_resolve_input_plain_stimulus_is_the_basic_one():
    from conftest import small_stimulus

    src = resolve_input("stim:dark_receding?size=60")
    for f, g in zip(src, small_stimulus("dark_receding", size=60).frames()):
        np.testing.assert_array_equal(f, g)


def test_resolve_input_passes_paths_to_open_source(tmp_path):
    arr = np.zeros((3, 20, 30), np.uint8)
    np.save(tmp_path / "a.npy", arr)
    src = resolve_input(tmp_path / "a.npy")
    assert src.n_frames == 3 and src.shape == (20, 30)
    with pytest.raises(InputError, match="no such file"):
        resolve_input(tmp_path / "missing.mp4")


@pytest.mark.parametrize("spec,match", [
    ("stim:purple_looming", "unknown stimulus"),
    ("stim:dark_looming?spin=3", "unknown parameter"),
    ("stim:dark_looming?seed=x", "not a number"),
    ("stim:dark_looming?coherence=0", "coherence"),
    ("stim:dark_looming?coherence=0.5&scatter=wobble", "scatter"),
    ("stim:grating?scatter=static", "scatter"),
])
def test_bad_stimulus_specs_give_one_line_errors(spec, match):
    with pytest.raises(InputError, match=match) as e:
        resolve_input(spec)
    assert "\n" not in str(e.value) and str(e.value).startswith(spec)


def test_parse_stim_spec_types():
    assert parse_stim_spec("stim:dark_looming?size=100&coherence=0.5") == ("dark_looming",
                                                                           {"size": 100, "coherence": 0.5})
