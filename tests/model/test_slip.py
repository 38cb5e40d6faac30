"""Generalised Maxwell-slip friction as identified terms (Al-Bender, Lampaert & Swevers 2005).

The elements' deflections are stop operators of q; with their break-away deflections on a
fixed grid the friction force is linear in the element stiffnesses, which the least squares
of Eq. 40 identifies. Checked here: the stop operator against the play operator written
independently, the two free-run engines against each other, the fit against data of a model
with known elements, and the configuration, the model file and the refusals.
"""

from dataclasses import replace

import numpy as np
import pytest

from debist.core.errors import WorkflowError
from debist.identify.config import IdentifyConfig
from debist.identify.fit import fit_rbf_model, slip_widths
from debist.model.friction import slip_clip, slip_state_rate, slip_states
from debist.model.rbf import RBFModel
from debist.simulate.freerun import simulate
from debist.simulate.kernel import kernel_arrays
from tests.conftest import (
    INSIDE_CLASS,
    SLIP_WIDTHS,
    example_rbf_model,
    slip_record,
    truth_model,
    with_slip,
)
from tests.model.conftest import curve_error

WIDTHS = SLIP_WIDTHS


def _play(q: np.ndarray, width: float) -> np.ndarray:
    """The play (backlash) operator of q, p = max(q - w, min(q + w, p_prev)), from p = q[0]."""
    out = np.empty_like(q)
    p = q[0]
    for k, x in enumerate(q):
        p = max(x - width, min(x + width, p))
        out[k] = p
    return out


def test_slip_states_are_the_stop_operator_of_the_integrated_velocity():
    """delta = q - play(q) for the trapezoidal q, |delta| <= Delta, and an element wider than
    the whole motion follows q exactly."""
    rng = np.random.default_rng(4)
    dt = 0.01
    q_dot = np.convolve(rng.standard_normal(3000), np.ones(40) / 40, mode="same") * 0.02
    q = np.concatenate([[0.0], np.cumsum(0.5 * dt * (q_dot[1:] + q_dot[:-1]))])
    widths = np.array([1e-4, 1e-3, 10.0])
    delta = slip_states(q_dot, dt, widths)
    for e, width in enumerate(widths):
        np.testing.assert_allclose(delta[:, e], q - _play(q, width), rtol=0, atol=1e-15)
        assert np.max(np.abs(delta[:, e])) <= width
    assert np.max(np.abs(delta[:, 0])) == pytest.approx(1e-4)  # it slips
    np.testing.assert_allclose(delta[:, 2], q, atol=1e-15)  # never reaches 10 m
    with pytest.raises(ValueError) as err:
        slip_states(q_dot, dt, np.array([0.0]))
    assert "positive" in str(err.value)


def test_the_compiled_stop_operator_is_the_numpy_recursion_with_slip_clip_bit_for_bit():
    """slip_states runs the compiled loop (debist.model.slip_kernel); the same recursion in
    NumPy with friction.slip_clip, written here, gives the same bits, a NaN included."""
    rng = np.random.default_rng(11)
    dt = 1e-3
    q_dot = np.cumsum(rng.standard_normal(5000)) * 1e-3
    q_dot[4000] = np.nan  # a NaN propagates as np.maximum propagates it
    widths = np.array([3e-7, 2e-6, 5e-5, 1.0])
    step = 0.5 * dt * (q_dot[1:] + q_dot[:-1])
    expected = np.zeros((q_dot.size, widths.size))
    delta = np.zeros(widths.size)
    for k, dq in enumerate(step):
        delta = slip_clip(delta + dq, widths)
        expected[k + 1] = delta
    got = slip_states(q_dot, dt, widths)
    assert got.shape == (5000, 4)
    np.testing.assert_array_equal(got, expected)
    assert np.isnan(got[4000:]).all() and np.isfinite(got[:4000]).all()
    assert np.abs(got[:4000, 0]).max() == 3e-7  # the narrow element slips


def test_an_element_sticks_until_break_away_then_slips_until_the_motion_reverses():
    width = 1e-3
    assert slip_state_rate(0.2, 0.5e-3, width) == 0.2  # inside: it deflects with q
    assert slip_state_rate(0.2, 1e-3, width) == 0.0  # at break-away, loading: it slips
    assert slip_state_rate(-0.2, 1e-3, width) == -0.2  # unloading: it sticks again
    assert slip_state_rate(-0.2, -1e-3, width) == 0.0
    np.testing.assert_array_equal(
        slip_clip(np.array([2e-3, -3e-3, 1e-4]), width), np.array([1e-3, -1e-3, 1e-4])
    )


