"""Seeded mutation fuzz of the untrusted inputs that are not event recordings (issue 37): videos
(motion-JPEG and FFV1 AVI), ``.npy`` frame arrays and ``labels.csv`` files.

Every case runs the command line in a child process under a memory cap (``RLIMIT_AS``) and a
time cap, with the NumPy reference backend (no kernel compile), and must end in exactly one
``error:`` line (exit 1 or 2) or a valid result (exit 0, with its traces): never a traceback, a
hang or memory past the cap. The mutants are drawn from fixed seeds, so a failure names a case
that reproduces; mutants that found bugs are kept as regression files
``tests/data/fuzz/inputs_*`` and run first.
"""
from __future__ import annotations

import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mjpeg_avi import mjpeg_avi
from test_faults import ENV

from cdnf_ti.video import write_video

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="uses RLIMIT_AS")

CORPUS = Path(__file__).resolve().parent / "data" / "fuzz"
#: Address space a case may use (bytes): the interpreter with NumPy and OpenCV needs about 1 GiB.
MEMORY_CAP = 2 << 30
#: Seconds a case may run (a loaded machine starts Python slowly; a hang is far longer).
TIME_CAP = 120
#: Mutants drawn per input kind.
CASES = 8
#: Frames of every base clip (T, H, W), uint8.
SHAPE = (6, 16, 16)


def _frames(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, SHAPE, dtype=np.uint8)


def _npy_bytes(a: np.ndarray) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def _ffv1_bytes(tmp: Path) -> bytes:
    path = tmp / "base.avi"
    write_video(path, list(_frames(1)), fps=30.0)
    return path.read_bytes()


LABELS = ("clip,label,window_start,window_end,contact_frame\n"
          "c1,collision,2,5,5\n"
          "c2,non-collision,,,\n"
          "c3,near-miss,,,\n")


def mutate_bytes(data: bytes, rng: np.random.Generator, head: int | None = None) -> bytes:
    """One seeded mutation of ``data``: flipped bits, a zeroed or 0xFF run, a cut, or inserted bytes.

    ``head``: mutate within the first ``head`` bytes only (a header).
    """
    b = bytearray(data)
    span = len(b) if head is None else min(head, len(b))
    kind = int(rng.integers(5))
    at = int(rng.integers(span))
    if kind == 0:
        for i in rng.integers(span, size=int(rng.integers(1, 9))):
            b[int(i)] ^= 1 << int(rng.integers(8))
    elif kind in (1, 2):
        n = int(rng.integers(1, 65))
        b[at:at + n] = (b"\0" if kind == 1 else b"\xff") * len(b[at:at + n])
    elif kind == 3:
        del b[at:]
    else:
        b[at:at] = rng.integers(0, 256, int(rng.integers(1, 33)), dtype=np.uint8).tobytes()
    return bytes(b)


#: Header values a hostile .npy may state.
NPY_SHAPES = ["(0, 16, 16)", "(6, 0, 16)", "(6, 16)", "(6, 16, 16, 2)", "(100000, 100000, 100000)",
              "(-6, 16, 16)", "(6, 4294967297, 16)", "(6, 16, 16, 3)", "(6, 1, 1)", "()"]
NPY_DESCRS = ["'|O'", "'<f8'", "'<U3'", "'>i4'", "'|b1'", "'<c16'", "'<M8[s]'", "'|V3'", "'<f2'", "'u1'"]


def mutate_npy(data: bytes, rng: np.random.Generator) -> bytes:
    """A header field replaced by a hostile value (shape, dtype, order), or a byte mutation."""
    text = data.decode("latin-1")
    kind = int(rng.integers(4))
    if kind == 0:
        start = text.index("'shape': ") + len("'shape': ")
        end = text.index(")", start) + 1
        text = text[:start] + NPY_SHAPES[int(rng.integers(len(NPY_SHAPES)))] + text[end:]
    elif kind == 1:
        start = text.index("'descr': ") + len("'descr': ")
        end = text.index(",", start)
        text = text[:start] + NPY_DESCRS[int(rng.integers(len(NPY_DESCRS)))] + text[end:]
    elif kind == 2:
        text = text.replace("'fortran_order': False", "'fortran_order': True")
        return mutate_bytes(text.encode("latin-1"), rng)
    else:
        return mutate_bytes(data, rng, head=128)
    return text.encode("latin-1")


#: Values a hostile labels row may hold.
CLIP_NAMES = ["../c1", "/etc/passwd", "c1/../c1", "", "c1\0", "c\u00e9", "c1" * 2000, ".", "..", "C:c1", "c1 "]
FRAME_VALUES = ["-1", "1e300", "nan", "inf", "3.5", "99999999999999999999", "", "0x10", "2", "\u0663"]
LABEL_VALUES = ["collision", "COLLISION", "", "maybe", "near_miss", "non-collision\0"]


