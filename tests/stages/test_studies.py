"""Hyper-parameter studies (Fig. 11b/11c) on the noise-free synthetic bistable record."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

from debist.core.errors import WorkflowError
from debist.stages.studies import StudyConfig, alpha_study, derivative_roughness, rbf_grid_study

IDENTIFY = {"T_z": 0.0, "backbone": ["linear_spring", "cubic_spring", "viscous"]}
TVR = {"method": "tvregdiff", "alpha": 1e-5, "iterations": 10, "ep": 1e-12}


def _tables(rec, noise=0.0, validation=False):
    """Stage-shaped tables and derivatives; optionally the second half as validation data."""
    q = rec["q"] + noise * np.random.default_rng(3).standard_normal(rec["q"].size)
    n = rec["q"].size
    parts = {"est": slice(0, n)} if not validation else {"est": slice(0, n // 2)}
    if validation:
        parts["val"] = slice(n // 2, n)
    tables, derivs = {}, {}
    for name, s in parts.items():
        tab = pd.DataFrame(
            {"t": rec["t"][s], "q": q[s], "v1": rec["v"][s, 0], "v2": rec["v"][s, 1]}
        )
        tab.attrs.update(role="estimation" if name == "est" else "validation", units={"q": "m"})
        der = pd.DataFrame(
            {
                "t": rec["t"][s],
                "q": q[s],
                "q_hat": q[s],
                "q_dot": rec["q_dot"][s],
                "q_ddot": rec["q_ddot"][s],
            }
        )
        der.attrs["dt"] = rec["dt"]
        tables[name], derivs[name] = tab, der
    return tables, derivs


@pytest.fixture(scope="module")
def grid(bistable_record):
    tables, derivs = _tables(bistable_record)
    cfg = StudyConfig.from_dict({"M": [4, 8, 12], "sigma_n": [0.25, 0.5, 1.0], "free_run": False})
    table, fig = rbf_grid_study(tables, derivs, IDENTIFY, {}, cfg)
    yield table
    plt.close(fig)


def test_grid_has_one_ok_row_per_cell(grid):
    assert len(grid) == 9
    assert list(grid[["M", "sigma_n"]].itertuples(index=False, name=None))[:3] == [
        (4, 0.25),
        (4, 0.5),
        (4, 1.0),
    ]
    assert (grid["status"] == "ok").all()
    assert (grid["rank"] == grid["n_columns"]).all()
    assert grid["nrmse_q_est"].isna().all()  # free_run = False
    assert grid.attrs["max_samples"] == 20000


def test_condition_grows_with_sigma_n_at_every_M(grid):
    """Wider Gaussians overlap more: the regressor gets more collinear."""
    for _, cells in grid.groupby("M"):
        cond = cells.sort_values("sigma_n")["condition"].to_numpy()
        assert np.all(np.diff(cond) > 0), cond
    # measured: 41 -> 570 -> 8.6e3 at M = 4
    assert grid["condition"].max() / grid["condition"].min() > 100


def test_equation_error_falls_with_M_on_smooth_truth(grid):
    """At sigma_n = 1 more centres fit the curves better (measured: 3.2e-5 -> 3.9e-6)."""
    cells = grid[grid.sigma_n == 1.0].sort_values("M")
    eq = cells["eq_mse"].to_numpy()
    assert np.all(np.diff(eq) < 0), eq
    assert eq[0] / eq[-1] > 4


def test_rejected_cells_are_rows_not_errors(bistable_record):
    tables, derivs = _tables(bistable_record)
    cfg = StudyConfig.from_dict({"M": [4, 24], "sigma_n": [0.25, 1.5], "max_samples": 1500})
    section = {**IDENTIFY, "min_support": 40, "max_condition": 5e4}
    table, fig = rbf_grid_study(tables, derivs, section, {}, cfg)
    plt.close(fig)
    status = dict(zip(zip(table.M, table.sigma_n, strict=True), table.status, strict=True))
    assert status[(4, 0.25)] == "ok" and status[(4, 1.5)] == "ok"
    assert status[(24, 0.25)].startswith("centre xi_")  # too few samples near a centre
    assert "max_condition" in status[(24, 1.5)]
    bad = table[table.status != "ok"]
    assert bad["nrmse_q_est"].isna().all()
    # a rejected but solvable cell still reports its condition number (above the limit)
    assert table.set_index(["M", "sigma_n"]).loc[(24, 1.5), "condition"] > 5e4
    ok = table[table.status == "ok"]
    # free run of the first 1500 samples: the 4-centre models track q within 10 %
    assert (ok["nrmse_q_est"] < 0.1).all()
    assert table.attrs["n_samples"] == {"est": 1500}


def test_grid_scores_validation_data(bistable_record):
    tables, derivs = _tables(bistable_record, validation=True)
    cfg = StudyConfig.from_dict({"M": [6], "sigma_n": [1.0], "max_samples": 800})
    table, fig = rbf_grid_study(tables, derivs, IDENTIFY, {}, cfg)
    plt.close(fig)
    assert table.loc[0, "status"] == "ok"
    assert 0 < table.loc[0, "nrmse_q_est"] < 0.1
    assert np.isfinite(table.loc[0, "nrmse_q_val"])


def test_grid_figure_has_two_panels_and_colour_bars(bistable_record):
    tables, derivs = _tables(bistable_record)
    cfg = StudyConfig.from_dict({"M": [4, 6], "sigma_n": [0.5], "free_run": False})
    _, fig = rbf_grid_study(tables, derivs, IDENTIFY, {}, cfg)
    assert len(fig.axes) == 4
    assert "condition" in fig.axes[1].get_title()
    plt.close(fig)


@pytest.fixture(scope="module")
def alpha_run(bistable_record):
    tables, _ = _tables(bistable_record, noise=2e-5)  # 20 um noise on +-20 mm
    cfg = StudyConfig.from_dict({"alpha": [1e-8, 1e-7, 1e-6, 1e-5], "max_samples": 1500})
    table, fig = alpha_study(tables, IDENTIFY, {}, TVR, cfg)
    yield table, fig
    plt.close(fig)


def test_alpha_study_roughness_falls_with_alpha(alpha_run):
    table, _ = alpha_run
    assert len(table) == 4
    assert list(table.alpha) == [1e-8, 1e-7, 1e-6, 1e-5]
    rough = table["roughness"].to_numpy()
    assert np.all(np.diff(rough) < 0), rough  # measured 7.7e-3 ... 1.5e-3 m/s
    assert rough[0] / rough[-1] > 3
    # the equation error follows the noise of the derivatives
    assert np.all(np.diff(table["eq_mse"].to_numpy()) < 0)
    assert (table["status"] == "ok").all()
    assert table["nrmse_q_est"].notna().all()
    assert table.attrs["workflow_alpha"] == 1e-5


def test_alpha_figure_layout(alpha_run):
    _, fig = alpha_run
    assert len(fig.axes) == 6
    ax_dot = fig.axes[2]  # row-major: q, scores; q_dot, eq_mse; ...
    assert ax_dot.get_ylabel().startswith("q_dot")
    assert len(ax_dot.get_lines()) == 4  # one q_dot per alpha


def test_alpha2_is_scaled_with_alpha(bistable_record):
    """alpha2 = 10 alpha in the section stays 10 alpha for every studied alpha."""
    tables, _ = _tables(bistable_record, noise=2e-5)
    cfg = StudyConfig.from_dict({"alpha": [1e-6], "free_run": False, "max_samples": 500})
    a, fig_a = alpha_study(tables, IDENTIFY, {}, {**TVR, "alpha2": 1e-4}, cfg)
    b, fig_b = alpha_study(tables, IDENTIFY, {}, {**TVR, "alpha": 1e-6, "alpha2": 1e-5}, cfg)
    plt.close(fig_a)
    plt.close(fig_b)
    assert a.loc[0, "eq_mse"] == pytest.approx(b.loc[0, "eq_mse"], rel=1e-12)


def test_alpha_study_needs_tvregdiff(bistable_record):
    tables, _ = _tables(bistable_record)
    cfg = StudyConfig.from_dict({"alpha": [1e-6], "free_run": False})
    with pytest.raises(WorkflowError) as err:
        alpha_study(tables, IDENTIFY, {}, {"method": "savgol"}, cfg)
    assert "method = 'tvregdiff'" in str(err.value)
    assert "'savgol'" in str(err.value)


def test_config_is_checked():
    cfg = StudyConfig.from_dict({})
    assert cfg.M == (4, 6, 8, 10, 12, 16) and cfg.free_run is True
    with pytest.raises(WorkflowError) as err:
        StudyConfig.from_dict({"sigma": [0.5]})
    assert err.value.key == "study.sigma"
    assert "unknown" in str(err.value)
    assert "'sigma_n'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        StudyConfig.from_dict({"M": [1, 4]})
    assert err.value.key == "study.M"
    assert ">= 2" in str(err.value)
    assert "got 1" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        StudyConfig.from_dict({"alpha": [0.0]})
    assert err.value.key == "study.alpha"
    assert "> 0" in str(err.value)
    assert "got 0.0" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        StudyConfig.from_dict({"sigma_n": []})
    assert err.value.key == "study.sigma_n"
    assert "least 1" in str(err.value)


def test_roughness_of_a_line_is_zero_and_of_noise_is_large():
    assert derivative_roughness(np.linspace(0.0, 1.0, 50)) == pytest.approx(0.0, abs=1e-15)
    noise = np.random.default_rng(0).standard_normal(10000)
    # white noise of unit variance: var(diff2) = 6
    assert derivative_roughness(noise) == pytest.approx(np.sqrt(6.0), rel=0.03)


def test_alpha_figure_survives_an_all_failed_study():
    from debist.stages.studies import alpha_figure

    nan = [np.nan, np.nan]
    failed = "centre xi_1 has only 3 samples"
    table = pd.DataFrame(
        {
            "alpha": [1e-8, 1e-7],
            "eq_mse": nan,
            "nrmse_q_est": nan,
            "nrmse_q_val": nan,
            "condition": nan,
            "status": [failed, failed],
            "roughness": [1.0, 0.5],
            "converged": [True, True],
        }
    )
    t = np.arange(50) * 0.01
    curve = pd.DataFrame({"t": t, "q": np.sin(t), "q_dot": np.cos(t), "q_ddot": -np.sin(t)})
    fig = alpha_figure(table, [(1e-8, curve), (1e-7, curve)], "estimation")
    assert len(fig.axes) == 6
    assert fig.axes[-1].get_yscale() == "log"  # roughness is positive: log scale kept
    plt.close(fig)
