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


@pytest.mark.parametrize("rows", [1, 2, 7, 200])
@pytest.mark.parametrize("chunk", [1, 3, 20])
def test_the_tail_percentiles_of_chunks_equal_numpys_over_all_rows(rows, chunk):
    """Only the extreme ranks are kept, yet every percentile asked equals numpy's over the
    whole array, bit for bit, for any chunking; columns with 0, 1 or few finite values too."""
    from debist.core.metrics import TailPercentiles

    rng = np.random.default_rng(11)
    x = rng.normal(size=(rows, 500))
    x[rng.random(x.shape) < 0.3] = np.nan
    x[:, :2] = np.nan  # no finite value
    x[1:, 2] = np.nan  # one finite value
    x[:, 3] = 1.0  # ties
    percentiles = (2.5, 97.5, 0.0, 100.0)
    tail = TailPercentiles(x.shape[1], rows=rows, percentiles=percentiles)
    for a in range(0, rows, chunk):
        tail.add(x[a : a + chunk])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        expected = np.nanpercentile(x, percentiles, axis=0)
    assert np.array_equal(tail.result(), expected, equal_nan=True)
    assert tail.low.shape[0] <= (6 if rows == 200 else rows)  # B = 200: 6 ranks per tail


def test_the_tail_percentiles_refuse_what_they_cannot_answer():
    from debist.core.metrics import TailPercentiles

    tail = TailPercentiles(4, rows=2, percentiles=(2.5,))
    with pytest.raises(ValueError, match="no rows"):
        tail.result()
    with pytest.raises(ValueError, match="shape"):
        tail.add(np.zeros((1, 5)))
    tail.add(np.zeros((2, 4)))
    with pytest.raises(ValueError, match="more than the 2 rows"):
        tail.add(np.zeros((1, 4)))
    with pytest.raises(ValueError, match="percentiles"):
        TailPercentiles(4, rows=2, percentiles=(101.0,))
