"""Basic selectivity (paper Table I) of every model on the six basic stimuli.

The whole table is printed next to the paper's values (run with ``-s`` to see
it). Where a model disagrees with the paper, the test pins what the model
does; docs/MODELS.md explains each disagreement. Frames are 96 x 96 (same
geometry as the paper's 600 x 600; the 600 x 600 demo gives the same table).
"""
from __future__ import annotations

import pytest

from cdnf_ti.demo import format_table1, selectivity_table
from cdnf_ti.models import MODELS
from cdnf_ti.paper import TABLE1
from cdnf_ti.stimuli.basic import BASIC_STIMULI

SIZE = 96
BASELINES = ("sdnf", "lgmd2", "flgmd_onn", "lgmd1")

#: What cdnf_ti's models do (1 = alert), in BASIC_STIMULI order:
#: dark/light looming, dark/light receding, dark/light translating.
PINNED = {
    "lgmd2": (1, 0, 0, 0, 0, 0),      # = paper
    "sdnf": (1, 1, 0, 0, 0, 0),       # paper: translating 1 (reconstruction differs, see docs/MODELS.md)
    "flgmd_onn": (0, 0, 0, 0, 0, 0),  # paper: 1 1 1 1 0 0 (reconstruction differs, see docs/MODELS.md)
    "lgmd1": (0, 0, 0, 0, 0, 0),      # not in the paper; FFI/SFA stop it before 8 spikes (docs/MODELS.md)
}


@pytest.fixture(scope="module")
def table():
    models = [m for m in ("cdnf", *BASELINES) if m in MODELS]
    res = selectivity_table(models, size=SIZE, progress=False)
    print(f"\nBasic selectivity at {SIZE}x{SIZE} px (paper's Table I in brackets):")
    print(format_table1(res))
    return res


def test_every_comparison_model_is_registered():
    assert set(BASELINES) <= set(MODELS)


@pytest.mark.parametrize("model", BASELINES)
def test_basic_selectivity_is_pinned(table, model):
    got = tuple(table[model][s]["alert"] for s in BASIC_STIMULI)
    assert got == PINNED[model]


def test_lgmd2_reproduces_the_papers_table1_column(table):
    assert all(table["lgmd2"][s]["alert"] == TABLE1["lgmd2"][s] for s in BASIC_STIMULI)


def test_sdnf_reconstruction_keeps_the_published_looming_and_receding_behaviour(table):
    paper = TABLE1["sdnf"]
    for s in ("dark_looming", "light_looming", "dark_receding", "light_receding"):
        assert table["sdnf"][s]["alert"] == paper[s]


def test_printed_table_has_one_column_per_model_and_marks_disagreements(table):
    text = format_table1(table)
    head = text.splitlines()[0]
    for m in table:
        assert m in head
    assert "differs" in text  # the reconstructions disagree with the paper somewhere
    assert len(text.splitlines()) == 2 + len(BASIC_STIMULI)
