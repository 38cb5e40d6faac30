"""Stability and design numbers of identified and analytical models (debist.identify.stability).

The identified models here have known curves: the cubic double well f(q) = k1 q + k3 q^3 with
k1 < 0 (wells at +-sqrt(-k1/k3), stiffness -2 k1 there, barrier k1^2 / (4 k3), local maximum
f_max = 2 (-k1/3)^(3/2) / sqrt(k3) at -sqrt(-k1/(3 k3))), constant damping and constant input
gains of opposite sign, either as backbone terms (exact) or as RBF weights fitted by least
squares.
"""

import numpy as np
import pytest

from debist.core.errors import DebistError
from debist.identify.stability import (
    StabilityError,
    equilibria,
    model_is_stable,
    small_signal,
    stability_table,
    switching_voltages,
    verdict,
)
from debist.model.basis import RBFBasis
from debist.model.rbf import RBFModel
from debist.model.terms import PhysicsPrior
from tests.conftest import F_MAX, K1, K3, M_Q, Q_RANGE, D, G, double_well

A = np.sqrt(-K1 / K3)  # well position [m]


def fitted_double_well():
    """The same curves as RBF weights fitted by least squares (no backbone)."""
    basis = RBFBasis.equidistant(-0.02, 0.02, 25, 1.5)
    q = np.linspace(*Q_RANGE, 801)
    phi = basis(q)

    def fit(y):
        return np.linalg.lstsq(phi, y, rcond=None)[0]

    ones = np.ones_like(q)
    theta_g = np.stack([fit(G * ones), fit(-G * ones)])
    return RBFModel(
        basis, "v2", 2, M_Q, 0.0, 1e-3, fit(K1 + K3 * q**2), fit(D * ones), theta_g, {},
        Q_RANGE,
    )  # fmt: skip


def cubic_roots(force):
    """Real roots of k3 q^3 + k1 q - force in the range, ascending."""
    r = np.roots([K3, 0.0, K1, -force])
    r = np.sort(r[np.abs(r.imag) < 1e-12].real)
    return r[(r >= Q_RANGE[0]) & (r <= Q_RANGE[1])]


def energy(q, force):
    """U(q) = k1 q^2 / 2 + k3 q^4 / 4 - force q [J]."""
    return K1 * q**2 / 2 + K3 * q**4 / 4 - force * q


@pytest.mark.parametrize("model, rtol", [(double_well(), 1e-7), (fitted_double_well(), 1e-5)])
def test_rest_equilibria_match_the_closed_forms(model, rtol):
    rest = [p for p in equilibria(model) if p.level == 0]
    assert [p.q for p in rest] == pytest.approx([-A, 0.0, A], abs=rtol * A)
    assert [p.static_stable for p in rest] == [True, False, True]
    assert [p.stable for p in rest] == [True, False, True]
    wells = [rest[0], rest[2]]
    f_n = np.sqrt(-2 * K1 / M_Q) / (2 * np.pi)
    zeta = D / (2 * np.sqrt(-2 * K1 * M_Q))
    for w in wells:
        assert w.k == pytest.approx(-2 * K1, rel=rtol)
        assert w.f_n == pytest.approx(f_n, rel=rtol)
        assert w.zeta == pytest.approx(zeta, rel=rtol)
        assert w.barrier == pytest.approx(K1**2 / (4 * K3), rel=rtol)
    saddle = rest[1]
    assert saddle.k == pytest.approx(K1, rel=rtol)
    assert np.isnan(saddle.f_n) and np.isnan(saddle.zeta) and np.isnan(saddle.barrier)


