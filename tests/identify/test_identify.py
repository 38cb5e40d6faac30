import re

import numpy as np
import pytest

from debist.core.errors import IdentificationError, WorkflowError
from debist.identify.config import IdentifyConfig
from debist.identify.fit import Record, fit_rbf_model
from debist.model.basis import RBFBasis
from debist.model.friction import friction_state
from debist.model.rbf import RBFModel
from debist.model.terms import force_columns, force_table, input_columns
from debist.model.termtable import input_map
from tests.conftest import INSIDE_CLASS, bistable_truth, truth_model


def test_basis_is_eq38_with_equidistant_centres():
    b = RBFBasis.equidistant(-0.012, 0.012, M=10, sigma_n=0.5, outside="zero")
    delta = 0.024 / 9
    assert b.sigma == pytest.approx(0.5 * delta)
    phi = b(np.array([b.xi[3], b.xi[3] + b.sigma]))
    assert phi[0, 3] == pytest.approx(1.0)
    assert phi[1, 3] == pytest.approx(np.exp(-0.5))
    assert phi[0, 4] == pytest.approx(np.exp(-(delta**2) / (2 * b.sigma**2)))
    # clipping holds the basis at the edge; "zero" lets it decay
    clip = RBFBasis(b.xi, b.sigma, "clip")
    assert np.allclose(clip(np.array([1.0])), clip(np.array([b.xi[-1]])))
    assert b(np.array([1.0])).max() < 1e-100


def test_friction_state_exact_for_piecewise_linear_velocity():
    # reference: the continuous filter integrated with a fine step on the linear interpolant
    from scipy.integrate import solve_ivp

    rng = np.random.default_rng(3)
    dt, T_z = 0.01, 0.037
    qd = rng.standard_normal(60)
    t = np.arange(qd.size) * dt
    sol = solve_ivp(
        lambda tt, z: (np.interp(tt, t, qd) - z) / T_z,
        (0, t[-1]),
        [qd[0]],
        t_eval=t,
        rtol=1e-11,
        atol=1e-12,
        max_step=dt / 20,
    )
    assert np.allclose(friction_state(qd, dt, T_z), sol.y[0], atol=1e-8)
    assert np.array_equal(friction_state(qd, dt, 0.0), qd)


def _fit(rec, **kw):
    cfg = IdentifyConfig.from_dict({"M": 10, "sigma_n": 0.5, "T_z": 0.0, **kw})
    records = [Record("sim", rec["q"], rec["q_dot"], rec["q_ddot"], rec["v"], rec["dt"])]
    return fit_rbf_model(records, cfg)


def test_rbf_fit_approximates_smooth_curves(bistable_record):
    """Truth outside the model class (polynomial curves): c(q) q within 1 % of its range."""
    model, diag = _fit(
        bistable_record, backbone=["linear_spring", "cubic_spring", "viscous"], max_condition=1e10
    )
    assert diag.rank == len(diag.columns)
    assert diag.fit_r2 > 0.9999
    q = np.linspace(*model.q_range, 101)[5:-5]
    truth = bistable_truth(q)
    assert np.max(np.abs(model.curves(q)["cq"] - truth["c"] * q)) < 1e-2 * np.ptp(truth["c"] * q)


def _curve_errors(truth, model, q):
    grid = np.linspace(q.min(), q.max(), 50)
    want, got = truth.curves(grid), model.curves(grid)
    return {k: np.max(np.abs(got[k] - want[k])) / np.max(np.abs(want[k])) for k in ("cq", "d", "g")}


def test_rbf_fit_recovers_exact_weights_noise_free(inside_class):
    """Data from a model inside the class (solve_ivp, exact q''): weights recovered to 1e-6."""
    truth, rec = inside_class
    model, diag = _fit(rec, **INSIDE_CLASS)
    assert diag.rank == len(diag.columns)
    assert diag.fit_r2 > 1 - 1e-12
    for key, err in _curve_errors(truth, model, rec["q"]).items():
        assert err < 1e-6, key


