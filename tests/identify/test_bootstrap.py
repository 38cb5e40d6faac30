"""The block bootstrap of the least squares: spread under correlated errors, exact replicates."""

import numpy as np
import pytest

from debist.identify.bootstrap import block_bootstrap, block_length


def _ar1_regression(rng, n=3000, phi=0.95):
    t = np.arange(n)
    X = np.column_stack([np.ones(n), np.sin(2 * np.pi * t / 400.0), rng.standard_normal(n)])
    e = np.empty(n)
    e[0] = rng.standard_normal()
    for k in range(1, n):
        e[k] = phi * e[k - 1] + np.sqrt(1 - phi**2) * rng.standard_normal()
    return X, X @ np.array([1.0, 2.0, -0.5]) + e


def test_block_bootstrap_spread_matches_the_monte_carlo_spread_under_ar1_errors():
    """With strongly autocorrelated errors (AR(1), phi = 0.95) the i.i.d. formula understates
    the spread of the slow regressors' estimates several-fold; the block bootstrap recovers
    the Monte Carlo spread over independent noise realisations."""
    rng = np.random.default_rng(11)
    estimates = []
    for _ in range(300):
        X, y = _ar1_regression(rng)
        estimates.append(np.linalg.lstsq(X, y, rcond=None)[0])
    mc_sd = np.std(estimates, axis=0)
    X, y = _ar1_regression(np.random.default_rng(12))
    boot, block = block_bootstrap(X, y, [X.shape[0]], 400, seed=3)
    boot_sd = np.std(boot, axis=0)
    resid = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    iid_sd = np.sqrt(np.diag(np.var(resid) * np.linalg.inv(X.T @ X)))
    assert block >= 20  # covers the correlation time (1 / (1 - phi) = 20 samples)
    assert iid_sd[0] < 0.4 * mc_sd[0]  # the naive formula is far too optimistic here
    np.testing.assert_allclose(boot_sd[:2], mc_sd[:2], rtol=0.35)


def test_a_replicate_is_the_least_squares_on_its_resampled_blocks():
    """The weighted-Gram solution equals lstsq on the stacked rows of the drawn blocks."""
    rng = np.random.default_rng(5)
    X = rng.standard_normal((230, 4)) * np.array([1.0, 1e3, 1e-3, 10.0])
    y = rng.standard_normal(230)
    record_rows = [100, 130]
    boot, block = block_bootstrap(X, y, record_rows, 3, seed=9, block=25)
    starts = [*range(0, 100, 25), *range(100, 230, 25)]
    ends = [min(s + 25, 100 if s < 100 else 230) for s in starts]
    draw = np.random.default_rng(9)
    k = int(np.ceil(230 / 25))
    for b in range(3):
        pick = draw.integers(0, len(starts), k)
        rows = np.concatenate([np.arange(starts[i], ends[i]) for i in pick])
        ref = np.linalg.lstsq(X[rows], y[rows], rcond=None)[0]
        np.testing.assert_allclose(boot[b], ref, rtol=1e-9)
    assert block == 25


def test_block_bootstrap_rejects_inconsistent_rows():
    with pytest.raises(ValueError) as err:
        block_bootstrap(np.ones((6, 1)), np.ones(6), [5], 2, seed=0)
    assert "record_rows" in str(err.value)
    assert "to 5" in str(err.value)


@pytest.mark.parametrize("penalised", [False, True])
def test_a_replicate_that_misses_a_column_s_rows_gets_its_minimum_norm_fit(penalised):
    """Column 2 is nonzero in the first block only: a replicate without that block has a
    singular Gram and must give the fit of its own rows (plain: the minimum-norm one, zero
    there; penalised: the penalty ties the column to its neighbours)."""
    from debist.identify.regularise import Estimator, smoothness_operator

    rng = np.random.default_rng(11)
    X = rng.standard_normal((120, 4))
    X[30:, 2] = 0.0
    y = X @ np.array([1.0, -2.0, 0.5, 3.0]) + 0.1 * rng.standard_normal(120)
    P = smoothness_operator([f"c[{k}]" for k in range(4)], 4)
    est = Estimator(P, 0.3, np.full(4, -np.inf), np.full(4, np.inf))
    boot, _ = block_bootstrap(
        X, y, [120], 12, seed=2, block=30, estimator=est if penalised else None
    )
    scale = np.linalg.norm(X, axis=0)
    draw = np.random.default_rng(2)
    missed = 0
    for b in range(12):
        pick = draw.integers(0, 4, 4)
        rows = np.concatenate([np.arange(30 * i, 30 * i + 30) for i in pick])
        A = X[rows] / scale
        ref = (est.solve(A, y[rows]) if penalised else np.linalg.lstsq(A, y[rows])[0]) / scale
        np.testing.assert_allclose(boot[b], ref, rtol=1e-7, atol=1e-9)
        if not penalised and 0 not in pick:
            assert boot[b, 2] == pytest.approx(0.0, abs=1e-12)
        missed += 0 not in pick
    assert missed >= 1  # the draw does contain a replicate without the first block


def test_block_length_is_twice_the_correlation_time_of_ar1_errors():
    """AR(1) with phi = 0.95: the autocorrelation phi^k first falls below 1/e at lag 20
    (0.95^19 = 0.377, 0.95^20 = 0.358), so the block is about 40 rows."""
    rng = np.random.default_rng(7)
    e = np.empty(40_000)
    e[0] = rng.standard_normal()
    for k in range(1, e.size):
        e[k] = 0.95 * e[k - 1] + np.sqrt(1 - 0.95**2) * rng.standard_normal()
    assert 36 <= block_length([e], e.size) <= 44


def test_block_length_floor_and_cap():
    """White noise: n^(1/3) rows at least (1000 rows: 10); a random walk, whose correlation
    never falls below 1/e within the records: a quarter of the shortest record."""
    rng = np.random.default_rng(8)
    assert block_length([rng.standard_normal(1000)], 1000) == 10
    walks = [np.cumsum(rng.standard_normal(n)) for n in (400, 48)]
    assert block_length(walks, 448) == 12
