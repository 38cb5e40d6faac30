"""The DEs' creep of Eq. 26 in the analytical model's own form: backbone ``physics_creep``.

The force ``s_k,i k_bar k_i(q) q_eps,i`` with the creep strains
``q_eps,i' = k_i(q) q_dot - lambda q_eps,i`` (``k_i``, ``k_bar`` and ``lambda = Y_MW / eta_MW``
from ``[physics]``) is linear in the scales ``s_k,i``. Checked here: the acceleration against
the balance written out, the fit against noise-free data of a model with that creep, the
model file, the prior built from ``[physics]``, and the configuration.
"""

from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from debist.identify.config import IdentifyConfig
from debist.identify.fit import Record, fit_rbf_model
from debist.model.rbf import RBFModel
from debist.model.terms import PhysicsPrior
from tests.conftest import INSIDE_CLASS, excitation, truth_model, with_physics_creep
from tests.model.conftest import curve_error

RATE = 3.7  # [1/s] lambda (the defaults of conftest.with_physics_creep)
K_BAR = 0.02  # [N m]
S_K = np.array([0.8, 1.3])


def creep_prior() -> PhysicsPrior:
    """The prior of :func:`with_physics_creep` on a model without one."""
    return with_physics_creep(truth_model(np.random.default_rng(2))).prior


def test_the_acceleration_has_the_creep_force_of_eq_26():
    """q'' of the model with strains eps minus q'' at eps = 0 is -s_k k_bar k(q) eps / m_q."""
    model = with_physics_creep(truth_model(np.random.default_rng(2)))
    assert model.has_physics_creep and not model.has_creep and model.n_states == 5
    rng = np.random.default_rng(4)
    q = rng.uniform(-0.012, 0.012, 30)
    q_dot = rng.uniform(-0.3, 0.3, 30)
    v = rng.uniform(0.0, 2500.0, (30, 2))
    eps = rng.normal(0.0, 0.05, (30, 2))
    k = np.stack([-40.0 - 2e3 * q, 40.0 - 2e3 * q], axis=1)
    want = -(S_K * K_BAR * k * eps).sum(axis=1) / model.m_q
    got = model.accel(q, q_dot, v, eps) - model.accel(q, q_dot, v, np.zeros_like(eps))
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-14)
    # the strains' rate: k_i(q) q_dot - lambda eps_i (the state after q, q_dot, z)
    x = np.column_stack([q, q_dot, q_dot, eps])
    dx, _ = model.table_model().rhs(x, v)
    np.testing.assert_allclose(dx[:, 3:], k * q_dot[:, None] - RATE * eps, rtol=1e-12)


def _record(truth: RBFModel, n=6000, dt=0.002) -> Record:
    """Noise-free data of the model with its creep strains (solve_ivp DOP853), exact q''."""
    t = np.arange(n) * dt
    prior = truth.prior

    def rhs(tt, x):
        v = excitation(np.array([tt]))
        q, q_dot, eps = x[:1], x[1:2], x[None, 2:]
        k = np.array([np.interp(x[0], prior.q, col) for col in prior.k.T])
        return [x[1], truth.accel(q, q_dot, v, eps, q_dot)[0], *(k * x[1] - RATE * x[2:])]

    sol = solve_ivp(rhs, (t[0], t[-1]), [-0.01, 0.0, 0.0, 0.0], t_eval=t, method="DOP853",
                    rtol=1e-11, atol=1e-14)  # fmt: skip
    q, q_dot, eps = sol.y[0], sol.y[1], sol.y[2:].T
    v = excitation(t)
    return Record("sim", q, q_dot, truth.accel(q, q_dot, v, eps, q_dot), v, dt)