def _inputs(n, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    f = rng.uniform(0.1, 1.0, size=2)
    return np.stack([1500 + 900 * np.sin(2 * np.pi * f[i] * t + i) for i in range(2)], axis=1)


@pytest.mark.parametrize(("T_z", "substeps"), [(0.02, 1), (0.0, 3)])
def test_a_model_with_slip_elements_in_both_engines_and_its_term_table(T_z, substeps):
    """The slip states follow z (and creep): the model's rhs, its term table and the compiled
    kernel (serial and lock-step) agree to 1e-12; the elements load to their break-away
    deflections and never past them, and their force changes the trajectory."""
    model = with_slip(example_rbf_model(T_z))
    assert model.n_states == 6 and kernel_arrays(model).n_states == 6
    records = [_inputs(1500, 0), _inputs(900, 1), _inputs(700, 2)]
    q0, qd0 = np.array([-0.01, 0.009, 0.0]), np.array([0.0, 0.01, 0.0])
    ref = simulate(model, records, 0.01, q0, qd0, engine="numpy", substeps=substeps)
    new = simulate(model, records, 0.01, q0, qd0, engine="compiled", substeps=substeps)
    one = simulate(model, records[:1], 0.01, q0[:1], qd0[:1], engine="compiled", substeps=substeps)
    table = simulate(model.table_model(), records, 0.01, q0, qd0, engine="numpy", substeps=substeps)
    for a, b, c in zip(ref, new, table, strict=True):
        assert not a.diverged
        scale = np.max(np.abs(a.states), axis=0)
        assert np.all(np.abs(a.states - b.states) <= 1e-12 * scale)
        assert np.all(np.abs(a.states - c.states) <= 1e-12 * scale)
    np.testing.assert_array_equal(one[0].states, new[0].states)
    delta = ref[0].states[:, 3:]
    assert np.all(delta[0] == 0.0)
    assert np.all(np.abs(delta) <= np.array(WIDTHS) * (1 + 1e-12))
    assert np.max(np.abs(delta[:, 0])) == pytest.approx(WIDTHS[0])  # the narrow one slips
    plain = simulate(example_rbf_model(T_z), records[:1], 0.01, q0[:1], qd0[:1], substeps=substeps)
    assert np.max(np.abs(plain[0].q - ref[0].q)) > 1e-4  # the friction force matters


def test_the_fit_recovers_element_stiffnesses_and_the_curves_they_would_bias():
    """Data of a model with three elements (k = 400, 150, 40 N/m per unit mass): with
    ``slip`` at the true deflections the stiffnesses come back to 0.2 % and the curves to
    0.1 % (measured 0.04 % and 0.02 %); without, the same data bias the curves by 56 %."""
    truth = with_slip(truth_model(np.random.default_rng(2)))
    record, x = slip_record(truth)
    assert np.max(np.abs(x[:, 3])) == pytest.approx(WIDTHS[0])  # the elements slip
    base = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0}
    model, diag = fit_rbf_model([record], IdentifyConfig.from_dict({**base, "slip": WIDTHS}))
    assert diag.columns[16:19] == ["slip[0]", "slip[1]", "slip[2]"]
    assert model.slip_width == WIDTHS
    np.testing.assert_allclose(model.theta_slip, truth.theta_slip, rtol=2e-3)
    without, _ = fit_rbf_model([record], IdentifyConfig.from_dict(base))
    assert curve_error(model, truth) < 1e-3
    assert curve_error(without, truth) > 100 * curve_error(model, truth)
    elements = model.slip_elements()
    np.testing.assert_allclose(elements["F"], elements["k"] * np.array(WIDTHS))
    assert elements["k_total"] == pytest.approx(sum(truth.theta_slip), rel=2e-3)


