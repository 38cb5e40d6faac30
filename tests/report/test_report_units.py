"""Every printed table and plot shows units, derived from the data and the model form."""

import re

import numpy as np
import pytest
from rich.console import Console

from debist.core.errors import WorkflowError
from debist.model.sindy import SindyConfig, fit_sindy
from debist.report.tables import design_table, identify_table, summary_units
from debist.stages.identify import run_identify
from debist.stages.validate import run_validate
from tests.conftest import DT_LOG as DT
from tests.conftest import double_well, logged_tables

SECTION = {
    "T_z": 0,
    "bootstrap": 0,
    "backbone": ["linear_spring", "cubic_spring", "viscous", "offset"],
}


def _render(table) -> str:
    console = Console(record=True, width=200)
    console.print(table)
    return console.export_text()


@pytest.fixture(scope="module")
def data():
    truth = double_well()
    tables, derivs = logged_tables(truth)
    for d in derivs.values():
        d.attrs["dt"] = DT
    return truth, tables, derivs


def test_identified_model_in_newtons_when_m_q_is_a_mass(data):
    truth, tables, derivs = data
    summary = run_identify(tables, derivs, {**SECTION, "m_q": truth.m_q}).summary
    assert summary["units"] == {
        "q": "m",
        "v1": "V",
        "v2": "V",
        "input_map": "v2",
        "per_unit_mass": False,
    }
    text = _render(identify_table(summary))
    for row in (
        "mass m_q [kg]",
        "backbone coefficient k_1 (a basis term; the stiffness k* is in the equilibria) [N/m]",
        "backbone coefficient k_3 (a basis term) [N/m^3]",
        "backbone coefficient d_v (a basis term; the damping d(q*) is in the equilibria) [N s/m]",
        "offset force F_0 [N]",
        "T_z [s]",
    ):
        assert row in text
    assert "per unit mass" not in text
    design = _render(design_table(summary))
    assert "q* [m]" in design and "inputs [V]" in design and "barrier [J]" in design
    assert "d(q*) [N s/m]" in design and "k* [N/m]" in design


def test_identified_model_per_unit_mass_in_accelerations(data):
    _, tables, derivs = data
    summary = run_identify(tables, derivs, {**SECTION, "m_q": 1.0}).summary
    assert summary["units"]["per_unit_mass"] is True
    text = _render(identify_table(summary))
    for row in (
        "mass m_q: the unit mass (per-unit-mass model: its forces are accelerations of q,",
        "k_1 (a basis term; the stiffness k* is in the equilibria) [1/s^2]",
        "k_3 (a basis term) [1/m^2/s^2]",
        "d_v (a basis term; the damping d(q*) is in the equilibria) [1/s]",
        "offset force F_0 [m/s^2]",
        "forces in m/s^2",
    ):
        assert row in text
    assert "[N" not in text and "m_q [1]" not in text


@pytest.mark.parametrize(
    ("per_unit_mass", "expected"),
    [
        (True, {"k_1": "1/s^2", "d_v": "1/s", "F_0": "V/s^2", "g_0": ["V/s^2"], "force": "V/s^2"}),
        (False, {"k_1": "N/V", "k_3": "N/V^3", "d_v": "N s/V", "F_c": "N", "g_0": ["N"]}),
    ],
)
def test_units_follow_q_in_volts_and_a_dimensionless_linear_input(per_unit_mass, expected):
    summary = {
        "m_q": 1.0 if per_unit_mass else 2.0,
        "backbone": {"k_1": 1.0, "g_0": [0.0]},
        "units": {"q": "V", "v1": "1", "input_map": "v", "per_unit_mass": per_unit_mass},
    }
    units = summary_units(summary)
    assert {k: units[k] for k in expected} == expected
    assert units["inputs"] == ["1"]


def test_input_gain_rows_in_force_per_mapped_input():
    summary = {
        "T_z": 0.0,
        "m_q": 95.0,
        "condition": 1.0,
        "rank": 3,
        "n_columns": 3,
        "n_params": 3,
        "fit_r2": 1.0,
        "backbone": {"k_1": 1.0, "g_0": [35.15]},
        "units": {"q": "m", "v1": "V", "input_map": "v", "per_unit_mass": False},
    }
    assert "(a basis term; g_i(q) in Fig. 14) g_0,1 [N/V]" in _render(identify_table(summary))


