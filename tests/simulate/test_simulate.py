import numpy as np
import pytest

from debist.core.metrics import nrmse, rms
from debist.simulate import warmup
from debist.simulate.freerun import simulate, upsample_inputs
from debist.validate.freerun import initial_state


def oscillator(k1=(2 * np.pi * 3.0) ** 2, dv=2.0, T_z=0.0):
    """q'' + dv z + k1 q = v: a linear oscillator as an RBFModel with backbone only."""
    return warmup.oscillator(k1, dv, T_z)


def analytic_forced(t, k1, dv, omega):
    """Exact response of q'' + dv q' + k1 q = sin(omega t) from q(0) = q'(0) = 0."""
    from scipy.integrate import solve_ivp

    sol = solve_ivp(
        lambda tt, x: [x[1], np.sin(omega * tt) - dv * x[1] - k1 * x[0]],
        (t[0], t[-1]),
        [0.0, 0.0],
        t_eval=t,
        rtol=1e-12,
        atol=1e-14,
        method="DOP853",
    )
    return sol.y[0]


def test_rk4_matches_exact_linear_response_with_bandlimited_input():
    model = oscillator()
    dt = 0.01
    t = np.arange(0, 4.0, dt)
    omega = 2 * np.pi * 5.0
    v = np.sin(omega * t)[:, None]
    (res,) = simulate(model, [v], dt, np.array([0.0]), np.array([0.0]), substeps=2)
    exact = analytic_forced(t, model.backbone["k_1"], 2.0, omega)
    assert np.max(np.abs(res.q - exact)) < 2.5e-3 * np.max(np.abs(exact))
    # a linear (not band-limited) interpolation of the same input is worse
    (lin,) = simulate(
        model, [v], dt, np.array([0.0]), np.array([0.0]), substeps=2, interpolation="linear"
    )
    assert np.max(np.abs(lin.q - exact)) > np.max(np.abs(res.q - exact))
    # the reported acceleration is the model's q'' along the trajectory
    want = v[:, 0] - 2.0 * res.q_dot - model.backbone["k_1"] * res.q
    assert np.max(np.abs(res.q_ddot - want)) < 1e-3


def test_batch_equals_single_runs_and_shorter_records_are_cut():
    model = oscillator()
    dt = 0.01
    rng = np.random.default_rng(5)
    a, b = rng.standard_normal((300, 1)), rng.standard_normal((200, 1))
    both = simulate(model, [a, b], dt, np.zeros(2), np.zeros(2))
    (only_b,) = simulate(model, [b], dt, np.zeros(1), np.zeros(1))
    assert both[1].q.shape == (200,)
    assert np.allclose(both[1].q, only_b.q, atol=1e-12)


def test_divergence_is_reported_not_a_number():
    model = oscillator(k1=-50.0, dv=0.0)  # unstable
    v = np.zeros((500, 1))
    (res,) = simulate(model, [v], 0.01, np.array([0.01]), np.array([0.0]), q_limit=1.0)
    assert res.diverged and 0 < res.diverged_at < 500
    assert np.isnan(res.q[res.diverged_at :]).all()
    assert np.isnan(nrmse(np.linspace(0, 1, 500), res.q))


def test_friction_filter_forces_substeps():
    model = oscillator(T_z=0.001)
    (res,) = simulate(model, [np.zeros((10, 1))], 0.01, np.zeros(1), np.zeros(1), substeps=1)
    assert res.substeps >= int(np.ceil(0.01 / (1.5 * 0.001)))


def test_upsampling_is_exact_on_samples_and_bandlimited_between():
    t = np.arange(400)
    v = np.sin(2 * np.pi * 0.05 * t)[:, None]
    fine = upsample_inputs(v, 4, "bandlimited")
    assert fine.shape == (399 * 4 + 1, 1)
    assert np.max(np.abs(fine[::4, 0] - v[:, 0])) < 1e-3
    between = fine[2::4, 0]
    err = np.abs(between - np.sin(2 * np.pi * 0.05 * (np.arange(399) + 0.5)))
    assert err.max() < 2e-3  # the odd-reflected ends
    assert err[10:-10].max() < 1e-4


def test_nrmse_and_rms_properties():
    rng = np.random.default_rng(0)
    y = rng.standard_normal(100)
    assert nrmse(y, y) == 0.0
    assert nrmse(3 * y, 3 * y + 3 * 0.1) == pytest.approx(nrmse(y, y + 0.1))
    assert rms(np.full(10, -2.0)) == 2.0
    with pytest.raises(ValueError) as err:
        nrmse(np.ones(5), np.ones(5))
    assert "constant" in str(err.value)


def test_initial_state_from_first_samples_of_a_cubic():
    dt = 0.01
    t = np.arange(50) * dt
    q = 0.1 + 2.0 * t - 3.0 * t**2 + 5.0 * t**3
    q0, qd0 = initial_state(q, dt, 16)
    assert q0 == pytest.approx(0.1, abs=1e-12) and qd0 == pytest.approx(2.0, abs=1e-9)
