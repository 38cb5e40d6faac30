"""A position-dependent inertia m(q) = m_q + sum_a mu_a q^a as identified terms.

Lagrange's equation of a coordinate with kinetic energy 1/2 m(q) q_dot^2 has
m(q) q'' + 1/2 m'(q) q_dot^2 on its left; with the coefficients mu_a in the regressor (the
q_ddot-weighted columns ``q^a q'' + 1/2 a q^(a-1) q_dot^2``) the least squares of Eq. 40
identifies them beside the curves. Checked here: the NumPy acceleration against the balance
solved by hand, the fit against data of a model with a known m(q), the model file and the
configuration.
"""

from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from debist.identify.config import IdentifyConfig
from debist.identify.fit import Record, fit_rbf_model
from debist.model.rbf import RBFModel
from tests.conftest import INSIDE_CLASS, excitation, random_states, truth_model
from tests.model.conftest import curve_error

#: m(q) = 1 + 2 q + 900 q^2 (per unit mass): +15 % at q = +12 mm, +11 % at -12 mm.
MU = np.array([2.0, 900.0])


def _with_inertia(model: RBFModel, mu=MU) -> RBFModel:
    return replace(model, theta_inertia=np.asarray(mu, dtype=float))


def test_the_acceleration_is_the_lagrangian_balance_solved_for_q_ddot():
    """q'' = (G - F - 1/2 m'(q) q_dot^2) / m(q), with F, G from the constant-mass model."""
    truth = truth_model(np.random.default_rng(2))
    model = _with_inertia(truth)
    q, q_dot, v = random_states(3)
    balance = truth.accel(q, q_dot, v) * truth.m_q  # G - F at z = q_dot (T_z = 0)
    m = 1.0 + MU[0] * q + MU[1] * q**2
    dm = MU[0] + 2.0 * MU[1] * q
    want = (balance - 0.5 * dm * q_dot**2) / m
    np.testing.assert_allclose(model.accel(q, q_dot, v), want, rtol=1e-12)
    np.testing.assert_allclose(model.mass(q), m, rtol=1e-15)
    np.testing.assert_allclose(model.table_model().mass_of(q), m, rtol=1e-12)


def _record(truth: RBFModel, n=6000, dt=0.002) -> Record:
    """Noise-free data of the model (solve_ivp DOP853), with the exact q''."""
    t = np.arange(n) * dt

    def rhs(tt, x):
        v = excitation(np.array([tt]))
        return [x[1], truth.accel(x[:1], x[1:], v, q_dot=x[1:])[0]]

    sol = solve_ivp(rhs, (t[0], t[-1]), [-0.01, 0.0], t_eval=t, method="DOP853",
                    rtol=1e-10, atol=1e-13)  # fmt: skip
    q, q_dot = sol.y
    v = excitation(t)
    return Record("sim", q, q_dot, truth.accel(q, q_dot, v, q_dot=q_dot), v, dt)


def test_the_fit_recovers_the_inertia_and_the_curves_it_would_bias():
    """With ``inertia = 2`` the coefficients and the curves come back to rounding (measured
    3e-14 and 9e-15: the data are noise-free with the exact q'', inside the model class);
    without, the same data bias the curves by 20 % of their scale (asserted 10 %)."""
    truth = _with_inertia(truth_model(np.random.default_rng(2)))
    record = _record(truth)
    assert np.ptp(truth.mass(record.q)) > 0.1  # the data see m(q) vary by > 10 %
    base = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0}
    model, diag = fit_rbf_model([record], IdentifyConfig.from_dict({**base, "inertia": 2}))
    assert diag.columns[16:18] == ["inertia[1]", "inertia[2]"]
    np.testing.assert_allclose(model.theta_inertia, MU, rtol=1e-9)
    without, _ = fit_rbf_model([record], IdentifyConfig.from_dict(base))
    assert curve_error(model, truth) < 1e-9
    assert curve_error(without, truth) > 0.1


def test_the_model_file_keeps_the_inertia_and_a_constant_mass_keeps_its_bytes():
    truth = truth_model(np.random.default_rng(2))
    model = _with_inertia(truth)
    back = RBFModel.from_tree(model.to_tree())
    np.testing.assert_array_equal(back.theta_inertia, MU)
    names, values = back.parameters()
    np.testing.assert_array_equal(
        values[[names.index("inertia[1]"), names.index("inertia[2]")]], MU
    )
    assert "inertia" not in truth.to_tree()["model"]
    assert not RBFModel.from_tree(truth.to_tree()).has_inertia


@pytest.mark.parametrize("bad", [-1, 5, 1.5, "yes"])
def test_the_inertia_degree_is_checked(bad):
    with pytest.raises(Exception) as err:
        IdentifyConfig.from_dict({"inertia": bad})
    assert "inertia" in str(err.value)


def test_a_list_of_powers_fits_only_those_and_a_symmetric_mass_comes_back():
    """``inertia = [2]``: one column, ``inertia[2]``; data of m(q) = 1 + 900 q^2 give mu_2 to
    0.1 % and mu_1 exactly 0 (left out, not fitted)."""
    cfg = IdentifyConfig.from_dict({"inertia": [2]})
    assert cfg.inertia_powers == (2,)
    assert IdentifyConfig.from_dict({"inertia": 3}).inertia_powers == (1, 2, 3)
    truth = _with_inertia(truth_model(np.random.default_rng(2)), mu=[0.0, 900.0])
    record = _record(truth)
    base = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0, "inertia": [2]}
    model, diag = fit_rbf_model([record], IdentifyConfig.from_dict(base))
    assert [c for c in diag.columns if c.startswith("inertia")] == ["inertia[2]"]
    assert model.theta_inertia[0] == 0.0
    assert model.theta_inertia[1] == pytest.approx(900.0, rel=1e-3)
    assert model.parameters()[0].count("inertia[1]") == 0


def test_a_mass_that_is_not_positive_where_the_data_are_is_unstable():
    """m(q) = 1 - 1e4 q^2 vanishes at |q| = 10 mm: inside the visited +-12 mm, unstable."""
    from debist.identify.stability import model_is_stable

    truth = truth_model(np.random.default_rng(2))
    q = np.linspace(-0.012, 0.012, 200)
    ok, _ = model_is_stable(_with_inertia(truth, mu=[0.0, 1e3]), q)
    bad, reason = model_is_stable(_with_inertia(truth, mu=[0.0, -1e4]), q)
    assert ok and not bad
    assert "m(q)" in reason and "mass" in reason and "positive" in reason


def test_the_report_lists_the_mass_at_the_range_edges_and_at_zero():
    from debist.report.tables import inertia_rows, term_rows

    summary = {"inertia": {"mu": [2.0, 900.0], "q": [-0.016, 0.0, 0.016],
                           "m": [1.2, 1.0, 1.26]}, "units": {"q": "m", "mass": "kg"}}  # fmt: skip
    rows = inertia_rows(summary)
    assert [r[2] for r in rows] == [1.2, 1.0, 1.26]
    assert rows[0][0].startswith("mass m(q) at q = -0.016")
    assert term_rows(summary) == rows  # no slip elements
    assert inertia_rows({"units": {}}) == []
