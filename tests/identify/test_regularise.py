"""Regularised and sign-constrained least squares (debist.identify.regularise)."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from debist.core.errors import WorkflowError
from debist.identify.bootstrap import block_bootstrap
from debist.identify.config import IdentifyConfig
from debist.identify.fit import Record, fit_rbf_model
from debist.identify.regularise import (
    LAMBDA_GRID,
    TIE_WEIGHT,
    Estimator,
    constraint_bounds,
    gcv_lambda,
    smoothness_operator,
    tie_rows,
    weight_penalty,
)
from tests.conftest import bistable_truth


def test_gcv_equals_its_definition_with_the_explicit_hat_matrix():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((80, 6))
    y = A @ rng.standard_normal(6) + 0.3 * rng.standard_normal(80)
    P = smoothness_operator([f"c[{k}]" for k in range(6)], 6)
    Q, R = np.linalg.qr(A)
    qty = Q.T @ y
    lam, trace = gcv_lambda(R, qty, float(y @ y - qty @ qty), 80, P)
    for lam_k, gcv_k, tr_k in trace[::8]:
        H = A @ np.linalg.solve(A.T @ A + lam_k * P.T @ P, A.T)
        rss = np.sum((y - H @ y) ** 2)
        assert tr_k == pytest.approx(np.trace(H), rel=1e-9)
        assert gcv_k == pytest.approx(80 * rss / (80 - np.trace(H)) ** 2, rel=1e-9)
    assert lam == trace[np.argmin(trace[:, 1]), 0] and lam in LAMBDA_GRID


def test_second_differences_per_curve():
    names = ["c[0]", "c[1]", "c[2]", "c[3]", "viscous", "g1[0]", "g1[1]", "g1[2]", "g1[3]"]
    P = smoothness_operator(names, 4)
    assert P.shape == (4, 9)
    theta = np.array([1.0, 2.0, 3.0, 4.0, 7.0, 0.0, 1.0, 4.0, 9.0])  # linear, quadratic
    np.testing.assert_array_equal(np.sort(P @ theta), [0.0, 0.0, 2.0, 2.0])


def test_constraint_bounds_and_bad_statements():
    names = ["c[0]", "d[0]", "viscous", "g1[0]", "g2[0]", "input_gain2", "physics_gain1",
             "physics_quadratic2"]  # fmt: skip
    lo, hi = constraint_bounds(names, ["d >= 0", "g2 <= 0", "g1 >= 0"])
    # the analytical curves' scales are non-negative whatever the sign: their curves carry it
    np.testing.assert_array_equal(lo, [-np.inf, 0, 0, 0, -np.inf, -np.inf, 0, 0])
    np.testing.assert_array_equal(hi, [np.inf, np.inf, np.inf, np.inf, 0, 0, np.inf, np.inf])
    with pytest.raises(WorkflowError) as err:
        constraint_bounds(names, ["c >= 0"])
    assert "'c >= 0'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        constraint_bounds(names, ["g3 >= 0"])
    assert "'g3'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        IdentifyConfig.from_dict({"constraints": ["g1 > 0"]})
    assert "constraints" in str(err.value)


def _noisy(rec, level, seed):
    rng = np.random.default_rng(seed)
    qdd = rec["q_ddot"] + level * np.std(rec["q_ddot"]) * rng.standard_normal(rec["q"].size)
    return [Record("sim", rec["q"], rec["q_dot"], qdd, rec["v"], rec["dt"])]


def _cfg(**kw):
    base = {"M": 16, "sigma_n": 0.5, "T_z": 0.0, "max_condition": 1e12, "bootstrap": 0,
            "backbone": ["linear_spring", "cubic_spring", "viscous"], "min_support": 0}  # fmt: skip
    return IdentifyConfig.from_dict({**base, **kw})


def test_gcv_smoothing_brings_noisy_curves_closer_to_the_truth(bistable_record):
    """M = 16 on accelerations with 30 % noise: plain least squares wiggles; the GCV-chosen
    penalty reduces the error of the restoring force and of d against the truth and the
    weights' roughness (g_i, whose truth is linear in q, stay within 30 % of their error)."""
    records = _noisy(bistable_record, 0.3, seed=3)
    plain, d0 = fit_rbf_model(records, _cfg())
    smooth, d1 = fit_rbf_model(records, _cfg(smoothing="gcv"))
    assert d0.smoothing == 0.0 and d1.smoothing > 0.0
    q = np.linspace(-0.012, 0.012, 80)
    truth = bistable_truth(q)

    def err(model, key, j=None):
        got = model.curves(q)[key] if j is None else model.curves(q)["g"][:, j]
        if j is not None:
            want = truth[f"g{j + 1}"]
        else:
            want = truth["c"] * q if key == "cq" else truth[key]
        return np.sqrt(np.mean((got - want) ** 2))

    assert err(smooth, "d") < 0.9 * err(plain, "d")
    assert err(smooth, "cq") < err(plain, "cq")
    assert err(smooth, "g", 0) < 1.3 * err(plain, "g", 0)
    P = smoothness_operator(d0.columns, 16)
    assert np.linalg.norm(P @ d1.theta) < np.linalg.norm(P @ d0.theta)


