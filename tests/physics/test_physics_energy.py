"""Kinematics and energies of the physics model: exact derivatives, geometry, generated code."""

import numpy as np
import pytest
from scipy.integrate import quad

from debist.physics import _generated
from debist.physics.energy import capacitances, energy_parts, potential
from debist.physics.kinematics import (
    de_lengths,
    deflection,
    pitch_angle,
    ritz_basis,
    stretches,
    tip_displacement,
    tip_slope,
    vertical_displacement,
)
from debist.physics.params import PrototypeParams

P = PrototypeParams.paper()
SCALE = ritz_basis(P.l).scale


def random_states(n, seed):
    """Ritz coordinates with tip displacements of +-20 mm and S-shapes, u_0 ~ -35 um."""
    rng = np.random.default_rng(seed)
    xi = rng.normal(size=(n, 4)) * np.array([0.02, 0.05, 0.03, 2e-5])
    return xi / SCALE


def central(f, x, k, h):
    e = np.zeros(4)
    e[k] = h
    return (f(x + e) - f(x - e)) / (2 * h)


def test_geometry_at_rest_matches_notes_item_1():
    length = de_lengths(np.zeros(4), P)[0]
    # (16 mm, 71 mm + u_y) with u_y = 0: l_DE = 72.78 mm, stretch 1.427
    # (docs/interpretation.md item 1: 72.7 mm, 1.43)
    assert length == pytest.approx([np.hypot(16e-3, 71e-3)] * 2, rel=1e-12)
    assert stretches(np.zeros(4), P) == pytest.approx([1.4271] * 2, abs=1e-4)


def test_larger_b_shortens_the_des():
    l23 = de_lengths(np.zeros(4), P, b=23e-3)[0][0]
    l25 = de_lengths(np.zeros(4), P, b=25e-3)[0][0]
    assert l25 < l23  # less pre-stretch for larger b (z_b smaller), Fig. 3


def test_tilting_right_stretches_the_left_de():
    qm = np.array([0.5, 0.0, 0.0, 0.0])  # q = 4 mm to the right
    lam = stretches(qm, P)
    assert lam[0] > lam[1]  # docs/interpretation.md item 6: dC1/dq > 0, dC2/dq < 0
    assert tip_displacement(qm, P) == pytest.approx(0.5 * P.l**2)
    assert pitch_angle(qm, P) == pytest.approx(np.arctan(2 * 0.5 * P.l))


def test_ritz_kinematics_are_exact():
    qm = random_states(3, seed=1)
    x = np.linspace(0, P.l, 7)
    w = deflection(qm, x, P)
    assert w[:, -1] == pytest.approx(tip_displacement(qm, P), rel=1e-13)
    for k in range(3):
        dw = lambda s, k=k: 2 * qm[k, 0] * s + 3 * qm[k, 1] * s**2 + 4 * qm[k, 2] * s**3  # noqa: E731
        integral = quad(lambda s, dw=dw: 0.5 * dw(s) ** 2, 0, P.l, epsabs=1e-14)[0]
        assert vertical_displacement(qm[k], P) == pytest.approx(qm[k, 3] - integral, rel=1e-12)
        assert tip_slope(qm[k], P) == pytest.approx(dw(P.l), rel=1e-13)


def test_bending_energy_against_quadrature():
    qm = random_states(2, seed=2)
    p = P.replace(m=1e-12, A_0=1e-12, V_DE=1e-30)  # beam only (DE energy ~ 0, mass ~ 0)
    for k in range(2):
        q2, q3, q4, u0 = qm[k]
        w1 = lambda s, q2=q2, q3=q3, q4=q4: 2 * q2 * s + 3 * q3 * s**2 + 4 * q4 * s**3  # noqa: E731
        w2 = lambda s, q2=q2, q3=q3, q4=q4: 2 * q2 + 6 * q3 * s + 12 * q4 * s**2  # noqa: E731
        bend = quad(
            lambda s, w1=w1, w2=w2: 0.5 * p.E * p.I * w2(s) ** 2 * (1 + w1(s) ** 2), 0, p.l
        )[0]
        parts = energy_parts(qm[k], p)
        assert parts["U_s"] == pytest.approx(bend + 0.5 * p.E * p.A / p.l * u0**2, rel=1e-10)