def test_free_run_figure_shows_q_in_the_report_unit(data):
    from debist.report.figures import free_run_figure
    from debist.stages.report import _split_runs

    truth, tables, derivs = data
    res = run_validate(truth, tables, derivs, {"substeps": 1, "report_unit": "mm"})
    simulated = res.simulated["val"]
    runs = _split_runs(simulated, "rbf")
    measured = simulated[["t", "q"]]
    fig = free_run_figure(measured, runs, (0, 0), "val", "m", None, None, "mm", 5)
    whole, zoom, error = fig.axes[:3]
    assert whole.get_ylabel() == "q [mm]" and zoom.get_ylabel() == "q [mm]"
    assert error.get_ylabel() == "error [mm]"
    t, measured_mm = whole.get_lines()[0].get_data()
    np.testing.assert_allclose(measured_mm, 1e3 * tables["val"]["q"].to_numpy(), rtol=1e-12)
    np.testing.assert_allclose(
        error.get_lines()[0].get_ydata(),
        1e3 * (simulated["q"] - simulated["q_sim"]).to_numpy(),
        rtol=1e-9,
        atol=1e-12,  # [mm]: the difference of two scaled values rounds differently
    )
    # the samples of the initial state are shaded on the whole record and the errors
    spans = [p.get_x() for p in whole.patches] + [p.get_x() for p in error.patches]
    assert spans.count(t[0]) == 2
    volts = free_run_figure(measured, runs, (0, 0), "val", "V", None, None, "mV")
    assert volts.axes[0].get_ylabel() == "q [mV]"
    np.testing.assert_allclose(
        volts.axes[0].get_lines()[0].get_ydata(), 1e3 * tables["val"]["q"].to_numpy()
    )
    with pytest.raises(WorkflowError, match="cannot express q"):
        free_run_figure(measured, runs, (0, 0), "val", "m", None, None, "mV")


def test_sindy_legend_names_the_inputs_actual_unit(data):
    _, tables, derivs = data
    frame, d = tables["est"], derivs["est"]
    args = (frame["q"].to_numpy(), d["q_dot"].to_numpy(), d["q_ddot"].to_numpy())
    v = frame[["v1", "v2"]].to_numpy()
    cfg = SindyConfig.from_dict({})
    volts = fit_sindy(*args, v, DT, cfg).equations
    assert "h_i = v_i^2 [V^2], i = 1..2" in volts
    plain = fit_sindy(*args, v, DT, cfg, input_units=["1", "1"]).equations
    assert "h_i = v_i^2, i = 1..2" in plain and "[V" not in plain


def test_the_refinement_row_names_why_it_was_rejected_and_shows_the_held_out_windows(data):
    """A rejected refinement prints its own reason (held-out windows here, not "the full
    records"), with the held-out windows' RMS; without held-out blocks those rows are absent."""
    truth, tables, derivs = data
    summary = run_identify(tables, derivs, {**SECTION, "m_q": truth.m_q}).summary
    refine = {
        "accepted": False, "nfev": 12, "window_rms_equation_error": 3e-4,
        "window_rms_simulation_error": 5e-5, "holdout_rms_equation_error": 1.5e-4,
        "holdout_rms_simulation_error": 4.4e-3, "full_rms_equation_error": 3e-4,
        "full_rms_simulation_error": 2.9e-4,
        "message": "rejected: the windows of the held-out estimation blocks got worse "
                   "(0.00015 -> 0.0044 RMS)",
    }  # fmt: skip
    text = _render(identify_table({**summary, "refine": refine}))
    assert "rejected: the windows of the held-out estimation blocks got worse (0.00015 -> " in text
    assert "free-run RMS, held-out windows: simulation error [m]" in text
    kept = {**refine, "accepted": True, "message": "`ftol` termination condition is satisfied.",
            "holdout_rms_equation_error": float("nan"),
            "holdout_rms_simulation_error": float("nan")}  # fmt: skip
    text = _render(identify_table({**summary, "refine": kept}))
    assert "accepted, 12 evaluations" in text and "held-out" not in text
    # several ridge weights: the kept one and each weight's free-run error, rejections named
    several = {**refine, "accepted": True, "prior": 30.0, "holdout_windows": 3,
               "holdout_rms_simulation_error": 1.2e-4,
               "candidates": [{"prior": 0.0, "accepted": False, "message": "rejected",
                               "full_rms_simulation_error": 4.4e-3},
                              {"prior": 30.0, "accepted": True, "message": "ftol",
                               "full_rms_simulation_error": 1.2e-4}]}  # fmt: skip
    text = _render(identify_table({**summary, "refine": several}))
    assert "refinement ridge prior: kept 30, estimation free-run RMS [m] per weight" in text
    assert "0: 0.0044 (rejected); 30: 0.00012" in text
    # a weight never run (records shorter than one window) is not called diverged
    unrun = {"prior": 0.0, "accepted": False, "message": "records shorter than one window",
             "full_rms_simulation_error": float("nan"), "nfev": 0}  # fmt: skip
    text = _render(identify_table({**summary, "refine": {**several, "candidates": [
        unrun, {**unrun, "prior": 30.0}]}}))  # fmt: skip
    assert "0: - (rejected); 30: - (rejected)" in text and "diverged" not in text


