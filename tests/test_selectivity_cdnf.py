"""Paper Table I, C-DNF column: looming and receding alert, translating does not."""
import pytest
from conftest import small_stimulus

from cdnf_ti import CDNF
from cdnf_ti.paper import TABLE1
from cdnf_ti.stimuli.basic import BASIC_STIMULI


@pytest.mark.parametrize("name", BASIC_STIMULI)
def test_cdnf_basic_selectivity_matches_paper_table1(name):
    tr = CDNF().run(small_stimulus(name, size=120).frames())
    alerted = int(tr.first_alert is not None)
    assert alerted == TABLE1["cdnf"][name]
