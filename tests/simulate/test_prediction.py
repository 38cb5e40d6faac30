"""k-step-ahead prediction and residual analysis (Ljung 1999, Sec. 7.3 and 16.6)."""

import numpy as np
import pytest
from scipy import linalg, stats

from debist.core.errors import WorkflowError
from debist.simulate.freerun import simulate
from debist.validate.prediction import _correlation, k_step_prediction, residual_analysis


class Oscillator:
    """q'' = -w^2 q - 2 zeta w q' + b u: a linear plant whose exact flow is a matrix exponential."""

    n_states = 2

    def __init__(self, w=2 * np.pi * 3.0, zeta=0.05, b=40.0):
        self.a = np.array([[0.0, 1.0], [-(w**2), -2 * zeta * w]])
        self.b = np.array([0.0, b])

    def initial_state(self, q0, q_dot0):
        return np.stack([np.asarray(q0, float), np.asarray(q_dot0, float)], axis=-1)

    def rhs(self, x, v):
        dx = x @ self.a.T + v[:, :1] * self.b
        return dx, dx[:, 1]

    def max_step(self):
        return np.inf


def _exact(model, x0, u, dt, k):
    """k samples of the exact zero-order-hold-free flow for a constant input u."""
    aug = np.zeros((3, 3))
    aug[:2, :2] = model.a
    aug[:2, 2] = model.b * u
    phi = linalg.expm(aug * dt * k)
    return (phi @ np.append(x0, 1.0))[:2]


def test_k_step_prediction_of_a_linear_plant_matches_its_exact_flow():
    model = Oscillator()
    dt, n, k = 0.002, 400, 7
    rng = np.random.default_rng(3)
    u = 0.3  # constant input, linear interpolation: exact; only RK4 error remains
    t = np.arange(n) * dt
    q = 1e-3 * np.sin(2 * np.pi * 3.0 * t) + 1e-4 * rng.standard_normal(n)
    q_dot = 2e-2 * np.cos(2 * np.pi * 3.0 * t)
    v = np.full((n, 1), u)
    q_hat = k_step_prediction(model, q, q_dot, v, dt, k, substeps=4, interpolation="linear")
    assert np.isnan(q_hat[:k]).all()
    expected = [_exact(model, np.array([q[j - k], q_dot[j - k]]), u, dt, k)[0] for j in range(k, n)]
    np.testing.assert_allclose(q_hat[k:], expected, rtol=0, atol=1e-10)


def test_sampled_starts_on_long_records_predict_the_same_values():
    model = Oscillator()
    dt, n, k = 0.002, 300, 3
    rng = np.random.default_rng(5)
    q, q_dot = rng.standard_normal(n) * 1e-3, rng.standard_normal(n) * 1e-2
    v = rng.standard_normal((n, 1))
    every = k_step_prediction(model, q, q_dot, v, dt, k, interpolation="linear")
    few = k_step_prediction(model, q, q_dot, v, dt, k, interpolation="linear", max_windows=40)
    kept = np.isfinite(few)
    assert 30 <= kept.sum() <= 40
    np.testing.assert_array_equal(few[kept], every[kept])


def test_one_step_prediction_is_never_sampled_so_residuals_stay_consecutive():
    model = Oscillator()
    n = 120
    q_hat = k_step_prediction(
        model, np.zeros(n), np.zeros(n), np.ones((n, 1)), 0.01, 1, max_windows=10
    )
    assert np.isfinite(q_hat[1:]).all()


@pytest.mark.parametrize(("k", "n"), [(0, 10), (5, 5)])
def test_k_step_prediction_refuses_a_horizon_it_cannot_score(k, n):
    with pytest.raises(WorkflowError, match=r"k must be >= 1|too short"):
        k_step_prediction(Oscillator(), np.zeros(n), np.zeros(n), np.zeros((n, 1)), 0.01, k)


def test_correlation_matches_a_direct_sum():
    rng = np.random.default_rng(11)
    a, b = rng.standard_normal(50), rng.standard_normal(50)
    r = _correlation(a, b, 4)
    a0, b0 = a - a.mean(), b - b.mean()
    scale = 50 * a0.std() * b0.std()
    for tau in range(-4, 5):
        direct = sum(a0[t] * b0[t - tau] for t in range(max(tau, 0), 50 + min(tau, 0)))
        assert r[tau + 4] == pytest.approx(direct / scale, abs=1e-12)


def test_white_errors_pass_and_coloured_errors_fail_the_ljung_box_test():
    rng = np.random.default_rng(7)
    white = rng.standard_normal(4000)
    u = rng.standard_normal((4000, 2))
    assert residual_analysis(white, u).white
    coloured = np.empty(4000)  # AR(1), pole 0.5: r(1) = 0.5 >> 2.58 / sqrt(4000)
    coloured[0] = 0.0
    for t in range(1, 4000):
        coloured[t] = 0.5 * coloured[t - 1] + white[t]
    res = residual_analysis(coloured, u)
    assert not res.white
    assert res.autocorr[1] == pytest.approx(0.5, abs=0.05)
    assert res.auto_limit == pytest.approx(stats.norm.ppf(0.995) / np.sqrt(4000))