def test_a_curve_identified_nowhere_says_why_with_the_calibrated_numbers():
    from debist.report.tables import identified_text

    bands = {
        "bands": {"model_error": {"d": 0.652, "g": 0.576, "restoring": 0.04}, "tolerance": 0.2}
    }
    assert identified_text("d", [], bands) == (
        "nowhere: its calibrated model error alone (65 % of its scale each side) is wider than "
        "the band tolerance (20 %)"
    )
    # a gain's band is narrow enough only where |g| <= 0.2 / (2 * 0.576) = 17 % of its scale
    assert "17 %" in identified_text("g2", [], bands)
    assert "excitation" in identified_text("restoring", [], bands)
    assert identified_text("restoring", [[-0.2031, 0.20557]], bands) == "[-0.2031, 0.2056]"
    assert identified_text("d", [], {}) == "nowhere"  # a summary from before the tolerance


def test_a_thinned_trace_keeps_every_columns_extremes_and_a_short_one_is_unchanged():
    from debist.report.figures import thin, thin_band

    rng = np.random.default_rng(5)
    t = np.arange(100_000) * 1e-3
    y = np.cumsum(rng.normal(size=t.size))
    y[50_000:50_010] = np.nan  # a gap stays a gap only where a whole column is missing
    tt, yy = thin(t, y, bins=1000)
    assert tt.size == yy.size == 2000
    assert np.nanmax(yy) == np.nanmax(y) and np.nanmin(yy) == np.nanmin(y)
    column = slice(100 * 137, 100 * 138)  # column 137 of 1000: samples 13700..13799
    assert yy[2 * 137] == y[column].min() and yy[2 * 137 + 1] == y[column].max()
    assert tt[2 * 137] == t[column].mean()
    short = np.arange(10.0)
    assert np.array_equal(thin(short, short, bins=1000)[1], short)
    tb, lo, hi = thin_band(t, y - 1.0, y + 1.0, bins=1000)
    assert tb.size == 1000 and np.all(lo <= hi)
    assert hi[137] == y[column].max() + 1.0 and lo[137] == y[column].min() - 1.0


def test_the_design_table_reads_as_lines_in_a_narrow_terminal():
    from debist.report.tables import design_lines

    well = {"model": "rbf", "level": 0, "static_stable": True, "stable": True, "identified": True,
            "q": -0.0095, "v1": 0.0, "v2": 0.0, "d": 0.33, "k": 10.6, "k_lo": 8.4, "k_hi": 12.9,
            "f_n": 2.3, "zeta": 0.22, "barrier": 1.5e-4, "d_identified": False}  # fmt: skip
    summary = {
        "units": {"q": "m", "v1": "V", "v2": "V", "per_unit_mass": False},
        "design": {"verdict": "stable", "reason": "1 visited well(s)", "equilibria": [well],
                   "switching": [{"model": "rbf", "input": 1, "v_switch": 1282.0,
                                  "identified": True}]},
    }  # fmt: skip
    lines = design_lines(summary)
    assert lines[0].startswith("Equilibria and switching")
    assert lines[1] == (
        "  rbf well at q* = -0.0095 m (inputs 0, 0): d(q*) 0.33 N s/m (not identified), "
        "k* 10.6 N/m (8.4-12.9), f_n 2.3 Hz, zeta 0.22 (not identified), barrier 0.00015 J"
    )
    assert lines[2] == "  rbf switching voltage, input 1: 1282 V"
    assert lines[-1].startswith("identified model: stable")
    assert design_lines({}) == []


