"""A finished result is reused only when the code, compiler, arch and engine settings that made it are the same."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from cdnf_ti.experiments.layout import fingerprint, load_meta
from cdnf_ti.experiments.synthetic import make_synthetic_dataset
from cdnf_ti.provenance import code_identity, differences, source_digest


def _installed_layout(dest: Path) -> Path:
    """A copy of the package as a wheel installs it (``kernels/``, ``stimuli/``, ``bench/`` under ``cdnf_ti``)."""
    import cdnf_ti.bench
    import cdnf_ti.kernels
    import cdnf_ti.stimuli

    pkg = dest / "cdnf_ti"
    ignore = shutil.ignore_patterns("__pycache__")
    shutil.copytree(Path(cdnf_ti.__file__).parent, pkg, ignore=ignore)
    for sub in (cdnf_ti.kernels, cdnf_ti.stimuli, cdnf_ti.bench):
        target = pkg / sub.__name__.split(".")[-1]
        if not target.exists():  # an editable install: the folders live beside the package
            shutil.copytree(Path(sub.__file__).parent, target, ignore=ignore)
    return dest


def _dataset_run(root: Path, data: Path, out: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(root)}
    cmd = [sys.executable, "-m", "cdnf_ti.run", "dataset", str(data), "--out", str(out), "--backend", "numpy",
           "--workers", "0", "--no-progress", "--no-figures"]
    return subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True)


@pytest.mark.slow
def test_resume_recomputes_after_a_source_file_changes(tmp_path):
    root = _installed_layout(tmp_path / "pkg")
    data = tmp_path / "data"
    make_synthetic_dataset(data, size=48, clips=("dark_looming",))
    out = tmp_path / "out"
    first = _dataset_run(root, data, out)
    assert first.returncode == 0, first.stderr
    again = _dataset_run(root, data, out)
    assert again.returncode == 0, again.stderr
    assert "0 run now, 1 reused" in again.stderr + again.stdout
    with open(root / "cdnf_ti" / "models" / "cdnf.py", "a", encoding="utf-8") as f:
        f.write("\n# an edit after the first run\n")
    edited = _dataset_run(root, data, out)
    assert edited.returncode == 0, edited.stderr
    text = edited.stderr + edited.stdout
    assert "1 run now, 0 reused" in text
    assert "made by other code or options" in text and "source code" in text


def test_source_digest_names_this_package():
    assert len(source_digest()) == 16
    assert code_identity("numpy")["source_digest"] == source_digest()


def test_code_identity_names_the_compiler_arch_and_lanes(monkeypatch):
    monkeypatch.setenv("CDNF_TI_COMPILER", "taichi")
    ident = code_identity("taichi", "cpu")
    assert ident["compiler"] == "taichi" and ident["arch"] == "cpu" and ident["compiler_version"]
    assert differences(ident, code_identity("taichi", "cuda")) == ["arch"]
    monkeypatch.setenv("CDNF_TI_LANES", "16")
    assert differences(ident, code_identity("taichi", "cpu")) == ["lanes"]


@pytest.mark.parametrize("change", ["compiler", "compiler_version", "arch", "source_digest", "lanes"])
def test_a_result_made_by_other_code_is_not_finished(tmp_path, change):
    from cdnf_ti.atomic import atomic_write_json
    from cdnf_ti.experiments.layout import trace_path

    clip = tmp_path / "clip.npy"
    clip.write_bytes(b"x")
    expected = fingerprint(clip, "clean", "cdnf", 0, "taichi", None, "cpu")
    saved = dict(expected, **{change: "something else"})
    trace_path(tmp_path, "clean", "clip", "cdnf").parent.mkdir(parents=True)
    trace_path(tmp_path, "clean", "clip", "cdnf").write_text("frame\n")
    atomic_write_json(trace_path(tmp_path, "clean", "clip", "cdnf", "json"), {"model": "cdnf", "fingerprint": saved})
    stale: list[str] = []
    assert load_meta(tmp_path, "clean", "clip", "cdnf", expected, stale) is None
    assert len(stale) == 1 and stale[0].startswith("clip.cdnf [clean]: ")
    atomic_write_json(trace_path(tmp_path, "clean", "clip", "cdnf", "json"), {"model": "cdnf", "fingerprint": expected})
    assert load_meta(tmp_path, "clean", "clip", "cdnf", expected) is not None
