"""Design numbers in the identify stage: held levels, identified beside analytical."""

import dataclasses

import numpy as np
import pytest

from debist.identify.design import analytical_as_eq37, design_numbers, held_levels
from debist.identify.fit import Record
from debist.physics.params import PrototypeParams
from tests.conftest import F_MAX, K1, K3, M_Q, G, double_well


def _record(v, dt=0.01):
    n = v.shape[0]
    q = np.linspace(-0.011, 0.011, n)
    return Record("r", q, np.zeros(n), np.zeros(n), v, dt)


def test_held_levels_are_the_inputs_held_long_enough():
    v = np.zeros((1000, 2))
    v[100:160, 0] = 3000.0  # 0.6 s: held
    v[300:310, 1] = 3000.0  # 0.1 s: a pulse, not held
    v[500:900, 1] = 1203.0  # 4 s at a sub-threshold level (rounded to 2 % of 3 kV)
    v[600:700, 1] += np.linspace(0, 10, 100)  # a slow drift within the resolution
    levels = held_levels([_record(v)])
    assert levels[0] == pytest.approx((0.0, 1200.0))
    assert levels[1] == pytest.approx((3000.0, 0.0))
    assert len(levels) == 2


def test_design_numbers_of_a_double_well_match_the_closed_forms():
    v = np.zeros((1000, 2))
    v[100:200, 0] = 0.5 * np.sqrt(F_MAX / G)  # a held sub-switching level
    v[400:405] = 1.2 * np.sqrt(F_MAX / G)  # short pulses beyond the switching voltage
    d = design_numbers(double_well(), [_record(v)])
    eq = d["equilibria"]
    wells = eq[(eq.level == 0) & eq.static_stable]
    a = np.sqrt(-K1 / K3)
    assert wells.q.to_numpy() == pytest.approx([-a, a], rel=1e-6)
    f_n = np.sqrt(-2 * K1 / M_Q) / (2 * np.pi)
    assert wells.f_n.to_numpy() == pytest.approx([f_n, f_n], rel=1e-5)
    assert eq.attrs["verdict"] == "stable"
    sw = d["switching"]
    assert sw.v_switch.to_numpy() == pytest.approx(np.sqrt(F_MAX / G) * np.ones(2), rel=1e-4)
    assert set(eq.model) == {"rbf"} and len(eq[eq.level == 1]) >= 1


def test_the_analytical_rows_are_the_reduced_model_in_eq37_form():
    """Paper prototype: wells at +-10.21 mm and 1.42 kV switching (the full model's statics
    give 1425 V), with frequencies invariant to the model's m_q scaling."""
    P = PrototypeParams.paper()
    v = np.zeros((600, 2))
    rec = _record(v)
    for m_q in (1.0, 0.042):
        model = dataclasses.replace(double_well(), m_q=m_q)
        eq37 = analytical_as_eq37(P, [rec], model)
        d = design_numbers(model, [rec], P)
        ana = d["equilibria"][d["equilibria"].model == "analytical"]
        wells = ana[ana.static_stable]
        assert wells.q.to_numpy() == pytest.approx([-0.01021, 0.01021], abs=2e-5)
        sw = d["switching"][d["switching"].model == "analytical"]
        assert sw.v_switch.to_numpy() == pytest.approx([1425.0, 1425.0], rel=0.01)
        assert eq37.m_q == model.m_q
        assert wells.f_n.to_numpy() == pytest.approx([2.84, 2.84], rel=0.01)


def test_equilibria_where_the_curves_are_not_identified_are_marked():
    """An equilibrium on an unidentified part of its force curve is flagged, not vouched for."""
    import pandas as pd

    from debist.identify.design import mark_identified
    from debist.report.tables import equilibrium_kind

    q = np.linspace(-0.01, 0.01, 21)
    curves = pd.DataFrame({"q": q, "restoring_identified": np.abs(q) > 0.004})
    static = pd.DataFrame({"v1": 1e3, "v2": 0.0, "q": q, "F_identified": q > 0.0})
    eq = pd.DataFrame({
        "model": ["rbf", "rbf", "rbf", "rbf", "analytical"],
        "level": [0, 0, 1, 1, 0],
        "v1": [0.0, 0.0, 1e3, 1e3, 0.0],
        "v2": 0.0,
        "q": [-0.008, 0.001, -0.005, 0.005, 0.0],
        "static_stable": [True, False, True, True, False],
        "stable": [True, False, True, True, False],
    })  # fmt: skip
    eq.attrs["verdict"] = "stable"
    out = mark_identified(eq, curves, static)
    assert out["identified"].tolist() == [True, False, False, True, True]
    assert out["d_identified"].tolist() == [False, False, False, False, True]  # no d mask
    with_d = mark_identified(eq, curves.assign(d_identified=q < 0.0), static)
    assert with_d["d_identified"].tolist() == [True, False, True, False, True]
    assert out.attrs["verdict"] == "stable"
    rows = out.to_dict(orient="records")
    assert equilibrium_kind(rows[0]) == "well"
    assert equilibrium_kind(rows[1]) == "saddle (not identified at q*)"
    assert equilibrium_kind(rows[2]) == "well (not identified at q*)"


