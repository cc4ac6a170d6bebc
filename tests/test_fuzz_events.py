"""Seeded mutation fuzz of the event formats and of ``.npy`` inputs (issue 37).

Each format's small valid file is mutated (bytes flipped, runs set to 0x00 or 0xFF, cut short,
a block repeated) by a seeded generator; every mutant is read by the command line in a child
process capped in address space (``RLIMIT_AS``) and time. Each mutant must give a valid result
(exit 0) or exactly one ``error: <file>: ...`` line (exit 2); never a traceback, a decoder's
panic text, a hang or memory past the cap. Event recordings go through ``events --info``, which
reads and bins every event as ``run`` does; a plain ``.npy`` frame array through ``events VIDEO``,
which decodes every frame (neither compiles kernels, so the fuzz stays within seconds).

The mutants that found bugs are kept as regression files, ``tests/data/fuzz/events_*``, and
checked the same way.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from event_encoders import encode_aedat4, encode_dat, encode_evt2, encode_evt3, random_events, raw_header
from test_faults import ENV, linux_only

SIZE = (64, 48)
FUZZ = Path(__file__).resolve().parent / "data" / "fuzz"
#: Mutants per format.
N_MUTANTS = 24
#: Address-space cap of a child (its imports take about 0.4 GiB), and seconds per mutant.
CAP_BYTES = 3 << 29
SECONDS_PER_FILE = 20

pytestmark = linux_only

#: The child: reads each file given, one JSON line per file (exit code, stderr), under the caps.
CHILD = r"""
import contextlib, io, json, os, resource, signal, sys, tempfile, traceback
cap, seconds = int(sys.argv[1]), int(sys.argv[2])
resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
from cdnf_ti.run import main

class Hang(Exception):
    pass

def on_alarm(*_):
    raise Hang()

signal.signal(signal.SIGALRM, on_alarm)
out = tempfile.mkdtemp()
for i, f in enumerate(sys.argv[3:]):
    print(json.dumps({"start": f}), flush=True)
    err = io.StringIO()
    argv = (["events", f, "--out", os.path.join(out, f"{i}.npy"), "--no-progress"] if "frames" in f
            else ["events", "--info", f])
    signal.alarm(seconds)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main(argv)
    except Hang:
        code = "hang"
    except BaseException:
        code = "crash"
        err.write(traceback.format_exc())
    signal.alarm(0)
    print(json.dumps({"file": f, "code": code, "stderr": err.getvalue()}), flush=True)
"""


def base_files(folder: Path) -> dict[str, Path]:
    """One small valid file per format (a few KB each)."""
    ev = random_events(300, SIZE, duration_us=1_000_000, seed=0)
    files = {
        "npy": folder / "base.npy", "npz": folder / "base.npz", "dat": folder / "base.dat",
        "evt2": folder / "base_evt2.raw", "evt3": folder / "base_evt3.raw", "frames": folder / "base_frames.npy",
    }
    np.save(files["npy"], ev)
    np.savez(files["npz"], t=ev["t"], x=ev["x"], y=ev["y"], p=ev["p"])
    files["dat"].write_bytes(encode_dat(ev, SIZE))
    files["evt2"].write_bytes(raw_header({"evt": "2.0", "geometry": "64x48"}) + encode_evt2(ev))
    files["evt3"].write_bytes(raw_header({"evt": "3.0", "geometry": "64x48"}) + encode_evt3(ev))
    np.save(files["frames"], np.random.default_rng(0).integers(0, 256, (4, 16, 16), dtype=np.uint8))
    try:
        import aedat  # noqa: F401

        files["aedat4"] = folder / "base.aedat4"
        files["aedat4"].write_bytes(encode_aedat4(ev, SIZE, packet_events=100))
    except ImportError:
        pass
    try:
        import h5py

        files["hdf5"] = folder / "base.h5"
        with h5py.File(files["hdf5"], "w") as h:
            for k in "txyp":
                h.create_dataset(f"events/{k}", data=ev[k])
            h.create_dataset("t_offset", data=np.int64(0))
            h.attrs["width"], h.attrs["height"] = SIZE
    except ImportError:
        pass
    return files


def mutate(data: bytes, rng: np.random.Generator) -> bytes:
    """One seeded mutation of ``data``: flipped bytes, a run of 0x00 or 0xFF, a cut, or a repeated block.
    Half of the changes fall in the first 256 bytes, where the headers are."""
    b = bytearray(data)

    def pos() -> int:
        return int(rng.integers(0, min(256, len(b)))) if rng.random() < 0.5 else int(rng.integers(0, len(b)))

    kind = int(rng.integers(0, 4))
    if kind == 0:
        for _ in range(int(rng.integers(1, 5))):
            b[pos()] ^= 1 << int(rng.integers(0, 8))
    elif kind == 1:
        i = pos()
        b[i:i + 8] = bytes([0xFF if rng.random() < 0.5 else 0x00]) * len(b[i:i + 8])
    elif kind == 2:
        del b[pos():]
    else:
        i, n = pos(), int(rng.integers(1, 64))
        b[i:i] = b[i:i + n]
    return bytes(b)


def check_in_child(files: list[Path]) -> list[str]:
    """Read ``files`` in a capped child; the problems found (empty: every file behaved)."""
    proc = subprocess.run([sys.executable, "-c", CHILD, str(CAP_BYTES), str(SECONDS_PER_FILE), *map(str, files)],
                          capture_output=True, text=True, env=ENV, timeout=SECONDS_PER_FILE * len(files) + 60)
    results = [json.loads(ln) for ln in proc.stdout.splitlines() if ln.startswith("{")]
    done = {r["file"]: r for r in results if "file" in r}
    problems = []
    for f in map(str, files):
        r = done.get(f)
        if r is None:
            problems.append(f"{f}: the child died (exit {proc.returncode}): {proc.stderr[-500:]}")
            break
        lines = [ln for ln in r["stderr"].splitlines() if ln.strip()]
        errors = [ln for ln in lines if ln.startswith("error:")]
        others = [ln for ln in lines if not ln.startswith(("error:", "warning:", "note:"))]
        if r["code"] not in (0, 2) or others or len(errors) != (r["code"] == 2):
            problems.append(f"{f}: exit {r['code']}: {r['stderr'][-800:]}")
        elif errors and not errors[0].startswith(f"error: {f}: "):
            problems.append(f"{f}: the error line does not name the file: {errors[0]}")
    if "panicked" in proc.stderr:
        problems.append(f"a decoder's panic text reached stderr: {proc.stderr[-300:]}")
    return problems


@pytest.mark.parametrize("fmt", ["npy", "npz", "dat", "evt2", "evt3", "aedat4", "hdf5", "frames"])
def test_mutants_of_each_format_give_a_result_or_one_error_line(fmt, tmp_path):
    files = base_files(tmp_path)
    if fmt not in files:
        pytest.skip(f"the {fmt} reader's package is not installed")
    base = files[fmt]
    rng = np.random.default_rng(["npy", "npz", "dat", "evt2", "evt3", "aedat4", "hdf5", "frames"].index(fmt))
    mutants = [base]
    for i in range(N_MUTANTS):
        m = tmp_path / f"m{i:02d}_{base.name}"
        m.write_bytes(mutate(base.read_bytes(), rng))
        mutants.append(m)
    assert check_in_child(mutants) == []


def test_the_kept_mutants_give_one_error_line_each():
    kept = sorted(FUZZ.glob("events_*"))
    assert kept, "no regression files in tests/data/fuzz"
    if any(f.suffix == ".aedat4" for f in kept):
        pytest.importorskip("aedat")
    assert check_in_child(kept) == []
