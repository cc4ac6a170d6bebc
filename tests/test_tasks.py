"""The one task / cache / resume mechanism (cdnf_ti.experiments.tasks) that every experiment runs through."""
from __future__ import annotations

import inspect
import json
from dataclasses import dataclass

import pytest

from cdnf_ti import demo
from cdnf_ti.experiments import builtin, tasks
from cdnf_ti.experiments.tasks import Batch, Entry, batches, load_finished, run_cached, save_finished


@dataclass(frozen=True)
class Square:
    """A toy task: x squared, kept in ``<out>/<x>.json``; ``x < 0`` raises."""

    x: int
    out: str
    scale: int = 1

    def entry(self) -> Entry:
        return Entry.make(f"square {self.x}", f"{self.out}/{self.x}.json",
                          tasks.task_fingerprint("numpy", "cpu", {"x": self.x, "scale": self.scale}))

    def run(self) -> dict:
        if self.x < 0:
            raise ValueError("negative")
        return save_finished(self.entry(), {"x": self.x, "y": self.scale * self.x ** 2})


def _run(items, **kw):
    return run_cached([t.entry() for t in items], lambda todo: batches(todo, items, lambda t: (t.x % 2,)),
                      tasks.run_batch, failed=lambda i, msg: {"error": msg}, workers=0, arch=None, **kw)


def test_a_first_run_computes_every_entry_and_keeps_its_record(tmp_path):
    items = [Square(x, str(tmp_path)) for x in range(4)]
    run = _run(items)
    assert (run.ran, run.reused, run.failed) == (4, 0, 0)
    assert [r["y"] for r in run.records] == [0, 1, 4, 9]
    rec = json.loads((tmp_path / "3.json").read_text())
    assert rec["fingerprint"] == items[3].entry().fingerprint and "source_digest" in rec["fingerprint"]


def test_a_rerun_reuses_every_finished_entry(tmp_path):
    items = [Square(x, str(tmp_path)) for x in range(4)]
    _run(items)
    again = _run(items)
    assert (again.ran, again.reused) == (0, 4)
    assert [r["y"] for r in again.records] == [0, 1, 4, 9]


def test_other_options_recompute_and_say_why(tmp_path, capsys):
    _run([Square(x, str(tmp_path)) for x in range(3)])
    capsys.readouterr()
    again = _run([Square(x, str(tmp_path), scale=2) for x in range(3)])
    assert (again.ran, again.reused) == (3, 0)
    assert [r["y"] for r in again.records] == [0, 2, 8]
    err = capsys.readouterr().err
    assert "3 finished result(s)" in err and "square 0: scale" in err


def test_other_code_recomputes(tmp_path, monkeypatch, capsys):
    items = [Square(x, str(tmp_path)) for x in range(2)]
    _run(items)
    real = tasks.code_identity
    monkeypatch.setattr(tasks, "code_identity", lambda b, a: dict(real(b, a), source_digest="edited"))
    again = _run(items)
    assert (again.ran, again.reused) == (2, 0)
    assert "source code" in capsys.readouterr().err


def test_a_failed_task_gives_an_error_record_that_is_not_kept(tmp_path):
    items = [Square(-1, str(tmp_path)), Square(2, str(tmp_path))]
    run = _run(items)
    assert (run.ran, run.failed) == (1, 1)
    assert "negative" in run.records[0]["error"] and run.records[1]["y"] == 4
    assert not (tmp_path / "-1.json").exists()
    assert _run(items).failed == 1  # tried again, not reused


def test_an_entry_without_a_record_file_is_never_kept(tmp_path):
    e = Entry.make("demo", None, {"a": 1})
    assert save_finished(e, {"v": 1}) == {"v": 1, "fingerprint": {"a": 1}}
    assert load_finished(e) is None and not list(tmp_path.iterdir())


def test_batches_group_by_key_in_chunks_largest_first():
    items = [Square(x, "o") for x in range(7)]
    plan = batches(range(7), items, lambda t: (t.x % 2,), chunk=3)
    assert [ix for _, ix in plan] == [[0, 2, 4], [1, 3, 5], [6]]
    assert all(isinstance(b, Batch) and [t.x for t in b.tasks] == ix for b, ix in plan)


def test_demo_and_experiment_table1_run_table1_at_the_papers_600_px():
    assert builtin.TABLE1_SIZE == 600
    for fn in (builtin.table1, builtin.table1_results, demo.selectivity_table):
        assert inspect.signature(fn).parameters["size"].default == 600


def test_experiment_table1_resumes_and_recomputes_after_a_code_change(tmp_path, monkeypatch, capsys):
    res = builtin.table1(["lgmd2"], tmp_path, size=48, workers=0, progress=False, figures=False)
    records = sorted((tmp_path / "traces").glob("*.json"))
    assert len(records) == 6
    stamps = [p.stat().st_mtime_ns for p in records]
    again = builtin.table1(["lgmd2"], tmp_path, size=48, workers=0, progress=False, figures=False)
    assert again == res and [p.stat().st_mtime_ns for p in records] == stamps
    real = tasks.code_identity
    monkeypatch.setattr(tasks, "code_identity", lambda b, a: dict(real(b, a), source_digest="edited"))
    capsys.readouterr()
    builtin.table1(["lgmd2"], tmp_path, size=48, workers=0, progress=False, figures=False)
    assert "6 finished result(s)" in capsys.readouterr().err
    assert all(json.loads(p.read_text())["fingerprint"]["source_digest"] == "edited" for p in records)