def test_lowpass_keeps_the_weights_and_rejects_an_unmodelled_mode(inside_class):
    """Filtered equation error: the filter is linear, so exact data still give the exact
    weights. Then an actuator force that is 40 % weaker above 30 Hz (a second mode the
    one-coordinate model cannot represent) biases the unfiltered fit; a 10 Hz low-pass
    keeps only the band where Eq. 37 holds and recovers the curves."""
    from scipy import signal

    truth, rec = inside_class
    model, _ = _fit(rec, lowpass=10.0, **INSIDE_CLASS)
    for key, err in _curve_errors(truth, model, rec["q"]).items():
        assert err < 1e-5, key
    # Eq. 40 is algebraic per sample: broadband inputs with the exact accelerations
    rng = np.random.default_rng(11)
    v = np.abs(rec["v"] + 150.0 * rng.standard_normal(rec["v"].shape))
    q_ddot = truth.accel(rec["q"], rec["q_dot"], v)
    force = truth.curves(rec["q"])["g"] * v**2
    sos = signal.butter(8, 30.0, btype="highpass", fs=1.0 / rec["dt"], output="sos")
    weak = -0.4 * signal.sosfiltfilt(sos, force.sum(axis=1))
    disturbed = {**rec, "v": v, "q_ddot": q_ddot + weak}
    raw = _curve_errors(truth, _fit(disturbed, **INSIDE_CLASS)[0], rec["q"])
    filtered = _curve_errors(truth, _fit(disturbed, lowpass=10.0, **INSIDE_CLASS)[0], rec["q"])
    assert max(filtered.values()) < 1e-3  # measured 3e-5
    assert raw["g"] > 0.1  # measured 0.20: the gain absorbs the weak band


def test_lowpass_at_or_above_nyquist_is_an_error_naming_the_data_set(bistable_record):
    with pytest.raises(IdentificationError) as err:
        _fit(bistable_record, lowpass=250.0)
    assert "'sim'" in str(err.value)
    assert "lowpass = 250 Hz" in str(err.value)
    assert err.value.reason == "nyquist" and "Nyquist" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        IdentifyConfig.from_dict({"lowpass": -1.0})
    assert err.value.key == "identify.lowpass"
    assert "> 0" in str(err.value)


def test_T_z_search_recovers_the_time_constant(bistable_record):
    """Friction acting on z (Eq. 37), model inside the class: the outer search finds T_z."""
    truth = truth_model(np.random.default_rng(4))
    T_true = 0.03
    q, q_dot, v, dt = (bistable_record[k] for k in ("q", "q_dot", "v", "dt"))
    z = friction_state(q_dot, dt, T_true)
    rec = {"q": q, "q_dot": q_dot, "q_ddot": truth.accel(q, z, v), "v": v, "dt": dt}
    model, diag = _fit(
        rec,
        M=8,
        q_range=[-0.03, 0.03],
        min_support=0,
        backbone=["linear_spring", "cubic_spring", "viscous"],
        T_z="search",
        T_z_bounds=[0.002, 1.0],
        max_condition=1e10,
    )
    assert model.T_z == pytest.approx(T_true, rel=0.02)
    assert diag.T_z_trace.shape[1] == 2 and diag.T_z_trace.shape[0] > 5
    assert diag.T_z_trace[:, 1].min() < 1e-4


def test_model_accel_equals_regressor_row(bistable_record):
    """The simulator's fast path and the regression matrix are independent codes of Eq. 37."""
    model, _ = _fit(
        bistable_record,
        backbone=["linear_spring", "cubic_spring", "viscous", "offset", "input_gain"],
    )
    rng = np.random.default_rng(1)
    q = rng.uniform(-0.015, 0.015, 50)
    z = rng.standard_normal(50) * 0.05
    v = rng.uniform(0, 3000, (50, 2))
    F, _ = force_columns(
        q, z, model.basis, ("c", "d"), ("linear_spring", "cubic_spring", "viscous", "offset"), 1e-3
    )
    G, _ = input_columns(q, input_map(v, "v2"), model.basis, ("g",), ("input_gain",))
    bb = model.backbone
    theta_F = np.concatenate(
        [model.theta_c, model.theta_d, [bb["k_1"], bb["k_3"], bb["d_v"], bb["F_0"]]]
    )
    theta_G = np.concatenate([model.theta_g.ravel(), bb["g_0"]])
    assert np.allclose(model.accel(q, z, v), G @ theta_G - F @ theta_F, rtol=1e-10, atol=1e-12)


def test_the_position_part_given_once_gives_the_same_columns_for_every_z(bistable_record):
    """The T_z search computes the z terms' factors of q once (``position_part``) and moves
    only z: the columns are those of force_columns, bit for bit, for each z, and the part
    given is not modified."""
    model, _ = _fit(bistable_record)
    rng = np.random.default_rng(3)
    q = rng.uniform(-0.015, 0.015, 200)
    rbf, backbone = ("d",), ("viscous", "coulomb")
    table, names = force_table(model.basis, rbf, backbone, 1e-3)
    position = table.position_part(q)
    kept = position.copy()
    for scale in (0.01, 0.05, 0.2):
        z = rng.standard_normal(q.size) * scale
        F, want = force_columns(q, z, model.basis, rbf, backbone, 1e-3)
        got = table.columns(q, z, np.zeros((q.size, 1)), position=position)
        assert names == want and got.tobytes() == F.tobytes() and got.strides == F.strides
    assert position.tobytes() == kept.tobytes()


