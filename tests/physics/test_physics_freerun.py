"""The analytical model as a free-run model: RK4 on tabulated curves vs solve_ivp on Eq. 26."""

import numpy as np
import pytest

from debist.core.errors import WorkflowError
from debist.identify.physics_prior import analytical_for
from debist.physics.freerun import AnalyticalModel
from debist.physics.params import PrototypeParams
from debist.physics.reduced import fit_reduced, simulate_reduced
from debist.simulate.freerun import simulate
from debist.validate.config import ValidateConfig
from debist.validate.freerun import DataSet, validate_model

P = PrototypeParams.paper()
DT = 1e-3
T = np.arange(0.0, 4.0, DT)


def ramp(a, b):
    return np.clip((T - a) / 0.02, 0, 1) - np.clip((T - b) / 0.02, 0, 1)


@pytest.fixture(scope="module")
def reference():
    """Fig. 7-like switching (ramped 3 kV steps) integrated by DOP853 on ReducedModel.rhs."""
    red = fit_reduced(P, degree=24)
    v = np.stack([3000.0 * ramp(0.5, 1.5), 3000.0 * ramp(2.5, 3.5)], axis=1)
    q0 = -0.010206053
    sol = simulate_reduced(
        red,
        lambda s: float(np.interp(s, T, v[:, 0])),
        lambda s: float(np.interp(s, T, v[:, 1])),
        (0.0, T[-1]),
        [q0, 0.0, 0.0, 0.0],
        t_eval=T,
        breakpoints=[0.5, 0.52, 1.5, 1.52, 2.5, 2.52, 3.5, 3.52],
    )
    return red, v, sol


def test_rk4_on_tabulated_curves_matches_solve_ivp(reference):
    red, v, sol = reference
    model = AnalyticalModel(red)
    sim = simulate(model, [v], DT, np.array([sol.q[0]]), np.array([0.0]), interpolation="linear")
    assert sol.q.min() < -0.01 and sol.q.max() > 0.01  # it switches both ways
    np.testing.assert_allclose(sim[0].q, sol.q, atol=1e-8)
    np.testing.assert_allclose(sim[0].states[:, 2:], sol.x[:, 2:], atol=1e-8)
    np.testing.assert_allclose(model.phi(sol.q), red.phi(sol.q), atol=1e-9)


def test_validation_scores_the_analytical_model_and_phi(reference):
    red, v, sol = reference
    model = AnalyticalModel(red)
    qd = sol.x[:, 1]
    ds = DataSet("rig", "validation", T, sol.q, qd, np.gradient(qd, DT), v, "m")
    cfg = ValidateConfig(input_interpolation="linear")
    table, _ = validate_model(model, "analytical", [ds], cfg, 1.0, model.phi)
    row = table.iloc[0]
    assert row.nrmse_q < 1e-6 and row.nrmse_phi < 1e-6
    # phi is a different, nonlinear function of q: its NRMSE differs for a perturbed run
    shifted = DataSet("rig", "validation", T, sol.q + 1e-4, qd, ds.q_ddot, v, "m")
    other, _ = validate_model(model, "analytical", [shifted], cfg, 1.0, model.phi)
    assert other.iloc[0].nrmse_phi != pytest.approx(other.iloc[0].nrmse_q, rel=1e-3)


def test_analytical_needs_physics_and_de_data():
    ds = DataSet("s", "estimation", T, T, T, T, np.zeros((T.size, 2)), "V")
    with pytest.raises(WorkflowError) as err:
        analytical_for(None, [ds], ValidateConfig(analytical=True))
    assert "needs" in str(err.value) and "physics" in str(err.value)
    assert analytical_for(None, [ds], ValidateConfig()) is None
    with pytest.raises(WorkflowError) as err:
        analytical_for(P, [ds], ValidateConfig(analytical=True))
    assert "'s'" in str(err.value)
    assert "'V'" in str(err.value)