def _design_cells(table) -> dict[str, list[str]]:
    return {str(c.header).replace("\\[", "["): list(c._cells) for c in table.columns}


@pytest.mark.parametrize(("report_unit", "f", "shown"), [(None, 1e3, "mm"), ("um", 1e6, "\u00b5m")])
def test_the_display_shows_q_and_stiffness_per_length_in_the_report_unit(
    data, report_unit, f, shown
):
    """q* x f, k* and d(q*) / f (N per report unit), the barrier stays in J, in the CLI tables."""
    from debist.report.tables import display_summary

    truth, tables, derivs = data
    summary = run_identify(tables, derivs, {**SECTION, "m_q": truth.m_q}).summary
    shown_summary = display_summary(summary, report_unit)
    cells = _design_cells(design_table(shown_summary))
    wells = [
        r
        for r in summary["design"]["equilibria"]
        if r["static_stable"] and r["level"] == 0 and r["model"] == "rbf"
    ]
    assert f"q* [{shown}]" in cells and f"k* [N/{shown}]" in cells and "barrier [J]" in cells
    assert f"d(q*) [N s/{shown}]" in cells
    rows = [i for i, k in enumerate(cells["kind"]) if k.startswith("well")][: len(wells)]
    for i, r in zip(rows, wells, strict=True):
        assert float(cells[f"q* [{shown}]"][i]) == pytest.approx(f * r["q"], rel=1e-3)
        assert float(cells[f"k* [N/{shown}]"][i].split()[0]) == pytest.approx(r["k"] / f, rel=1e-3)
        assert float(cells["barrier [J]"][i]) == pytest.approx(r["barrier"], rel=1e-3)
    text = _render(identify_table(shown_summary))
    k_1 = summary["backbone"]["k_1"] / f
    assert f"(a basis term; the stiffness k* is in the equilibria) [N/{shown}]" in text
    assert f"{k_1:.4g}" in text
    assert f"identified on q [{shown}] in" in text
    lo, hi = summary["q_data_range"]
    reason = shown_summary["design"]["reason"]  # four digits, no exponent: [-15920, 15820] µm
    lo_text, hi_text = re.search(rf"in \[(\S+), (\S+)\] {shown}", reason).groups()
    assert "e" not in lo_text + hi_text, reason
    assert [float(lo_text), float(hi_text)] == pytest.approx([f * lo, f * hi], rel=1e-3)
    assert summary["units"]["q"] == "m"  # the stage's summary is left as it was


def test_per_unit_mass_stiffness_is_one_over_seconds_squared_in_any_length_unit(data):
    """k* [1/s^2] keeps its numbers; a force per unit mass is an acceleration of q [mm/s^2]."""
    from debist.report.tables import display_summary, slip_rows

    _, tables, derivs = data
    summary = run_identify(tables, derivs, {**SECTION, "m_q": 1.0}).summary
    shown = display_summary(summary)
    cells = _design_cells(design_table(shown))
    assert "k* [1/s^2]" in cells and "barrier [J/kg]" in cells and "d(q*) [1/s]" in cells
    k_si = [r["k"] for r in summary["design"]["equilibria"] if r["static_stable"]]
    k_shown = [float(c.split()[0]) for c in cells["k* [1/s^2]"] if c]
    assert k_shown[: len(k_si)] == pytest.approx(k_si, rel=1e-3)
    text = _render(identify_table(shown))
    assert "offset force F_0 [mm/s^2]" in text and "forces in mm/s^2" in text
    assert f"{1e3 * summary['backbone']['F_0']:.4g}" in text
    slip = {"Delta": [1e-5], "k": [3000.0], "F": [0.03], "F_total": 0.03, "k_total": 3000.0}
    rows = slip_rows(display_summary({**summary, "slip": slip}))
    assert [(unit, pytest.approx(v)) for _, unit, v in rows] == [
        ("mm", 0.01), ("1/s^2", 3000.0), ("mm/s^2", 30.0), ("mm/s^2", 30.0), ("1/s^2", 3000.0)
    ]  # fmt: skip


