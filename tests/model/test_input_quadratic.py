"""An input force quadratic in h(v): the backbone term ``input_quadratic``, g_h,i h(v_i)^2.

Eq. 37's input force g_i(q) h(v_i) is separable; the full model's is not: the DEs' pull bends
the beam off the v = 0 path, so the force change at 3 kV is 72-97 % of g_i(q) h(v_i) between
q = 0 and the wells (Fig. 4). The term is the next order of the input force's expansion in
h(v); g_i stays the small-signal gain (the coefficient of h(v_i)). Checked here: the
acceleration against the balance by hand, the fit against data of a model with a known g_h,
the static force against the dynamic model at rest, the bands' linear map of the static force,
the model file, and the compiled kernel against the NumPy engine.
"""

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import brentq

from debist.identify.bands import curve_maps
from debist.identify.config import IdentifyConfig
from debist.identify.fit import fit_rbf_model
from debist.model.rbf import RBFModel
from debist.simulate.freerun import simulate
from tests.conftest import (
    INSIDE_CLASS,
    computed_once,
    excitation,
    random_states,
    truth_model,
    with_physics_quadratic,
    with_quadratic,
    with_quadratic_curve,
)
from tests.model.conftest import curve_error, truth_and_record

#: g_h,i per unit mass [m/s^2 / V^4] (:func:`conftest.with_quadratic`'s): at 2.5 kV -0.23 and
#: +0.20 m/s^2, about a fifth of the truth's g_i h(v_i) there, each against its gain's sign.
G_H = np.array([-6e-15, 5e-15])
_with_quadratic = with_quadratic


@pytest.fixture(scope="module")
def quadratic(tmp_path_factory):
    """The truth with :data:`G_H` and its noise-free record (once for all xdist workers)."""
    return computed_once(
        tmp_path_factory, "input-quadratic", lambda: truth_and_record(_with_quadratic)
    )


def test_the_acceleration_adds_g_h_h_squared_to_the_separable_balance():
    truth = truth_model(np.random.default_rng(2))
    model = _with_quadratic(truth)
    q, q_dot, v = random_states(3)
    want = truth.accel(q, q_dot, v) + (v**4 @ G_H) / truth.m_q
    np.testing.assert_allclose(model.accel(q, q_dot, v), want, rtol=1e-12, atol=1e-12)
    assert "input_quadratic1" in model.parameters()[0]


def test_the_fit_recovers_g_h_and_the_small_signal_gains_it_would_bias(quadratic):
    """With ``input_quadratic`` g_h and the curves come back to rounding (measured 1.3e-14 and
    4.7e-15: noise-free data with the exact q'', inside the model class); without it, the same
    data bias g_i and c(q) q by 21 % of their largest magnitude (asserted 10 %)."""
    truth, record = quadratic
    base = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0}
    quadratic = {**base, "backbone": [*base["backbone"], "input_quadratic"]}
    model, diag = fit_rbf_model([record], IdentifyConfig.from_dict(quadratic))
    assert diag.columns[-2:] == ["input_quadratic1", "input_quadratic2"]
    np.testing.assert_allclose(model.backbone["g_h"], G_H, rtol=1e-9)
    assert curve_error(model, truth) < 1e-9
    without, _ = fit_rbf_model([record], IdentifyConfig.from_dict(base))
    assert curve_error(without, truth) > 0.1


def test_the_static_force_vanishes_where_the_dynamic_model_rests_and_is_the_bands_map(quadratic):
    """A zero of ``static_force`` at a held level is a rest point of ``accel`` (z = q_dot = 0),
    and the bands' linear map of the static force times the parameters is the same curve."""
    _, record = quadratic
    cfg = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0}
    cfg["backbone"] = [*cfg["backbone"], "input_quadratic"]
    model, diag = fit_rbf_model([record], IdentifyConfig.from_dict(cfg))
    level = np.array([900.0, 400.0])
    grid = np.linspace(-0.03, 0.03, 601)
    force = model.static_force(grid, level)
    maps = curve_maps(diag.columns, grid, model.basis, 2, "v2", model.coulomb_velocity,
                      level=level**2)  # fmt: skip
    np.testing.assert_allclose(maps["F"] @ diag.theta, force, rtol=1e-9, atol=1e-9)
    roots = np.flatnonzero(np.sign(force[:-1]) != np.sign(force[1:]))
    assert roots.size >= 1
    for i in roots:
        q_star = brentq(lambda x: model.static_force(np.array([x]), level)[0], grid[i], grid[i + 1])
        rest = model.accel(np.array([q_star]), np.zeros(1), level[None, :])[0]
        scale = np.max(np.abs(force))
        assert abs(rest) <= 1e-9 * scale
    # the small-signal gains leave g_h out: the static force differs from the separable one
    separable = grid * model.curves(grid)["c"] - model.curves(grid)["g"] @ level**2
    np.testing.assert_allclose(force - separable, -(level**4) @ model.backbone["g_h"], rtol=1e-9)


def test_the_model_file_keeps_g_h_and_a_model_without_it_keeps_its_bytes():
    truth = truth_model(np.random.default_rng(2))
    back = RBFModel.from_tree(_with_quadratic(truth).to_tree())
    np.testing.assert_array_equal(back.backbone["g_h"], G_H)
    assert "g_h" not in truth.to_tree()["model"]["backbone"]
    assert "g_h" not in RBFModel.from_tree(truth.to_tree()).backbone


@pytest.mark.parametrize(
    "term",
    [with_quadratic, with_quadratic_curve, with_physics_quadratic],
    ids=["constant", "gh", "physics_quadratic"],
)
@pytest.mark.parametrize("T_z", [0.0, 0.02])
def test_the_compiled_kernel_runs_the_quadratic_term_like_the_numpy_engine(T_z, term):
    """The term is h(v)^2 in the term table's input powers (one coefficient, the RBF curve
    ``gh`` or the scaled analytical curve of ``physics_quadratic``): the compiled kernel reads
    it from the same arrays (to 1e-12 of the NumPy engine), and the term changes the runs."""
    truth = replace(truth_model(np.random.default_rng(2)), T_z=T_z)
    model = term(truth)
    assert model.table_model().table.term_hpow.max() == 2
    v = [excitation(np.arange(0.0, 6.0, 0.002))]
    q0, qd0 = np.array([-0.01]), np.zeros(1)
    ref = simulate(model, v, 0.002, q0, qd0, engine="numpy")[0]
    new = simulate(model, v, 0.002, q0, qd0, engine="compiled")[0]
    assert not ref.diverged and np.ptp(ref.q) > 5e-3
    np.testing.assert_allclose(new.q, ref.q, rtol=0, atol=1e-12 * np.max(np.abs(ref.q)))
    # the same model without the term, on the engine just checked against the NumPy one
    plain = simulate(truth, v, 0.002, q0, qd0, engine="compiled")[0]
    assert np.max(np.abs(plain.q - ref.q)) > 1e-3 * np.ptp(ref.q)
