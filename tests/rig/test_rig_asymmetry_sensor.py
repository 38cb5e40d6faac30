"""The rig's DE gains, tip force offset and logger: block averaging, laser lag, zero offset."""

import math

import numpy as np
import pytest

from debist.core.errors import WorkflowError
from debist.physics.dynamics import well_state
from debist.physics.kinematics import ritz_basis
from debist.physics.statics import equilibria
from debist.rig.drivers import DriverOutput
from debist.rig.params import RigParams
from debist.rig.plant import RigPlant
from debist.rig.reduced import ReducedPlant
from debist.rig.run import _laser_lag, _trailing_mean, simulate_rig, true_curves

FULL = RigParams()
REDUCED = RigParams(model="reduced")


def state(rig, seed):
    """A full-plant state near the left well with random velocities and friction loads."""
    rng = np.random.default_rng(seed)
    x = np.concatenate([well_state(rig.prototype, -1), rng.normal(size=rig.n_friction) * 50e-6])
    x[4:8] = rng.normal(size=4) * 0.02 / ritz_basis(rig.prototype.l).scale
    x[8:10] = rng.normal(size=2) * 1e-3
    return x


@pytest.mark.parametrize("compiled", [False, True])
def test_a_de_gain_scales_that_des_force_on_the_full_plant(compiled):
    """The DE force goes with gain v^2: the acceleration's voltage part scales by the gain."""
    x = state(FULL, 1)
    gain = 1.13
    base = RigPlant(FULL, lambda t: 0.0, lambda t: 0.0, compiled=compiled).rhs(0.0, x)
    one = RigPlant(FULL, lambda t: 1500.0, lambda t: 0.0, compiled=compiled).rhs(0.0, x)
    rig = FULL.replace(gain_1=gain, gain_2=0.5)
    scaled = RigPlant(rig, lambda t: 1500.0, lambda t: 0.0, compiled=compiled).rhs(0.0, x)
    # equal to a voltage sqrt(gain) times higher on the prototype
    root = RigPlant(FULL, lambda t: 1500.0 * math.sqrt(gain), lambda t: 0.0, compiled=compiled)
    assert scaled == pytest.approx(root.rhs(0.0, x), rel=1e-10, abs=1e-12)
    assert not np.allclose(scaled[4:8], one[4:8], rtol=1e-3)
    assert np.allclose(scaled[:4], base[:4])


def test_the_compiled_plant_carries_the_gains_and_the_tip_force_like_the_reference():
    rig = FULL.replace(gain_1=0.9, gain_2=1.12, force_offset=1.5e-3)
    t = np.arange(300) * 1e-3
    r = np.repeat(np.random.default_rng(2).uniform(0, 3000, (2, 30)), 10, axis=1)
    d = [DriverOutput(t, r[i], tau=5e-3, slew=1e5) for i in range(2)]
    ref, fast = RigPlant(rig, *d, compiled=False), RigPlant(rig, *d)
    for seed in range(5):
        x = state(rig, 10 + seed)
        a, b = ref.rhs(0.05 + 0.04 * seed, x), fast.rhs(0.05 + 0.04 * seed, x)
        assert b == pytest.approx(a, rel=1e-6, abs=1e-9)


def test_the_tip_force_moves_the_rest_states_and_the_true_restoring_force():
    F0 = 1.5e-3
    rig = FULL.replace(force_offset=F0)
    plant = RigPlant(rig, lambda t: 0.0, lambda t: 0.0)
    for side in (-1, 1):
        x = plant.rest_state(side)
        tip_acc = ritz_basis(rig.prototype.l).L @ plant.rhs(0.0, x)[4:8]
        assert abs(tip_acc) < 1e-8  # at rest under F0 [m/s^2]
        q = float(plant.tip(x))
        right = [e.q for e in equilibria(rig.prototype, F=F0) if e.stable and side * e.q > 0]
        assert q == pytest.approx(max(right, key=abs), abs=1e-9)
    grid = np.linspace(-12e-3, 12e-3, 25)
    c0, c = true_curves(FULL, grid), true_curves(rig, grid)
    assert c["f"] == pytest.approx(c0["f"] - F0, abs=1e-15)
    assert c["k"] == pytest.approx(c0["k"])