def test_model_roundtrips_through_its_tree(bistable_record):
    model, _ = _fit(bistable_record)
    again = RBFModel.from_tree(model.to_tree())
    q = np.linspace(-0.02, 0.02, 7)
    assert np.allclose(again.curves(q)["cq"], model.curves(q)["cq"])
    assert again.T_z == model.T_z and again.n_params == model.n_params


def test_centre_without_data_is_an_error_naming_it(bistable_record):
    with pytest.raises(IdentificationError) as err:
        _fit(bistable_record, q_range=[-0.012, 0.05])
    assert err.value.reason == "support"
    assert re.search(r"centre xi_\d+ = 0\.0\d+ has", str(err.value))
    assert "only 0 samples" in str(err.value) and "sigma = " in str(err.value)


def test_unexcited_input_is_an_error_naming_the_channel(bistable_record):
    rec = dict(bistable_record)
    rec["v"] = rec["v"].copy()
    rec["v"][:, 1] = 0.0
    with pytest.raises(IdentificationError) as err:
        _fit(rec)
    assert err.value.reason == "excitation" and "v2" in str(err.value)


def test_bad_conditioning_is_reported_with_the_number(bistable_record):
    with pytest.raises(IdentificationError) as err:
        _fit(bistable_record, max_condition=10.0)
    assert err.value.reason == "condition"
    assert "max_condition = 10" in str(err.value)


def test_config_rejects_unknown_keys_and_terms():
    with pytest.raises(WorkflowError) as err:
        IdentifyConfig.from_dict({"sigma": 0.5})
    assert err.value.key == "identify.sigma"
    assert "unknown" in str(err.value)
    assert "'sigma_n'?" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        IdentifyConfig.from_dict({"backbone": ["quartic"]})
    assert err.value.key == "identify.backbone"
    assert "'quartic'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        IdentifyConfig.from_dict({"m_q": "identify"})
    assert err.value.key == "identify.m_q"
    assert "'identify'" in str(err.value)
    assert "`input_gain`" in str(err.value)


def test_mass_identified_with_known_input_gain():
    """IDIM-like structure: m q'' + Fv q' + Fc tanh(q'/vc) + F0 = gain * v, recovered exactly."""
    rng = np.random.default_rng(11)
    n, dt = 4000, 1e-3
    q_dot = np.convolve(rng.standard_normal(n), np.ones(50) / 50, mode="same") * 0.2
    q = np.cumsum(q_dot) * dt
    q_ddot = np.gradient(q_dot, dt)
    m, fv, fc, f0, gain = 95.0, 200.0, 20.0, -3.0, 35.0
    v = (m * q_ddot + fv * q_dot + fc * np.tanh(q_dot / 1e-3) + f0) / gain
    cfg = IdentifyConfig.from_dict(
        {
            "rbf": [],
            "backbone": ["viscous", "coulomb", "offset"],
            "m_q": "identify",
            "input_gain": [gain],
            "T_z": 0.0,
            "input_map": "v",
        }
    )
    model, _ = fit_rbf_model([Record("s", q, q_dot, q_ddot, v[:, None], dt)], cfg)
    assert model.m_q == pytest.approx(m, rel=1e-9)
    assert model.backbone["d_v"] == pytest.approx(fv, rel=1e-9)
    assert model.backbone["F_c"] == pytest.approx(fc, rel=1e-9)
    assert model.backbone["F_0"] == pytest.approx(f0, rel=1e-9)


def _creep_record(truth, t):
    """Noise-free states of a model with creep (Eq. 26 in the RBF basis), exact q''."""
    from scipy.integrate import solve_ivp

    from tests.conftest import excitation

    def rhs(tt, x):
        return truth.rhs(x[None], excitation(np.array([tt])))[0][0]

    x0 = truth.initial_state(np.array([-0.01]), np.array([0.0]))[0]
    sol = solve_ivp(rhs, (t[0], t[-1]), x0, t_eval=t, method="DOP853", rtol=1e-9, atol=1e-12)
    x, v = sol.y.T, excitation(t)
    q_ddot = truth.accel(x[:, 0], x[:, 1], v, x[:, 3:])
    return {"q": x[:, 0], "q_dot": x[:, 1], "q_ddot": q_ddot, "v": v, "dt": t[1] - t[0]}


