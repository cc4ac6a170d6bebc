"""The same dataset run on a real Dask LocalCluster gives the same results as in this process."""
from __future__ import annotations

import csv
from pathlib import Path

import pytest

from cdnf_ti.experiments.dataset import run_dataset
from cdnf_ti.experiments.synthetic import make_synthetic_dataset

distributed = pytest.importorskip("distributed")


def _rows(out: Path) -> list[dict]:
    with open(out / "results.csv", newline="") as f:
        return [{k: v for k, v in r.items() if k != "seconds"} for r in csv.DictReader(f)]


def _traces(out: Path) -> dict[str, str]:
    return {str(p.relative_to(out)): p.read_text() for p in sorted((out / "traces").rglob("*.csv"))}


def test_dask_local_cluster_gives_identical_results(tmp_path):
    ds = tmp_path / "ds"
    make_synthetic_dataset(ds, size=96, clips=("dark_looming", "light_translating", "dark_receding"))
    (ds / "corrupt.mp4").write_bytes(b"\x00garbage" * 64)
    with open(ds / "labels.csv", "a") as f:
        f.write("corrupt,non-collision,,,,,bad file\n")
    local = run_dataset(ds, None, tmp_path / "local", models=["cdnf"], workers=0, progress=False, figures=False)
    with distributed.LocalCluster(n_workers=1, processes=True, threads_per_worker=1, dashboard_address=None,
                                  silence_logs=40) as cluster:
        dask = run_dataset(ds, None, tmp_path / "dask", models=["cdnf"], scheduler=cluster.scheduler_address,
                           progress=False, figures=False)
    assert dask.ran == local.ran == 3
    assert _traces(tmp_path / "dask") == _traces(tmp_path / "local")
    assert _rows(tmp_path / "dask") == _rows(tmp_path / "local")
    assert dask.failed and "corrupt.mp4" in [r for r in dask.rows if r["clip"] == "corrupt"][0]["error"]


def test_unreachable_scheduler_is_a_one_line_error(tmp_path):
    from cdnf_ti.experiments.parallel import map_tasks

    with pytest.raises(ValueError, match="cannot connect to the Dask scheduler at tcp://127.0.0.1:9"):
        list(map_tasks(abs, [1], scheduler="tcp://127.0.0.1:9", connect_timeout=1))


@pytest.mark.parametrize("address", ["notanaddress", "tcp://"])
def test_a_malformed_scheduler_address_is_a_one_line_error(address):
    from cdnf_ti.errors import UserError
    from cdnf_ti.experiments.parallel import map_tasks

    with pytest.raises(UserError, match=f"cannot connect to the Dask scheduler at {address}: ") as e:
        list(map_tasks(abs, [1], scheduler=address, connect_timeout=1))
    assert "\n" not in str(e.value)
