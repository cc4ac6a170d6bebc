"""``python -m cdnf_ti.run dataset`` / ``experiment``: outputs, exit codes, one-line errors."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cdnf_ti.experiments.synthetic import make_synthetic_dataset
from cdnf_ti.run import main

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("cli_ds")
    make_synthetic_dataset(folder, size=96, clips=("dark_looming", "light_translating"))
    return folder


def test_dataset_command_writes_reports_and_exits_0(dataset, tmp_path, capsys):
    rc = main(["dataset", str(dataset), "--out", str(tmp_path), "--workers", "0", "--no-progress",
               "--pad-before", "2", "--pad-after", "1"])
    assert rc == 0
    assert "| Normal | 100.00% (paper 77.14%) |" in capsys.readouterr().out
    assert (tmp_path / "figures" / "traces_dark_looming.png").is_file()
    assert "window padding: 2 frames before the window start, 1 frames after its end" in \
        (tmp_path / "summary.md").read_text()


def test_dataset_command_exits_1_when_a_clip_fails(dataset, tmp_path, capsys):
    ds = tmp_path / "ds"
    ds.mkdir()
    for p in dataset.iterdir():
        (ds / p.name).write_bytes(p.read_bytes())
    (ds / "bad.avi").write_bytes(b"junk" * 100)
    with open(ds / "labels.csv", "a") as f:
        f.write("bad,non-collision,,,,,\n")
    rc = main(["dataset", str(ds), "--out", str(tmp_path / "o"), "--workers", "0", "--no-progress",
               "--no-figures"])
    assert rc == 1
    err = capsys.readouterr().err
    assert "bad.avi" in err and "Traceback" not in err


def test_bad_labels_exit_2_with_one_line_naming_the_row(dataset, tmp_path):
    labels = tmp_path / "labels.csv"
    labels.write_text("clip,label,window_start,window_end\ndark_looming,collision,9,3\n")
    r = subprocess.run([sys.executable, "-m", "cdnf_ti.run", "dataset", str(dataset), "--labels", str(labels),
                        "--out", str(tmp_path / "o")], capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "row 2" in lines[0] and "Traceback" not in r.stderr
    assert not (tmp_path / "o" / "results.csv").exists()


def test_unknown_model_is_a_usage_error(dataset, tmp_path, capsys):
    assert main(["dataset", str(dataset), "--out", str(tmp_path), "--models", "nope"]) == 2
    assert "unknown model 'nope'" in capsys.readouterr().err


def test_experiment_table1_prints_and_writes_the_table(tmp_path, capsys):
    rc = main(["experiment", "table1", "--models", "cdnf", "--size", "64", "--out", str(tmp_path),
               "--workers", "0", "--no-progress", "--no-figures"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "| Dark approaching |" in out and (tmp_path / "table1.json").is_file()


def test_experiment_coherence_writes_the_sweep_table(tmp_path, capsys):
    pytest.importorskip("cdnf_ti.stimuli.incoherent")
    rc = main(["experiment", "coherence", "--models", "cdnf", "--size", "48", "--coherences", "1,0.5",
               "--stimuli", "light_looming", "--out", str(tmp_path), "--workers", "0", "--no-progress",
               "--no-figures"])
    assert rc == 0
    csv_text = (tmp_path / "coherence.csv").read_text().splitlines()
    assert csv_text[0] == "stimulus,model,coherence,alert,first_alert,max_output" and len(csv_text) == 3


def test_experiment_coherence_static_scatter_runs_the_static_construction(tmp_path, capsys):
    rc = main(["experiment", "coherence", "--models", "cdnf", "--size", "48", "--coherences", "0.5",
               "--stimuli", "dark_translating", "--scatter", "static", "--out", str(tmp_path), "--workers", "0",
               "--no-progress", "--no-figures"])
    assert rc == 0
    meta = json.loads((tmp_path / "coherence.json").read_text())
    assert meta["scatter"] == "static"
    assert "static dots" in (tmp_path / "coherence.md").read_text()
    from cdnf_ti import CDNF
    from cdnf_ti.models.base import Trace
    from cdnf_ti.stimuli.incoherent import incoherent_stimulus

    saved = Trace.from_csv(tmp_path / "traces" / "dark_translating_c050_static.cdnf.csv", "cdnf")
    stim = incoherent_stimulus("dark_translating", 0.5, 0, scatter="static", height=48, width=48)
    ref = CDNF(fps=stim.fps).run(stim.frames())
    np.testing.assert_allclose(saved.output, ref.output, atol=1e-6)


def test_experiment_coherence_rejects_bad_coherence(tmp_path, capsys):
    assert main(["experiment", "coherence", "--coherences", "1,0", "--out", str(tmp_path)]) == 2
    assert "coherence must be in (0, 1]" in capsys.readouterr().err


def test_table2_without_a_folder_asks_for_one(monkeypatch, tmp_path, capsys):
    from cdnf_ti.experiments import builtin

    monkeypatch.setattr(builtin, "default_real_folder", lambda: None)
    assert main(["experiment", "table2", "--out", str(tmp_path)]) == 2
    assert "pass one" in capsys.readouterr().err


def test_table2_on_a_real_dashcam_clip(shared_real, tmp_path):
    if shared_real is None:
        pytest.skip("the development dashcam clips are absent (this test exercises the real clips only)")
    labels = tmp_path / "labels.csv"
    rows = (shared_real / "labels.csv").read_text().splitlines()
    labels.write_text("\n".join([rows[0]] + [r for r in rows if r.startswith("tc22,")]) + "\n")
    rc = main(["experiment", "table2", str(shared_real), "--labels", str(labels), "--models", "cdnf",
               "--rain", "none", "--out", str(tmp_path / "o"), "--workers", "0", "--no-progress", "--no-figures"])
    assert rc == 0
    res = (tmp_path / "o" / "results.csv").read_text().splitlines()
    assert len(res) == 2 and res[1].startswith("tc22,cdnf,clean,collision,48,61")