def test_reduced_plant_gains_tip_force_and_rest_state_are_exact():
    rig = REDUCED.replace(gain_1=1.1, gain_2=0.88, force_offset=-1e-3)
    plant = ReducedPlant(rig, lambda t: 900.0, lambda t: 400.0)
    x = plant.rest_state(-1)
    m, _, _, f, g1, g2, *_ = plant.curves(float(x[0])).tolist()
    assert f == pytest.approx(-1e-3, abs=1e-12)  # f(q_rest) = F0
    expected = (1.1 * g1 * 900.0**2 + 0.88 * g2 * 400.0**2) / m
    assert plant.rhs(0.0, x)[1] == pytest.approx(expected, rel=1e-12)
    grid = np.linspace(-12e-3, 12e-3, 13)
    c0, c = true_curves(REDUCED, grid), true_curves(rig, grid)
    assert c["g1"] == pytest.approx(1.1 * c0["g1"]) and c["g2"] == pytest.approx(0.88 * c0["g2"])
    assert c["f"] == pytest.approx(c0["f"] + 1e-3)


def test_trailing_mean_delays_a_ramp_by_half_the_window():
    y = np.arange(50, dtype=float)
    for n in (1, 4, 10):
        out = _trailing_mean(y, n)
        assert np.all(np.isnan(out[: n - 1]))
        assert out[n - 1 :] == pytest.approx(y[n - 1 :] - (n - 1) / 2)


def test_laser_lag_is_the_exact_first_order_step_response():
    dt, tau = 1e-4, 2e-3
    y = np.concatenate([np.zeros(10), np.ones(200)])
    out = _laser_lag(y, tau, dt)
    k = np.arange(1, 201)
    assert out[:10] == pytest.approx(0.0, abs=1e-15)
    assert out[10:] == pytest.approx(1.0 - np.exp(-k * dt / tau), rel=1e-12)
    assert _laser_lag(y, 0.0, dt) is y


def test_point_sampled_log_is_the_truth_plus_the_zero_offset():
    rig = REDUCED.replace(sensor_noise=0.0, sensor_resolution=0.0, sensor_average=1,
                          sensor_offset=0.4e-3, monitor_noise=0.0)  # fmt: skip
    t = np.arange(2000) * 1e-3
    r = np.zeros((2, t.size))
    r[0, 200:800] = 3000.0
    run = simulate_rig(rig, t, r[0], r[1], sample_time=0.01, seed=0)
    assert run.q == pytest.approx(run.q_true + 0.4e-3, abs=1e-15)
    assert run.v1 == pytest.approx(run.v1_applied, abs=1e-9)  # point-sampled monitors


def test_block_average_lags_the_switching_motion_by_its_group_delay():
    """N-sample block average on the 1 ms grid: the logged q is the truth (N - 1)/2 ms late."""
    base = REDUCED.replace(sensor_noise=0.0, sensor_resolution=0.0, oversample=1)
    t = np.arange(2000) * 1e-3
    r = np.zeros((2, t.size))
    r[0, 200:800] = 3000.0
    point = simulate_rig(base.replace(sensor_average=1), t, r[0], r[1], sample_time=0.001, seed=0)
    block = simulate_rig(base.replace(sensor_average=10), t, r[0], r[1], sample_time=0.001, seed=0)
    moving = (np.abs(np.gradient(point.q_true, 1e-3)) > 0.02)[20:]
    delayed = np.interp(point.t - 4.5e-3, point.t, point.q_true)
    err = np.abs(block.q - delayed)[20:][moving]
    assert np.median(err) < 0.02 * np.median(np.abs(block.q - point.q_true)[20:][moving])


def test_sensor_average_is_bounded_and_validated():
    with pytest.raises(WorkflowError) as err:
        RigParams.from_dict({"sensor_average": 200, "oversample": 10})
    assert err.value.key.endswith(".sensor_average")
    with pytest.raises(WorkflowError) as err:
        RigParams.from_dict({"gain_1": 0.0})
    assert err.value.key.endswith(".gain_1")
