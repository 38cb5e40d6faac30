"""The vectorised NaN-aware percentiles against numpy's, bit for bit."""

import warnings

import numpy as np
import pytest

from debist.core.metrics import nan_percentiles
from debist.validate.prediction import _correlation


@pytest.mark.parametrize("shape", [(100, 2000), (7, 300), (1, 40), (2, 9)])
@pytest.mark.parametrize("nan_share", [0.0, 0.2])
def test_nan_percentiles_equal_numpys_bit_for_bit(shape, nan_share):
    rng = np.random.default_rng(7)
    x = rng.normal(size=shape)
    x[rng.random(shape) < nan_share] = np.nan
    x[:, :2] = np.nan  # columns where every replicate diverged
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        expected = np.nanpercentile(x, [2.5, 50.0, 97.5], axis=0)
    got = nan_percentiles(x, (2.5, 50.0, 97.5))
    assert np.array_equal(got, expected, equal_nan=True)
    assert np.isnan(got[:, :2]).all()


def test_the_lagged_correlation_equals_the_full_one_at_the_lags_asked_for():
    rng = np.random.default_rng(3)
    a = rng.normal(size=3000)
    b = rng.normal(size=3000) + 0.5 * np.roll(a, 4)
    lags = 25
    am, bm = a - a.mean(), b - b.mean()
    full = np.correlate(am, bm, mode="full")[a.size - 1 - lags : a.size + lags]
    expected = full / (a.size * np.sqrt(np.mean(am**2) * np.mean(bm**2)))
    got = _correlation(a, b, lags)
    assert got.shape == (2 * lags + 1,)
    assert np.allclose(got, expected, rtol=0.0, atol=1e-14)
    assert np.argmax(got) == lags - 4  # b(t) follows a(t - 4): r_ab peaks at tau = -4
