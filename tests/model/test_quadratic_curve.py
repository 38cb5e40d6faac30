"""The input force's second order in h(v) as a curve of q: the RBF term ``gh``.

``input_quadratic`` adds one coefficient g_h,i per input; on a DE actuator the departure of the
large-signal force from Eq. 37's separable g_i(q) h(v_i) depends on q (Fig. 4: the force change
at 3 kV is 72 % of g_i(q) h(v_i) near q = 0 and 95-100 % in the wells on the paper's prototype).
The RBF term ``gh`` writes it as ``g_h,i(q) h(v_i)^2 = Phi(q) theta_gh,i h(v_i)^2``; g_i stays the
small-signal gain. Checked here against independent computations: the acceleration against the
balance by hand, the fit against data of a model with known g_h,i(q), the static force and the
bands' linear map of it and the model file (the compiled kernel against the NumPy engine:
``tests/model/test_input_quadratic.py``).
"""

import numpy as np
import pytest

from debist.core.errors import WorkflowError
from debist.identify.bands import curve_maps
from debist.identify.config import IdentifyConfig
from debist.identify.fit import fit_rbf_model
from debist.model.rbf import RBFModel
from tests.conftest import (
    INSIDE_CLASS,
    computed_once,
    quadratic_curve_weights,
    random_states,
    truth_model,
    with_quadratic_curve,
)
from tests.model.conftest import curve_error, truth_and_record

_theta_gh = quadratic_curve_weights
_with_curve = with_quadratic_curve


@pytest.fixture(scope="module")
def curved(tmp_path_factory):
    """The truth with g_h,i(q) and its noise-free record (inside the model class); computed
    once for all pytest-xdist workers."""
    return computed_once(tmp_path_factory, "quadratic-curve", lambda: truth_and_record(_with_curve))


def test_the_acceleration_adds_phi_theta_gh_h_squared_to_the_separable_balance():
    truth = truth_model(np.random.default_rng(2))
    model = _with_curve(truth)
    q, q_dot, v = random_states(3)
    by_hand = np.sum(truth.basis(q) @ _theta_gh(truth.basis).T * v**4, axis=1)
    want = truth.accel(q, q_dot, v) + by_hand / truth.m_q
    np.testing.assert_allclose(model.accel(q, q_dot, v), want, rtol=1e-12, atol=1e-12)
    assert {"gh1[0]", "gh2[7]"} <= set(model.parameters()[0])
    np.testing.assert_allclose(model.quadratic_gain(q), truth.basis(q) @ model.theta_gh.T)


def test_the_fit_recovers_g_h_of_q_and_the_small_signal_gains_it_would_bias(curved):
    """With ``gh`` the curves and g_h,i(q) come back to rounding (noise-free data with the exact
    q'', inside the model class); without it the same data bias g_i and c(q) q by more than 10 %
    of their largest magnitude, and a constant ``input_quadratic`` cannot take its place."""
    truth, record = curved
    base = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0}
    model, diag = fit_rbf_model(
        [record], IdentifyConfig.from_dict({**base, "rbf": ["c", "d", "g", "gh"]})
    )
    assert diag.columns[-16:] == [f"gh{j}[{i}]" for j in (1, 2) for i in range(8)]
    grid = np.linspace(-0.012, 0.012, 50)
    want = truth.quadratic_gain(grid)
    assert np.max(np.abs(model.quadratic_gain(grid) - want)) < 1e-9 * np.max(np.abs(want))
    assert curve_error(model, truth) < 1e-9
    without, _ = fit_rbf_model([record], IdentifyConfig.from_dict(base))
    assert curve_error(without, truth) > 0.1
    constant = {**base, "backbone": [*base["backbone"], "input_quadratic"]}
    assert curve_error(fit_rbf_model([record], IdentifyConfig.from_dict(constant))[0], truth) > 0.01


def test_the_static_force_has_g_h_of_q_and_is_the_bands_map(curved):
    """The static force at a held level is ``c q - g h - g_h(q) h^2`` (by hand), and the bands'
    linear map of it times the parameters is the same curve; the gain maps leave g_h out."""
    truth, record = curved
    cfg = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0, "rbf": ["c", "d", "g", "gh"]}
    model, diag = fit_rbf_model([record], IdentifyConfig.from_dict(cfg))
    level = np.array([900.0, 400.0])
    grid = np.linspace(-0.03, 0.03, 301)
    cur = truth.curves(grid)
    by_hand = cur["cq"] - cur["g"] @ level**2 - truth.quadratic_gain(grid) @ level**4
    scale = np.max(np.abs(by_hand))
    np.testing.assert_allclose(truth.static_force(grid, level), by_hand, rtol=0, atol=1e-12 * scale)
    maps = curve_maps(diag.columns, grid, model.basis, 2, "v2", model.coulomb_velocity,
                      level=level**2)  # fmt: skip
    np.testing.assert_allclose(maps["F"] @ diag.theta, model.static_force(grid, level),
                               rtol=0, atol=1e-9 * scale)  # fmt: skip
    np.testing.assert_allclose(maps["g1"] @ diag.theta, model.curves(grid)["g"][:, 0], rtol=1e-9)


def test_the_model_file_keeps_theta_gh_and_a_model_without_it_keeps_its_bytes():
    truth = truth_model(np.random.default_rng(2))
    back = RBFModel.from_tree(_with_curve(truth).to_tree())
    np.testing.assert_array_equal(back.theta_gh, _theta_gh(truth.basis))
    assert "theta_gh" not in truth.to_tree()["model"]
    assert RBFModel.from_tree(truth.to_tree()).theta_gh is None
    assert back.scaled(2.0).theta_gh[0, 0] == 2.0 * back.theta_gh[0, 0]


def test_gh_alone_is_not_an_input_term():
    """The small-signal gain must come from somewhere: ``gh`` without ``g``, ``input_gain`` or
    ``physics_gain`` is refused."""
    with pytest.raises(WorkflowError) as err:
        IdentifyConfig.from_dict({**INSIDE_CLASS, "rbf": ["c", "d", "gh"]})
    assert "input" in str(err.value) and "term" in str(err.value)
