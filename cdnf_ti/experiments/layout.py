"""The output layout of a dataset run: results.csv columns, trace paths, finished records and their fingerprints.

The clip engine (:mod:`.clip_tasks`), the reports, the figures and the parameter
sweep read and write a run's folder through it; its finished records are the
cache entries of :mod:`.tasks`.
"""
from __future__ import annotations

import json
import os
import zlib
from pathlib import Path
from typing import Any

from ..paths import inside
from ..provenance import input_identity
from .tasks import Entry, load_finished, report_stale as report_stale, task_fingerprint

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
    """``OUT/traces/<condition>/<clip>.<model>.<ext>``, checked to lie inside it (:func:`cdnf_ti.paths.inside`)."""
    return inside(Path(out) / "traces" / condition, f"{clip}.{model}.{ext}")


def fingerprint(path: str | os.PathLike, condition: str, model: str, seed: int, backend: str,
                rain_params: dict | None, arch: str = "cpu", options: dict | None = None) -> dict:
    """What a saved result depends on: the input file (path, size, mtime and a digest of its first and
    last MiB, :func:`cdnf_ti.provenance.input_identity`), the model, the code that
    ran it (:func:`cdnf_ti.provenance.code_identity`: a digest of the package's source files, the
    kernel compiler and its version, the arch and the engine settings) and, for rain, the seed and
    rain settings.

    A finished result is reused on a rerun only when its fingerprint is the same, so changing
    ``--seed``, the rain settings, the backend, the compiler, the input or any source file of
    cdnf_ti recomputes it.
    """
    fp: dict[str, Any] = {**input_identity(path), "model": model, "condition": condition}
    if condition == "rain":
        fp.update(seed=seed, rain_params=rain_params or {})
    if options:  # how the input is read and the model set up, where not the defaults (--fps, --param, ...)
        fp.update(options=options)
    return task_fingerprint(backend, arch, fp)


def trace_entry(out: str | os.PathLike, condition: str, clip: str, model: str, fp: dict) -> Entry:
    """The cache entry (:class:`.tasks.Entry`) of the trace of (clip, model, condition) under ``out``:
    its record ``<clip>.<model>.json`` beside the trace CSV, with fingerprint ``fp``."""
    return Entry.make(f"{clip}.{model} [{condition}]", trace_path(out, condition, clip, model, "json"), fp,
                      [trace_path(out, condition, clip, model)])


def load_meta(out: str | os.PathLike, condition: str, clip: str, model: str,
              expected: dict | None = None, stale: list[str] | None = None) -> dict | None:
    """The finished record of (clip, model, condition), or None if not finished.

    With ``expected`` (a :func:`fingerprint`), a record made with other code, options or
    another input counts as not finished; when ``stale`` is a list, a line naming the record
    and what differs (``"c01.cdnf [clean]: source code"``) is appended to it, so the caller
    can say what it recomputes.
    """
    if expected is not None:
        meta = load_finished(trace_entry(out, condition, clip, model, expected), stale)
        return meta if meta is not None and meta.get("model") == model else None
    jp = trace_path(out, condition, clip, model, "json")
    if not (jp.is_file() and trace_path(out, condition, clip, model).is_file()):
        return None
    try:
        meta = json.loads(jp.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return meta if isinstance(meta, dict) and meta.get("model") == model else None
