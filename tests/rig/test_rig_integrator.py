"""Segmented integration with LSODA (scipy.integrate.odeint): accuracy, statistics, failures."""

import numpy as np
import pytest

from debist.physics import segments
from debist.physics.segments import solve_segments
from debist.rig.params import RigParams
from debist.rig.run import simulate_rig


def step_input(t):
    """u(t) = 1 on [0.5, 1.5), 0 elsewhere: breakpoints 0.5 and 1.5."""
    return 1.0 if 0.5 <= t < 1.5 else 0.0


def rhs(t, x, k):
    """Stiff linear system with a step input: x0' = -k (x0 - u), x1' = x0."""
    return np.array([-k * (x[0] - step_input(t)), x[0]])


def jac(t, x, k):
    return np.array([[-k, 0.0], [1.0, 0.0]])


def exact(t, k):
    """Closed-form solution from x(0) = [0, 0]."""
    t = np.asarray(t, dtype=float)

    def rise(s):  # response to a unit step at s = 0, per component
        s = np.maximum(s, 0.0)
        return 1.0 - np.exp(-k * s), s - (1.0 - np.exp(-k * s)) / k

    a0, a1 = rise(t - 0.5)
    b0, b1 = rise(t - 1.5)
    return np.stack([a0 - b0, a1 - b1], axis=1)


@pytest.mark.parametrize("method", ["odeint", "Radau"])
def test_both_paths_integrate_a_stiff_step_response_to_the_tolerance(method):
    k = 1e4
    t = np.linspace(0.0, 2.0, 201)
    sol = solve_segments(
        rhs, (0.0, 2.0), [0.0, 0.0], t, [0.5, 1.5], method=method, jac=jac, args=(k,),
        rtol=1e-8, atol=[1e-10, 1e-10],
    )  # fmt: skip
    assert sol.success
    np.testing.assert_array_equal(sol.t, t)
    assert np.max(np.abs(sol.y - exact(t, k))) < 1e-6
    assert sol.nfev > 0 and sol.njev > 0  # the analytic Jacobian is used
    if method == "odeint":
        assert sol.message == "Integration successful."


def test_odeint_never_steps_beyond_a_breakpoint():
    seen = []

    def f(t, x):
        seen.append(t)
        return rhs(t, x, 1e3)

    t = np.linspace(0.0, 2.0, 11)  # output times far apart: LSODA would overshoot them
    sol = solve_segments(f, (0.0, 2.0), [0.0, 0.0], t, [0.5, 1.5], method="odeint", rtol=1e-8)
    assert sol.success
    seen = np.array(seen)
    # the calls of the first segment end before the last call below 0.5
    first = seen[: np.flatnonzero(seen < 0.5)[-1]]
    second = seen[: np.flatnonzero(seen < 1.5)[-1]]
    assert np.max(first) <= 0.5 + 1e-12 and np.max(second) <= 1.5 + 1e-12
    assert np.max(np.abs(sol.y - exact(t, 1e3))) < 1e-6


def test_odeint_failure_keeps_the_reached_prefix_and_reports_it():
    t = np.linspace(0.0, 2.0, 201)
    sol = solve_segments(
        rhs, (0.0, 2.0), [0.0, 0.0], t, [0.5, 1.5], method="odeint", jac=jac, args=(1e4,),
        rtol=1e-8, mxstep=20,  # too few steps for the transient after the step at 0.5
    )  # fmt: skip
    assert not sol.success
    assert "Excess" in sol.message
    assert 50 <= sol.t.size < 60  # up to the step at 0.5, then a few outputs
    np.testing.assert_array_equal(sol.t, t[: sol.t.size])
    assert np.all(np.isfinite(sol.y))
    assert np.max(np.abs(sol.y - exact(sol.t, 1e4))) < 1e-6  # only reached rows
    assert sol.nfev > 0


def test_rig_failure_leaves_nan_beyond_it(monkeypatch):
    """A failing integration: NaN rows from the failure on, success False, the message."""
    monkeypatch.setattr(segments, "ODEINT_MXSTEP", 3)
    t = np.arange(500) * 1e-3
    r = np.where((t >= 0.1) & (t < 0.3), 3000.0, 0.0)
    run = simulate_rig(RigParams(), t, r, np.zeros_like(t), sample_time=0.01, seed=0)
    assert not run.success and "Excess" in run.message
    bad = np.flatnonzero(np.isnan(run.q_true))
    assert bad.size and np.all(np.isnan(run.q_true[bad[0] :]))
    assert bad[0] > 0 and np.all(np.isfinite(run.q_true[: bad[0]]))
    assert run.nfev > 0


def test_methods_agree_on_a_switching_pulse():
    """LSODA (default) and Radau, both at their default tolerances, on one 3 kV switch."""
    t = np.arange(800) * 1e-3
    r = np.where((t >= 0.1) & (t < 0.4), 3000.0, 0.0)
    a = simulate_rig(RigParams(), t, r, np.zeros_like(t), sample_time=0.01, seed=0)
    b = simulate_rig(RigParams(), t, r, np.zeros_like(t), sample_time=0.01, seed=0, method="Radau")
    assert a.success and b.success
    assert np.max(a.q_true) > 10e-3  # it switched
    assert np.max(np.abs(a.q_true - b.q_true)) < 0.5e-6