def test_excitation_warnings_follow_a_report_unit_of_another_scale():
    """The identify stage words q in V (q in V); a report in mV rewrites its positions x1000."""
    from debist.report.tables import display_summary

    said = (
        "no data: fewer than 10 samples within sigma = 0.05 V of the centres for q in "
        "[-0.3, -0.21] and [0.2, 0.25] V: c, d there are not identified"
    )
    summary = {"units": {"q": "V", "per_unit_mass": True}, "excitation": {"warnings": [said]}}
    shown = display_summary(summary, "mV")["excitation"]["warnings"]
    assert shown == [
        "no data: fewer than 10 samples within sigma = 50 mV of the centres for q in "
        "[-300, -210] and [200, 250] mV: c, d there are not identified"
    ]
    assert display_summary(summary)["excitation"]["warnings"] == [said]  # V: as worded


@pytest.mark.parametrize(("report_unit", "text"), [(None, "-21.28 ... +23.05"),
                                                   ("um", "-21280 ... +23050"),
                                                   ("m", "-0.02128 ... +0.02305")])  # fmt: skip
def test_the_rig_table_gives_the_q_range_in_the_report_unit(report_unit, text):
    from debist.report.tables import rig_table

    summary = {"ident": {"samples": 3750, "q_min": -0.02128, "q_max": 0.02305,
                         "well_changes": 6, "saturated": 0, "nfev": 10}}  # fmt: skip
    out = _render(rig_table(summary, report_unit))
    unit = {"um": "\u00b5m", None: "mm"}.get(report_unit, report_unit)
    assert f"q range [{unit}]" in out and text in out


@pytest.mark.parametrize(("report_unit", "f", "shown"), [(None, 1e3, "mm"), ("um", 1e6, "\u00b5m")])
def test_the_excitation_figure_draws_q_in_the_report_unit(data, report_unit, f, shown):
    from debist.report.figures import excitation_figure

    _, tables, derivs = data
    name = next(iter(tables))
    fig = excitation_figure(tables[name], derivs[name], name, "m", report_unit)
    q_ax, q_dot_ax = fig.axes[:2]
    assert q_ax.get_ylabel() == f"q [{shown}]" and q_dot_ax.get_ylabel() == f"q_dot [{shown}/s]"
    drawn = q_ax.get_lines()[0].get_ydata()
    q = tables[name]["q"].to_numpy()
    assert float(np.max(drawn)) == pytest.approx(f * q.max(), rel=1e-12)
    assert float(np.min(drawn)) == pytest.approx(f * q.min(), rel=1e-12)


def _panel(ax):
    """Unit of a Fig. 14 panel's y label and the power of ten its values are shown in."""
    label = ax.get_ylabel().strip("[]")
    if label.startswith("10^"):
        decade, label = label[3:].split(" ", 1)
        return label, 10.0 ** int(decade)
    return label, 1.0


def _curves():
    q = np.linspace(-0.016, 0.016, 33)
    frame = {"q": q, "restoring": 2.0 * q - 400.0 * q**3, "d": 0.5 + 0 * q,
             "g1": 1e-8 + 0 * q, "g2": -1e-8 + 0 * q}  # fmt: skip
    out = {}
    for name, y in frame.items():
        out[name] = y
        if name != "q":
            out.update({f"{name}_lo": 0.9 * y, f"{name}_hi": 1.1 * y,
                        f"{name}_identified": np.ones(q.size, bool)})  # fmt: skip
    import pandas as pd

    return pd.DataFrame(out)


