"""Full dynamic model: mass and damping matrices, power balance, Jacobian, modes, switching."""

import numpy as np
import pytest
from scipy.integrate import quad

from pipeline.physics.dynamics import FullModel, mode_analysis, simulate, well_state
from pipeline.physics.energy import potential
from pipeline.physics.kinematics import ritz_basis, stretches, vertical_displacement
from pipeline.physics.params import V_MAX, PrototypeParams

P = PrototypeParams.paper()
S = ritz_basis(P.l).scale
S10 = np.concatenate([S, S, [1.0, 1.0]])


def random_state(seed):
    rng = np.random.default_rng(seed)
    qm = rng.normal(size=4) * np.array([0.02, 0.05, 0.03, 2e-5]) / S
    qd = rng.normal(size=4) * np.array([0.2, 0.5, 0.3, 1e-4]) / S
    qe = rng.normal(size=2) * 0.01
    return np.concatenate([qm, qd, qe])


def test_mass_matrix_is_the_kinetic_energy_of_eq_8():
    x = random_state(1)
    qm, qd = x[:4], x[4:8]
    M = FullModel(P, lambda t: 0.0, lambda t: 0.0).matrices(qm)["M"]
    h = 1e-6
    uy_dot = (vertical_displacement(qm + h * qd, P) - vertical_displacement(qm - h * qd, P)) / (
        2 * h
    )
    q_dot = qd @ ritz_basis(P.l).L
    wd = lambda s: qd[0] * s**2 + qd[1] * s**3 + qd[2] * s**4  # noqa: E731
    wd1 = lambda s: 2 * qd[0] * s + 3 * qd[1] * s**2 + 4 * qd[2] * s**3  # noqa: E731
    beam = quad(lambda s: 0.5 * P.rho * (P.I * wd1(s) ** 2 + P.A * wd(s) ** 2), 0, P.l)[0]
    T = 0.5 * P.m * (q_dot**2 + uy_dot**2) + beam
    assert 0.5 * qd @ M @ qd == pytest.approx(T, rel=1e-9)
    assert np.all(np.linalg.eigvalsh(M / np.outer(S, S)) > 0)


def test_beam_damping_is_the_dissipation_of_eq_12():
    x = random_state(2)
    qd = x[4:8]
    mats = FullModel(P.replace(eta_v=0.0), lambda t: 0.0, lambda t: 0.0).matrices(x[:4])
    wdd = lambda s: 2 * qd[0] + 6 * qd[1] * s + 12 * qd[2] * s**2  # noqa: E731
    dissipation = quad(lambda s: 2 * P.eta * P.I * wdd(s) ** 2, 0, P.l)[0]
    assert qd @ mats["D"] @ qd == pytest.approx(dissipation, rel=1e-10)


def test_creep_matrix_is_the_thickness_stretch_gradient():
    qm = random_state(3)[:4]
    mats = FullModel(P, lambda t: 0.0, lambda t: 0.0).matrices(qm)
    for k in range(4):
        h = 1e-6 / S[k]
        e = np.zeros(4)
        e[k] = h
        lam3 = lambda y: stretches(y, P) ** -0.5  # noqa: E731
        fd = (lam3(qm + e) - lam3(qm - e)) / (2 * h)
        assert fd * S[k] == pytest.approx(mats["K"][k] * S[k], rel=1e-6, abs=1e-10)
    assert mats["K_bar"] == pytest.approx(P.V_DE * P.Y_MW * mats["K"], rel=1e-14)