def test_actuated_levels_move_the_roots_as_the_cubic_says():
    model = double_well()
    v = 2000.0
    points = equilibria(model, [(v, 0.0), (0.0, v), (0.0, 0.0)])
    assert sorted({p.level for p in points}) == [0, 1, 2]  # the repeated rest level is dropped
    for level, force in ((1, G * v**2), (2, -G * v**2)):
        rows = [p for p in points if p.level == level]
        roots = cubic_roots(force)
        assert len(roots) == 3
        assert [p.q for p in rows] == pytest.approx(roots, abs=1e-12)
        assert [p.k for p in rows] == pytest.approx(K1 + 3 * K3 * roots**2, rel=1e-7)
        # each well's barrier is the lower of its saddles: here the single middle root
        for j in (0, 2):
            want = energy(roots[1], force) - energy(roots[j], force)
            assert rows[j].barrier == pytest.approx(want, rel=1e-7)
    # the push on DE 1 makes the left well shallower than the right one
    left, right = [p.barrier for p in points if p.level == 1 and p.static_stable]
    assert left < K1**2 / (4 * K3) < right


def test_table_has_one_row_per_equilibrium_and_the_verdict():
    table = stability_table(double_well(), [(1000.0, 0.0)], visited=[(-0.011, 0.011)])
    assert list(table.columns[:3]) == ["level", "v1", "v2"]
    assert len(table) == 6 and table["visited"].all()
    assert table.loc[table.level == 1, "v1"].tolist() == [1000.0] * 3
    assert table.attrs["verdict"] == "stable"
    assert verdict(table, [(0.005, 0.011)]).label == "stable"
    assert verdict(table, [(-0.004, 0.004)]).label == "unstable"  # only the saddle at 0 V


@pytest.mark.parametrize("model", [double_well(), fitted_double_well()])
def test_switching_voltage_of_a_constant_gain_double_well(model):
    sw = switching_voltages(model, v_max=3000.0)
    v_s = np.sqrt(F_MAX / G)
    assert sw["reached"].tolist() == [True, True]
    assert sw["v_switch"].tolist() == pytest.approx([v_s, v_s], rel=1e-5)
    # DE 1 (g > 0) pushes out of the left well, DE 2 out of the right one
    assert sw["q_well"].tolist() == pytest.approx([-A, A], rel=1e-5)
    q_fold = np.sqrt(-K1 / (3 * K3))
    assert sw["q_fold"].tolist() == pytest.approx([-q_fold, q_fold], rel=1e-4)
    # just below v_s the left well is there, just above it is gone
    for factor, n_left in ((0.999, 1), (1.001, 0)):
        pts = equilibria(model, [(factor * v_s, 0.0)])
        assert sum(p.static_stable and p.q < 0 for p in pts if p.level == 1) == n_left


def test_switching_voltage_with_a_linear_input_map():
    sw = switching_voltages(double_well(g=2e-5, input_map="v"), v_max=10000.0)
    assert sw["v_switch"].tolist() == pytest.approx([F_MAX / 2e-5] * 2, rel=1e-7)


def test_switching_not_reached_is_reported_not_invented():
    sw = switching_voltages(double_well(), v_max=2000.0)
    assert not sw["reached"].any()
    assert sw["v_switch"].isna().all() and sw["q_fold"].isna().all()
    assert sw["q_well"].tolist() == pytest.approx([-A, A])
    assert all("persists" in r and "v_max = 2000 V" in r for r in sw["reason"])
    mono = switching_voltages(double_well(k1=40.0), v_max=3000.0)
    assert mono["v_switch"].isna().all() and mono["q_well"].isna().all()
    assert all("well" in r and "0 V" in r and "unstable" in r for r in mono["reason"])
    dead = switching_voltages(double_well(g=0.0), v_max=3000.0)
    assert dead["reason"].tolist() == ["the input exerts no force"] * 2


def test_negative_damping_in_a_visited_well_is_unstable():
    model = double_well(d_v=-0.2)
    table = stability_table(model, visited=[Q_RANGE])
    assert not table["damped"].any() and not table["stable"].any()
    assert table["static_stable"].tolist() == [True, False, True]
    assert table.attrs["verdict"] == "unstable"
    assert "damping" in table.attrs["reason"] and "d = -0.2" in table.attrs["reason"]
    ok, reason = model_is_stable(model, np.linspace(-0.011, 0.011, 50))
    assert not ok and "negative" in reason and "damping" in reason
    assert model_is_stable(double_well(), np.linspace(-0.011, 0.011, 50))[0]


