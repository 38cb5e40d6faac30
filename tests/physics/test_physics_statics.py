"""Statics of the physics model: the behaviour of Sections 3.3.3-3.3.5 for the paper prototype."""

import numpy as np
import pytest

from debist.physics.energy import potential
from debist.physics.kinematics import ritz_basis
from debist.physics.params import V_MAX, PrototypeParams
from debist.physics.prestrain import (
    equilibrium_branches,
    pitchfork_zb,
    prestrain_sweep,
    switching_limit_zb,
)
from debist.physics.statics import (
    FORCE_STATES,
    StaticsError,
    equilibria,
    force_displacement,
    force_displacements,
    solve_equilibrium,
    switches,
    switching_voltage,
)

P = PrototypeParams.paper()
STROKE = np.linspace(-15e-3, 15e-3, 121)


@pytest.fixture(scope="module")
def curves():
    return {v: force_displacement(P, STROKE, v1=v[0], v2=v[1]) for v in FORCE_STATES}


def summary(eqs):
    return [(round(e.q * 1e3, 2) + 0.0, e.stable) for e in eqs]


def test_bistable_at_b_23mm():
    eqs = equilibria(P)
    assert [e.stable for e in eqs] == [True, False, True], summary(eqs)
    assert 10e-3 <= -eqs[0].q <= 12e-3 and 10e-3 <= eqs[2].q <= 12e-3
    assert eqs[0].q == pytest.approx(-eqs[2].q, rel=1e-9)
    assert eqs[1].q == pytest.approx(0.0, abs=1e-12)
    assert eqs[2].q == pytest.approx(10.206e-3, abs=2e-6)  # interpretation item 3: +-10.2 mm
    assert all(e.residual < 1e-9 and e.converged for e in eqs)


def test_left_de_leaves_only_the_right_state_and_vice_versa():
    right = equilibria(P, v1=V_MAX)
    left = equilibria(P, v2=V_MAX)
    assert [e.stable for e in right] == [True] and right[0].q > 5e-3, summary(right)
    assert [e.stable for e in left] == [True] and left[0].q < -5e-3, summary(left)
    assert right[0].q == pytest.approx(-left[0].q, rel=1e-9)


def test_both_des_make_the_straight_beam_the_only_equilibrium():
    eqs = equilibria(P, v1=V_MAX, v2=V_MAX)
    assert summary(eqs) == [(0.0, True)]


def test_capacitance_slopes_have_the_signs_of_fig_5(curves):
    c = curves[(0.0, 0.0)]
    assert np.all(c.dC_dq[:, 0] > 0)  # left DE: dC1/dq > 0 over the stroke
    assert np.all(c.dC_dq[:, 1] < 0)  # right DE: dC2/dq < 0
    assert c.C[60] == pytest.approx(P.C_0 * c.lambda_1[60], rel=1e-14)  # C = C_0 lambda_1
    assert c.lambda_1[60] == pytest.approx([1.4264] * 2, abs=1e-4)  # q = 0, u_0 = -36 um
    # the path tangent gives dC/dq exactly: compare with differences of C along the path
    fd = np.gradient(c.C[:, 0], c.q)
    assert fd[1:-1] == pytest.approx(c.dC_dq[1:-1, 0], rel=2e-3)


def test_force_range_and_symmetry(curves):
    F = np.array([c.F for c in curves.values()])
    assert 0.08 < np.max(np.abs(F)) < 0.2  # about +-100 mN over the stroke (Fig. 4)
    f0 = curves[(0.0, 0.0)].F
    assert f0 == pytest.approx(-f0[::-1], abs=1e-12)
    assert pytest.approx(-curves[(0.0, V_MAX)].F[::-1], abs=1e-12) == curves[(V_MAX, 0.0)].F
    assert np.all(curves[(V_MAX, V_MAX)].dF_dq > 0)  # both on: monotone, single equilibrium
    assert np.all(curves[(V_MAX, 0.0)].F < curves[(0.0, 0.0)].F)  # left DE pushes right


def test_path_tangents_against_differences(curves):
    c = curves[(V_MAX, 0.0)]
    dq = c.q[1] - c.q[0]
    dF = (c.F[2:] - c.F[:-2]) / (2 * dq)
    assert dF == pytest.approx(c.dF_dq[1:-1], rel=1e-3, abs=1e-2)  # O(dq^2) of the differences
    s = ritz_basis(P.l).scale
    dqm = (c.qm[2:] - c.qm[:-2]) / (2 * dq) * s
    assert np.max(np.abs(dqm - c.dqm_dq[1:-1] * s)) < 5e-3 * np.max(np.abs(c.dqm_dq * s))
    assert c.dqm_dq @ ritz_basis(P.l).L == pytest.approx(np.ones_like(c.q), rel=1e-12)


