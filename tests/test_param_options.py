"""``--param [MODEL.]NAME=VALUE`` and ``--epsilon``: one meaning in every command that runs models."""
from __future__ import annotations

import pytest

from cdnf_ti.errors import UserError
from cdnf_ti.param_options import model_params
from cdnf_ti.run import main


def test_a_bare_name_sets_every_selected_model_that_has_it():
    p = model_params(["lgmd1", "lgmd2"], ["n_ts=5"])
    assert p["lgmd1"].n_ts == 5 and p["lgmd2"].n_ts == 5


def test_a_model_prefix_sets_that_model_only():
    p = model_params(["lgmd1", "lgmd2"], ["lgmd2.n_ts=5"])
    assert p["lgmd1"] is None and p["lgmd2"].n_ts == 5


def test_models_without_a_change_keep_their_defaults():
    assert model_params(["cdnf", "sdnf"], []) == {"cdnf": None, "sdnf": None}


def test_epsilon_is_the_cdnf_epsilon_parameter():
    assert model_params(["cdnf"], [], epsilon=0.01)["cdnf"].epsilon == 0.01


def test_epsilon_without_cdnf_is_an_error():
    with pytest.raises(UserError, match="--epsilon applies to the cdnf model only"):
        model_params(["lgmd2"], [], epsilon=0.01)


@pytest.mark.parametrize("spec, problem", [
    ("nope=1", "no selected model"),
    ("lgmd2.nope=1", "unknown parameter"),
    ("sdnf.h=1", "not among --model"),
    ("n_ts=2.5", "not a whole number"),
    ("n_ts", "expected NAME=VALUE"),
    ("n_ts=0", "n_ts must be a positive integer"),
])
def test_a_bad_param_is_one_user_error(spec, problem):
    with pytest.raises(UserError, match=problem):
        model_params(["lgmd2"], [spec])


def test_run_applies_a_param_and_records_it_in_the_summary(tmp_path, capsys):
    import csv

    import numpy as np

    from cdnf_ti.stimuli.basic import basic_stimulus

    clip = tmp_path / "looming.npy"
    np.save(clip, np.stack(list(basic_stimulus("dark_looming", height=48, width=48).frames())))
    out = tmp_path / "o"
    assert main([str(clip), "--out", str(out), "--no-progress", "--backend", "numpy", "--param", "epsilon=0.02"]) == 0
    row = next(csv.DictReader(open(out / "summary.csv")))
    assert row["params"] == "epsilon=0.02"


def test_run_rejects_epsilon_for_models_without_it(tmp_path, capsys):
    code = main(["stim:dark_looming?size=48", "--model", "lgmd2", "--epsilon", "0.01", "--out", str(tmp_path / "o")])
    assert code == 2
    assert "--epsilon applies to the cdnf model only" in capsys.readouterr().err
