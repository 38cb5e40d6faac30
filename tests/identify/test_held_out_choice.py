"""Settings a workflow leaves to debist, chosen per rig by blocked cross-validation.

Checked: which keys the default search covers (and that a stated key or an
``[identify.auto]`` table turns it off), the folds left out when no candidate scores them,
a fold that fits the centres its training pieces support, the fallback when every
candidate fails, and the choice itself on data with and without Maxwell-slip friction.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from debist.core.errors import IdentificationError
from debist.identify.autotune import (
    _evaluate,
    blocked_folds,
    scored_folds,
    select_hyperparameters,
    undecided,
)
from debist.identify.config import IdentifyConfig
from debist.identify.fit import supported_size
from debist.identify.searchspace import Facts, held_out_grid
from debist.stages.identify import run_identify
from tests.conftest import INSIDE_CLASS, slip_record, truth_model, with_slip


def test_the_default_grid_covers_only_what_the_workflow_leaves_open():
    assert held_out_grid(Facts({})) == {"slip": [False, 2, 4]}
    assert held_out_grid(Facts({"slip": False})) == {}
    assert held_out_grid(Facts({"slip": 4, "M": 6})) == {}
    assert held_out_grid(Facts({"auto": {"M": [6, 8]}})) == {}
    assert held_out_grid(Facts({"M": 6}))["slip"][0] is False  # the simplest candidate first


def test_a_fold_no_candidate_scores_is_left_out_of_every_mean():
    inf, nan = np.inf, np.nan
    scores = np.array([[0.1, inf, 0.3, 0.2], [0.2, inf, nan, 0.1], [0.3, nan, 0.1, inf]])
    np.testing.assert_array_equal(scored_folds(scores), [True, False, True, True])
    # fewer than two folds would remain: every fold counts (the candidates stay unscored)
    np.testing.assert_array_equal(scored_folds(np.array([[0.1, inf], [inf, inf]])), [True] * 2)
    np.testing.assert_array_equal(scored_folds(np.full((2, 3), inf)), [True] * 3)


@pytest.fixture(scope="module")
def slip_data():
    """6500 samples of a bistable model with three Maxwell-slip elements (noise-free)."""
    truth = with_slip(truth_model(np.random.default_rng(2)))
    record, _ = slip_record(truth)
    return record


def _frames(record):
    t = np.arange(record.q.size) * record.dt
    frame = pd.DataFrame({"t": t, "q": record.q, "v1": record.v[:, 0], "v2": record.v[:, 1]})
    frame.attrs.update(role="estimation", units={"q": "m", "t": "s", "v1": "V", "v2": "V"})
    deriv = pd.DataFrame({"q_dot": record.q_dot, "q_ddot": record.q_ddot})
    deriv.attrs["dt"] = record.dt
    return {"sim": frame}, {"sim": deriv}


_SECTION = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0, "min_support": 10}


def test_the_default_search_picks_slip_elements_where_the_friction_has_them(slip_data):
    """Without a `slip` key the stage compares no, 2 and 4 elements on held-out blocks: on
    data of a plant with three elements it keeps elements, and its held-out score is below
    the score without them by more than one standard error."""
    tables, derivs = _frames(slip_data)
    res = run_identify(tables, derivs, _SECTION)
    auto = res.summary["auto"]
    assert [c["settings"]["slip"] for c in auto["candidates"]] == [False, 2, 4]
    assert auto["chosen"]["slip"] in (2, 4) and res.model.has_slip
    table = res.search.table
    chosen = table.loc[table["chosen"]].iloc[0]
    without = table.loc[table["slip"] == False].iloc[0]  # noqa: E712 (a column of objects)
    assert chosen["mean"] + chosen["se"] < without["mean"]
    stated = run_identify(tables, derivs, {**_SECTION, "slip": False})
    assert "auto" not in stated.summary and stated.search is None
    assert not stated.model.has_slip


@pytest.fixture(scope="module")
def in_class_frames():
    """The slip plant's data with the elements' stiffnesses set to zero."""
    truth = with_slip(truth_model(np.random.default_rng(2)), stiffness=(0.0, 0.0, 0.0))
    record, _ = slip_record(truth)
    return _frames(record)


def test_the_default_search_keeps_the_simpler_model_without_friction(in_class_frames):
    """Data of the same plant without slip elements: no candidate is better by one standard
    error, so the one-standard-error rule keeps Eq. 37's friction only."""
    tables, derivs = in_class_frames
    res = run_identify(tables, derivs, _SECTION)
    assert res.summary["auto"]["chosen"] == {"slip": False}
    assert not res.model.has_slip


def test_a_fold_fits_the_centres_its_training_pieces_support(slip_data):
    """A min_support the whole record meets with M = 8 but some fold's training pieces do
    not: without adaptation that fold's fit fails for every candidate; with it (``M`` not
    searched) every fold is scored, with the centres :func:`supported_size` allows."""
    base = IdentifyConfig.from_dict({**_SECTION, "q_range": None})
    folds = blocked_folds([slip_data.q.size], 4)
    chosen = None
    for least in range(10, 2000, 10):
        cfg = IdentifyConfig.from_dict({**_SECTION, "q_range": None, "min_support": least})
        whole = supported_size(slip_data.q, cfg) == base.M
        pieces = [np.concatenate([slip_data.q[a:b] for _, a, b in fold.train]) for fold in folds]
        if whole and min(supported_size(q, cfg) for q in pieces) < base.M:
            chosen = cfg
            break
    assert chosen is not None
    strict = _evaluate([slip_data], chosen, folds, 2, 300, adapt=False)
    adapted = _evaluate([slip_data], chosen, folds, 2, 300, adapt=True)
    assert strict["status"] == "fit failed" and "min_support" in strict["message"]
    assert adapted["status"] == "ok" and np.all(np.isfinite(adapted["scores"]))


def test_every_candidate_failing_falls_back_to_the_stated_values(slip_data):
    """A condition limit no fit can meet: the default search keeps the base configuration's
    own values and says the choice is undecided; an explicit search still raises."""
    cfg = IdentifyConfig.from_dict({**_SECTION, "max_condition": 1.0})
    res = select_hyperparameters([slip_data], cfg, {"slip": [4, False, 2]}, fallback=True)
    assert res.chosen == {"slip": False} and undecided(res)
    assert res.to_summary()["candidates"][0]["mean"] is None
    with pytest.raises(IdentificationError):
        select_hyperparameters([slip_data], cfg, {"slip": [4, False]})