def test_loaded_equilibrium_is_on_the_force_curve(curves):
    F = 0.02
    eqs = equilibria(P, F=F)
    assert len(eqs) == 3
    c = curves[(0.0, 0.0)]
    for e in eqs:
        assert np.interp(e.q, c.q, c.F) == pytest.approx(F, abs=2e-4)
        ev = potential(e.qm, P)
        s = ritz_basis(P.l).scale
        assert ev.grad / s == pytest.approx(F * ritz_basis(P.l).L / s, abs=1e-9)


def test_solve_equilibrium_from_a_start_point():
    e = solve_equilibrium(P, np.array([40e-3, -110e-3, 60e-3, 0.0]) / ritz_basis(P.l).scale)
    assert e.converged and e.stable
    assert abs(e.q) == pytest.approx(10.206e-3, abs=2e-6)
    assert e.eigenvalues[0] > 0 and np.all(np.diff(e.eigenvalues) > 0)


def test_slack_equilibria_are_filtered():
    slack = P.replace(l_0=80e-3)  # longer than the DE distance: both membranes slack
    assert equilibria(slack) == ()


def test_pitchfork_point():
    z_min = pitchfork_zb(P)
    assert z_min == pytest.approx(4.837e-3, abs=5e-6)
    below = equilibria(P, b=P.b_max - z_min + 0.1e-3)  # z_b < z_b,min: straight beam stable
    above = equilibria(P, b=P.b_max - z_min - 0.1e-3)
    assert summary(below) == [(0.0, True)]
    assert [e.stable for e in above] == [True, False, True]


def test_switching_limit():
    z_max = switching_limit_zb(P)
    assert z_max == pytest.approx(11.653e-3, abs=5e-6)
    before = equilibria(P, b=P.b_max - z_max + 0.1e-3, v1=V_MAX)
    after = equilibria(P, b=P.b_max - z_max - 0.1e-3, v1=V_MAX)
    assert [e.q > 0 for e in before] == [True]  # still switchable
    assert any(e.stable and e.q < 0 for e in after)  # the left well survives actuation


def test_bifurcation_search_errors():
    with pytest.raises(StaticsError) as err:
        pitchfork_zb(P, b_bracket=(26e-3, 30e-3))
    assert "b_bracket" in str(err.value)
    with pytest.raises(StaticsError) as err:
        switching_limit_zb(P, b_range=(20e-3, 30e-3))
    assert "b_range" in str(err.value)


def test_force_displacement_checks_grid():
    with pytest.raises(ValueError) as err:
        force_displacement(P, [0.0, -1e-3])
    assert "strictly" in str(err.value) and "increasing" in str(err.value)


def test_the_states_continued_together_are_each_states_own_path(curves):
    """Fig. 4's four voltage states continued in one pass are each state's path continued
    alone (to Newton's tolerance: the batch takes the same steps), in the order asked, with
    the same stability and convergence; the grid and the states are checked."""
    together = force_displacements(P, STROKE, FORCE_STATES[::-1])
    scale = ritz_basis(P.l).scale
    for state, curve in zip(FORCE_STATES[::-1], together, strict=True):
        alone = curves[state]
        assert (curve.v1, curve.v2, curve.b) == (*state, P.b)
        assert np.max(np.abs((curve.qm - alone.qm) * scale)) < 1e-9  # [m]
        np.testing.assert_allclose(curve.F, alone.F, rtol=0, atol=1e-9 * np.ptp(alone.F))
        np.testing.assert_allclose(curve.dC_dq, alone.dC_dq, rtol=1e-8)
        np.testing.assert_array_equal(curve.stable, alone.stable)
        assert curve.converged.all()
    with pytest.raises(ValueError) as err:
        force_displacements(P, STROKE, [])
    assert "(v1, v2)" in str(err.value)
    with pytest.raises(ValueError) as err:
        force_displacements(P, STROKE[::-1], FORCE_STATES)
    assert "strictly" in str(err.value)


def test_a_path_solved_from_a_nearby_path_is_the_continuations(curves):
    """Natural continuation in the voltage: every point of the 1.5 kV path solved at once from
    the 0 V path gives the continuation's path (to Newton's tolerance) and its forces; a
    guess it cannot solve from falls back to the continuation, the same numbers."""
    ref = force_displacement(P, STROKE, v1=1500.0)
    fast = force_displacement(P, STROKE, v1=1500.0, guess=curves[(0.0, 0.0)].qm)
    assert fast.converged.all()
    scale = ritz_basis(P.l).scale
    assert np.max(np.abs((fast.qm - ref.qm) * scale)) < 1e-9  # [m]
    np.testing.assert_allclose(fast.F, ref.F, rtol=0, atol=1e-9 * np.ptp(ref.F))
    bad = force_displacement(P, STROKE, v1=1500.0, guess=np.full((STROKE.size, 4), 1e9))
    np.testing.assert_array_equal(bad.qm, ref.qm)


