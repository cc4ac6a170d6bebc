"""``bench/ab_step.py --interleave``: both versions step in one process, each from its own checkout."""
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _interleaved(a: Path, b: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(ROOT / "bench" / "ab_step.py"), "--a", f"{sys.executable}:{a}", "--b",
         f"{sys.executable}:{b}", "--models", "lgmd1", "--size", "64x48", "--frames", "6", "--rounds", "2",
         "--interleave"], capture_output=True, text=True, timeout=900)


def _copy_of_the_code(dest: Path) -> Path:
    for folder in ("cdnf_ti", "kernels", "stimuli", "bench"):
        shutil.copytree(ROOT / folder, dest / folder, ignore=shutil.ignore_patterns("__pycache__"))
    return dest


def test_interleaved_versions_run_from_their_own_checkouts_and_agree_when_the_code_is_the_same(tmp_path):
    copy = _copy_of_the_code(tmp_path / "copy")
    proc = _interleaved(ROOT, copy)
    assert proc.returncode == 0, proc.stderr[-3000:]
    loaded = [ln.split(" ", 1)[1] for ln in proc.stderr.splitlines() if ln.startswith("LOADED ")]
    assert len(loaded) == 4  # two rounds, the two versions each
    assert {Path(p).parent.parent for p in loaded} == {ROOT, copy.resolve()}
    row = next(ln for ln in proc.stdout.splitlines() if ln.startswith("| lgmd1 |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert float(cells[7]) == 0.0 and cells[8] == "yes"  # the same code: the same outputs and alerts


def test_interleave_refuses_two_interpreters(tmp_path):
    proc = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "ab_step.py"), "--a", f"{sys.executable}:{ROOT}", "--b",
         f"/usr/bin/env:{ROOT}", "--models", "lgmd1", "--rounds", "1", "--interleave"],
        capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0
    assert proc.stderr.strip().splitlines()[-1].startswith("error: --interleave:")