def test_the_fit_recovers_the_creep_scales_and_the_curves_it_would_bias():
    """With the term the scales come back to 1e-4 and the curves to 1e-3 of their scale
    (measured 3.5e-5 and 3.8e-5: the fit filters the strains from the sampled q_dot by the
    first-order hold, the data have the continuous ones); without it, the same data bias the
    curves by more than 5 %."""
    truth = with_physics_creep(truth_model(np.random.default_rng(2)))
    record = _record(truth)
    base = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0}
    with_term = {**base, "backbone": [*INSIDE_CLASS["backbone"], "physics_creep"]}
    cfg = replace(IdentifyConfig.from_dict(with_term), prior=truth.prior)
    model, diag = fit_rbf_model([record], cfg)
    assert diag.columns.count("physics_creep1") == 1 and "physics_creep2" in diag.columns
    np.testing.assert_allclose(model.backbone["s_k"], S_K, rtol=1e-4)
    assert model.creep_rate == RATE and model.n_states == 5
    assert curve_error(model, truth) < 1e-3
    without, _ = fit_rbf_model([record], IdentifyConfig.from_dict(base))
    assert curve_error(without, truth) > 0.05


def test_the_model_file_keeps_the_creep_and_a_prior_without_it_keeps_its_bytes():
    truth = truth_model(np.random.default_rng(2))
    model = with_physics_creep(truth)
    back = RBFModel.from_tree(model.to_tree())
    np.testing.assert_array_equal(back.backbone["s_k"], S_K)
    np.testing.assert_array_equal(back.prior.k, model.prior.k)
    assert back.prior.k_bar == K_BAR and back.creep_rate == RATE and back.has_physics_creep
    names, values = back.parameters()
    np.testing.assert_array_equal(values[[names.index("physics_creep1"),
                                          names.index("physics_creep2")]], S_K)  # fmt: skip
    plain = replace(creep_prior(), k=None)
    assert "k" not in plain.to_tree() and PhysicsPrior.from_tree(plain.to_tree()).k is None


def test_the_prior_from_physics_has_the_reduced_models_creep():
    """k_i(q) of the analytical reduced model, k_bar = V_DE Y_MW, lambda = Y_MW / eta_MW."""
    from debist.identify.physics_prior import physics_prior
    from debist.physics.params import PrototypeParams
    from debist.physics.reduced import reduced_curves

    physics = PrototypeParams()
    record = Record("r", np.linspace(-0.01, 0.01, 50), np.zeros(50), np.zeros(50),
                    np.ones((50, 2)), 0.01)  # fmt: skip
    prior = physics_prior(physics, [record], n_grid=201)
    cur = reduced_curves(physics, prior.q)
    np.testing.assert_array_equal(prior.k, np.stack([cur.k1, cur.k2], axis=1))
    assert prior.k_bar == pytest.approx(physics.V_DE * physics.Y_MW, rel=1e-15)
    assert prior.creep_rate == pytest.approx(physics.Y_MW / physics.eta_MW, rel=1e-15)
    assert np.all(prior.k[:, 0] < 0) and np.all(prior.k[:, 1] > 0)  # DE 1 stretches as q falls


def test_one_creep_rate_per_model():
    with pytest.raises(Exception) as err:
        IdentifyConfig.from_dict({"creep": 3.7, "backbone": ["physics_creep"]})
    assert "both" in str(err.value)
    with pytest.raises(Exception) as err:
        replace(creep_prior(), creep_rate=0.0).creep()
    assert "Y_MW" in str(err.value)
    assert "> 0" in str(err.value)
    assert "eta_MW" in str(err.value)


def test_a_model_without_the_creep_term_keeps_no_creep_curves():
    """Another ``physics_*`` term takes the prior, not its creep curves: the model file of
    such a model is what it was before the creep term existed."""
    truth = truth_model(np.random.default_rng(2))
    record = _record(with_physics_creep(truth, s_k=(0.0, 0.0)))
    spring = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0,
              "backbone": [*INSIDE_CLASS["backbone"], "physics_spring"]}  # fmt: skip
    prior = creep_prior()
    prior = replace(prior, c=-30.0 + 3e5 * prior.q**2)  # a curve for physics_spring
    cfg = replace(IdentifyConfig.from_dict(spring), prior=prior)
    model, _ = fit_rbf_model([record], cfg)
    assert model.prior is not None and model.prior.k is None and not model.has_physics_creep
    assert "k" not in model.to_tree()["model"]["backbone"]["prior"]
