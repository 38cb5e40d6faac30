"""Blocked cross-validation of the free-run error for the RBF hyper-parameters."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from debist.core.errors import IdentificationError, WorkflowError
from debist.identify.autotune import (
    auto_settings,
    blocked_folds,
    one_standard_error,
    paired_gaps,
    select_hyperparameters,
)
from debist.identify.config import IdentifyConfig
from debist.identify.fit import Record
from debist.model.rbf import RBFModel
from debist.report.study_plots import autotune_figure


def _reference_choice(rows: list[dict]) -> int:
    """The one-standard-error rule written out on plain lists (ESL 2nd ed., Sec. 7.10)."""
    finite = [r for r in rows if r["mean"] < float("inf")]
    best = min(finite, key=lambda r: r["mean"])
    limit = best["mean"] + best["se"]
    near = [r for r in finite if r["mean"] <= limit]

    def key(r):
        lowpass = float("inf") if r["lowpass"] is None else r["lowpass"]
        return (r["n_params"], -r["sigma_n"], -r["lambda"], lowpass, r["mean"])

    return min(near, key=key)["id"]


def _frame(rows: list[dict]) -> pd.DataFrame:
    frame = pd.DataFrame(rows).set_index("id")
    frame["lowpass"] = frame["lowpass"].astype(float)  # None -> NaN, as the result's table
    return frame


def test_one_standard_error_rule_on_a_hand_made_table():
    """Best mean 1.00 +- 0.30: rows up to 1.30 qualify; the fewest parameters win, then
    the wider RBFs, the stronger penalty and the lower corner; a failed row never wins."""
    rows = [
        {"id": 0, "mean": 1.00, "se": 0.30, "n_params": 44, "sigma_n": 0.5, "lambda": 0.0, "lowpass": 5.0},  # noqa: E501
        {"id": 1, "mean": 1.31, "se": 0.05, "n_params": 20, "sigma_n": 1.0, "lambda": 0.0, "lowpass": 5.0},  # noqa: E501
        {"id": 2, "mean": 1.25, "se": 0.10, "n_params": 28, "sigma_n": 0.5, "lambda": 0.0, "lowpass": None},  # noqa: E501
        {"id": 3, "mean": 1.28, "se": 0.10, "n_params": 28, "sigma_n": 0.5, "lambda": 0.0, "lowpass": 5.0},  # noqa: E501
        {"id": 4, "mean": 1.10, "se": 0.10, "n_params": 36, "sigma_n": 1.0, "lambda": 1e-3, "lowpass": 5.0},  # noqa: E501
        {"id": 5, "mean": float("inf"), "se": float("inf"), "n_params": 12, "sigma_n": 2.0, "lambda": 0.0, "lowpass": 5.0},  # noqa: E501
    ]  # fmt: skip
    assert _reference_choice(rows) == 3
    assert one_standard_error(_frame(rows)) == 3
    # the rule is not "the best": without its standard error only row 0 qualifies
    rows[0]["se"] = 0.0
    assert one_standard_error(_frame(rows)) == 0
    rows[0]["se"] = 0.30
    # equal parameters and width: the stronger penalty wins over the lower corner
    rows[2].update(n_params=28, sigma_n=0.5, **{"lambda": 1e-4})
    assert one_standard_error(_frame(rows)) == _reference_choice(rows) == 2


def test_paired_gaps_are_the_mean_log_ratio_to_the_best_and_its_standard_error():
    rng = np.random.default_rng(7)
    scores = rng.uniform(0.01, 0.2, size=(5, 4))
    scores[3, 2] = np.inf  # a diverged fold: no gap
    gap, se = paired_gaps(scores)
    best = int(np.argmin([np.mean(r) if np.all(np.isfinite(r)) else np.inf for r in scores]))
    for i, row in enumerate(scores):
        if i == 3:
            assert gap[i] == se[i] == np.inf
            continue
        d = [np.log(a / b) for a, b in zip(row, scores[best], strict=True)]
        m = sum(d) / 4
        assert gap[i] == pytest.approx(m, rel=1e-12, abs=1e-15)
        sd = (sum((x - m) ** 2 for x in d) / 3) ** 0.5
        assert se[i] == pytest.approx(sd / 2, rel=1e-12, abs=1e-15)
    assert gap[best] == se[best] == 0.0


def test_the_paired_rule_sees_a_candidate_worse_on_every_fold_through_the_folds_spread():
    """Fold 1 holds a switch and scores ten times the others for every candidate: unpaired,
    its spread admits the simpler candidate that is 40 % worse on every fold; paired, not."""
    folds = np.array([[0.10, 0.010, 0.012, 0.011], [0.14, 0.014, 0.0168, 0.0154]])
    gap, se = paired_gaps(folds)
    rows = [
        {"id": i, "mean": float(folds[i].mean()), "n_params": n, "sigma_n": 0.5,
         "lambda": 0.0, "lowpass": None,
         "se": float(folds[i].std(ddof=1) / 2)}
        for i, n in ((0, 32), (1, 28))
    ]  # fmt: skip
    assert _reference_choice(rows) == 1  # unpaired: the simpler one
    frame = _frame(rows).assign(gap=gap, gap_se=se)
    assert gap[1] == pytest.approx(np.log(1.4)) and se[1] < 1e-12
    assert one_standard_error(frame) == 0  # paired: the one better on every fold
    # within the noise of the pairing, the simpler one again
    folds[1] = folds[0] * np.array([1.3, 0.8, 1.2, 0.85])
    gap, se = paired_gaps(folds)
    assert 0.0 < gap[1] <= se[1]
    assert one_standard_error(_frame(rows).assign(gap=gap, gap_se=se)) == 1


def test_one_standard_error_rule_agrees_with_the_reference_on_random_tables():
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = int(rng.integers(2, 12))
        rows = [
            {
                "id": i,
                "mean": float(rng.choice([rng.uniform(0.01, 0.2), np.inf], p=[0.85, 0.15])),
                "se": float(rng.uniform(0.0, 0.05)),
                "n_params": int(rng.choice([20, 28, 36])),
                "sigma_n": float(rng.choice([0.5, 1.0])),
                "lambda": float(rng.choice([0.0, 1e-4, 1e-2])),
                "lowpass": rng.choice([None, 5.0, 10.0]),
            }
            for i in range(n)
        ]
        if not any(np.isfinite(r["mean"]) for r in rows):
            with pytest.raises(IdentificationError) as err:
                one_standard_error(_frame(rows))
            assert err.value.reason == "candidates"
            continue
        assert one_standard_error(_frame(rows)) == _reference_choice(rows)


@pytest.mark.parametrize(("lengths", "folds"), [([3750], 4), ([101, 57, 8], 3), ([10, 11], 5)])
def test_blocked_folds_partition_the_rows(lengths, folds):
    """Every row is held out exactly once; a fold trains on exactly the rows it does not
    hold out, in contiguous pieces."""
    out = blocked_folds(lengths, folds)
    assert [f.index for f in out] == list(range(folds))
    held = [np.zeros(n, dtype=int) for n in lengths]
    for fold in out:
        seen = [np.zeros(n, dtype=int) for n in lengths]
        assert len(fold.test) == len(lengths)
        for j, a, b in fold.test:
            assert 0 <= a < b <= lengths[j]
            held[j][a:b] += 1
            seen[j][a:b] -= 1  # held-out rows: -1
        for j, a, b in fold.train:
            assert 0 <= a < b <= lengths[j]
            seen[j][a:b] += 2  # training rows: +2; a row in both would be +1
        for s in seen:
            assert set(np.unique(s)) <= {-1, 2}
    for h in held:
        assert np.all(h == 1)
    # contiguous quarters of one long record
    assert [f.test[0][1:] for f in blocked_folds([3750], 4)] == [
        (0, 938), (938, 1875), (1875, 2812), (2812, 3750)
    ]  # fmt: skip


def test_blocked_folds_refuse_too_many_folds():
    with pytest.raises(WorkflowError) as err:
        blocked_folds([100], 1)
    assert ">= 2" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        blocked_folds([100, 3], 4)
    assert "record 1" in str(err.value)
    assert "has 3" in str(err.value)
    assert "folds = 4" in str(err.value)


# --- a synthetic actuator inside the model class ------------------------------------------

_DT = 0.004


def _excitation(t: np.ndarray) -> np.ndarray:
    """Two voltages [V]: switching pulses plus a sub-threshold multisine (as conftest's)."""
    from tests.conftest import excitation

    return excitation(t)


def _truth() -> RBFModel:
    """A bistable model inside the class: M = 8, sigma_n = 0.5 on [-30, 30] mm (seed 2)."""
    from tests.conftest import truth_model

    return truth_model(np.random.default_rng(2))


@pytest.fixture(scope="module")
def in_class_record(tmp_path_factory) -> Record:
    """13 s of the truth (solve_ivp DOP853), with 5 % white noise on q_ddot (seeded); computed
    once for all pytest-xdist workers."""
    from tests.conftest import computed_once

    return computed_once(tmp_path_factory, "autotune-in-class-record", _in_class_record)


def _in_class_record() -> Record:
    truth = _truth()
    t = np.arange(0.0, 13.0, _DT)

    def rhs(tt, x):
        v = _excitation(np.array([tt]))
        return [x[1], truth.accel(np.array([x[0]]), np.array([x[1]]), v)[0]]

    sol = solve_ivp(
        rhs, (t[0], t[-1]), [-0.01, 0.0], t_eval=t, method="DOP853", rtol=1e-9, atol=1e-12
    )
    q, q_dot = sol.y
    v = _excitation(t)
    q_ddot = truth.accel(q, q_dot, v)
    rng = np.random.default_rng(5)
    q_ddot = q_ddot + 0.05 * np.std(q_ddot) * rng.standard_normal(t.size)
    return Record("synthetic", q, q_dot, q_ddot, v, _DT)


_BASE = {
    "M": 8,
    "q_range": (-0.03, 0.03),
    "backbone": ("linear_spring", "cubic_spring", "viscous"),
    "T_z": 0.0,
    "max_condition": 1e10,
    "min_support": 0,
    "bootstrap": 0,
}


def test_cross_validation_picks_the_true_size_within_one_se(in_class_record):
    """Grid M in [4, 8, 16] around a truth with M = 8: the chosen row is within one SE of the
    best mean, no row with fewer parameters is, and the choice is M = 8 (M = 4 cannot
    represent the curves; M = 16 buys nothing but variance)."""
    res = select_hyperparameters(
        [in_class_record], IdentifyConfig(**_BASE), {"M": [4, 8, 16]}, folds=4
    )
    t = res.table
    assert res.strategy == "product" and list(t["M"]) == [4, 8, 16]
    assert t["n_params"].tolist() == [4 * 4 + 3, 8 * 4 + 3, 16 * 4 + 3]
    scores = t[[f"fold_{k}" for k in range(1, 5)]].to_numpy()
    finite = np.isfinite(scores).all(axis=1)
    mean = np.where(finite, scores.mean(axis=1), np.inf)
    best = int(np.argmin(mean))
    se = scores[best].std(ddof=1) / 2.0
    assert t.loc[best, "se"] == pytest.approx(se, rel=1e-12)
    chosen = int(np.flatnonzero(t["chosen"])[0])
    assert mean[chosen] <= mean[best] + se
    smaller = t["n_params"] < t.loc[chosen, "n_params"]
    assert not np.any(mean[smaller.to_numpy()] <= mean[best] + se)
    assert res.chosen == {"M": 8}
    assert mean[1] < 0.01 < mean[0]  # measured 0.40 % and 3.0 %
    assert mean[2] > mean[1]  # M = 16: fits the noise (measured: diverges in fold 1)
    summary = res.to_summary()
    json.dumps(summary, allow_nan=False)
    assert summary["chosen"] == {"M": 8} and summary["n_candidates"] == 3
    fig = autotune_figure(res)
    assert fig.axes[0].get_xlabel() == "M"


def test_a_failing_fit_is_scored_inf_with_its_status(in_class_record):
    """M = 40 with min_support = 10: the outer centres (+-30 mm, width 0.75 mm) have no
    sample near them (the data reach +-28.8 mm), so the fit raises in the first fold; the
    candidate is scored inf and reported, the search goes on."""
    base = IdentifyConfig(**{**_BASE, "min_support": 10})
    res = select_hyperparameters([in_class_record], base, {"M": [6, 40]}, folds=3)
    t = res.table.set_index("M")
    assert t.loc[40, "status"] == "fit failed"
    assert "fold 1" in t.loc[40, "message"] and "min_support = 10" in t.loc[40, "message"]
    assert np.isinf(t.loc[40, "mean"]) and np.isinf(t.loc[40, "fold_1"])
    assert t.loc[6, "status"] == "ok" and np.isfinite(t.loc[6, "mean"])
    assert res.chosen == {"M": 6}
    assert res.to_summary()["candidates"][1]["mean"] is None


def test_every_candidate_failing_is_an_identification_error(in_class_record):
    base = IdentifyConfig(**{**_BASE, "min_support": 10})
    with pytest.raises(IdentificationError) as err:
        select_hyperparameters([in_class_record], base, {"M": [40]}, folds=2)
    assert err.value.reason == "candidates"


def test_the_grid_is_checked_before_any_fit(in_class_record):
    base = IdentifyConfig(**_BASE)
    with pytest.raises(WorkflowError) as err:
        select_hyperparameters([in_class_record], base, {"sigma": [0.5]})
    assert "'sigma'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        select_hyperparameters([in_class_record], base, {"M": [8, 1]})
    assert "'M'" in str(err.value)


def test_a_large_grid_is_swept_one_parameter_at_a_time(in_class_record, monkeypatch):
    """5 x 3 x 3 = 45 settings exceed the product limit: one sweep per parameter, each
    around the best so far, evaluates 5 + 2 + 2 = 9 distinct settings."""
    import debist.identify.autotune as autotune

    def fake(records, cfg, fold_list, substeps, window, adapt=False):
        score = abs(cfg.M - 8) + abs(cfg.sigma_n - 1.0) + (cfg.smoothing or 0.0)
        return {"scores": np.full(len(fold_list), 0.01 + score), "lambda": 0.0,
                "status": "ok", "message": ""}  # fmt: skip

    monkeypatch.setattr(autotune, "_evaluate", fake)
    grid = {"M": [4, 6, 8, 10, 12], "sigma_n": [0.5, 1.0, 2.0], "smoothing": [0.0, 0.1, 1.0]}
    res = select_hyperparameters([in_class_record], IdentifyConfig(**_BASE), grid)
    assert res.strategy == "sweep"
    assert len(res.table) == 9
    assert res.chosen == {"M": 8, "sigma_n": 1.0, "smoothing": 0.0}
    # the sweep of sigma_n ran at the M found by the first sweep
    assert set(res.table.loc[res.table["sigma_n"] != 0.5, "M"]) == {8}


def test_the_auto_table_is_checked_when_the_workflow_is_read():
    """[identify.auto] errors name the table, the key and the value, on one line."""
    ok = IdentifyConfig.from_dict({"auto": {"M": [6, 8], "sigma_n": 1.0, "folds": 3}})
    assert auto_settings(ok) == ({"M": [6, 8], "sigma_n": [1.0]}, {"folds": 3, "window": 300})
    for table, message in (
        ({"Q": [1]}, r"\[identify.auto\]: unknown key 'Q'"),
        ({"M": [8, 1]}, r"\[identify.auto\]: the setting \{'M': 1\}.*greater than or equal to 2"),
        ({"M": [8], "folds": 1}, r"\[identify.auto\] folds: expected an integer >= 2, got 1"),
        ({"auto": [None]}, r"unknown key 'auto'"),
        ({}, r"\[identify.auto\] is empty"),
    ):
        with pytest.raises(WorkflowError, match=message) as info:
            IdentifyConfig.from_dict({"auto": table})
        assert "\n" not in str(info.value)


def test_the_identify_stage_fits_the_searched_setting_and_reports_the_search(in_class_record):
    """With [identify.auto] the stage's model is the fit at the chosen setting (the same
    model as a plain fit at that setting), and the summary carries the search."""
    from debist.identify.autotune import UNDECIDED_SE, undecided
    from debist.report.tables import auto_line
    from debist.stages.identify import run_identify

    rec = in_class_record
    t = np.arange(rec.q.size) * rec.dt
    frame = pd.DataFrame({"t": t, "q": rec.q, "v1": rec.v[:, 0], "v2": rec.v[:, 1]})
    frame.attrs.update(role="estimation", units={"q": "m", "t": "s", "v1": "V", "v2": "V"})
    deriv = pd.DataFrame({"q_dot": rec.q_dot, "q_ddot": rec.q_ddot})
    deriv.attrs["dt"] = rec.dt
    section = {**_BASE, "q_range": list(_BASE["q_range"]), "backbone": list(_BASE["backbone"])}
    section["min_support"] = 10  # the excitation check's sample count
    res = run_identify({"sim": frame}, {"sim": deriv}, {**section, "auto": {"M": [4, 8]}})
    assert res.search is not None and res.search.chosen == {"M": 8}
    assert res.model.basis.M == 8
    plain = run_identify({"sim": frame}, {"sim": deriv}, {**section, "M": 8})
    np.testing.assert_array_equal(res.model.theta_c, plain.model.theta_c)
    auto = res.summary["auto"]
    json.dumps(auto, allow_nan=False)
    assert auto["chosen"] == {"M": 8} and auto["n_candidates"] == 2
    best = res.search.table.loc[res.search.best]
    assert auto["undecided"] == (best["se"] > UNDECIDED_SE * best["mean"]) == undecided(res.search)
    line = auto_line(res.summary)
    assert line.startswith("hyper-parameters: M = 8, chosen among 2 candidates")
    assert ("undecided" in line) == auto["undecided"]
    assert "hyper-parameters" in res.timings and "auto" not in plain.summary
