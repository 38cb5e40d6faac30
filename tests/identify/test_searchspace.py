"""The held-out search space: one table of the settings debist chooses on held-out data.

Checked: every entry's candidates are valid settings of the identify configuration, its
predicate on thin and on thick data, and that its parsimony rank orders its candidates
strictly (a tie in the score is always broken).
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from debist.identify.autotune import PARSIMONY
from debist.identify.config import IdentifyConfig, candidate_config, check_grid
from debist.identify.searchspace import SEARCH_SPACE, Facts, held_out_grid
from debist.model.terms import column_names

_CFG = IdentifyConfig.from_dict({"M": 8})
_THIN, _THICK = Facts({}, _CFG, thin=True), Facts({}, _CFG, thin=False)


def _n_params(cfg: IdentifyConfig, n_inputs: int = 2) -> int:
    force, inputs = column_names(
        cfg.rbf, cfg.backbone, cfg.M, n_inputs, cfg.creep is not False, cfg.n_slip,
        cfg.inertia_powers,
    )  # fmt: skip
    return len(force) + len(inputs)


def test_the_table_names_each_setting_once_with_a_known_parsimony_column():
    keys = [c.key for c in SEARCH_SPACE]
    assert len(keys) == len(set(keys)) and {"slip", "M"} <= set(keys)
    columns = [column for column, _ in PARSIMONY]
    assert all(c.rank in columns for c in SEARCH_SPACE)
    assert len(columns) == len(set(columns))  # one rank per column: the order is total


@pytest.mark.parametrize("facts", [_THIN, _THICK], ids=["thin", "thick"])
def test_every_candidate_is_a_valid_setting_ranked_strictly_simplest_first(facts):
    for choice in SEARCH_SPACE:
        values = list(choice.candidates(facts.cfg))
        assert len(values) >= 2
        assert check_grid(_CFG, {choice.key: values}) == {choice.key: values}
        ranks = [_n_params(candidate_config(_CFG, {choice.key: v})) for v in values]
        ascending = dict(PARSIMONY)[choice.rank]
        assert ranks == sorted(set(ranks), reverse=not ascending), choice.key


def test_m_is_searched_on_thin_data_only_and_slip_whenever_left_open():
    assert list(held_out_grid(_THICK)) == ["slip"]
    thin = held_out_grid(_THIN)
    assert list(thin) == ["slip", "M"]  # the table's order is the grid's
    assert thin["M"] == list(range(2, 9)) and thin["slip"] == [False, 2, 4]
    # a stated key, an [identify.auto] table or too few supported centres turn an entry off
    assert list(held_out_grid(replace(_THIN, section={"M": 8}))) == ["slip"]
    assert held_out_grid(replace(_THIN, section={"slip": 4, "M": 8})) == {}
    assert held_out_grid(replace(_THIN, section={"auto": {"M": [6, 8]}})) == {}
    assert list(held_out_grid(replace(_THIN, cfg=replace(_CFG, M=2)))) == ["slip"]
    assert list(held_out_grid(Facts({}, None, thin=True))) == ["slip"]  # before the data
