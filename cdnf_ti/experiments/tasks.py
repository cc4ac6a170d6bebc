"""The one task / cache / resume mechanism of every experiment.

Every experiment (``dataset``, ``experiment sweep``, ``experiment selectivity``,
``experiment table1`` and ``coherence``, and the demo) is a list of cache
entries, each one result: a model on a clip or a stimulus. An entry names

* its **record**: a JSON file written atomically when the result is finished
  (the "done" marker), holding the result and its fingerprint;
* the other files the result needs (its trace CSV);
* its **fingerprint** (:func:`task_fingerprint`): the code that makes the result
  (:func:`cdnf_ti.provenance.code_identity`: a digest of the package's source
  files, the kernel compiler and its version, the arch and the engine settings)
  plus the task's inputs and options.

:func:`run_cached` runs an experiment the same way for all of them:

1. an entry whose record exists, with its files, and whose fingerprint equals
   the one the run would write is reused; any other record is recomputed, and
   :func:`report_stale` says on stderr which and what differs;
2. the engine groups the entries left into units of work (a clip decoded once
   for several models, a model kept at one frame size so that it compiles
   once), which run in this process, on local processes or on a Dask cluster
   (:func:`cdnf_ti.experiments.parallel.map_tasks`);
3. each unit saves its entries' records as they finish (:func:`save_finished`),
   so an interrupted run resumes where it stopped; a unit that fails gives an
   error record for each of its entries, and an error is never saved.

Reports are written by the caller after :func:`run_cached` returns; nothing here
imports a reporter.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

from ..atomic import atomic_write_json
from ..provenance import code_identity, describe_differences, differences
from . import parallel  # parallel.map_tasks looked up at call time (tests replace it)
from .parallel import TaskFailed


def task_fingerprint(backend: str, arch: str, inputs: dict) -> dict:
    """The fingerprint of one result: its inputs and options plus the code that makes it.

    Parameters
    ----------
    backend, arch : str
        Model backend and Taichi arch (:func:`cdnf_ti.provenance.code_identity`).
    inputs : dict
        Everything else the result depends on (model, stimulus settings, input
        file size and time, seed, parameters...); JSON values.

    Returns
    -------
    dict
        The fingerprint as it reads back from a JSON file (tuples become lists).
    """
    return json.loads(json.dumps({**inputs, **code_identity(backend, arch)}, default=str))


@dataclass(frozen=True)
class Entry:
    """One cached result.

    Attributes
    ----------
    name : str
        How a report names it: ``"c01.cdnf [clean]"``.
    record_file : str
        Its JSON record; empty: the result is not kept (never reused, never saved).
    fingerprint_json : str
        Its fingerprint (:func:`task_fingerprint`) as canonical JSON (so entries are hashable).
    outputs : tuple of str
        Other files a finished result needs (its trace).
    """

    name: str
    record_file: str
    fingerprint_json: str
    outputs: tuple[str, ...] = ()

    @classmethod
    def make(cls, name: str, record_file: str | Path | None, fingerprint: dict,
             outputs: Sequence[str | Path] = ()) -> "Entry":
        """An entry from a fingerprint dict (``record_file`` None: not kept)."""
        return cls(name, "" if record_file is None else str(record_file),
                   json.dumps(fingerprint, sort_keys=True, default=str), tuple(str(p) for p in outputs))

    @property
    def fingerprint(self) -> dict:
        return json.loads(self.fingerprint_json)

    @property
    def kept(self) -> bool:
        """Whether the result is saved (and so can be reused by a rerun)."""
        return bool(self.record_file)


def load_finished(entry: Entry, stale: list[str] | None = None) -> dict | None:
    """The finished record of ``entry``, or None.

    A record is finished when it and every file in ``entry.outputs`` exist, it
    reads as a JSON object without an error, and its ``fingerprint`` equals the
    entry's. A record made by other code or options is not finished; when
    ``stale`` is a list, ``"<name>: <what differs>"`` is appended to it.
    """
    if not entry.kept:
        return None
    rp = Path(entry.record_file)
    if not rp.is_file() or not all(Path(p).is_file() for p in entry.outputs):
        return None
    try:
        rec = json.loads(rp.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(rec, dict) or rec.get("error"):
        return None
    expected = entry.fingerprint
    if rec.get("fingerprint") != expected:
        if stale is not None:
            what = describe_differences(differences(rec.get("fingerprint"), expected))
            stale.append(f"{entry.name}: {what or 'fingerprint'}")
        return None
    return rec


def save_finished(entry: Entry, record: dict) -> dict:
    """Save a finished result's record (atomically, with the entry's fingerprint); return it.

    Call it after the entry's other files are written: the record is the done marker.
    A record with an error, or of an entry that is not kept, is returned unsaved.
    """
    record = dict(record, fingerprint=entry.fingerprint)
    if entry.kept and not record.get("error"):
        atomic_write_json(entry.record_file, record)
    return record


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


@dataclass
class CachedRun:
    """What :func:`run_cached` did.

    Attributes
    ----------
    records : list of dict
        One record per entry, in the entries' order: reused, computed now, or an
        error record (``error`` set).
    ran : int
        Entries computed now without error.
    reused : int
        Entries found finished.
    failed : int
        Entries that gave an error.
    """

    records: list[dict] = field(default_factory=list)
    ran: int = 0
    reused: int = 0
    failed: int = 0


def one_per_entry(todo: Sequence[int], make: Callable[[int], Any]) -> list[tuple[Any, list[int]]]:
    """A unit of work per entry: ``[(make(i), [i]) for i in todo]`` (for :func:`run_cached`)."""
    return [(make(i), [i]) for i in todo]


def run_cached(entries: Sequence[Entry], plan: Callable[[list[int]], list[tuple[Any, list[int]]]],
               fn: Callable[[Any], Any], *, failed: Callable[[int, str], dict],
               workers: int | None = None, scheduler: Any = None, arch: str | None = "cpu",
               progress: bool | str = False, describe: Callable[[Any, Any], str] | None = None,
               on_record: Callable[[int, dict], None] | None = None) -> CachedRun:
    """Reuse the finished entries, compute the others in parallel, return every record.

    Parameters
    ----------
    entries : sequence of Entry
        Every result of the experiment.
    plan : callable
        ``plan(todo)`` -> ``[(unit, indices), ...]``: the units of work that compute
        the entries ``todo`` (indices into ``entries``, in order); each index in
        exactly one unit. A unit is a picklable task for ``fn``.
    fn : callable
        Top-level function of one unit; returns the records of its entries, in the
        order of its indices (a single dict for a unit of one entry), and saves the
        finished ones with :func:`save_finished`.
    failed : callable
        ``failed(index, message)`` -> the error record of an entry whose unit raised.
    workers, scheduler, arch, progress, describe
        As :func:`cdnf_ti.experiments.parallel.map_tasks`.
    on_record : callable, optional
        ``on_record(index, record)`` in this process as each record computed now arrives.

    Returns
    -------
    CachedRun
    """
    stale: list[str] = []
    records: list[dict | None] = [load_finished(e, stale) for e in entries]
    report_stale(stale)
    todo = [i for i, r in enumerate(records) if r is None]
    run = CachedRun(reused=len(entries) - len(todo))
    if progress and run.reused:
        label = progress if isinstance(progress, str) else "tasks"
        print(f"{label}: {run.reused} of {len(entries)} result(s) reused from the output folder", file=sys.stderr)
    units = plan(todo) if todo else []
    for j, res in parallel.map_tasks(fn, [u for u, _ in units], workers=workers, scheduler=scheduler, arch=arch,
                                     progress=progress, describe=describe):
        indices = units[j][1]
        if isinstance(res, TaskFailed):
            recs = [failed(i, str(res)) for i in indices]
        else:
            recs = [res] if isinstance(res, dict) else list(res)
        for i, rec in zip(indices, recs):
            records[i] = rec
            if rec.get("error"):
                run.failed += 1
            else:
                run.ran += 1
            if on_record is not None:
                on_record(i, rec)
    run.records = [r if r is not None else failed(i, "not run") for i, r in enumerate(records)]
    return run


@dataclass(frozen=True)
class Batch:
    """Tasks run one after another in one worker (a unit of :func:`run_cached`).

    Taichi specialises a model's kernels to the frame shape, so a worker that
    keeps one model at one frame size compiles once per batch instead of once
    per task. Each task is an object with a ``run()`` method returning its record.

    Attributes
    ----------
    tasks : tuple
    label : str
        How progress lines name the batch (``"cdnf 600x600 px"``).
    """

    tasks: tuple
    label: str = ""


def run_batch(batch: Batch) -> list[dict]:
    """Run every task of a batch; a task that raises gives ``{"error": ...}`` and the rest go on."""
    out = []
    for t in batch.tasks:
        try:
            out.append(t.run())
        except Exception as e:  # noqa: BLE001 - one failed task must not stop the batch
            out.append({"error": parallel._one_line(e)})
    return out


def describe_batch(batch: Batch, records: Any) -> str:
    """Progress line of a batch: ``cdnf 600x600 px (6 tasks): 12.3 s`` (a batch of one: its label) or its errors."""
    n = len(batch.tasks)
    head = (batch.label or "batch") + ("" if n == 1 else f" ({n} tasks)")
    if records is None:
        return head
    if isinstance(records, TaskFailed):
        return f"{head}: error: {records}"
    errs = [r for r in records if r.get("error")]
    secs = sum(float(r.get("seconds") or 0) for r in records if not r.get("error"))
    return f"{head}: {secs:.1f} s" + (f"; {len(errs)} failed: {errs[0]['error']}" if errs else "")


def batches(todo: Sequence[int], tasks: Sequence[Any], group: Callable[[Any], tuple],
            label: Callable[[Any], str] = lambda t: "", chunk: int = 16) -> list[tuple[Batch, list[int]]]:
    """A :func:`run_cached` plan: the tasks ``todo`` (indices into ``tasks``) grouped by ``group(task)``
    (e.g. model and frame shape), in chunks of at most ``chunk``, largest first."""
    groups: dict[tuple, list[int]] = {}
    for i in todo:
        groups.setdefault(group(tasks[i]), []).append(i)
    out = []
    for ix in groups.values():
        for k in range(0, len(ix), chunk):
            part = ix[k:k + chunk]
            out.append((Batch(tuple(tasks[i] for i in part), label(tasks[part[0]])), part))
    out.sort(key=lambda b: -len(b[1]))
    return out