def test_creep_search_recovers_the_relaxation_rate_and_the_curves(bistable_record):
    """Data of a model with creep (lambda = 3.7 1/s, the Table 1 Y_MW / eta_MW): the creep
    columns w_j filtered from q, q_dot and the bounded search over lambda give lambda to 1 %
    and the curves to < 1 %; without creep the same data bias the curves many times more."""
    from dataclasses import replace

    weights = np.random.default_rng(5).uniform(60.0, 120.0, 8)
    truth = replace(truth_model(np.random.default_rng(2)), creep_rate=3.7, theta_creep=weights)
    rec = _creep_record(truth, bistable_record["t"])
    model, diag = _fit(rec, creep="search", **INSIDE_CLASS)
    assert model.creep_rate == pytest.approx(3.7, rel=0.01)  # measured 3.6995
    assert diag.creep_trace.shape[0] > 5 and diag.creep_trace[:, 1].min() < 1e-3
    assert diag.columns[16:24] == [f"creep[{k}]" for k in range(8)]
    with_creep = _curve_errors(truth, model, rec["q"])
    assert max(with_creep.values()) < 0.01, with_creep  # measured 8.5e-4
    assert np.max(np.abs(model.theta_creep - weights)) < 0.05 * np.ptp(weights)  # 0.02
    fixed, _ = _fit(rec, creep=3.7, **INSIDE_CLASS)
    assert fixed.creep_rate == 3.7 and max(_curve_errors(truth, fixed, rec["q"]).values()) < 0.01
    without = _curve_errors(truth, _fit(rec, **INSIDE_CLASS)[0], rec["q"])
    for key in ("cq", "d", "g"):
        assert without[key] > 100 * with_creep[key], key  # measured 3.1 / 11 / 26 vs < 1e-3


def test_creep_states_are_the_filter_of_eq_26_discretised_exactly():
    """w' = phi q_dot - lambda w (first-order hold): exact for a piecewise linear input."""
    from scipy.integrate import solve_ivp

    from debist.model.friction import creep_states

    dt, rate = 0.01, 3.7
    t = np.arange(0, 2.0, dt)
    qd = np.sin(3 * t) + 0.5 * np.cos(7 * t)
    phi = np.stack([np.ones_like(t), np.exp(-t)], axis=1)
    u = phi * qd[:, None]
    sol = solve_ivp(
        lambda tt, w: [np.interp(tt, t, u[:, i]) - rate * w[i] for i in range(2)],
        (0, t[-1]), u[0] / rate, t_eval=t, rtol=1e-11, atol=1e-13, max_step=dt / 20,
    )  # fmt: skip
    assert np.allclose(creep_states(phi, qd, dt, rate), sol.y.T, atol=1e-8)
    with pytest.raises(ValueError) as err:
        creep_states(phi, qd, dt, 0.0)
    assert "rate" in str(err.value)


def test_creep_config_and_model_tree(bistable_record):
    """`creep` is false, a rate > 0 [1/s] or "search"; a model with creep keeps lambda and
    its weights through model.h5's tree, a model without has no creep group."""
    for bad in (True, -1.0, "yes"):
        with pytest.raises(WorkflowError) as err:
            IdentifyConfig.from_dict({"creep": bad})
        assert err.value.key == "identify.creep"
        assert "false" in str(err.value) and "relax" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        IdentifyConfig.from_dict({"creep_bounds": [5.0, 1.0]})
    assert err.value.key == "identify.creep_bounds"
    assert "expected" in str(err.value)
    assert IdentifyConfig.from_dict({}).creep is False
    from debist.core.preflight import identify_columns

    plain_cols = identify_columns(IdentifyConfig.from_dict({}), 2)[0]
    assert identify_columns(IdentifyConfig.from_dict({"creep": "search"}), 2)[0] == plain_cols + 10
    plain, _ = _fit(bistable_record)
    assert "creep" not in plain.to_tree()["model"] and plain.n_states == 3
    model, _ = _fit(bistable_record, creep=2.0)
    again = RBFModel.from_tree(model.to_tree())
    assert again.creep_rate == 2.0 and np.array_equal(again.theta_creep, model.theta_creep)
    assert again.n_states == 3 + 10 and again.n_params == model.n_params
    x = again.measured_states(bistable_record["q"], bistable_record["q_dot"], 0.002)
    assert x.shape == (bistable_record["q"].size, 13) and np.all(x[0, 3:] == 0.0)