@pytest.mark.parametrize("seed", [4, 5])
def test_power_balance(seed):
    """d/dt (T + U) = -q_dot D q_dot - q_dot K_bar q_eps + F dq/dt (Lagrange with M(q_m))."""
    x = random_state(seed)
    qm, qd, qe = x[:4], x[4:8], x[8:]
    model = FullModel(P, lambda t: 2e3, lambda t: 1e3, F=lambda t: 0.03)
    xdot = model.rhs(0.0, x)
    mats = model.matrices(qm)
    h = 1e-7
    M_dot = (model.matrices(qm + h * qd)["M"] - model.matrices(qm - h * qd)["M"]) / (2 * h)
    grad = potential(qm, P, v1=2e3, v2=1e3).grad
    dE = qd @ mats["M"] @ xdot[4:8] + 0.5 * qd @ M_dot @ qd + grad @ qd
    expected = -qd @ mats["D"] @ qd - qd @ mats["K_bar"] @ qe + 0.03 * (qd @ ritz_basis(P.l).L)
    assert dE == pytest.approx(expected, rel=1e-6)
    assert xdot[8:] == pytest.approx(mats["K"].T @ qd - P.Y_MW / P.eta_MW * qe, rel=1e-12)


def test_rest_state_is_a_fixed_point_and_jacobian_is_exact_there():
    x0 = well_state(P, +1)
    model = FullModel(P, lambda t: 0.0, lambda t: 0.0)
    assert np.max(np.abs(model.rhs(0.0, x0)[4:8] * S)) < 1e-5  # [m/s^2], Newton tolerance
    J = model.jac(0.0, x0)
    for k in range(10):
        h = 1e-7 / S10[k]
        e = np.zeros(10)
        e[k] = h
        fd = (model.rhs(0.0, x0 + e) - model.rhs(0.0, x0 - e)) / (2 * h)
        col = J[:, k] * S10 * (1 / S10[k])
        assert np.max(np.abs(fd * S10 / S10[k] - col)) <= 1e-5 * max(np.max(np.abs(col)), 1.0)
    eig = np.linalg.eigvals(J)
    assert np.all(eig.real < 0)  # the well is asymptotically stable
    first = eig[np.argmin(np.abs(eig - 17.9j))]  # lightly damped first mode, ~2.85 Hz
    assert abs(first.imag) == pytest.approx(17.9, abs=0.2) and -first.real < 0.1 * first.imag


def test_well_state_sides():
    left, right = well_state(P, -1), well_state(P, +1)
    L = ritz_basis(P.l).L
    assert left[:4] @ L == pytest.approx(-(right[:4] @ L), rel=1e-9)
    assert left[:4] @ L < -10e-3
    with pytest.raises(ValueError, match="no stable equilibrium"):
        well_state(P, -1, b=29e-3)


def test_modes_exact_for_a_single_shape():
    rng = np.random.default_rng(9)
    shape = np.array([0.3, -1.0, 2.0, 0.0])
    qm = np.outer(np.sin(np.linspace(0, 7, 200)) + 0.1 * rng.normal(size=200), shape)
    m = mode_analysis(qm, P)
    assert m.energy_fraction[0] == pytest.approx(1.0, abs=1e-12)
    w = m.modes[:, 0] * m.coefficients[:, 0][:, None]
    x = m.x
    direct = qm[:, :1] * x**2 + qm[:, 1:2] * x**3 + qm[:, 2:3] * x**4
    assert w == pytest.approx(direct, abs=1e-12)


@pytest.mark.slow
def test_switching_and_first_mode_dominance():
    x0 = well_state(P, -1)
    v1 = lambda t: V_MAX if 0.05 <= t < 1.05 else 0.0  # noqa: E731
    res = simulate(P, v1, lambda t: 0.0, (0.0, 1.6), x0, breakpoints=(0.05, 1.05))
    assert res.success
    assert res.q[0] < -10e-3 and res.q[-1] > 5e-3  # switched to the right well and stays
    assert np.max(res.q) > 15e-3  # overshoot, lightly damped first mode
    m = mode_analysis(res.qm, P)
    assert m.energy_fraction[0] > 0.95 and m.energy_fraction[2] < 1e-3
    assert res.phi == pytest.approx(np.arctan(res.qm @ ritz_basis(P.l).S), rel=1e-14)
