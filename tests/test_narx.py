"""The polynomial NARX peer of the compare stage (Billings 2013, Ch. 3; SysIdentPy's FROLS)."""

import warnings

import numpy as np
import pandas as pd
import pytest

from debist.errors import WorkflowError
from debist.metrics import nrmse
from debist.model.narx import NARX_MISSING, NarxConfig, fit_narx, narx_available
from debist.report.tables import not_modelled, verdict

pytestmark = pytest.mark.skipif(not narx_available(), reason="SysIdentPy (debist[narx]) absent")


def _narx_record(n, seed):
    """y(k) = 0.5 y(k-1) - 0.1 y(k-2) + 0.3 u(k-1) + 0.05 u(k-1)^2, a seeded random input."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, n)
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 0.5 * y[k - 1] - 0.1 * y[k - 2] + 0.3 * u[k - 1] + 0.05 * u[k - 1] ** 2
    return y, u[:, None]


def test_a_polynomial_narx_is_recovered_and_runs_free_on_unseen_data():
    """Data of a known degree-2 NARX: its structure wins, and the free run on another record
    of the same system is exact to rounding."""
    y, u = _narx_record(2000, 1)
    cfg = NarxConfig(degree=(1, 2), lags=(1, 2), n_info_values=10)
    model = fit_narx([y], [u], "v", cfg, q_limit=100.0)
    assert (model.degree, model.lag) == (2, 2)
    assert model.n_params <= 6  # the four true terms and at most two spurious ones
    y2, u2 = _narx_record(1500, 2)
    sim, diverged_at = model.simulate(y2, u2)
    assert diverged_at == -1
    assert nrmse(y2, sim) < 1e-8
    table = model.candidates
    assert len(table) == 4 and set(table.status) == {"ok"}
    assert table.loc[table.holdout_nrmse_q.idxmin(), ["degree", "lag"]].tolist() == [2, 2]
    tree = model.to_tree()
    assert tree["attrs"]["model"] == "narx" and tree["model"]["theta"].size == model.n_params


def test_the_structure_comes_from_the_estimation_data_only():
    """The same estimation data give the same model whatever is validated afterwards; the
    holdout decides, and a structure that cannot fit is scored, not fatal."""
    y, u = _narx_record(1200, 3)
    cfg = NarxConfig(degree=(1, 2), lags=(1, 2), n_info_values=8)
    a = fit_narx([y], [u], "v", cfg, q_limit=100.0)
    b = fit_narx([y], [u], "v", cfg, q_limit=100.0)
    np.testing.assert_array_equal(a.estimator.theta, b.estimator.theta)
    other, _ = _narx_record(1200, 4)
    sim_a, _ = a.simulate(other, u)
    sim_b, _ = b.simulate(other, u)
    np.testing.assert_array_equal(sim_a, sim_b)


def test_the_nested_information_criterion_equals_sysidentpy_s_own():
    """One FROLS pass scores every model size as SysIdentPy's per-size reruns do."""
    from debist.model.narx import _estimator, _sysidentpy

    FROLS, Polynomial, LeastSquares = _sysidentpy()  # never a bare import: see the next test

    rng = np.random.default_rng(7)
    n = 800
    x = rng.uniform(-1, 1, (n, 2))
    y = np.zeros((n, 1))
    for k in range(2, n):
        y[k] = 0.6 * y[k - 1] - 0.2 * y[k - 1] ** 3 + 0.4 * x[k - 1, 0] * x[k - 2, 1]
    y += 1e-3 * rng.standard_normal((n, 1))
    ours = _estimator(3, 2, 2, NarxConfig(n_info_values=12))
    ref = FROLS(order_selection=True, n_info_values=12, info_criteria="aic", ylag=2,
                xlag=[[1, 2], [1, 2]], basis_function=Polynomial(degree=3),
                estimator=LeastSquares(), model_type="NARMAX")  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ours.fit(X=x, y=y)
        ref.fit(X=x, y=y)
    np.testing.assert_allclose(ours.info_values, ref.info_values, rtol=1e-12)
    np.testing.assert_array_equal(ours.final_model, ref.final_model)
    np.testing.assert_allclose(ours.theta, ref.theta, rtol=1e-12)


def test_fitting_a_narx_model_leaves_matplotlib_s_settings_alone():
    """SysIdentPy sets global matplotlib settings on import; debist's figures (and so its
    artifacts' bytes) must not depend on whether a NARX model was fitted earlier."""
    import matplotlib

    before = dict(matplotlib.rcParams)
    y, u = _narx_record(300, 6)
    fit_narx([y], [u], "v", NarxConfig(degree=(2,), lags=(1,)), q_limit=100.0)
    after = dict(matplotlib.rcParams)
    assert {k: after[k] for k in before if str(before[k]) != str(after[k])} == {}


def test_a_diverging_free_run_is_cut_at_the_limit():
    y, u = _narx_record(600, 5)
    model = fit_narx([y], [u], "v", NarxConfig(degree=(2,), lags=(2,)), q_limit=100.0)
    model.q_limit = 0.05  # below the record's own range: "diverged" at the first excursion
    sim, at = model.simulate(y, u)
    assert at > 0 and np.isnan(sim[at:]).all() and np.isfinite(sim[:at]).all()
    assert np.abs(sim[:at]).max() <= 0.05


def test_the_settings_are_checked_with_their_table():
    with pytest.raises(WorkflowError, match=r"\[compare.narx\] unknown key 'lagz'"):
        NarxConfig.from_dict({"lagz": [1]})
    with pytest.raises(WorkflowError, match=r"\[compare.narx\] holdout"):
        NarxConfig.from_dict({"holdout": 0.95})


def test_verdicts_name_narx_and_its_unmodelled_columns_are_not_divergence():
    rows = [
        {"dataset": "unseen", "role": "validation", "model": "rbf", "nrmse_q": 0.015,
         "nrmse_q_baseline": 0.3, "status": "ok"},
        {"dataset": "unseen", "role": "validation", "model": "narx", "nrmse_q": 0.006,
         "nrmse_q_dot": float("nan"), "nrmse_q_baseline": 0.3, "status": "ok"},
    ]  # fmt: skip
    assert "worse than narx (0.60 %)" in verdict(rows[0], rows)
    assert verdict(rows[1], rows) == "ok"
    assert not_modelled(rows[1], "nrmse_q_dot") and not not_modelled(rows[1], "nrmse_q")


def test_without_sysidentpy_the_rows_say_so(monkeypatch, bistable_record):
    """The stage never drops the peer silently: its rows carry the reason and NaN numbers."""
    import debist.stages.compare as compare_stage
    from debist.records import Record
    from debist.stages.compare import _narx_rows
    from debist.validate import DataSet, ValidateConfig

    monkeypatch.setattr(compare_stage, "narx_available", lambda: False)
    rec = bistable_record
    ds = DataSet("unseen", "validation", rec["t"], rec["q"], rec["q_dot"], rec["q_ddot"],
                 rec["v"], "m")  # fmt: skip
    record = Record("est", rec["q"], rec["q_dot"], rec["q_ddot"], rec["v"], rec["dt"])
    simulated = {"unseen": pd.DataFrame({"t": rec["t"], "q": rec["q"]})}
    with pytest.warns(UserWarning, match="NARX peer is not available"):
        model, table = _narx_rows([record], [ds], "v2", NarxConfig(), ValidateConfig(), 1.0,
                                  None, simulated)  # fmt: skip
    assert model is None
    assert table.status.tolist() == [NARX_MISSING] and np.isnan(table.nrmse_q).all()
