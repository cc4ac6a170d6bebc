"""Experiments at scale: labelled datasets, scoring, reports, figures, local/Dask parallel runs.

Entry points: :func:`run_dataset` (``python -m cdnf_ti.run dataset``) and
:mod:`.builtin` (``python -m cdnf_ti.run experiment table1|coherence|table2``).
"""
from __future__ import annotations

from .dataset import DatasetRun, run_dataset
from .labels import ClipLabel, read_labels, validate_dataset
from .scoring import ClipScore, Padding, Tally, score_clip, tally

__all__ = ["DatasetRun", "run_dataset", "ClipLabel", "read_labels", "validate_dataset", "ClipScore", "Padding",
           "Tally", "score_clip", "tally"]
