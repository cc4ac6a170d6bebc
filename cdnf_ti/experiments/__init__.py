"""Experiments at scale: labelled datasets, scoring, reports, figures, local/Dask parallel runs.

Entry points: :func:`run_dataset` (``python -m cdnf_ti.run dataset``),
:mod:`.builtin` (``experiment table1|coherence|table2``), :mod:`.selectivity`
(``experiment selectivity``) and :mod:`.paramsweep` (``experiment sweep``).

Layers, each importing only the ones above it:

* the task core, :mod:`.tasks` (cache entries, fingerprints, resume, parallel
  runs through :mod:`.parallel`), and the output layout, :mod:`.layout`;
* the engines, which define an experiment's tasks and run them through the
  core: :mod:`.clip_tasks` (clips, for ``dataset`` and ``sweep``) and
  :mod:`.stimulus_tasks` (generated stimuli, for ``table1``, ``coherence``,
  ``selectivity`` and the demo);
* scoring (:mod:`.scoring`, :mod:`.clipscores`, :mod:`.sweep`);
* the reporters (:mod:`.reports`, :mod:`.sweep_reports`, :mod:`.figures`,
  :mod:`.report_page`, :mod:`.htmlreport`, :mod:`.tables`), which an experiment
  calls after its engine returns; they name the engines' result types only
  for type checking;
* the experiments themselves and :mod:`.cli`.
"""
from __future__ import annotations

from .dataset import DatasetRun, run_dataset
from .labels import ClipLabel, read_labels, validate_dataset
from .scoring import ClipScore, Padding, Tally, score_clip, tally

__all__ = ["DatasetRun", "run_dataset", "ClipLabel", "read_labels", "validate_dataset", "ClipScore", "Padding",
           "Tally", "score_clip", "tally"]