@pytest.mark.parametrize(
    ("report_unit", "per_unit_mass", "q_label", "k_q", "labels", "factors"),
    [
        (None, False, "mm", 1e3, ["N", "N s/mm", "N/V^2"], [1.0, 1e-3, 2.0]),
        ("um", False, "µm", 1e6, ["N", "N s/µm", "N/V^2"], [1.0, 1e-6, 2.0]),
        ("m", False, "m", 1.0, ["N", "N s/m", "N/V^2"], [1.0, 1.0, 2.0]),
        ("mm", True, "mm", 1e3, ["mm/s^2", "1/s", "mm/s^2/V^2"], [1e3, 1.0, 2e3]),
    ],
)
def test_fig14_draws_q_and_the_curves_in_the_report_unit(
    report_unit, per_unit_mass, q_label, k_q, labels, factors
):
    """Fig. 14's axes in the unit of the tables: q, damping per length of q and, per unit
    mass, forces as accelerations of q, each value the recorded one times its factor."""
    from debist.report.plots import curves_figure

    curves = _curves()
    summary = {"units": {"q": "m", "v1": "V", "v2": "V", "input_map": "v2",
                         "per_unit_mass": per_unit_mass}, "m_q": 1.0 if per_unit_mass else 0.04,
               "backbone": {"g_0": [0.0, 0.0]}}  # fmt: skip
    fig = curves_figure(curves, None, summary, report_unit)
    assert fig.axes[2].get_xlabel() == f"q [{q_label}]"
    for ax, name, label, factor in zip(fig.axes[:3], ("restoring", "d", "g1"), labels, factors,
                                       strict=True):  # fmt: skip
        unit, scale = _panel(ax)
        assert unit == label
        line = ax.lines[1]  # the identified part, in colour
        np.testing.assert_allclose(line.get_xdata(), k_q * curves["q"].to_numpy())
        np.testing.assert_allclose(line.get_ydata() * scale, factor * curves[name].to_numpy())


def test_fig14_refuses_a_report_unit_that_is_not_of_q():
    from debist.report.plots import curves_figure

    summary = {"units": {"q": "m", "v1": "V"}, "m_q": 0.04, "backbone": {"g_0": [0.0]}}
    with pytest.raises(WorkflowError, match="report_unit 'mV' cannot express q in 'm'"):
        curves_figure(_curves(), None, summary, "mV")


def test_the_physics_figures_and_the_analyze_table_show_q_in_the_report_unit():
    """Fig. 5 and the reduced model's curves (Section 3) in µm: q, dC/dq and d per µm,
    against the physics model's own arrays [SI]; a unit of another quantity keeps mm."""
    from debist.physics.params import PrototypeParams
    from debist.physics.reduced import reduced_curves
    from debist.report.physics_plots import plot_reduced_curves
    from debist.report.tables import analyze_table

    cur = reduced_curves(PrototypeParams.from_dict({}), np.linspace(-0.012, 0.012, 25))
    fig = plot_reduced_curves(cur, "um")
    f_ax, d_ax, g_ax, _ = fig.axes
    assert g_ax.get_xlabel() == "tip displacement $q$ [µm]"
    assert d_ax.get_ylabel() == "$d(q)$ [N s/µm]" and g_ax.get_ylabel().endswith("[nF/µm]")
    np.testing.assert_allclose(d_ax.lines[0].get_xdata(), 1e6 * cur.q)
    np.testing.assert_allclose(d_ax.lines[0].get_ydata(), 1e-6 * cur.d)
    np.testing.assert_allclose(g_ax.lines[0].get_ydata(), 1e9 * 1e-6 * cur.g1)
    np.testing.assert_allclose(f_ax.lines[0].get_ydata(), 1e3 * cur.f)  # mN: not of q
    default = plot_reduced_curves(cur)
    assert default.axes[2].get_xlabel() == "tip displacement $q$ [mm]"
    assert plot_reduced_curves(cur, "mV").axes[2].get_xlabel().endswith("[mm]")
    summary = {"b": 0.023, "z_b_min": 0.004837, "z_b_max": 0.01165, "nrmse_q": 0.0383,
               "nrmse_phi": 0.0453, "operating_points": {"v1_0kV_v2_0kV": [
                   {"q": -0.010206, "stable": True}, {"q": 1e-19, "stable": False}]}}  # fmt: skip
    text = _render(analyze_table(summary, "um"))
    assert "equilibria q [µm], (v1, v2) (0, 0) kV" in text and "-10206, +0 (unstable)" in text
    assert "z_b,min [mm]" in text and "4.837" in text  # a design length, not q
    assert "-0.010206, +0.000000 (unstable)" in _render(analyze_table(summary, "m"))
    assert "-10.206, +0.000 (unstable)" in _render(analyze_table(summary))