def test_switching_voltages_where_g_is_not_identified_are_marked():
    """A switching voltage rests on the restoring force and g_i from the well to the fold."""
    import pandas as pd

    from debist.identify.design import mark_switching
    from debist.report.tables import switching_note

    q = np.linspace(-0.016, 0.016, 33)  # 1 mm grid
    curves = pd.DataFrame({
        "q": q,
        "restoring_identified": True,
        "g1_identified": (q >= -0.0105) & (q <= -0.0055),  # covers well -0.010 .. fold -0.006
        "g2_identified": (q >= 0.0075) & (q <= 0.0115),  # misses the fold at 0.006
    })  # fmt: skip
    sw = pd.DataFrame({
        "model": ["rbf", "rbf", "rbf", "analytical"],
        "input": [1, 2, 1, 1],
        "v_switch": [1300.0, 1500.0, np.nan, 1424.0],
        "q_well": [-0.010, 0.010, -0.010, -0.0102],
        "q_fold": [-0.006, 0.006, np.nan, -0.0056],
    })  # fmt: skip
    out = mark_switching(sw, curves)
    assert out["identified"].tolist() == [True, False, False, True]
    rows = out.assign(v_switch=[1300.0, 1500.0, None, 1424.0]).to_dict(orient="records")
    assert switching_note(rows[0]) == ""
    assert switching_note(rows[1]).startswith(" (not identified: g2")
    assert switching_note(rows[2]) == ""  # no number, nothing to caveat
    # the restoring force matters too
    curves["restoring_identified"] = np.abs(q) > 0.007
    assert mark_switching(sw, curves)["identified"].tolist() == [False, False, False, True]


def test_design_cells_carry_the_stiffness_band_and_say_where_d_is_not_identified():
    """k* and f_n with their band in brackets; d and zeta "not identified" off d's mask."""
    import math

    from debist.report.tables import small_signal_cells

    fmt = lambda x, digits=4: "-" if x is None else f"{x:.{digits}g}"  # noqa: E731
    row = {"static_stable": True, "d": 0.26, "k": 8.486, "f_n": 2.313, "zeta": 0.2227,
           "barrier": 1.2e-4, "k_lo": 4.44, "k_hi": 12.56, "f_n_lo": 1.673, "f_n_hi": 2.813,
           "d_identified": np.False_}  # fmt: skip
    assert small_signal_cells(row, fmt) == [
        "0.26 (not identified)", "8.486 (4.44-12.6)", "2.313 (1.67-2.81)",
        "0.2227 (not identified)", "0.00012",
    ]  # fmt: skip
    row.update(d_identified=True, k_lo=math.nan, f_n_lo=None)
    assert small_signal_cells(row, fmt)[:4] == ["0.26", "8.486", "2.313", "0.2227"]
    assert small_signal_cells({**row, "static_stable": False}, fmt) == [""] * 5


def test_the_analytical_rows_keep_the_physical_scale_under_the_effective_mass_scale():
    """A model rescaled to a rigid mass m_q / lambda (identify/mass.py) passes its effective mass:
    the analytical rows are then those of the unscaled model, not scaled by 1 / lambda."""
    P = PrototypeParams.paper()
    rec = _record(np.zeros((600, 2)))
    model = dataclasses.replace(double_well(), m_q=0.0402)
    rigid = model.scaled(1.25)

    def analytical(d):
        eq = d["equilibria"]
        return eq[eq.model == "analytical"][["q", "k", "f_n", "zeta", "barrier"]].to_numpy()

    base = analytical(design_numbers(model, [rec], P))
    kept = analytical(design_numbers(rigid, [rec], P, mass=rigid.m_q / 1.25))
    np.testing.assert_allclose(kept, base, rtol=1e-9)
    inflated = analytical(design_numbers(rigid, [rec], P))  # without it: forces x 1.25
    wells = ~np.isnan(base[:, 2])
    np.testing.assert_allclose(inflated[wells, 1], 1.25 * base[wells, 1], rtol=1e-9)


def test_the_figure_curves_keep_the_physical_scale_under_the_effective_mass_scale():
    """Fig. 14's analytical curves are per the mass the identified curves refer to (the
    summary's ``m_q_curves``), not per the rescaled model's rigid mass."""
    from debist.stages.identify import analytical_curves

    P = PrototypeParams.paper()
    model = dataclasses.replace(double_well(), m_q=0.0402)
    rigid = model.scaled(1.25)
    base = analytical_curves(P, model)
    kept = analytical_curves(P, rigid, mass=rigid.m_q / 1.25)
    np.testing.assert_allclose(kept.to_numpy(), base.to_numpy(), rtol=1e-12)
    inflated = analytical_curves(P, rigid)
    np.testing.assert_allclose(inflated.g1, 1.25 * base.g1, rtol=1e-12)
