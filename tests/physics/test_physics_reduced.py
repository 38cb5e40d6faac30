"""Reduced one-coordinate model (Eq. 24-26): curves, consistency with statics, full vs reduced."""

import numpy as np
import pytest

from debist.core.metrics import nrmse
from debist.physics.kinematics import pitch_angle, ritz_basis
from debist.physics.params import V_MAX, PrototypeParams
from debist.physics.reduced import (
    compare_full_reduced,
    fit_reduced,
    reduced_curves,
    switching_profile,
)
from debist.physics.statics import force_displacement

P = PrototypeParams.paper()
Q = np.linspace(-20e-3, 20e-3, 81)


@pytest.fixture(scope="module")
def model():
    return fit_reduced(P)


@pytest.fixture(scope="module")
def static():
    return force_displacement(P, Q)


def test_fit_reproduces_the_static_path(model, static):
    assert model.fit_residual < 5e-5  # [m] in q_m * [l^2, l^3, l^4, 1]
    L = ritz_basis(P.l).L
    assert model.qm(Q) @ L == pytest.approx(Q, abs=1e-15)  # q = L q_m(q) exactly
    assert model.qm(Q, 1) @ L == pytest.approx(np.ones_like(Q), abs=1e-12)
    s = ritz_basis(P.l).scale
    assert np.max(np.abs((model.qm(Q, 1) - static.dqm_dq) * s)) < 0.1  # tangent, max ~17
    assert model.phi(Q) == pytest.approx(pitch_angle(static.qm, P), abs=1e-4)


def test_curves_match_the_statics(model, static):
    c = model.curves(Q)
    assert c.f == pytest.approx(static.F, abs=2e-4)  # f(q) = F(q) at v = 0 [N]
    assert c.c * Q == pytest.approx(c.f, abs=1e-12)
    assert c.c[40] == pytest.approx(c.k[40])  # q = 0: c = df/dq
    assert c.k == pytest.approx(static.dF_dq, abs=0.1)
    assert 2 * c.g1 == pytest.approx(static.dC_dq[:, 0], rel=2e-3)  # g = 1/2 dC/dq (Eq. 33)
    assert 2 * c.g2 == pytest.approx(static.dC_dq[:, 1], rel=2e-3)
    assert pytest.approx(static.C[:, 0], rel=1e-6) == c.C1
    assert np.all(c.g1 > 0) and np.all(c.g2 < 0)
    assert np.all(c.d > 0)
    assert c.m_q == pytest.approx(c.m_q[::-1], rel=1e-6)
    assert P.m < c.m_q.min() and c.m_q.max() < 1.15 * P.m  # tip mass plus part of the beam
    dm = np.gradient(c.m_q, Q)
    assert dm[1:-1] == pytest.approx(c.dm_q[1:-1], rel=0.05, abs=5e-3)
    assert c.k_bar1 == pytest.approx(P.V_DE * P.Y_MW * c.k1, rel=1e-14)


def test_reduced_curves_function(model):
    c = reduced_curves(P, Q)
    assert c.q.shape == c.m_q.shape == c.g2.shape == Q.shape
    assert c.f == pytest.approx(model.curves(Q).f, abs=1e-6)


def test_rest_in_the_well_is_a_fixed_point(model, static):
    q_well = 10.206e-3
    xdot = model.rhs(0.0, np.array([q_well, 0.0, 0.0, 0.0]), lambda t: 0, lambda t: 0, None)
    assert abs(xdot[1]) < 1e-3  # [m/s^2]: residual of the polynomial fit only
    pushed = model.rhs(0.0, np.array([q_well, 0.0, 0.0, 0.0]), lambda t: V_MAX, lambda t: 0, None)
    assert pushed[1] > 1.0  # the left DE accelerates the beam to the right


def test_nrmse_definition():
    y = np.sin(np.linspace(0, 6, 100))
    assert nrmse(y, y, on_constant="nan") == 0.0
    assert nrmse(y, y + 0.1) == pytest.approx(0.1 / (y.max() - y.min()))
    assert np.isnan(nrmse(np.ones(3), np.zeros(3), on_constant="nan"))  # the full model at rest
    with pytest.raises(ValueError) as err:
        nrmse(np.ones(3), np.zeros(3))
    assert "constant" in str(err.value)
    v1, v2, bp = switching_profile()
    assert (v1(0.49), v1(0.5), v1(1.5), v2(2.5), v2(3.5)) == (0.0, V_MAX, 0.0, V_MAX, 0.0)
    assert bp == (0.5, 1.5, 2.5, 3.5)


@pytest.mark.slow
def test_full_and_reduced_agree_and_both_switch(model):
    cmp = compare_full_reduced(P, model=model)
    assert cmp.full.success and cmp.reduced.success
    assert cmp.nrmse_q < 0.05  # Eq. 41, full model as reference
    assert cmp.nrmse_phi < 0.06
    t = cmp.full.t
    for q in (cmp.full.q, cmp.reduced.q):
        assert q[0] < -10e-3
        assert np.all(q[(t > 2.0) & (t < 2.5)] > 5e-3)  # switched right by the left DE
        assert np.all(q[t > 4.5] < -5e-3)  # and back left by the right DE
        assert np.max(q) > 15e-3  # overshoot of the lightly damped first mode