@pytest.mark.parametrize(
    ("v1", "v2", "b"), [(0.0, 0.0, 23e-3), (3e3, 0.0, 21e-3), (1e3, 2.5e3, 27e-3)]
)
def test_gradient_and_hessian_against_central_differences(v1, v2, b):
    X = random_states(4, seed=3)
    for x in X:
        ev = potential(x, P, b=b, v1=v1, v2=v2)

        def U(y):
            return potential(y, P, b=b, v1=v1, v2=v2, order=0).U

        def G(y):
            return potential(y, P, b=b, v1=v1, v2=v2, order=1).grad

        for k in range(4):
            h = 1e-6 / SCALE[k]
            g_fd = central(U, x, k, h)
            h_fd = central(G, x, k, h)
            # relative to the size of the gradient / Hessian column (scaled coordinates)
            assert abs(g_fd - ev.grad[k]) * SCALE[k] <= 1e-6 * np.max(np.abs(ev.grad * SCALE))
            col = ev.hess[:, k] * SCALE * SCALE[k]
            assert np.max(np.abs((h_fd - ev.hess[:, k]) * SCALE * SCALE[k])) <= 1e-6 * np.max(
                np.abs(col)
            )
        assert ev.hess == pytest.approx(ev.hess.T, rel=1e-12, abs=0)


def test_batched_evaluation_equals_pointwise():
    X = random_states(5, seed=4).reshape(5, 1, 4)
    b = np.linspace(20e-3, 30e-3, 3)
    ev = potential(X, P, b=b, v1=3e3)
    assert ev.hess.shape == (5, 3, 4, 4)
    for i in range(5):
        for j in range(3):
            e = potential(X[i, 0], P, b=b[j], v1=3e3)
            assert ev.grad[i, j] == pytest.approx(e.grad, rel=1e-13)
            assert ev.hess[i, j] == pytest.approx(e.hess, rel=1e-13)


def test_de_length_derivatives_and_capacitance():
    x = random_states(1, seed=5)[0]
    length, grad, hess = de_lengths(x, P, order=2)
    C, dC = capacitances(x, P)
    assert pytest.approx(P.C_0 * length / P.l_0, rel=1e-14) == C
    for k in range(4):
        h = 1e-6 / SCALE[k]
        fd = central(lambda y: de_lengths(y, P)[0], x, k, h)
        assert fd * SCALE[k] == pytest.approx(grad[:, k] * SCALE[k], rel=1e-7, abs=1e-9)
        fd2 = central(lambda y: de_lengths(y, P, order=1)[1], x, k, h)
        assert np.max(np.abs(fd2 - hess[:, :, k]) * SCALE * SCALE[k]) < 1e-6
        assert dC[:, k] == pytest.approx(P.C_0 / P.l_0 * grad[:, k], rel=1e-14)


def test_parts_add_up_and_voltage_enters_as_minus_half_c_v2():
    x = random_states(1, seed=6)[0]
    parts = energy_parts(x, P, v1=3e3, v2=1e3)
    assert sum(parts.values()) == pytest.approx(potential(x, P, v1=3e3, v2=1e3, order=0).U)
    C = capacitances(x, P, order=0)[0]
    dU = potential(x, P, v1=3e3, v2=1e3, order=0).U - potential(x, P, order=0).U
    assert dU == pytest.approx(-0.5 * C[0] * 9e6 - 0.5 * C[1] * 1e6, rel=1e-9)


def test_mirror_symmetry():
    x = random_states(3, seed=7)
    mirrored = x * np.array([-1, -1, -1, 1])
    a = potential(x, P, v1=3e3, v2=0.5e3)
    b = potential(mirrored, P, v1=0.5e3, v2=3e3)
    assert pytest.approx(b.U, rel=1e-12) == a.U
    assert a.lambda_1 == pytest.approx(b.lambda_1[:, ::-1], rel=1e-13)