def mutate_labels(text: str, rng: np.random.Generator) -> bytes:
    """A field of a row replaced by a hostile value, a row duplicated or cut, or a byte mutation."""
    rows = [r.split(",") for r in text.splitlines()]
    kind = int(rng.integers(6))
    row = rows[1 + int(rng.integers(len(rows) - 1))]
    if kind == 0:
        row[0] = CLIP_NAMES[int(rng.integers(len(CLIP_NAMES)))]
    elif kind == 1:
        row[2 + int(rng.integers(3))] = FRAME_VALUES[int(rng.integers(len(FRAME_VALUES)))]
    elif kind == 2:
        row[1] = LABEL_VALUES[int(rng.integers(len(LABEL_VALUES)))]
    elif kind == 3:
        rows.append(list(row))
    elif kind == 4:
        del row[int(rng.integers(len(row))):]
    else:
        return mutate_bytes(text.encode(), rng)
    return ("\n".join(",".join(r) for r in rows) + "\n").encode("utf-8", "surrogatepass")


def _cap_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP, MEMORY_CAP))


def run_capped(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """``python -m cdnf_ti.run ARGS`` in a child process under :data:`MEMORY_CAP` and :data:`TIME_CAP`."""
    env = dict(ENV, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-m", "cdnf_ti.run", *args, "--backend", "numpy", "--no-progress"],
                          capture_output=True, text=True, errors="replace", timeout=TIME_CAP, env=env, cwd=cwd,
                          preexec_fn=_cap_memory)


def assert_one_error_or_a_result(proc: subprocess.CompletedProcess, result: Path) -> None:
    """Exactly one ``error:`` line and exit 1 or 2, or exit 0 with ``result`` written; never a traceback."""
    err = proc.stderr
    assert "Traceback" not in err and "MemoryError" not in err, err[-3000:]
    errors = [ln for ln in err.splitlines() if ln.startswith("error:")]
    if proc.returncode == 0:
        assert not errors and result.exists(), err
    else:
        assert proc.returncode in (1, 2) and len(errors) == 1, (proc.returncode, err)


def _cases(kind: str) -> list[str]:
    kept = sorted(p.name for p in CORPUS.glob(f"inputs_{kind}_*")) if CORPUS.is_dir() else []
    return kept + [f"seed{s}" for s in range(CASES)]


def _input(kind: str, case: str, tmp: Path) -> bytes:
    """The bytes of one case: a kept regression file, or the mutant of seed ``case``."""
    if not case.startswith("seed"):
        return (CORPUS / case).read_bytes()
    rng = np.random.default_rng([37, ["mjpeg", "ffv1", "npy", "labels"].index(kind), int(case[4:])])
    if kind == "mjpeg":
        return mutate_bytes(mjpeg_avi(list(_frames(0))), rng)
    if kind == "ffv1":
        return mutate_bytes(_ffv1_bytes(tmp), rng)
    if kind == "npy":
        return mutate_npy(_npy_bytes(_frames(2)), rng)
    return mutate_labels(LABELS, rng)


@linux_only
@pytest.mark.parametrize("kind,case", [(k, c) for k in ("mjpeg", "ffv1", "npy") for c in _cases(k)])
def test_mutated_clip_gives_one_error_line_or_a_result(kind, case, tmp_path):
    clip = tmp_path / ("clip.npy" if kind == "npy" else "clip.avi")
    clip.write_bytes(_input(kind, case, tmp_path))
    proc = run_capped(str(clip), "--out", "out", cwd=tmp_path)
    assert_one_error_or_a_result(proc, tmp_path / "out" / "clip.cdnf.csv")


@linux_only
@pytest.mark.parametrize("case", _cases("labels"))
def test_mutated_labels_file_gives_one_error_line_or_a_result(case, tmp_path):
    ds = tmp_path / "a" / "ds"
    ds.mkdir(parents=True)
    for seed, name in enumerate(("c1", "c2", "c3")):
        np.save(ds / f"{name}.npy", _frames(10 + seed))
    (ds / "labels.csv").write_bytes(_input("labels", case, tmp_path))
    np.save(tmp_path / "c1.npy", _frames(99))  # outside the dataset folder: never read
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    proc = run_capped("dataset", str(ds), "--out", str(tmp_path / "a" / "out"), "--workers", "0", "--no-figures",
                      cwd=tmp_path)
    assert_one_error_or_a_result(proc, tmp_path / "a" / "out" / "results.csv")
    after = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if not p.is_relative_to(tmp_path / "a"))
    assert after == [p for p in before if not (tmp_path / p).is_relative_to(tmp_path / "a")]


def test_mutations_are_reproducible_from_their_seed(tmp_path):
    assert _input("npy", "seed3", tmp_path) == _input("npy", "seed3", tmp_path)
    assert _input("labels", "seed3", tmp_path) == _input("labels", "seed3", tmp_path)
    assert len({_input("mjpeg", f"seed{s}", tmp_path) for s in range(CASES)}) == CASES
