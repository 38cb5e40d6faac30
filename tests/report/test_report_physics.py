"""Nothing misleading printed (issue 23): physics shown as physics, basis terms as such,
headings that match, the input's own quantity and unit."""

import numpy as np
import pandas as pd
import pytest

from debist.identify.stability import stability_table
from debist.report.html import _design
from debist.report.tables import de_inputs, design_table, identify_table, summary_units
from tests.conftest import K1, M_Q, D, double_well, duffing_record


def _cells(table):
    """Columns of a rich table by header (rich's markup escapes removed)."""
    return {str(c.header).replace("\\[", "["): list(c._cells) for c in table.columns}


def _summary(model, units, analytical=False):
    eq = stability_table(model).assign(model="rbf")
    rows = eq.to_dict(orient="records")
    if analytical:
        rows += [{**r, "model": "analytical"} for r in rows]
    return {
        "T_z": 0.01,
        "m_q": M_Q,
        "rank": 3,
        "n_columns": 3,
        "condition": 1.0,
        "n_params": 3,
        "fit_r2": 1.0,
        "backbone": {k: np.asarray(v).tolist() for k, v in model.backbone.items()},
        "units": units,
        "design": {"verdict": "stable", "reason": "test", "equilibria": rows, "switching": []},
    }


def test_wells_show_the_total_damping_stiffness_and_frequency_in_closed_form():
    """c(q) = k1 + k3 q^2, d = D: wells at +-sqrt(-k1/k3) with k* = -2 k1, d(q*) = D and
    f_n = sqrt(-2 k1 / m_q) / (2 pi), in the CLI and the HTML table alike."""
    units = {"q": "m", "v1": "V", "v2": "V", "input_map": "v2", "per_unit_mass": False}
    summary = _summary(double_well(), units)
    cells = _cells(design_table(summary))
    wells = [i for i, k in enumerate(cells["kind"]) if k == "well"]
    assert len(wells) == 2
    f_n = np.sqrt(-2 * K1 / M_Q) / (2 * np.pi)
    for i in wells:
        assert float(cells["k* [N/m]"][i]) == pytest.approx(-2 * K1, rel=1e-3)
        assert float(cells["d(q*) [N s/m]"][i]) == pytest.approx(D, rel=1e-3)
        assert float(cells["f_n [Hz]"][i]) == pytest.approx(f_n, rel=1e-3)
    html = _design(summary)
    assert html["stiffness"] == "N/m" and html["damping"] == "N s/m"
    well_rows = [r for r in html["rows"] if r[3] == "well"]
    assert [float(r[5]) for r in well_rows] == pytest.approx([-2 * K1] * 2, rel=1e-3)
    assert [float(r[4]) for r in well_rows] == pytest.approx([D] * 2, rel=1e-3)


def test_heading_says_beside_analytical_only_with_analytical_rows():
    units = {"q": "m", "v1": "V", "v2": "V"}
    alone = design_table(_summary(double_well(), units)).title
    both = design_table(_summary(double_well(), units, analytical=True)).title
    assert "analytical" not in alone and alone.endswith("(identified)")
    assert both.endswith("(identified beside analytical)")
    assert _design(_summary(double_well(), units))["title"] == "identified"


def test_backbone_coefficients_are_named_as_basis_terms():
    units = {"q": "m", "v1": "V", "v2": "V"}
    labels = _cells(identify_table(_summary(double_well(), units)))["quantity"]
    text = " ".join(labels)
    assert "viscous friction" not in text and "linear spring" not in text
    assert sum("a basis term" in x for x in labels) >= 3  # k_1, k_3, d_v, g_0,i


def test_an_acceleration_input_is_named_and_drawn_as_such():
    """A base-excited Duffing oscillator (input an acceleration [m/s^2], h = u) through
    run_identify: switching levels in m/s^2, Fig. 14 shows g_i, not dC_i/dq."""

    from debist.report.plots import curves_figure
    from debist.stages.identify import run_identify

    rec = duffing_record(lambda t: 15.0 * np.cos(2 * np.pi * 0.8 * t), "sine", t_end=60.0)
    t = np.arange(rec.q.size) * rec.dt
    frame = pd.DataFrame({"t": t, "q": rec.q, "v1": rec.v[:, 0]})
    frame.attrs.update(role="estimation", units={"q": "m", "t": "s", "v1": "m/s^2"})
    deriv = pd.DataFrame({"q_dot": rec.q_dot, "q_ddot": rec.q_ddot})
    deriv.attrs["dt"] = rec.dt
    section = {"M": 6, "T_z": 0.0, "input_map": "v", "rbf": ["c", "d", "g"], "bootstrap": 10,
               "m_q": 1.0, "backbone": ["linear_spring", "viscous"]}  # fmt: skip
    res = run_identify({"est": frame}, {"est": deriv}, section)
    units = summary_units(res.summary)
    assert units["quantities"] == ["acceleration"] and not de_inputs(units)
    # a switching row as a bistable base-excited beam would have it
    summary = dict(res.summary)
    summary["design"] = dict(summary["design"])
    summary["design"]["switching"] = [{"model": "rbf", "input": 1, "v_switch": 4.2}]
    cells = _cells(design_table(summary))
    assert cells["inputs [m/s^2]"].count("switching acceleration, input 1") >= 1  # a cell of it
    assert "4.2 m/s^2" in cells["kind"]
    html = _design(summary)
    assert any(r[1] == "switching acceleration, input 1" and r[3] == "4.2 m/s^2"
               for r in html["rows"])  # fmt: skip
    fig = curves_figure(res.curves, None, res.summary, "m")  # g1 [m/s^2] as recorded
    titles = [ax.get_title() for ax in fig.axes]
    assert not any("dC_i/dq" in x for x in titles)
    assert any("g_i(q)" in x for x in titles)
    # g1 drawn as itself (factor 1, not 2): the identified line's largest magnitude
    line = fig.axes[2].lines[1].get_ydata()
    decade = fig.axes[2].get_ylabel()
    scale = 10.0 ** int(decade.split("^")[1].split()[0]) if "10^" in decade else 1.0
    g1 = res.curves.g1.to_numpy()
    ident = res.curves.g1_identified.to_numpy()
    if ident.any():
        assert np.nanmax(np.abs(line)) * scale == pytest.approx(np.max(np.abs(g1[ident])))


def test_de_voltage_inputs_keep_the_capacitance_gradient():
    units = summary_units({"units": {"q": "m", "v1": "V", "v2": "V", "input_map": "v2"}})
    assert de_inputs(units) and units["quantities"] == ["voltage", "voltage"]
    assert not de_inputs({**units, "input_map": "v"})
