"""A model states its own event-bin width: ``Model.event_bin_ms``, and ``--bin-ms`` when given wins."""
from __future__ import annotations

from cdnf_ti.events.binning import DEFAULT_BIN_MS
from cdnf_ti.models import Model, get_model_class
from cdnf_ti.models.base import bin_ms_for


def test_the_bin_width_hook_is_documented_with_its_unit_and_its_default():
    doc = Model.event_bin_ms.__doc__
    assert "ms" in doc and "None" in doc and "--bin-ms" in doc
    assert Model.event_bin_ms() is None


def test_a_model_without_a_width_of_its_own_bins_at_the_default():
    assert get_model_class("cdnf").event_bin_ms() is None
    assert bin_ms_for(get_model_class("cdnf")) == DEFAULT_BIN_MS


def test_bin_ms_given_wins_over_the_model_s_own_width():
    assert bin_ms_for(get_model_class("cdnf"), None, 20.0) == 20.0