def test_prestrain_sweep_fig3():
    sweep = prestrain_sweep(P, b=np.linspace(18e-3, 30e-3, 25), n_q=120)
    assert sweep.z_b_min == pytest.approx(4.837e-3, abs=5e-6)
    assert sweep.z_b_max == pytest.approx(11.653e-3, abs=5e-6)
    i23 = int(np.argmin(np.abs(sweep.b - 23e-3)))
    q, st = sweep.equilibria_of(0, i23)
    assert st.tolist() == [True, False, True] and q[2] == pytest.approx(10.206e-3, abs=2e-6)
    q, st = sweep.equilibria_of(1, i23)
    assert st.tolist() == [True] and q[0] > 0
    i30 = int(np.argmin(np.abs(sweep.b - 30e-3)))
    assert sweep.equilibria_of(0, i30)[1].tolist() == [True]  # z_b = 0: straight, stable
    i18 = int(np.argmin(np.abs(sweep.b - 18e-3)))  # z_b = 12 mm > z_b,max: left well survives
    q, st = sweep.equilibria_of(1, i18)
    assert np.any(st & (q < 0))
    branches = equilibrium_branches(sweep, 0)
    assert any(not s for *_, s in branches) and any(s for *_, s in branches)


def stable_wells(p):
    eqs = [e for e in equilibria(p) if e.stable]
    assert len(eqs) == 2 and eqs[0].q < 0 < eqs[1].q, summary(eqs)
    return eqs[0].q, eqs[1].q


def test_symmetric_prototype_has_mirror_image_wells():
    q_left, q_right = stable_wells(P)
    assert q_left == pytest.approx(-q_right, rel=1e-9)


@pytest.mark.parametrize(("dz_1", "dz_2"), [(0.2e-3, 0.2e-3), (0.3e-3, 0.0), (0.0, -0.3e-3)])
def test_asymmetric_anchors_make_the_wells_unequal(dz_1, dz_2):
    # a bearing offset (dz_1 = dz_2) or one displaced anchor breaks the mirror symmetry. The
    # antisymmetric part dz_1 + dz_2 decides the side: the DE upper ends sit outside the
    # anchors (a > e_z), so an anchor moved right stretches DE 1 more / DE 2 less, and both
    # pull the tip more to the right: the right well moves out, the left one in
    q_left, q_right = stable_wells(P.replace(dz_1=dz_1, dz_2=dz_2))
    assert abs(abs(q_right) - abs(q_left)) > 0.5e-3
    assert np.sign(abs(q_right) - abs(q_left)) == np.sign(dz_1 + dz_2)


def test_opposite_offsets_keep_the_wells_mirrored():
    # dz_1 = -dz_2 moves both anchors inwards by the same amount: still mirror-symmetric
    # (mirroring maps offsets (dz_1, dz_2) to (-dz_2, -dz_1)), only the pre-stretch changes
    q_left, q_right = stable_wells(P.replace(dz_1=0.5e-3, dz_2=-0.5e-3))
    assert q_left == pytest.approx(-q_right, rel=1e-9)
    assert abs(q_right) > 10.5e-3  # anchors inwards stretch the DEs more (a > e_z): wider wells


def test_switching_voltage_of_the_paper_prototype():
    # the reduced model's analytical rows give 1425 V (test_design), an independent route
    v1, v2 = switching_voltage(P, 1), switching_voltage(P, 2)
    assert v1 == pytest.approx(1425.0, rel=3e-3)
    assert v1 == pytest.approx(v2, abs=1.0)  # mirror symmetry, to the bisection's 1 V
    assert switches(P, 1, v1) and not switches(P, 1, v1 - 1.0)  # the bracket it returns
    assert switches(P, 2, v2) and not switches(P, 2, v2 - 1.0)


def test_switching_voltage_follows_the_asymmetry_and_the_mirror():
    # dz_1 + dz_2 > 0 moves the left well in (shallower, lower threshold for DE 1); the
    # mirror image (dz_1, dz_2) -> (-dz_2, -dz_1) swaps the two DEs' thresholds
    a = P.replace(dz_1=0.3e-3, dz_2=0.1e-3)
    b = P.replace(dz_1=-0.1e-3, dz_2=-0.3e-3)
    v1, v2 = switching_voltage(a, 1, tol=2.0), switching_voltage(a, 2, tol=2.0)
    assert v1 < 1300.0 < 1500.0 < v2
    assert switching_voltage(b, 2, tol=2.0) == pytest.approx(v1, abs=2.0)
    assert switching_voltage(b, 1, tol=2.0) == pytest.approx(v2, abs=2.0)


def test_switching_voltage_limits_and_errors():
    assert switching_voltage(P, 1, v_max=1000.0) == np.inf  # 1 kV keeps the left well
    with pytest.raises(ValueError) as err:
        switching_voltage(P, 3)
    assert "`de`" in str(err.value)
    assert "be 1" in str(err.value)
    assert "or 2" in str(err.value)
    with pytest.raises(ValueError) as err:
        switching_voltage(P, 1, tol=0.0)
    assert "positive" in str(err.value)
