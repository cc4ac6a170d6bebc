"""The output layout of a dataset run: results.csv columns, trace paths, finished records and their fingerprints.

A leaf of :mod:`cdnf_ti.experiments`: the engine (:mod:`.dataset`), the reports,
the figures and the parameter sweep read and write a run's folder through it.
"""
from __future__ import annotations

import json
import os
import sys
import zlib
from pathlib import Path
from typing import Any

from ..provenance import code_identity, describe_differences, differences

CONDITIONS = ("clean", "rain")
RAIN_CHOICES = {"none": ("clean",), "only": ("rain",), "both": ("clean", "rain")}

#: Columns of results.csv, in order.
RESULT_COLUMNS = (
    "clip", "model", "condition", "label", "window_start", "window_end", "window_lo", "window_hi",
    "contact_frame", "frames", "video_fps", "first_alert", "first_alert_s", "outcome", "fn_reason",
    "lead_time_ms", "output_name", "max_output", "threshold", "snr_db", "unconverged_frames",
    "seconds", "error",
)


def rain_seed(seed: int, clip: str) -> int:
    """The rain seed of one clip: a function of the run seed and the clip name only
    (so it does not depend on the order or place the clip runs)."""
    return (int(seed) * 1_000_003 + zlib.crc32(clip.encode("utf-8"))) % (2**32)


def trace_path(out: str | os.PathLike, condition: str, clip: str, model: str, ext: str = "csv") -> Path:
    """``OUT/traces/<condition>/<clip>.<model>.<ext>``."""
    return Path(out) / "traces" / condition / f"{clip}.{model}.{ext}"


def fingerprint(path: str | os.PathLike, condition: str, model: str, seed: int, backend: str,
                rain_params: dict | None, arch: str = "cpu", options: dict | None = None) -> dict:
    """What a saved result depends on: the input file (path, size, mtime), the model, the code that
    ran it (:func:`cdnf_ti.provenance.code_identity`: a digest of the package's source files, the
    kernel compiler and its version, the arch and the engine settings) and, for rain, the seed and
    rain settings.

    A finished result is reused on a rerun only when its fingerprint is the same, so changing
    ``--seed``, the rain settings, the backend, the compiler, the input or any source file of
    cdnf_ti recomputes it.
    """
    st = os.stat(path)
    fp: dict[str, Any] = {"source": str(path), "source_size": st.st_size, "source_mtime_ns": st.st_mtime_ns,
                          "model": model, "condition": condition, **code_identity(backend, arch)}
    if condition == "rain":
        fp.update(seed=seed, rain_params=rain_params or {})
    if options:  # how the input is read and the model set up, where not the defaults (--fps, --param, ...)
        fp.update(options=options)
    return json.loads(json.dumps(fp))  # the form it takes after a JSON round trip


def load_meta(out: str | os.PathLike, condition: str, clip: str, model: str,
              expected: dict | None = None, stale: list[str] | None = None) -> dict | None:
    """The finished record of (clip, model, condition), or None if not finished.

    With ``expected`` (a :func:`fingerprint`), a record made with other code, options or
    another input counts as not finished; when ``stale`` is a list, a line naming the record
    and what differs (``"c01.cdnf [clean]: source code"``) is appended to it, so the caller
    can say what it recomputes.
    """
    jp = trace_path(out, condition, clip, model, "json")
    cp = trace_path(out, condition, clip, model, "csv")
    if not (jp.is_file() and cp.is_file()):
        return None
    try:
        meta = json.loads(jp.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(meta, dict) or meta.get("model") != model:
        return None
    if expected is not None and meta.get("fingerprint") != expected:
        if stale is not None:
            what = describe_differences(differences(meta.get("fingerprint"), expected))
            stale.append(f"{clip}.{model} [{condition}]: {what or 'fingerprint'}")
        return None
    return meta


def report_stale(stale: list[str], stream: Any = None) -> None:
    """Say, on stderr, that finished results made by other code or options are recomputed.

    One line with the count and the first few results and what differs; nothing when none.
    """
    if not stale:
        return
    stream = sys.stderr if stream is None else stream
    shown = "; ".join(stale[:3]) + (f"; and {len(stale) - 3} more" if len(stale) > 3 else "")
    print(f"note: {len(stale)} finished result(s) in the output folder were made by other code or options "
          f"and are recomputed ({shown})", file=stream)