def test_errors_that_carry_an_input_are_flagged_against_that_input_only():
    rng = np.random.default_rng(13)
    n = 3000
    u = rng.standard_normal((n, 2))
    e = 0.2 * rng.standard_normal(n)
    e[3:] += 0.5 * u[:-3, 1]  # the model missed input 2's effect three samples later
    res = residual_analysis(e, u)
    outside = res.cross_outside
    assert outside[0] < 0.05
    assert outside[1] > 0
    lag3 = np.flatnonzero(res.cross_lags == 3)[0]
    assert abs(res.crosscorr[1, lag3]) > 5 * res.cross_limit[1]


def test_coloured_input_and_errors_widen_the_cross_limit_as_bartlett_says():
    rng = np.random.default_rng(17)
    n = 5000
    w = rng.standard_normal((n, 2))
    slow = np.empty((n, 2))
    slow[0] = w[0]
    for t in range(1, n):  # two independent AR(1) series, pole 0.8
        slow[t] = 0.8 * slow[t - 1] + w[t]
    res = residual_analysis(slow[:, 0], slow[:, 1:])
    # sum_k 0.8^|k| 0.8^|k| = (1 + 0.64) / (1 - 0.64) = 4.56 for the untruncated sums
    expected = stats.norm.ppf(0.995) * np.sqrt(4.56 / n)
    assert res.cross_limit[0] == pytest.approx(expected, rel=0.25)
    assert res.cross_outside[0] < 0.2


def test_residual_analysis_refuses_too_few_errors_and_constant_errors():
    with pytest.raises(WorkflowError) as err:
        residual_analysis(np.r_[np.ones(50), np.full(100, np.nan)], np.zeros((150, 1)))
    assert "least 100" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        residual_analysis(np.ones(200), np.zeros((200, 1)))
    assert "constant" in str(err.value)


class Truth:
    """The synthetic bistable plant of conftest (Eq. 37 with z = q_dot) as a free-run model."""

    n_states = 2

    def initial_state(self, q0, q_dot0):
        return np.stack([np.asarray(q0, float), np.asarray(q_dot0, float)], axis=-1)

    def rhs(self, x, v):
        from tests.conftest import bistable_truth

        q, qd = x[:, 0], x[:, 1]
        cur = bistable_truth(q)
        a = cur["g1"] * v[:, 0] ** 2 + cur["g2"] * v[:, 1] ** 2 - cur["c"] * q - cur["d"] * qd
        return np.stack([qd, a], axis=1), a

    def max_step(self):
        return np.inf


def test_the_true_plant_predicts_its_own_record_to_integration_error(bistable_record):
    from debist.validate.freerun import DataSet
    from debist.validate.prediction import prediction_table

    rec = bistable_record
    n = 2000
    ds = DataSet(
        "check", "validation", rec["t"][:n], rec["q"][:n], rec["q_dot"][:n],
        rec["q_ddot"][:n], rec["v"][:n], "m",
    )  # fmt: skip
    scores, corr = prediction_table(
        Truth(), "truth", [ds], k=10, max_lag=25, substeps=4, interpolation="bandlimited",
        q_limit=1.0, engine="numpy",
    )  # fmt: skip
    row = scores.iloc[0]
    assert row["k_steps"] == 10
    assert row["nrmse_q_k"] < 1e-5  # RK4 and input interpolation only

    # a wrong input gain leaves errors that the residual check ties to the input
    class Weak(Truth):
        def rhs(self, x, v):
            return super().rhs(x, 0.9 * v)

    weak, _ = prediction_table(
        Weak(), "weak", [ds], k=10, max_lag=25, substeps=4, interpolation="bandlimited",
        q_limit=1.0, engine="numpy",
    )  # fmt: skip
    assert weak.iloc[0]["nrmse_q_k"] > 100 * row["nrmse_q_k"]
    assert weak.iloc[0]["resid_cross_outside"] > 0.5
    assert set(corr["series"]) == {"autocorr", "cross_v1", "cross_v2"}
    assert corr.groupby("series").size().to_dict() == {
        "autocorr": 26,
        "cross_v1": 51,
        "cross_v2": 51,
    }


def _restart_errors(model, run, v, dt):
    """Worst 25-step prediction error (share of q's range) of a model restarted from the
    record's own states (``measured_states``), and of the same model restarted at rest
    (``initial_state``: z = q_dot, creep states 0)."""

    class AtRest:
        n_states = model.n_states
        initial_state = staticmethod(model.initial_state)
        rhs = staticmethod(model.rhs)
        max_step = staticmethod(model.max_step)

    errors = []
    for m in (model, AtRest()):
        q_hat = k_step_prediction(m, run.q, run.q_dot, v, dt, 25, substeps=4)
        errors.append(np.nanmax(np.abs(q_hat - run.q)) / np.ptp(run.q))
    return tuple(errors)


