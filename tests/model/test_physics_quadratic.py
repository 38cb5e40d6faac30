"""The full model's large-signal DE force as a scaled analytical curve: ``physics_quadratic``.

Eq. 37's input force g_i(q) h(v_i) is separable; the full model's is not (Fig. 4: the DEs' pull
bends the beam off the v = 0 path). Its second order in h = v^2, g_h,i(q), is computed from the
held-voltage force-displacement curves of the analytical model, and the term
``s_gh,i g_h,phys,i(q) h(v_i)^2`` is linear in its scale. Checked here: the second-order fit
against the force-displacement curves at a voltage it did not use, the acceleration against the
balance by hand, the fit against noise-free data of a model with the term, the static force, the
model file and the configuration (the compiled kernel against the NumPy engine:
``tests/model/test_input_quadratic.py``).
"""

from dataclasses import replace

import numpy as np
import pytest

from debist.core.errors import WorkflowError
from debist.identify.config import IdentifyConfig
from debist.identify.fit import fit_rbf_model
from debist.model.rbf import RBFModel
from debist.model.terms import PhysicsPrior
from tests.conftest import (
    INSIDE_CLASS,
    computed_once,
    random_states,
    truth_model,
    with_physics_quadratic,
)
from tests.model.conftest import curve_error, truth_and_record

S_GH = np.array([0.7, 1.3])


@pytest.fixture(scope="module")
def curved(tmp_path_factory):
    """The truth with the term and its noise-free record (inside the model class); computed
    once for all pytest-xdist workers."""
    return computed_once(tmp_path_factory, "physics-quadratic", _curved)


def _curved():
    return truth_and_record(lambda truth: with_physics_quadratic(truth, S_GH))


def test_the_second_order_reproduces_the_held_voltage_curves_at_a_voltage_it_did_not_use():
    """On the paper's prototype, ``F(q; 0) - F(q; v_1)`` at 2.2 kV (the fit used 0.5-3 kV in
    steps of 0.5 kV) is ``g_1 v^2 + g_h,1 v^4`` to 3 % of its largest value (g_1 = 1/2 dC_1/dq
    of the reduced model; measured 2.0 %), and the separable ``g_1 v^2`` alone is off by more
    than 10 % (measured 17 %); DE 2's curve is minus DE 1's mirrored (the symmetric prototype)."""
    from debist.identify.physics_prior import quadratic_force
    from debist.physics.params import PrototypeParams
    from debist.physics.reduced import reduced_curves
    from debist.physics.statics import force_displacement

    physics = PrototypeParams(b=23e-3)
    q = np.linspace(-0.015, 0.015, 61)
    gh = quadratic_force(physics, q, 3000.0)
    v = 2200.0
    delta = force_displacement(physics, q).F - force_displacement(physics, q, v1=v).F
    g1 = reduced_curves(physics, q).g1
    scale = np.max(np.abs(delta))
    assert np.max(np.abs(g1 * v**2 + gh[:, 0] * v**4 - delta)) < 0.03 * scale
    assert np.max(np.abs(g1 * v**2 - delta)) > 0.1 * scale
    with pytest.raises(WorkflowError) as err:
        quadratic_force(physics, q, 0.0)
    assert "positive" in str(err.value) and "voltage" in str(err.value)
    np.testing.assert_allclose(gh[:, 1], -gh[::-1, 0], rtol=1e-6, atol=1e-6 * np.abs(gh).max())


def test_the_acceleration_adds_the_scaled_curve_times_h_squared():
    truth = truth_model(np.random.default_rng(2))
    model = with_physics_quadratic(truth, S_GH)
    q, q_dot, v = random_states(3)
    curve = np.column_stack([np.interp(q, model.prior.q, c) for c in model.prior.gh.T])
    want = truth.accel(q, q_dot, v) + np.sum(S_GH * curve * v**4, axis=1) / truth.m_q
    np.testing.assert_allclose(model.accel(q, q_dot, v), want, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(model.quadratic_gain(q), S_GH * curve, rtol=1e-12)
    names, values = model.parameters()
    np.testing.assert_array_equal(values[[names.index("physics_quadratic1"),
                                          names.index("physics_quadratic2")]], S_GH)  # fmt: skip


def test_the_fit_recovers_the_scales_and_the_curves_it_would_bias(curved):
    """With the term the scales come back to 1e-9 (noise-free data with the exact q''); without
    it the same data bias g_i and c(q) q by more than 5 % of their largest magnitude."""
    truth, record = curved
    base = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0}
    with_term = {**base, "backbone": [*base["backbone"], "physics_quadratic"]}
    model, diag = fit_rbf_model([record], replace(IdentifyConfig.from_dict(with_term),
                                                  prior=truth.prior))  # fmt: skip
    assert diag.columns[-2:] == ["physics_quadratic1", "physics_quadratic2"]
    np.testing.assert_allclose(model.backbone["s_gh"], S_GH, rtol=1e-9)
    assert curve_error(model, truth) < 1e-9
    level = np.array([900.0, 400.0])
    grid = np.linspace(-0.012, 0.012, 50)
    np.testing.assert_allclose(
        model.static_force(grid, level),
        truth.static_force(grid, level),
        rtol=0,
        atol=1e-9 * np.abs(truth.static_force(grid, level)).max(),
    )
    without, _ = fit_rbf_model([record], IdentifyConfig.from_dict(base))
    assert curve_error(without, truth) > 0.05


def test_the_model_file_keeps_the_scales_and_a_prior_without_the_curve_keeps_its_bytes():
    model = with_physics_quadratic(truth_model(np.random.default_rng(2)), S_GH)
    back = RBFModel.from_tree(model.to_tree())
    np.testing.assert_array_equal(back.backbone["s_gh"], S_GH)
    np.testing.assert_array_equal(back.prior.gh, model.prior.gh)
    plain = replace(model.prior, gh=None)
    assert "gh" not in plain.to_tree() and PhysicsPrior.from_tree(plain.to_tree()).gh is None
    with pytest.raises(Exception) as err:
        plain.quadratic()
    assert "-order DE" in str(err.value)


def test_the_term_needs_h_equal_v_squared():
    with pytest.raises(WorkflowError) as err:
        IdentifyConfig.from_dict({"backbone": ["physics_quadratic"], "input_map": "v"})
    assert "input_map" in str(err.value)
    assert "v2" in str(err.value)
