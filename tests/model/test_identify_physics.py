"""The analytical model's curves as the RBF model's backbone (physics_* terms)."""

from dataclasses import replace

import numpy as np
import pytest

from debist.core import artifacts
from debist.core.errors import WorkflowError
from debist.identify.config import IdentifyConfig
from debist.identify.fit import Record, fit_rbf_model
from debist.identify.physics_prior import physics_prior
from debist.model.rbf import RBFModel
from debist.physics.freerun import AnalyticalModel
from debist.physics.params import PrototypeParams
from debist.physics.reduced import fit_reduced
from debist.simulate.freerun import simulate

P = PrototypeParams.paper()
PHYSICS = ["physics_spring", "physics_damping", "physics_gain"]


@pytest.fixture(scope="module")
def record():
    """Switching plus sub-threshold excitation of the reduced model (Eq. 26), exact q_ddot."""
    red = fit_reduced(P, degree=24)
    dt = 4e-3
    t = np.arange(0.0, 8.0, dt)
    rng = np.random.default_rng(3)

    def ramp(a, b):
        return np.clip((t - a) / 0.05, 0, 1) - np.clip((t - b) / 0.05, 0, 1)

    sub = 800.0 * (1 + np.sin(2 * np.pi * 1.3 * t[:, None] * [1.0, 1.7] + rng.uniform(0, 6, 2)))
    steps = np.stack([3000 * (ramp(1, 2) + ramp(6, 7)), 3000 * ramp(3.5, 4.5)], 1)
    v = np.clip(np.maximum(steps, sub), 0.0, 3000.0)
    # simulated by the shared RK4 on the tabulated Eq. 26 (checked against solve_ivp in
    # tests/physics/test_physics_freerun.py); the fit sees only separately tabulated curves
    model = AnalyticalModel(red)
    sim = simulate(model, [v], dt, np.array([-0.010206]), np.array([0.0]), substeps=4)[0]
    m_q = red.curves(sim.q).m_q
    return Record("sim", sim.q, sim.q_dot, sim.q_ddot, v, dt), m_q


def test_scales_of_the_analytical_curves_are_one_over_the_mass(record):
    rec, m_q = record
    assert rec.q.min() < -0.01 and rec.q.max() > 0.01
    cfg = IdentifyConfig.from_dict({"rbf": [], "backbone": PHYSICS, "T_z": 0, "m_q": 1.0})
    model, diag = fit_rbf_model([rec], replace(cfg, prior=physics_prior(P, [rec])))
    lo, hi = 1.0 / m_q.max(), 1.0 / m_q.min()  # the data's m_q(q) varies by 5 %
    bb = model.backbone
    for s in (bb["s_c"], *bb["s_g"]):
        assert 0.97 * lo < s < 1.03 * hi
    # the damping scale also absorbs the Maxwell creep the backbone has no term for
    assert 0.9 * lo < bb["s_d"] < 1.1 * hi
    assert diag.fit_r2 > 0.99
    # the model's curves are the scaled analytical ones
    q = np.linspace(-0.012, 0.012, 7)
    c_p, _, g_p = model.prior(q)
    np.testing.assert_allclose(model.curves(q)["c"], bb["s_c"] * c_p, rtol=1e-12)
    np.testing.assert_allclose(model.curves(q)["g"], g_p * bb["s_g"], rtol=1e-12)


def test_model_with_prior_round_trips_through_hdf5(record, tmp_path):
    rec, _ = record
    cfg = IdentifyConfig.from_dict({"M": 4, "rbf": ["c"], "backbone": PHYSICS, "T_z": 0})
    model, _ = fit_rbf_model([rec], replace(cfg, prior=physics_prior(P, [rec])))
    artifacts.write_stage(
        tmp_path / "s", stage="identify", key="k", code="c", versions={}, config={}, inputs={},
        upstream={}, outputs={"model.h5": artifacts.H5Tree(model.to_tree())}, summary={},
    )  # fmt: skip
    back = RBFModel.from_tree(artifacts.read_h5(tmp_path / "s" / "model.h5"))
    x = np.stack([rec.q[::50], rec.q_dot[::50], rec.q_dot[::50]], axis=1)
    np.testing.assert_array_equal(back.rhs(x, rec.v[::50])[0], model.rhs(x, rec.v[::50])[0])


def test_physics_terms_need_physics(record):
    rec, _ = record
    with pytest.raises(WorkflowError) as err:
        physics_prior(None, [rec])
    assert "need" in str(err.value) and "section" in str(err.value)
    cfg = IdentifyConfig.from_dict({"rbf": [], "backbone": PHYSICS, "T_z": 0})
    with pytest.raises(WorkflowError) as err:
        fit_rbf_model([rec], cfg)
    assert "add" in str(err.value) and "section" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        IdentifyConfig.from_dict({"prior": {}})
    assert err.value.key == "identify.prior"
    assert "unknown" in str(err.value)


def test_m_q_physics_is_the_analytical_mass_at_zero():
    from debist.identify.physics_prior import physics_mass
    from debist.physics.reduced import reduced_curves

    assert physics_mass(P) == pytest.approx(float(reduced_curves(P, np.array([0.0])).m_q[0]))
    assert 0.040 < physics_mass(P) < 0.041  # tip mass 40 g plus the beam's share
    with pytest.raises(WorkflowError) as err:
        physics_mass(None)
    assert "m_q = 'physics'" in str(err.value)