def test_negative_damping_in_the_visited_basin_but_not_at_the_wells():
    grid = np.linspace(-0.025, 0.025, 2001)
    d = -0.3 + 8000.0 * grid**2  # 0.5 at the wells, < 0 for |q| < 6.1 mm
    prior = PhysicsPrior(q=grid, c=np.zeros_like(grid), d=d, g=np.zeros((grid.size, 2)))
    model = double_well(d_v=0.0, prior=prior, s_d=1.0)
    table = stability_table(model, visited=[Q_RANGE])
    assert table.loc[table.static_stable, "d"].tolist() == pytest.approx([0.5, 0.5], rel=1e-3)
    assert table.attrs["verdict"] == "stable"  # the table holds d at the wells only
    ok, reason = model_is_stable(model, np.linspace(-0.011, 0.011, 50))
    assert not ok and "basin" in reason
    # data that stay near the right well never reach the negatively damped middle
    assert model_is_stable(model, np.linspace(0.0085, 0.0115, 20))[0]


def test_no_well_at_rest_in_the_visited_range_is_unstable():
    ok, reason = model_is_stable(double_well(), np.linspace(-0.004, 0.004, 20))
    assert not ok and "equilibrium" in reason and "0 V" in reason and "stable" in reason


def test_bad_levels_and_ranges_raise():
    with pytest.raises(StabilityError) as err:
        equilibria(double_well(), [(100.0,)])
    assert "has 1" in str(err.value)
    assert "has 2" in str(err.value)
    with pytest.raises(DebistError) as err:
        equilibria(double_well(), q_range=(0.01, 0.01))
    assert "empty" in str(err.value)
    with pytest.raises(ValueError) as err:
        model_is_stable(double_well(), [np.nan])
    assert "finite" in str(err.value)


def test_a_model_without_restoring_force_is_not_judged_by_the_well_rules():
    """A free mass with damping (a linear stage, EMPS): no equilibrium at rest, no verdict."""
    model = double_well(k1=0.0)
    model.backbone.update({"k_3": 0.0, "F_0": 0.02})  # a constant force: no root at 0 V
    ok, reason = model_is_stable(model, np.linspace(-0.011, 0.011, 50))
    assert ok and "equilibrium" in reason


def test_damping_that_feeds_energy_into_the_measured_motion_is_unstable():
    """With the measured velocities, the basin rule is the power balance sum d q_dot^2."""
    grid = np.linspace(-0.025, 0.025, 2001)
    d = -0.3 + 8000.0 * grid**2  # < 0 for |q| < 6.1 mm, 0.5 at the wells
    prior = PhysicsPrior(q=grid, c=np.zeros_like(grid), d=d, g=np.zeros((grid.size, 2)))
    model = double_well(d_v=0.0, prior=prior, s_d=1.0)
    q = np.linspace(-0.011, -0.0001, 200)
    fast_near_wells = np.where(np.abs(q) > 0.007, 1.0, 0.05)  # slow in the middle
    slow_near_wells = np.where(np.abs(q) > 0.007, 0.05, 1.0)  # fast in the middle
    assert model_is_stable(model, q, q_dot=fast_near_wells)[0]
    ok, reason = model_is_stable(model, q, q_dot=slow_near_wells)
    assert not ok and "feeds" in reason and "energy" in reason


def test_small_signal_is_the_mass_spring_damper_of_the_well():
    """k = (2 pi)^2 m: 1 Hz; d = 2 sqrt(k m): critical damping; no well (k <= 0): NaN."""
    m = 0.02
    k = (2.0 * np.pi) ** 2 * m
    f_n, zeta = small_signal(k, m, 2.0 * np.sqrt(k * m))
    assert f_n == pytest.approx(1.0, rel=1e-12) and zeta == pytest.approx(1.0, rel=1e-12)
    assert np.isnan(small_signal(0.0, m, 1.0)).all() and np.isnan(small_signal(-k, m, 1.0)).all()