def test_constrained_fit_is_the_bounded_least_squares(bistable_record):
    """g2 <= 0 and d >= 0 hold for every weight and the solution equals lsq_linear on the
    full scaled regressor (an independent solve without the QR compression)."""
    records = _noisy(bistable_record, 1.0, seed=5)
    cfg = _cfg(constraints=["g2 <= 0", "d >= 0", "g1 >= 0"], bootstrap=20)
    model, diag = fit_rbf_model(records, cfg)
    assert np.all(model.theta_g[1] <= 0) and np.all(model.theta_d >= 0)
    assert np.all(model.theta_g[0] >= 0) and model.backbone["d_v"] >= 0
    assert np.all(model.curves(np.linspace(-0.02, 0.02, 50))["g"][:, 1] <= 0)
    from debist.identify.fit import _system, _trimmed
    from debist.model.basis import RBFBasis
    from debist.model.friction import friction_state

    recs = _trimmed(records, 0)
    q_all = recs[0].q
    basis = RBFBasis.equidistant(q_all.min(), q_all.max(), 16, 0.5, "clip")
    psi, y, names = _system(recs, [friction_state(r.q_dot, r.dt, 0.0) for r in recs], basis, cfg)
    assert names == diag.columns
    scale = np.linalg.norm(psi, axis=0)
    lo, hi = constraint_bounds(names, cfg.constraints)
    ref = lsq_linear(psi / scale, y, bounds=(lo, hi), method="bvls", tol=1e-12).x / scale
    np.testing.assert_allclose(diag.theta, ref, rtol=1e-6, atol=1e-9 * np.abs(ref).max())
    assert np.all(diag.theta_boot[:, [names.index(f"g2[{k}]") for k in range(16)]] <= 0)


def test_a_penalised_replicate_is_the_penalised_fit_on_its_blocks():
    rng = np.random.default_rng(6)
    X = rng.standard_normal((120, 5))
    y = rng.standard_normal(120)
    P = smoothness_operator([f"c[{k}]" for k in range(5)], 5)
    est = Estimator(P, 0.7, np.full(5, -np.inf), np.r_[np.inf, np.inf, 0.0, np.inf, np.inf])
    boot, _ = block_bootstrap(X, y, [120], 2, seed=4, block=30, estimator=est)
    scale = np.linalg.norm(X, axis=0)
    draw = np.random.default_rng(4)
    for b in range(2):
        pick = draw.integers(0, 4, 4)
        rows = np.concatenate([np.arange(30 * i, 30 * i + 30) for i in pick])
        ref = est.solve(X[rows] / scale, y[rows]) / scale
        np.testing.assert_allclose(boot[b], ref, rtol=1e-7, atol=1e-10)


def test_the_penalty_acts_on_the_curve_weights_not_on_the_scaled_ones():
    """A centre the data hardly reach has a small column norm. The penalty must hold its
    weight theta_k to its neighbours (a large lambda leaves theta linear over the centres,
    the null space of the second differences), which a penalty on the column-scaled
    weights x = s theta does not: there theta_k = x_k / s_k is free to run off."""
    rng = np.random.default_rng(8)
    A = rng.standard_normal((200, 5)) * np.array([1.0, 1.0, 1e-3, 1.0, 1.0])
    y = A @ np.array([1.0, 2.0, 3.0, 4.0, 5.0]) + 0.5 * rng.standard_normal(200)
    names = [f"c[{k}]" for k in range(5)]
    scale = np.linalg.norm(A, axis=0)
    P = weight_penalty(smoothness_operator(names, 5), scale, names)
    est = Estimator(P, 1e6, np.full(5, -np.inf), np.full(5, np.inf))
    theta = est.solve(A / scale, y) / scale
    D2 = smoothness_operator(names, 5)
    assert np.max(np.abs(D2 @ theta)) < 1e-3 * np.max(np.abs(theta))
    # the same lambda on the scaled weights leaves the hardly reached centre's theta off the line
    x_only = Estimator(smoothness_operator(names, 5), 1e6, est.lower, est.upper)
    theta_x = x_only.solve(A / scale, y) / scale
    assert np.max(np.abs(D2 @ theta_x)) > 0.5 * np.max(np.abs(theta_x))
    # lambda is dimensionless: a curve's unit (its columns scaled by k, theta by 1 / k) does
    # not change the penalty on the scaled weights x = s theta
    x = rng.standard_normal(5)
    np.testing.assert_allclose(weight_penalty(D2, 7.0 * scale, names) @ x, P @ x, rtol=1e-12)
    # one factor per curve (the geometric mean of its norms), the rows of two curves apart
    two = ["c[0]", "c[1]", "c[2]", "viscous", "g1[0]", "g1[1]", "g1[2]"]
    s2 = np.array([1.0, 4.0, 2.0, 9.0, 1e-3, 1e-2, 1e-1])
    theta2 = rng.standard_normal(7)
    rows = weight_penalty(smoothness_operator(two, 3), s2, two) @ (s2 * theta2)
    want = [2.0 * (theta2[0] - 2 * theta2[1] + theta2[2]),  # (1 * 4 * 2)^(1/3) = 2
            1e-2 * (theta2[4] - 2 * theta2[5] + theta2[6])]  # fmt: skip
    np.testing.assert_allclose(rows, want, rtol=1e-12)


