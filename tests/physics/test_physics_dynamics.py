"""Full dynamic model: mass and damping matrices, power balance, Jacobian, modes, switching."""

import numpy as np
import pytest
from scipy.integrate import quad

from debist.physics.dynamics import FullModel, mode_analysis, simulate, well_state
from debist.physics.energy import potential
from debist.physics.kinematics import ritz_basis, stretches, vertical_displacement
from debist.physics.params import V_MAX, PrototypeParams

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
    with pytest.raises(ValueError) as err:
        well_state(P, -1, b=29e-3)
    assert "stable" in str(err.value) and "equilibrium" in str(err.value)


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


# --- compiled kernels (debist.physics.compiled) against the NumPy reference ----------------

P_ASYM = P.replace(dz_1=0.15e-3, dz_2=-0.05e-3)


def near_well_state(params, seed):
    """A state near the left well with random velocities and creep strains."""
    rng = np.random.default_rng(seed)
    x = well_state(params, -1)
    x[:4] += rng.normal(size=4) * np.array([5e-3, 1e-2, 5e-3, 1e-5]) / S
    x[4:8] = rng.normal(size=4) * np.array([0.2, 0.5, 0.3, 1e-4]) / S
    x[8:] = rng.normal(size=2) * 0.01
    return x


def models(params, v1, v2, F=None):
    ref = FullModel(params, lambda t: v1, lambda t: v2, F=F, compiled=False)
    return ref, FullModel(params, lambda t: v1, lambda t: v2, F=F)


@pytest.mark.parametrize("params", [P, P_ASYM], ids=["paper", "asymmetric"])
def test_compiled_generated_terms_equal_the_python_ones_bit_for_bit(params):
    from debist.physics import _generated, compiled

    model = FullModel(params, lambda t: 0.0, lambda t: 0.0)
    for seed in range(5):
        x = near_well_state(params, seed) if seed % 2 else random_state(seed)
        args = (*x[:4].tolist(), model.b, 2.1e6, 4e5, *model._consts)
        assert compiled.grad_terms(*args) == _generated.grad_terms(*args)
        assert compiled.hess_terms(*args) == _generated.hess_terms(*args)


@pytest.mark.parametrize("params", [P, P_ASYM], ids=["paper", "asymmetric"])
def test_compiled_rhs_and_jacobian_equal_the_numpy_reference(params):
    """Every entry to 1e-12 relative except the accelerations, which come out of a solve with
    the mass matrix (condition number about 2e6 in coordinates scaled to metres): there the
    compiled rows solve the reference's equations to 1e-12 (componentwise backward error,
    Oettli & Prager 1964), and agree with the reference's rows to 1e-6."""
    ref, fast = models(params, 1500.0, 700.0, F=lambda t: 0.01)
    for seed in range(20):
        x = near_well_state(params, 100 + seed) if seed % 2 else random_state(100 + seed)
        a, b = ref.rhs(0.1, x), fast.rhs(0.1, x)
        force, M, _, K, _, _ = ref._force(0.1, x)
        assert np.array_equal(b[:4], x[4:8])
        creep_scale = np.abs(K.T) @ np.abs(x[4:8]) + ref._relax * np.abs(x[8:])
        assert np.all(np.abs(b[8:] - a[8:]) <= 1e-12 * creep_scale)
        acc = b[4:8]
        assert np.all(np.abs(M @ acc - force) <= 1e-12 * (np.abs(M) @ np.abs(acc) + np.abs(force)))
        assert acc == pytest.approx(a[4:8], rel=1e-6)

        Ja, Jb = ref.jac(0.1, x), fast.jac(0.1, x)
        rows = np.r_[0:4, 8:10]
        assert Jb[rows] == pytest.approx(Ja[rows], rel=1e-12, abs=0.0)
        dJ = M @ (Jb[4:8] - Ja[4:8])
        assert np.all(np.abs(dJ) <= 1e-12 * (np.abs(M) @ np.abs(Ja[4:8])))
        assert Jb[4:8] == pytest.approx(Ja[4:8], rel=1e-6, abs=1e-6 * np.abs(Ja[4:8]).max())


def test_compiled_model_follows_the_inputs_and_the_extra_force():
    ref, fast = models(P_ASYM, 2400.0, 0.0, F=lambda t: -0.02)
    x = near_well_state(P_ASYM, 7)
    for F_extra in (0.0, 0.05):
        a, b = ref.rhs(0.3, x, F_extra=F_extra), fast.rhs(0.3, x, F_extra=F_extra)
        assert b == pytest.approx(a, rel=1e-6)
    # the extra force moves the accelerations by M^-1 L F_extra
    dF = fast.rhs(0.3, x, F_extra=0.05) - fast.rhs(0.3, x)
    L = ritz_basis(P.l).L
    assert dF[4:8] == pytest.approx(np.linalg.solve(fast.mass_matrix(x[:4]), L) * 0.05, rel=1e-6)
    assert np.array_equal(dF[[0, 1, 2, 3, 8, 9]], np.zeros(6))


def test_compiled_kernels_are_cached_under_the_hash_of_the_generated_code():
    """numba's disk cache sees changes of the kernels' own file only; the kernels close over
    the sha256 of the generated code, which numba hashes into the cache index key."""
    import hashlib
    import inspect
    from pathlib import Path

    from debist.physics import _generated, compiled

    digest = hashlib.sha256(Path(inspect.getfile(_generated)).read_bytes()).hexdigest()
    assert digest == compiled.STAMP
    for kernel in (compiled.full_rhs, compiled.full_jac):
        cells = [c.cell_contents for c in kernel.py_func.__closure__]
        assert cells == [digest]
