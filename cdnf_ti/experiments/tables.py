"""Plain-text tables of the experiment reports: CSV text, results.csv read-back, percentages.

A leaf of :mod:`cdnf_ti.experiments` shared by :mod:`.reports` and :mod:`.sweep_reports`.
"""
from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, float):
        if not math.isfinite(v):
            return ""
        return f"{v:.6g}"
    return str(v)


def csv_text(rows: Iterable[Mapping], columns: Sequence[str]) -> str:
    """CSV text of ``rows`` restricted to ``columns`` (None -> empty cell)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in columns])
    return buf.getvalue()


def read_results(path: str | Path) -> list[dict]:
    """Read a results.csv back (all values as strings)."""
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def pct(acc: float | None) -> str:
    """``0.7714`` -> ``"77.14%"``; None -> ``"n/a"``."""
    return "n/a" if acc is None else f"{100.0 * acc:.2f}%"
