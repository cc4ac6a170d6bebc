"""Command line: ``generate``, ``rain`` and ``--rain`` / ``stim:`` inputs of ``python -m cdnf_ti.run``."""
from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from cdnf_ti.run import main
from cdnf_ti.stimuli.incoherent import incoherent_stimulus
from cdnf_ti.stimuli.io import read_frames, read_frames_uint8, to_uint8
from cdnf_ti.stimuli.rain import RainParams, RainyFrames


def test_generate_writes_lossless_avi_and_sidecar_with_every_parameter(tmp_path, capsys):
    out = tmp_path / "loom.avi"
    rc = main(["generate", "dark_looming", "--coherence", "0.2", "--seed", "3", "--size", "60",
               "--out", str(out), "--no-progress"])
    assert rc == 0
    meta = json.loads((tmp_path / "loom.json").read_text())
    assert meta["stimulus"] == "dark_looming" and meta["coherence"] == 0.2 and meta["seed"] == 3
    assert meta["basic"]["height"] == 60 and meta["basic"]["start_half_size"] == 1.0
    assert meta["frames"] == 46 and meta["format"] == "avi" and meta["rain"] is None
    ref = incoherent_stimulus("dark_looming", 0.2, 3, height=60, width=60, start_half_size=1.0)
    assert meta["halted_at"] == ref.halted_at
    for f, g in zip(ref.frames(), read_frames(out)):
        np.testing.assert_array_equal(f, g)
    assert "loom.avi" in capsys.readouterr().out


def test_generate_static_scatter_writes_the_static_construction(tmp_path, capsys):
    out = tmp_path / "bar.avi"
    rc = main(["generate", "dark_translating", "--coherence", "0.2", "--scatter", "static", "--size", "48",
               "--out", str(out), "--no-progress"])
    assert rc == 0
    meta = json.loads((tmp_path / "bar.json").read_text())
    assert meta["scatter"] == "static" and meta["coherence"] == 0.2
    ref = incoherent_stimulus("dark_translating", 0.2, 0, scatter="static", height=48, width=48)
    for f, g in zip(ref.frames(), read_frames(out)):
        np.testing.assert_array_equal(f, g)


def test_generate_unknown_scatter_exits_2(tmp_path):
    with pytest.raises(SystemExit) as e:
        main(["generate", "dark_translating", "--scatter", "wobble", "--out", str(tmp_path / "x.avi")])
    assert e.value.code == 2


def test_generate_with_rain_to_png_folder_records_rain_and_snr(tmp_path):
    out = tmp_path / "trans"
    rc = main(["generate", "light_translating", "--coherence", "0.5", "--size", "48", "--rain",
               "--rain-seed", "4", "--rain-drops", "30", "--out", str(out), "--no-progress"])
    assert rc == 0
    meta = json.loads((out / "sidecar.json").read_text())
    assert meta["rain"]["seed"] == 4 and meta["rain"]["drops"] == 30 and meta["rain"]["weight"] == 0.5
    ref = incoherent_stimulus("light_translating", 0.5, 0, height=48, width=48, start_half_size=0.8)
    rain = RainyFrames(ref.frames(), RainParams(drops=30), seed=4)
    for f, g in zip(rain, read_frames_uint8(out)):
        np.testing.assert_array_equal(to_uint8(f), g)
    assert meta["rain"]["snr_db"] == pytest.approx(rain.snr_db)


def test_rain_subcommand_adds_rain_to_videos_and_reports_snr(tmp_path, capsys):
    rng = np.random.default_rng(0)
    clip = (rng.uniform(0.2, 0.7, (6, 40, 64)) * 255).astype(np.uint8)
    np.save(tmp_path / "clip.npy", clip)
    rc = main(["rain", str(tmp_path / "clip.npy"), "stim:dark_looming?size=40", "--out", str(tmp_path / "o"),
               "--seed", "2", "--no-progress"])
    assert rc == 0
    meta = json.loads((tmp_path / "o" / "clip_rain.json").read_text())
    assert meta["frames"] == 6 and meta["rain"]["seed"] == 2 and len(meta["snr_db_per_frame"]) == 6
    rain = RainyFrames(list(clip), seed=2)
    for f, g in zip(rain, read_frames_uint8(tmp_path / "o" / "clip_rain.avi")):
        np.testing.assert_array_equal(to_uint8(f), g)
    assert meta["snr_db"] == pytest.approx(rain.snr_db)
    out = capsys.readouterr().out
    assert f"SNR {rain.snr_db:.2f} dB" in out
    assert (tmp_path / "o" / "dark_looming_size40_rain.avi").exists()


def test_rain_subcommand_bad_input_is_one_line_error(tmp_path, capsys):
    rc = main(["rain", str(tmp_path / "nope.mp4"), "--out", str(tmp_path / "o")])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "nope.mp4" in err and "\n" not in err


def test_run_models_on_generated_stimulus_with_rain(tmp_path, capsys):
    rc = main(["stim:dark_looming?coherence=0.2&size=64", "--rain", "--rain-seed", "1",
               "--out", str(tmp_path), "--no-progress"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "rain SNR" in out and "dB" in out
    rows = list(csv.DictReader(open(tmp_path / "summary.csv")))
    assert rows[0]["clip"] == "dark_looming_c0.2_size64" and float(rows[0]["rain_snr_db"]) > 0
    assert (tmp_path / "dark_looming_c0.2_size64.cdnf.rain.csv").exists()  # the condition is in the name


def test_generate_bad_coherence_exits_2_without_traceback(tmp_path):
    p = subprocess.run([sys.executable, "-m", "cdnf_ti.run", "generate", "dark_looming", "--coherence", "1.5",
                        "--out", str(tmp_path / "x.avi")], capture_output=True, text=True)
    assert p.returncode == 2
    assert p.stderr.strip().startswith("error:") and "Traceback" not in p.stderr
    assert not (tmp_path / "x.avi").exists()


def test_frame_rate_the_avi_cannot_store_is_an_error_not_a_silent_loss(tmp_path, capsys):
    from cdnf_ti.run import main

    out = tmp_path / "fast.avi"
    assert main(["generate", "dark_looming", "--size", "40", "--fps", "2000", "--out", str(out)]) == 2
    assert "frame rate not representable" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("name", ["g.mp4", "g.txt"])
def test_generate_to_an_unsupported_output_type_is_a_one_line_error(tmp_path, capsys, name):
    rc = main(["generate", "dark_looming", "--size", "40", "--duration", "0.2", "--out", str(tmp_path / name)])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith(f"error: {tmp_path / name}: output must be a .avi file") and err.count("\n") == 1
    assert not (tmp_path / name).exists()


@pytest.mark.parametrize("command", ["generate", "rain"])
def test_every_option_has_help_text(command, capsys):
    """``--help`` gives every option a description (argparse prints an option without one alone on its line)."""
    from cdnf_ti.run import main

    with pytest.raises(SystemExit):
        main([command, "--help"])
    lines = capsys.readouterr().out.splitlines()
    options = lines[next(i for i, ln in enumerate(lines) if ln.startswith("options")) + 1:]
    bare = [ln.strip() for i, ln in enumerate(options)
            if ln.startswith("  -") and len(ln.split("  ")) < 3  # no description on the option's own line...
            and not (i + 1 < len(options) and options[i + 1].startswith(" " * 10))]  # ...nor on the next
    assert bare == []