def test_slip_config_the_default_grid_and_the_model_file():
    """`slip` is false, a count or ascending deflections; a count spreads the deflections
    geometrically over 1.5e-4 .. 1e-2 of the range; model.h5 keeps the elements."""
    for bad in (True, 0.5, [2e-5, 1e-5], [-1e-6], 21):
        with pytest.raises(WorkflowError) as err:
            IdentifyConfig.from_dict({"slip": bad})
        assert err.value.key == "identify.slip"
        assert "expected" in str(err.value)
    assert IdentifyConfig.from_dict({}).slip is False
    from debist.core.preflight import identify_columns

    plain_cols = identify_columns(IdentifyConfig.from_dict({}), 2)[0]
    assert identify_columns(IdentifyConfig.from_dict({"slip": 4}), 2)[0] == plain_cols + 4
    two = IdentifyConfig.from_dict({"slip": [1e-6, 1e-5]})
    assert two.n_slip == 2 and identify_columns(two, 2)[0] == plain_cols + 2
    widths = slip_widths(3, (-0.01, 0.01))
    np.testing.assert_allclose(widths, [3e-6, 3e-6 * np.sqrt(1e-2 / 1.5e-4), 2e-4])
    assert slip_widths([1e-6, 2e-6], (0, 1)) == (1e-6, 2e-6)
    model = with_slip(example_rbf_model())
    again = RBFModel.from_tree(model.to_tree())
    assert again.slip_width == WIDTHS and np.array_equal(again.theta_slip, model.theta_slip)
    assert again.n_params == model.n_params == example_rbf_model().n_params + 3
    assert "slip" not in example_rbf_model().to_tree()["model"]
    q = np.linspace(0, 1e-2, 50)
    states = again.measured_states(q, np.full(50, 1e-2 / 49 / 0.01), 0.01)
    np.testing.assert_allclose(states[:, 3:], np.minimum(q[:, None], WIDTHS), atol=1e-15)


def test_the_refinement_moves_biased_element_stiffnesses_to_the_truth():
    """Least squares on derivatives with seeded correlated noise bias the stiffnesses (525 /
    77 / 36 against 400 / 150 / 40 N/m); the simulation-error refinement, with the slip
    states' sensitivities and windows restarted from the exact states, brings them back to
    0.1 % (measured 0.01 %) and the free run's error down by 100x (measured 800x)."""
    from debist.identify.refine import RefineConfig, refine_model

    truth = with_slip(truth_model(np.random.default_rng(2)))
    record, _ = slip_record(truth)
    noise = np.convolve(np.random.default_rng(5).standard_normal(record.q.size), np.ones(15) / 15,
                        mode="same")  # fmt: skip
    noisy = replace(
        record,
        q_dot=record.q_dot + 0.3 * np.std(record.q_dot) * noise,
        q_ddot=record.q_ddot + 0.3 * np.std(record.q_ddot) * np.gradient(noise) * 15,
    )
    cfg = IdentifyConfig.from_dict({**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 0, "slip": WIDTHS})
    model, diag = fit_rbf_model([noisy], cfg)
    assert np.max(np.abs(model.theta_slip / truth.theta_slip - 1)) > 0.2  # biased
    res = refine_model(model, diag, [record], cfg, RefineConfig(windows=20, length=300))
    assert res.accepted, res.message
    assert res.model.slip_width == WIDTHS
    np.testing.assert_allclose(res.model.theta_slip, truth.theta_slip, rtol=1e-3)
    assert res.full_rms_refined < 0.01 * res.full_rms_ls


def test_the_restoring_band_holds_the_slip_force_the_elements_can_hold_at_rest():
    """The elements hold the beam at rest against any static force up to sum k_e Delta_e, so
    the restoring band reaches at least that far to each side (with the Coulomb level)."""
    from debist.identify.bands import curves_frame, friction_bound

    truth = with_slip(truth_model(np.random.default_rng(2)))
    record, _ = slip_record(truth)
    cfg = {**INSIDE_CLASS, "T_z": 0.0, "bootstrap": 50, "bootstrap_seed": 1, "slip": WIDTHS}
    model, diag = fit_rbf_model([record], IdentifyConfig.from_dict(cfg))
    held = float(np.dot(model.theta_slip, WIDTHS))
    assert held == pytest.approx(float(np.dot(truth.theta_slip, WIDTHS)), rel=2e-3)  # 0.33
    assert friction_bound(model) == pytest.approx(held + abs(model.backbone.get("F_c", 0.0)))
    frame, _ = curves_frame(model, diag, [record], min_support=1.0, band_tolerance=10.0)
    assert np.all(frame.restoring - frame.restoring_lo >= held * (1 - 1e-12))
    assert np.all(frame.restoring_hi - frame.restoring >= held * (1 - 1e-12))
