"""Tests of TVRegDiff: Chartrand's reference numbers, exact O(n) solves, properties."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize
from scipy.sparse.linalg import spsolve

from debist.core.errors import ConvergenceWarning
from debist.differentiate._tvr_solve import (
    large_bands,
    small_kkt,
    solve_large,
    solve_small,
)
from debist.differentiate.tvregdiff import TVRegDiffResult, tv_functional, tvregdiff

quiet = pytest.mark.filterwarnings("ignore::debist.core.errors.ConvergenceWarning")


# Dense operators written from Chartrand's definitions (reference only, small n).
def dense_small(n: int, dx: float) -> tuple[np.ndarray, np.ndarray]:
    """D: (n, n+1) forward difference / dx; A: (n, n+1) trapezoid integral to edge k+1."""
    d = (np.eye(n, n + 1, 1) - np.eye(n, n + 1)) / dx
    a = np.zeros((n, n + 1))
    for k in range(n):
        a[k, : k + 2] = dx
        a[k, 0] = a[k, k + 1] = dx / 2
    return d, a


def dense_large(n: int, dx: float) -> tuple[np.ndarray, np.ndarray]:
    """D: (n, n) forward difference / dx with a zero last row; A: cumulative sum."""
    d = (np.eye(n, n, 1) - np.eye(n)) / dx
    d[-1] = 0.0
    return d, np.tril(np.ones((n, n)))


def reference_data() -> tuple[np.ndarray, float]:
    x = np.arange(1, 101) * 0.01
    f = np.abs(x - 0.5) + 0.05 * np.random.default_rng(0).standard_normal(100)
    return f, 0.01


# ---------------------------------------------------------------- reference check


def test_reference_functional_values():
    f, dx = reference_data()
    with pytest.warns(ConvergenceWarning, match="after 100 iterations"):
        res = tvregdiff(f, 100, 0.2, scale="small", ep=1e-6, dx=dx)
    assert isinstance(res, TVRegDiffResult)
    assert res.n_iter == 100 and not res.converged
    np.testing.assert_allclose(
        res.functional[[0, 9, 99]], [0.571810, 0.484290, 0.474417], rtol=1e-5
    )
    # Each iteration's value is the functional of that iterate.
    assert res.functional[-1] == pytest.approx(
        tv_functional(res.u, f, 0.2, scale="small", ep=1e-6, dx=dx), rel=1e-14
    )


def test_reference_minimum_independently():
    f, dx = reference_data()
    alpha, ep, n = 0.2, 1e-6, f.size
    d, a = dense_small(n, dx)
    b = f - f[0]

    def fun(u):
        return alpha * dx * np.sum(np.sqrt((d @ u) ** 2 + ep)) + 0.5 * np.sum((a @ u - b) ** 2)

    def jac(u):
        du = d @ u
        return alpha * dx * d.T @ (du / np.sqrt(du**2 + ep)) + a.T @ (a @ u - b)

    def hess(u):
        s = np.sqrt((d @ u) ** 2 + ep)
        return alpha * dx * d.T @ ((ep / s**3)[:, None] * d) + a.T @ a

    with pytest.warns(ConvergenceWarning):
        res = tvregdiff(f, 100, alpha, scale="small", ep=ep, dx=dx)
    assert fun(res.u) == pytest.approx(res.functional[-1], rel=1e-12)
    opt = minimize(fun, res.u, jac=jac, hess=hess, method="trust-exact", options={"gtol": 1e-9})
    assert np.linalg.norm(jac(opt.x)) < 1e-7
    assert opt.fun == pytest.approx(0.473304, abs=1e-6)
    assert np.all(res.functional >= opt.fun)
    # Lagged diffusivity creeps towards the same minimum (linear convergence).
    with pytest.warns(ConvergenceWarning):
        long = tvregdiff(f, 3000, alpha, scale="small", ep=ep, dx=dx, u0=res.u, tol=1e-12)
    assert 0.0 < long.functional[-1] - opt.fun < 1e-5


# ---------------------------------------------------------------- exact solves


@pytest.mark.parametrize("n", [3, 4, 17, 60])
def test_small_step_equals_dense_solve(n):
    rng = np.random.default_rng(n)
    dx, alpha, ep = 0.02, 0.3, 1e-4
    f = np.cumsum(rng.standard_normal(n)) * 0.1
    u = rng.standard_normal(n + 1)
    d, a = dense_small(n, dx)
    q = 1 / np.sqrt((d @ u) ** 2 + ep)
    h = alpha * dx * d.T @ np.diag(q) @ d + a.T @ a
    b = f - f[0]
    ref = np.linalg.solve(h, a.T @ b)
    # Chartrand's update u - H^{-1} g is the same point.
    g = a.T @ (a @ u - b) + alpha * dx * d.T @ np.diag(q) @ d @ u
    np.testing.assert_allclose(u - np.linalg.solve(h, g), ref, rtol=1e-9, atol=1e-12)
    got = solve_small(q, b, alpha, dx)
    assert np.max(np.abs(got - ref)) <= 1e-10 * np.max(np.abs(ref))
    # One tvregdiff iteration from u0 is that solve.
    with pytest.warns(ConvergenceWarning):
        res = tvregdiff(f, 1, alpha, u0=u, scale="small", ep=ep, dx=dx)
    assert np.max(np.abs(res.u - ref)) <= 1e-10 * np.max(np.abs(ref))


@pytest.mark.parametrize("n", [3, 4, 17, 60])
def test_large_step_equals_dense_solve(n):
    rng = np.random.default_rng(100 + n)
    dx, alpha, ep = 0.05, 0.01, 1e-3
    f = np.cumsum(rng.standard_normal(n)) * 0.1
    u_ret = rng.standard_normal(n)  # derivative units; Chartrand's iterate is u_ret * dx
    d, a = dense_large(n, dx)
    q = 1 / np.sqrt((d @ (u_ret * dx)) ** 2 + ep)
    h = alpha * d.T @ np.diag(q) @ d + a.T @ a
    b = f - f[0]
    ref = np.linalg.solve(h, a.T @ b) / dx
    got = solve_large(q[:-1], b, alpha, dx)
    assert np.max(np.abs(got - ref)) <= 1e-10 * np.max(np.abs(ref))
    with pytest.warns(ConvergenceWarning):
        res = tvregdiff(f, 1, alpha, u0=u_ret, scale="large", ep=ep, dx=dx)
    assert np.max(np.abs(res.u - ref)) <= 1e-10 * np.max(np.abs(ref))


def test_default_u0_and_dx_are_chartrands():
    f, _ = reference_data()
    n = f.size
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        default = tvregdiff(f, 2, 0.2)
        explicit = tvregdiff(f, 2, 0.2, u0=np.r_[0.0, np.diff(f), 0.0], dx=1 / n)
        large = tvregdiff(f, 2, 0.2, scale="LARGE")
        large_explicit = tvregdiff(f, 2, 0.2, scale="large", u0=np.r_[0, np.diff(f)] / (1 / n))
    assert default.dx == 1 / n and default.scale == "small" and default.ep == 1e-6
    np.testing.assert_array_equal(default.u, explicit.u)
    np.testing.assert_array_equal(large.u, large_explicit.u)


def test_systems_have_bandwidth_two():
    n = 500
    q = np.random.default_rng(3).uniform(1, 1e3, n)
    ab = large_bands(q[:-1], 0.1, 0.01)
    assert ab.shape == (3, n)  # upper bandwidth 2: 3 stored diagonals
    kkt = small_kkt(q, 0.1, 0.01).tocoo()
    assert kkt.shape == (2 * n + 1, 2 * n + 1)
    assert np.max(np.abs(kkt.row - kkt.col)) == 2
    assert kkt.nnz <= 5 * (2 * n + 1)
    assert abs(kkt - kkt.T).max() == 0.0
    # The banded LU and a general sparse direct solve agree.
    b = np.random.default_rng(4).standard_normal(n)
    rhs = np.zeros(2 * n + 1)
    rhs[1::2] = np.diff(b, prepend=0.0)
    np.testing.assert_allclose(
        spsolve(kkt.tocsc(), rhs)[0::2], solve_small(q, b, 0.1, 0.01), rtol=1e-9, atol=1e-12
    )


# ---------------------------------------------------------------- properties


@quiet
@pytest.mark.parametrize("scale", ["small", "large"])
def test_functional_is_non_increasing(scale):
    rng = np.random.default_rng(7)
    t = np.linspace(0, 1, 300)
    f = np.where(t < 0.4, t, 0.4 + 3 * (t - 0.4) ** 2) + 0.01 * rng.standard_normal(t.size)
    res = tvregdiff(f, 40, 1e-3, scale=scale, ep=1e-6, dx=t[1] - t[0])
    assert res.n_iter == 40
    steps = np.diff(res.functional)
    assert np.all(steps <= 1e-12 * res.functional[:-1])
    assert steps[0] < 0


@quiet
def test_large_scale_smooth_signal_matches_analytic():
    dt, n = 0.01, 800
    t = np.arange(n) * dt
    f = np.sin(2 * np.pi * 0.8 * t) + 0.2 * t
    exact = 2 * np.pi * 0.8 * np.cos(2 * np.pi * 0.8 * t) + 0.2
    res = tvregdiff(f, 30, 1e-8, scale="large", ep=1e-8, dx=dt)
    err = np.abs(res.derivative - exact)
    assert err[40:-40].max() < 5e-3 * np.abs(exact).max()
    assert err.max() < 2e-2 * np.abs(exact).max()


@quiet
@pytest.mark.parametrize("scale", ["small", "large"])
def test_derivative_is_aligned_with_samples(scale):
    dt, n, w = 0.01, 1000, 2 * np.pi * 0.7
    t = np.arange(n) * dt
    res = tvregdiff(np.sin(w * t), 50, 1e-8, scale=scale, ep=1e-8, dx=dt)
    inner = slice(100, 900)

    def err(shift):
        return np.max(np.abs(res.derivative - w * np.cos(w * (t + shift * dt)))[inner])

    assert res.derivative.shape == (n,)
    assert res.u.shape == ((n + 1,) if scale == "small" else (n,))
    # A half-sample misalignment costs w * w * dt / 2 ~ 0.097; the aligned error is tiny.
    assert err(0.0) < 5e-3
    assert err(-0.5) > 0.08 and err(0.5) > 0.08


@settings(max_examples=15, deadline=None)
@given(
    c=st.floats(1e-3, 1e3),
    scale=st.sampled_from(["small", "large"]),
)
def test_unit_scaling_invariance(c, scale):
    f, dx = reference_data()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        base = tvregdiff(f, 5, 0.2, scale=scale, ep=1e-4, dx=dx)
        scaled = tvregdiff(c * f, 5, c * 0.2, scale=scale, ep=c**2 * 1e-4, dx=dx)
    np.testing.assert_allclose(
        scaled.u, c * base.u, rtol=1e-7, atol=1e-9 * c * np.abs(base.u).max()
    )
    np.testing.assert_allclose(scaled.functional, c**2 * base.functional, rtol=1e-7)


def test_converged_flag_and_warning():
    t = np.arange(200) * 0.01
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = tvregdiff(t**2, 500, 1e-4, scale="large", dx=0.01)
    assert res.converged and res.n_iter < 500 and res.rel_change[-1] < 1e-6
    assert res.functional.shape == res.rel_change.shape == (res.n_iter,)
    with pytest.warns(ConvergenceWarning, match=r"tol=1e-06 after 2 iterations"):
        res = tvregdiff(t**2, 2, 1e-4, scale="large", dx=0.01)
    assert not res.converged and res.n_iter == 2


@pytest.mark.parametrize("scale", ["small", "large"])
def test_constant_data_has_zero_derivative(scale):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = tvregdiff([2, 2, 2, 2, 2], 10, 0.1, scale=scale)
    assert res.converged and res.n_iter == 1
    np.testing.assert_array_equal(res.derivative, np.zeros(5))


def test_agrees_with_pynumdiff_large_scale():
    chartrand = pytest.importorskip("pynumdiff.utils._chartrand_tvregdiff")
    rng = np.random.default_rng(11)
    n, dx = 150, 0.01
    t = np.arange(n) * dx
    f = np.sin(2 * np.pi * t) + 0.01 * rng.standard_normal(n)
    ref = chartrand.TVRegDiff(f, 5, 1e-3, dx=dx, scale="large", ep=1e-2, plotflag=False)
    with pytest.warns(ConvergenceWarning):
        ours = tvregdiff(f, 5, 1e-3, scale="large", ep=1e-2, dx=dx)
    # Their steps are conjugate gradients to rtol 1e-4 (the difference grows as ep
    # shrinks and the steps get worse conditioned); ours are exact.
    assert np.max(np.abs(ours.u - ref)) < 3e-4 * np.max(np.abs(ours.u))


# ---------------------------------------------------------------- input checks


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"data": [0.0, np.nan, 1.0, 2.0]}, r"`data` must be finite, got nan at index 1"),
        ({"data": [0.0, 1.0, np.inf, 2.0]}, r"`data` must be finite, got inf"),
        ({"data": [0.0, 1.0]}, r"`data` must have at least 3 samples, got 2"),
        ({"data": np.zeros((3, 3))}, r"`data` must be 1-D, got shape \(3, 3\)"),
        ({"alpha": 0.0}, r"`alpha` must be positive and finite, got 0.0"),
        ({"alpha": -1.0}, r"`alpha` must be positive and finite, got -1.0"),
        ({"alpha": "big"}, r"`alpha` must be a positive number, got 'big'"),
        ({"iterations": 0}, r"`iterations` must be >= 1, got 0"),
        ({"iterations": 2.5}, r"`iterations` must be an integer >= 1, got 2.5"),
        ({"scale": "medium"}, r"`scale` must be 'small' or 'large', got 'medium'"),
        ({"ep": 0.0}, r"`ep` must be positive and finite, got 0.0"),
        ({"dx": -0.1}, r"`dx` must be positive and finite, got -0.1"),
        ({"tol": np.inf}, r"`tol` must be positive and finite, got inf"),
        ({"u0": np.zeros(4)}, r"`u0` must have shape \(5,\) for scale 'small' and n=4"),
        ({"u0": [0, 1, np.nan, 0, 0]}, r"`u0` must be finite"),
    ],
)
def test_invalid_input_raises(kwargs, match):
    args = {"data": [0.0, 1.0, 3.0, 2.0], "iterations": 2, "alpha": 0.1} | kwargs
    data, iterations, alpha = args.pop("data"), args.pop("iterations"), args.pop("alpha")
    with pytest.raises(ValueError, match=match):
        tvregdiff(data, iterations, alpha, **args)


def test_tv_functional_checks_length():
    with pytest.raises(ValueError) as err:
        tv_functional(np.zeros(5), np.zeros(4), 0.1, scale="large")
    assert "`u`" in str(err.value)
    assert "'large'" in str(err.value)
