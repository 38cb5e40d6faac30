"""Prototype fleets: seeded scatter, determinism, and every member bistable and switchable."""

import numpy as np
import pytest

from debist.core.errors import WorkflowError
from debist.physics.params import V_MAX, PrototypeParams
from debist.physics.statics import equilibria
from debist.rig.fleet import FleetError, is_bistable_and_switchable, make_fleet
from debist.rig.params import RigParams


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Seed 7's fleet of four, drawn once for all pytest-xdist workers."""
    from tests.conftest import computed_once

    return computed_once(tmp_path_factory, "rig-fleet-seed-7", lambda: make_fleet(4, seed=7))


@pytest.mark.slow
def test_same_seed_same_fleet_and_prefix_property(fleet):
    again = make_fleet(4, seed=7)
    assert again == fleet
    assert make_fleet(2, seed=7) == fleet[:2]
    other = make_fleet(1, seed=8)
    assert other[0] != fleet[0]


def test_members_are_drawn_only_when_asked_for_and_are_make_fleets(fleet, monkeypatch):
    """fleet_members screens a draw only when its iterator reaches the member, and yields
    make_fleet's members in order; a bad scatter is refused at the call."""
    from debist.rig import fleet as fleet_module

    screened = []
    real = fleet_module.is_bistable_and_switchable
    monkeypatch.setattr(
        fleet_module, "is_bistable_and_switchable", lambda p: screened.append(p) or real(p)
    )
    members = fleet_module.fleet_members(seed=7)
    assert screened == []
    first = [next(members), next(members)]
    assert first == fleet[:2]
    assert len(screened) >= 2 and screened[-1] == fleet[1]
    n_screened = len(screened)
    assert next(members) == fleet[2] and len(screened) > n_screened
    with pytest.raises(WorkflowError, match="unknown scatter 'mass'"):
        fleet_module.fleet_members(seed=7, scatter={"mass": 0.1})


def test_members_scatter_around_the_paper(fleet):
    paper = PrototypeParams.paper()
    b = np.array([m.prototype.b for m in fleet])
    dz = np.array([[m.prototype.dz_1, m.prototype.dz_2] for m in fleet])
    assert np.all(np.abs(b - paper.b) < 2.5e-3) and np.ptp(b) > 0
    assert np.all(np.abs(dz) < 1.5e-3) and np.all(dz != 0)
    F = np.array([m.friction_F for m in fleet])
    ratio = F / np.array(RigParams().friction_F)
    assert np.all((ratio > 0.2) & (ratio < 5)) and np.ptp(ratio) > 0
    # untouched by the default scatter: the other physics, the stiffnesses, the sensors
    for m in fleet:
        assert m.prototype.replace(b=paper.b, dz_1=0.0, dz_2=0.0) == paper
        assert m.friction_k == RigParams().friction_k
        assert m.sensor_noise == RigParams().sensor_noise


def test_every_member_is_bistable_and_switched_by_3_kV(fleet):
    for m in fleet:
        p = m.prototype
        rest = [e for e in equilibria(p) if e.stable]
        assert len(rest) == 2 and rest[0].q < 0 < rest[1].q
        on1 = [e for e in equilibria(p, v1=V_MAX) if e.stable]
        on2 = [e for e in equilibria(p, v2=V_MAX) if e.stable]
        assert len(on1) == 1 and on1[0].q > 0
        assert len(on2) == 1 and on2[0].q < 0


def test_rejection_check_catches_a_broken_prototype():
    # a 1 mm bearing offset leaves only the right well; a large b no bistability at all
    assert not is_bistable_and_switchable(
        RigParams(prototype=PrototypeParams(dz_1=1e-3, dz_2=1e-3))
    )
    assert not is_bistable_and_switchable(RigParams(prototype=PrototypeParams(b=27e-3)))
    assert is_bistable_and_switchable(RigParams())


def test_scatter_overrides_by_name():
    fleet = make_fleet(2, seed=1, scatter={"b": 0.0, "dz_1": 0.0, "dz_2": 0.0, "friction_k": 0.5})
    for m in fleet:
        assert m.prototype == PrototypeParams.paper()
        assert m.friction_k != RigParams().friction_k
    none = make_fleet(1, seed=1, scatter=dict.fromkeys(("b", "dz_1", "dz_2", "friction_F"), 0))
    assert none[0] == RigParams(prototype=PrototypeParams.paper())


def test_nominal_rig_is_the_centre():
    nominal = RigParams(oversample=4)
    m = make_fleet(1, seed=2, nominal=nominal, scatter={"b": 0.0})[0]
    assert m.oversample == 4 and m.prototype.b == nominal.prototype.b


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n": -1}, "`n` must be a non-negative integer"),
        ({"n": 1, "scatter": {"E": 0.1}}, "unknown scatter 'E'"),
        ({"n": 1, "scatter": {"b": -1e-3}}, "scatter 'b' must be a finite number >= 0"),
    ],
)
def test_invalid_arguments(kwargs, match):
    with pytest.raises(WorkflowError, match=match):
        make_fleet(seed=0, **kwargs)


def test_impossible_nominal_raises_fleet_error():
    broken = RigParams(prototype=PrototypeParams(b=27e-3))  # not bistable, no scatter
    with pytest.raises(FleetError) as err:
        make_fleet(1, seed=0, nominal=broken, max_draws=3)
    assert "bistable" in str(err.value) and "prototype" in str(err.value)


def test_every_member_switches_in_the_rig(fleet):
    from debist.rig.run import simulate_rig

    t = np.arange(4000) * 1e-3
    r1 = np.where((t >= 0.1) & (t < 1.1), V_MAX, 0.0)
    r2 = np.where((t >= 2.1) & (t < 3.1), V_MAX, 0.0)
    for m in fleet:
        eqs = equilibria(m.prototype)
        barrier = next(e.q for e in eqs if not e.stable)
        run = simulate_rig(m, t, r1, r2, sample_time=0.01, seed=0)
        assert run.q_true[0] == pytest.approx(eqs[0].q, abs=1e-8)  # at rest, left well
        # after each pulse the beam rings down on the other side of the barrier
        assert np.all(run.q_true[(run.t > 1.6) & (run.t < 2.1)] > barrier + 2e-3)
        assert np.all(run.q_true[(run.t > 3.6)] < barrier - 2e-3)