def test_generated_code_equals_the_vectorised_chain_rule():
    consts = (P.l, P.E * P.I, P.E * P.A, P.m * P.g, P.a, P.a_0, P.e_x, -P.e_z, P.e_z, P.l_0,
              P.V_DE * P.Y / 6, P.C_0 / 2)  # fmt: skip
    for x in random_states(5, seed=8):
        args = (*x, 22e-3, 9e6, 0.25e6, *consts)
        grad, length, dlen = _generated.grad_terms(*args)
        hu = _generated.hess_terms(*args)
        ev = potential(x, P, b=22e-3, v1=3e3, v2=0.5e3)
        L, dL = de_lengths(x, P, b=22e-3, order=1)
        assert np.array(grad) * SCALE == pytest.approx(ev.grad * SCALE, rel=1e-10, abs=1e-12)
        assert np.array(length) == pytest.approx(L, rel=1e-14)
        assert np.array(dlen).reshape(2, 4) == pytest.approx(dL, rel=1e-11, abs=1e-14)
        iu = np.triu_indices(4)
        Hs = ev.hess * np.outer(SCALE, SCALE)
        assert np.array(hu) * np.outer(SCALE, SCALE)[iu] == pytest.approx(
            Hs[iu], rel=1e-9, abs=1e-9 * np.abs(Hs).max()
        )


def test_order_is_checked():
    with pytest.raises(ValueError) as err:
        potential(np.zeros(4), P, order=3)
    assert "`order`" in str(err.value)
    assert "be 0" in str(err.value)
    assert "1 or" in str(err.value)


# --- geometric asymmetry: signed offsets dz_1, dz_2 of the fixed DE ends ---
P_BEARING = P.replace(dz_1=1e-3, dz_2=1e-3)  # a beam clamp 1 mm left of nominal


def generated_args(p, x, b, v1, v2):
    consts = (p.l, p.E * p.I, p.E * p.A, p.m * p.g, p.a, p.a_0, p.e_x, -p.e_z + p.dz_1,
              p.e_z + p.dz_2, p.l_0, p.V_DE * p.Y / 6, p.C_0 / 2)  # fmt: skip
    return (*x, b, v1**2, v2**2, *consts)


def test_asymmetry_offsets_are_signed_and_move_one_anchor_each():
    assert PrototypeParams.from_dict({"dz_1": -0.3e-3}).dz_1 == -0.3e-3
    assert P.dz_1 == 0.0 and P.dz_2 == 0.0
    x = random_states(3, seed=11)
    base = de_lengths(x, P)[0]
    h = 1e-3
    lp = de_lengths(x, P.replace(dz_1=h))[0]
    lm = de_lengths(x, P.replace(dz_1=-h))[0]
    assert lp[:, 1] == pytest.approx(base[:, 1], rel=1e-15)  # DE 2 untouched
    # the anchor of DE 1 moves along x: |d + dz e_x|^2 = |d|^2 + 2 dz d_x + dz^2
    assert 0.5 * (lp[:, 0] ** 2 + lm[:, 0] ** 2) - base[:, 0] ** 2 == pytest.approx(
        np.full(3, h**2), rel=1e-6
    )
    lr = de_lengths(x, P.replace(dz_2=h))[0]
    assert lr[:, 0] == pytest.approx(base[:, 0], rel=1e-15)  # DE 1 untouched
    assert np.all(np.abs(lr[:, 1] - base[:, 1]) > 1e-5)


def test_asymmetric_generated_gradient_equals_vectorised_and_differences():
    b, v1, v2 = 22.5e-3, 2e3, 0.7e3
    for x in random_states(4, seed=12):
        grad, length, dlen = _generated.grad_terms(*generated_args(P_BEARING, x, b, v1, v2))
        hu = _generated.hess_terms(*generated_args(P_BEARING, x, b, v1, v2))
        ev = potential(x, P_BEARING, b=b, v1=v1, v2=v2)
        # the offset matters: the symmetric gradient differs by far more than the tolerance
        ev0 = potential(x, P, b=b, v1=v1, v2=v2)
        gs = np.max(np.abs(ev.grad * SCALE))
        assert np.max(np.abs((ev.grad - ev0.grad) * SCALE)) > 1e-3 * gs
        assert np.array(grad) * SCALE == pytest.approx(ev.grad * SCALE, rel=1e-6, abs=1e-6 * gs)
        L, dL = de_lengths(x, P_BEARING, b=b, order=1)
        assert np.array(length) == pytest.approx(L, rel=1e-14)
        assert np.array(dlen).reshape(2, 4) == pytest.approx(dL, rel=1e-11, abs=1e-14)
        iu = np.triu_indices(4)
        Hs = ev.hess * np.outer(SCALE, SCALE)
        assert np.array(hu) * np.outer(SCALE, SCALE)[iu] == pytest.approx(
            Hs[iu], rel=1e-6, abs=1e-6 * np.abs(Hs).max()
        )

        def U(y):
            return potential(y, P_BEARING, b=b, v1=v1, v2=v2, order=0).U

        for k in range(4):
            g_fd = central(U, x, k, 1e-6 / SCALE[k])
            assert abs(g_fd - grad[k]) * SCALE[k] <= 1e-6 * gs