def test_restarts_carry_the_friction_state_of_the_record_not_z_equal_q_dot():
    from tests.conftest import example_rbf_model, excitation

    model = example_rbf_model(T_z=0.05, prior=False)
    dt = 0.002
    t = np.arange(0, 3.0, dt)
    v = excitation(t)
    (run,) = simulate(model, [v], dt, np.array([-0.008]), np.array([0.0]), substeps=4)
    z = model.measured_states(run.q, run.q_dot, dt)[:, 2]
    assert np.max(np.abs(z - run.states[:, 2])) < 1e-3 * np.ptp(run.states[:, 2])
    err, err_rest = _restart_errors(model, run, v, dt)
    assert err < 1e-4
    assert err_rest > 10 * err


def test_restarted_windows_of_a_free_run_repeat_it_sample_for_sample(bistable_record):
    """Windows restarted from a free run's own states, with the inputs interpolated over the
    whole record, are that free run's stretches (the same arithmetic)."""
    from debist.validate.freerun import DataSet
    from debist.validate.prediction import restarted_runs

    rec, n = bistable_record, 3000
    (run,) = simulate(
        Truth(), [rec["v"][:n]], rec["dt"], rec["q"][:1], rec["q_dot"][:1], substeps=2,
        engine="numpy",
    )  # fmt: skip
    own = DataSet("own", "validation", rec["t"][:n], run.q, run.q_dot, run.q_ddot,
                  rec["v"][:n], "m")  # fmt: skip
    windows = [(0, 0, 300), (0, 450, 1200), (0, 2990, 3000), (0, 1500, 1502)]
    outs = restarted_runs(Truth(), [own], windows, rec["dt"], substeps=2, engine="numpy")
    assert [o.size for o in outs] == [300, 750, 10, 2]
    for (_, a, b), out in zip(windows, outs, strict=True):
        np.testing.assert_allclose(out, run.q[a:b], rtol=0, atol=1e-15)
    with pytest.raises(WorkflowError) as err:
        restarted_runs(Truth(), [own], [(0, 2999, 3001)], rec["dt"])
    assert "2999" in str(err.value)
    assert "3001" in str(err.value)


def test_a_lost_switch_costs_one_restarted_window_not_the_rest_of_the_record(bistable_record):
    """The multiple-shooting score of [identify.auto]: a model whose input gain is too weak to
    switch misses the record after its first lost switch in one free run, but only the
    windows that hold a switch when every window restarts from the measured state."""
    from debist.core.metrics import nrmse
    from debist.validate.freerun import DataSet
    from debist.validate.prediction import restarted_runs

    class Weak(Truth):
        def rhs(self, x, v):
            return super().rhs(x, 0.6 * v)

    rec = bistable_record
    ds = DataSet("rec", "validation", rec["t"], rec["q"], rec["q_dot"], rec["q_ddot"],
                 rec["v"], "m")  # fmt: skip
    n, dt = rec["q"].size, rec["dt"]
    (free,) = simulate(Weak(), [rec["v"]], dt, rec["q"][:1], rec["q_dot"][:1], engine="numpy")
    wells = np.sign(rec["q"])
    assert np.mean(np.sign(free.q) != wells) > 0.2  # the weak model loses the switches
    windows = [(0, s, min(s + 500, n)) for s in range(0, n - 1, 500)]
    runs = restarted_runs(Weak(), [ds], windows, dt, engine="numpy")
    windowed = nrmse(rec["q"][: sum(r.size for r in runs)], np.concatenate(runs))
    assert windowed < 0.5 * nrmse(rec["q"], free.q)
    lost = [np.any(np.sign(r) != wells[a:b]) for r, (_, a, b) in zip(runs, windows, strict=True)]
    assert 0 < sum(lost) < 0.5 * len(windows)  # only windows that hold a switch lose it


def test_restarts_carry_the_creep_states_of_the_record():
    """A model with creep (Eq. 26): measured_states filters w_j from q, q_dot like z, so a
    restarted window continues the free run; restarted at rest (w = 0) it does not."""
    from tests.conftest import example_rbf_model, excitation

    model = example_rbf_model(T_z=0.05, prior=False, creep_rate=3.7)
    dt = 0.002
    t = np.arange(0, 3.0, dt)
    v = excitation(t)
    (run,) = simulate(model, [v], dt, np.array([-0.008]), np.array([0.0]), substeps=4)
    x = model.measured_states(run.q, run.q_dot, dt)
    assert x.shape == (t.size, 13)
    w, w_run = x[:, 3:], run.states[:, 3:]
    assert np.max(np.abs(w - w_run)) < 1e-3 * np.ptp(w_run)
    err, err_rest = _restart_errors(model, run, v, dt)
    assert err < 1e-4
    assert err_rest > 10 * err