def test_the_demo_gives_experiment_table1s_table(tmp_path):
    shown = demo.selectivity_table(["lgmd2"], size=48, progress=False, workers=0)
    saved = builtin.table1(["lgmd2"], tmp_path, size=48, workers=0, progress=False, figures=False)
    keys = ("alert", "first_alert", "max_output", "frames")
    assert {s: {k: r[k] for k in keys} for s, r in shown["lgmd2"].items()} == \
        {s: {k: r[k] for k in keys} for s, r in saved["lgmd2"].items()}


def test_coherence_sweep_resumes(tmp_path):
    kw = dict(size=48, coherences=(1.0,), stimuli=["dark_looming"], workers=0, progress=False, figures=False)
    builtin.coherence_sweep(["lgmd2"], tmp_path, **kw)
    rec = tmp_path / "traces" / "dark_looming_c100.lgmd2.json"
    stamp = rec.stat().st_mtime_ns
    builtin.coherence_sweep(["lgmd2"], tmp_path, **kw)
    assert rec.stat().st_mtime_ns == stamp


def _dataset(tmp_path):
    from cdnf_ti.experiments.synthetic import make_synthetic_dataset

    folder = tmp_path / "ds"
    if not folder.is_dir():  # made once: a rewritten clip is another input
        make_synthetic_dataset(folder, size=48, clips=("dark_looming",))
    return folder


def _experiment(name, tmp_path):
    """Run experiment ``name`` into ``tmp_path/out`` (small sizes, in this process); return (ran, reused)."""
    from cdnf_ti.experiments.dataset import run_dataset
    from cdnf_ti.experiments.paramsweep import run_param_sweep
    from cdnf_ti.experiments.selectivity import selectivity_sweep

    out = tmp_path / "out"
    quiet = dict(workers=0, progress=False, figures=False)
    if name == "dataset":
        run = run_dataset(_dataset(tmp_path), None, out, models=["lgmd2"], **quiet)
        return run.ran, run.skipped
    if name == "sweep":
        run = run_param_sweep(_dataset(tmp_path), None, out, "lgmd2", ["n_ts=4,8"], html=False, **quiet)
        return run.ran, run.skipped
    if name == "selectivity":
        res = selectivity_sweep(["lgmd2"], out, classes=["grating"], **quiet)
        return res["ran"], res["reused"]
    recs = sorted((out / "traces").glob("*.json")) if out.exists() else []
    before = {p: p.stat().st_mtime_ns for p in recs}
    builtin.table1(["lgmd2"], out, size=48, **quiet)
    recs = sorted((out / "traces").glob("*.json"))
    reused = sum(1 for p in recs if before.get(p) == p.stat().st_mtime_ns)
    return len(recs) - reused, reused


@pytest.mark.parametrize("name", ["dataset", "sweep", "selectivity", "table1"])
def test_every_experiment_resumes_and_recomputes_after_a_code_change(name, tmp_path, monkeypatch, capsys):
    ran, reused = _experiment(name, tmp_path)
    assert ran > 0 and reused == 0
    assert _experiment(name, tmp_path) == (0, ran)
    real = tasks.code_identity
    monkeypatch.setattr(tasks, "code_identity", lambda b, a: dict(real(b, a), source_digest="edited"))
    capsys.readouterr()
    assert _experiment(name, tmp_path) == (ran, 0)
    assert f"note: {ran} finished result(s)" in capsys.readouterr().err


def test_a_stimulus_tasks_fingerprint_holds_every_setting_of_its_stimulus():
    from dataclasses import replace

    from cdnf_ti.experiments.stimulus_tasks import StimulusTask

    a = StimulusTask("cdnf", "dark_translating", 48, 0.5, 0, "out")
    for other in (replace(a, seed=1), replace(a, size=64), replace(a, coherence=0.4), replace(a, scatter="static"),
                  replace(a, model="lgmd2"), replace(a, stimulus="dark_looming")):
        assert other.entry().fingerprint != a.entry().fingerprint
    assert replace(a, out="elsewhere").entry().fingerprint == a.entry().fingerprint


def test_a_coherence_sweep_of_one_model_still_runs_in_parallel_batches(tmp_path, monkeypatch):
    from cdnf_ti.experiments import parallel

    seen = []

    def fake_map(fn, units, **kw):
        seen.append((len(units), kw["workers"]))
        return iter(())

    monkeypatch.setattr(parallel, "map_tasks", fake_map)
    builtin.coherence_sweep(["cdnf"], tmp_path, size=48, workers=2, progress=False, figures=False)
    assert seen == [(4, 2)]  # 60 tasks: batches of at most 16, on the workers asked for
    seen.clear()
    builtin.table1(["cdnf"], tmp_path, size=48, workers=2, progress=False, figures=False)
    assert seen == [(6, 0)]  # one batch's worth: in this process, a task per unit