def _one_sided_record(rng, n=6000):
    """Eq. 37 rows of the truth with each DE driven on one side only: v1 where q > -5 mm,
    v2 where q < 5 mm (as a DE is driven from the well it pulls the beam out of)."""
    q = np.clip(0.015 * np.sin(7.0 * np.cumsum(rng.uniform(0, 0.01, n)))
                + 5e-4 * rng.standard_normal(n), -0.015, 0.015)  # fmt: skip
    q_dot = 0.1 * rng.standard_normal(n)
    v = np.column_stack([np.where(q > -0.005, 2000.0 * rng.random(n), 0.0),
                         np.where(q < 0.005, 2000.0 * rng.random(n), 0.0)])  # fmt: skip
    t = bistable_truth(q)
    q_ddot = t["g1"] * v[:, 0] ** 2 + t["g2"] * v[:, 1] ** 2 - t["c"] * q - t["d"] * q_dot
    q_ddot = q_ddot + 0.05 * np.std(q_ddot) * rng.standard_normal(n)
    return Record("one-sided", q, q_dot, q_ddot, v, 0.001)


def test_a_gain_is_continued_over_the_centres_its_input_never_drives():
    """Without ties the weights beyond an input's driven range are free (their columns see
    only Gaussian tails) and the gain runs off there; tied, it is right at the edge of the
    driven range and continues linearly, as the truth (linear in q) does."""
    rec = _one_sided_record(np.random.default_rng(3))
    cfg = IdentifyConfig.from_dict({"M": 10, "T_z": 0, "bootstrap": 0, "rbf": ["c", "d", "g"],
                                    "backbone": [], "tie_undriven": True})  # fmt: skip
    model, diag = fit_rbf_model([rec], cfg)
    assert diag.undriven == (
        "g1 continued from its neighbours at centre(s) 1, 2, 3 of 10: less than 10 samples' "
        "worth of data with v1 applied there; g2 continued from its neighbours at centre(s) 8, "
        "9, 10 of 10: less than 10 samples' worth of data with v2 applied there"
    )
    edge = np.array([-0.006, -0.005, 0.0, 0.005, 0.006])
    t = bistable_truth(edge)
    g = model.curves(edge)["g"]
    np.testing.assert_allclose(g[1:, 0], t["g1"][1:], rtol=0.03)  # v1 driven above -5 mm
    np.testing.assert_allclose(g[:-1, 1], t["g2"][:-1], rtol=0.03)  # v2 below 5 mm
    names = diag.columns
    D2 = smoothness_operator(names, 10)
    tied = [names.index(f"g1[{k}]") for k in range(3)] + [
        names.index(f"g2[{k}]") for k in (7, 8, 9)
    ]
    rows = np.abs(D2[:, tied]).sum(axis=1) > 0
    g_scale = np.max(np.abs(diag.theta[tied]))
    assert np.max(np.abs(D2[rows] @ diag.theta)) < 0.02 * g_scale
    # the same fit without the ties (the default) runs off past 5 mm
    _, free = fit_rbf_model([rec], replace(cfg, tie_undriven=False))
    assert free.undriven == ""
    assert np.max(np.abs(D2[rows] @ free.theta)) > 10.0 * g_scale


def test_tie_rows_hold_the_second_differences_that_touch_a_tied_weight():
    names = ["c[0]", "c[1]", "c[2]", "c[3]", "g1[0]", "g1[1]", "g1[2]", "g1[3]"]
    scale = np.array([1.0, 2.0, 4.0, 8.0, 1.0, 1.0, 1e-3, 1e-4])
    rows = tie_rows(names, 4, scale, ["g1[3]"])
    assert rows.shape == (1, 8)  # only g1's second difference (1, 2, 3)
    theta = np.array([0.0, 0.0, 0.0, 0.0, 5.0, 1.0, 2.0, 3.0])  # linear over centres 1-3
    np.testing.assert_allclose(rows @ (scale * theta), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(rows, axis=1), TIE_WEIGHT)  # unit rows, weighted
    theta[7] = 4.0  # off the line by 1: the row is D2 theta / s written on x = s theta
    a = np.array([1.0 / 1.0, -2.0 / 1e-3, 1.0 / 1e-4])
    assert (rows @ (scale * theta))[0] == pytest.approx(TIE_WEIGHT / np.linalg.norm(a))
    assert tie_rows(names, 4, scale, []).shape == (0, 8)