def test_mirror_symmetry_with_mirrored_offsets():
    # mirroring x -> -x maps the anchors -e_z + dz_1, e_z + dz_2 to e_z - dz_1, -e_z - dz_2:
    # the prototype with offsets (dz_1, dz_2) mirrors into the one with (-dz_2, -dz_1)
    x = random_states(3, seed=13)
    mirrored = x * np.array([-1, -1, -1, 1])
    pa = P.replace(dz_1=0.4e-3, dz_2=-0.1e-3)
    pb = P.replace(dz_1=0.1e-3, dz_2=-0.4e-3)
    a = potential(x, pa, v1=3e3, v2=0.5e3)
    b = potential(mirrored, pb, v1=0.5e3, v2=3e3)
    assert pytest.approx(b.U, rel=1e-12) == a.U
    assert a.lambda_1 == pytest.approx(b.lambda_1[:, ::-1], rel=1e-13)
    c = potential(mirrored, pa, v1=0.5e3, v2=3e3)
    assert np.all(np.abs(c.U - a.U) > 1e-6 * np.abs(a.U))  # pa alone is not mirror-symmetric


def test_scalar_gradient_hessian_equals_the_vectorised_potential():
    """The generated scalar path of the Newton solves agrees with potential() state by state."""
    from debist.physics.energy import scalar_gradient_hessian

    x = random_states(3, seed=21)
    b = np.array([21e-3, 22e-3, 23e-3])
    grad, hess = scalar_gradient_hessian(x, P_BEARING, b, 2e3, np.array([0.0, 1e3, 3e3]))
    ev = potential(x, P_BEARING, b=b, v1=2e3, v2=np.array([0.0, 1e3, 3e3]))
    assert grad * SCALE == pytest.approx(ev.grad * SCALE, rel=1e-10, abs=1e-12)
    H, H_ref = hess * np.outer(SCALE, SCALE), ev.hess * np.outer(SCALE, SCALE)
    np.testing.assert_allclose(H, H_ref, rtol=1e-9, atol=1e-9 * np.abs(H_ref).max())
    assert np.array_equal(hess, np.swapaxes(hess, 1, 2))  # symmetric by construction


@pytest.mark.parametrize("evaluated", [0, "limit"], ids=["python", "compiled"])
def test_scalar_gradient_hessian_is_the_generated_code_bit_for_bit(monkeypatch, evaluated):
    """Run as Python or compiled, the batch equals the generated terms state by state."""
    from debist.physics import energy
    from debist.physics.energy import HESS_INDEX, generated_constants, scalar_gradient_hessian

    count = energy.PYTHON_STATES if evaluated == "limit" else evaluated
    monkeypatch.setattr(energy, "_evaluated", count)
    x = random_states(6, seed=22).reshape(2, 3, 4)
    v2 = np.array([0.0, 1.5e3, 3e3])  # broadcast over the leading axis
    grad, hess = scalar_gradient_hessian(x, P_BEARING, 22e-3, 2e3, v2)
    assert grad.shape == (2, 3, 4) and hess.shape == (2, 3, 4, 4)
    assert energy._evaluated == (count if evaluated == "limit" else 6)  # the engine taken
    consts = generated_constants(P_BEARING)
    for i, j in np.ndindex(2, 3):
        args = (*x[i, j].tolist(), 22e-3, 2e3**2, float(v2[j]) ** 2, *consts)
        assert np.array_equal(grad[i, j], _generated.grad_terms(*args)[0])
        assert np.array_equal(hess[i, j], np.array(_generated.hess_terms(*args))[HESS_INDEX])
