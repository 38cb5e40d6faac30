"""SINDy's degree and threshold chosen by blocked cross-validation on the estimation data."""

import numpy as np

from debist.identify.fit import Record
from debist.model.sindy import SindyConfig
from debist.stages.sindy_choice import DEGREES, THRESHOLDS, choose_sindy
from debist.validate.config import ValidateConfig


def _record(rec):
    return Record("bistable", rec["q"], rec["q_dot"], rec["q_ddot"], rec["v"], rec["dt"])


def test_settings_the_workflow_gives_are_not_searched(bistable_record):
    cfg = SindyConfig(degree=3, threshold=0.02)
    chosen, rows = choose_sindy([_record(bistable_record)], cfg, {"degree": 3, "threshold": 0.02},
                                ValidateConfig())  # fmt: skip
    assert chosen is cfg and rows == []


def test_the_pick_is_the_fewest_terms_near_the_best_held_out_score(bistable_record):
    """Exact derivatives of a cubic-in-q truth: every candidate runs free over the held-out
    blocks; the pick has the fewest terms among those within 10 % of the best mean score,
    and a given degree restricts the search to it."""
    rec = _record(bistable_record)
    chosen, rows = choose_sindy([rec], SindyConfig(), {}, ValidateConfig())
    assert len(rows) == len(DEGREES) * len(THRESHOLDS)
    scores = np.array([r["holdout_nrmse_q"] for r in rows])
    assert np.all(np.isfinite(scores)) and scores.min() < 0.05
    near = [r for r in rows if r["holdout_nrmse_q"] <= 1.1 * scores.min()]
    assert min(r["n_terms"] for r in near) == next(
        r["n_terms"] for r in rows
        if (r["degree"], r["threshold"]) == (chosen.degree, chosen.threshold)
    )  # fmt: skip
    _, rows3 = choose_sindy([rec], SindyConfig(degree=3), {"degree": 3}, ValidateConfig())
    assert {r["degree"] for r in rows3} == {3} and len(rows3) == len(THRESHOLDS)
