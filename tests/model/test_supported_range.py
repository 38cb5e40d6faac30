"""The RBF basis's range adapts to the data's support instead of failing the fit."""

import numpy as np
import pytest

from debist.identify.config import IdentifyConfig
from debist.identify.fit import supported_range
from debist.model.basis import RBFBasis


def test_a_supported_range_comes_back_unchanged():
    q = np.random.default_rng(0).uniform(-10e-3, 10e-3, 5000)
    cfg = IdentifyConfig(M=8)
    assert supported_range(q, cfg) == (q.min(), q.max())


def test_an_overshoot_peak_is_left_beyond_the_range_and_every_centre_is_supported():
    rng = np.random.default_rng(1)
    body = rng.uniform(-10e-3, 10e-3, 4000)
    peak = np.linspace(10e-3, 20e-3, 6)  # six samples of one overshoot to 20 mm
    q = np.concatenate([body, peak])
    cfg = IdentifyConfig(M=10, min_support=10)
    full = RBFBasis.equidistant(q.min(), q.max(), cfg.M, cfg.sigma_n).support(q)
    assert full[-1] < cfg.min_support  # the fit would fail on the full range
    lo, hi = supported_range(q, cfg)
    assert lo == q.min() and 10e-3 <= hi < 20e-3
    support = RBFBasis.equidistant(lo, hi, cfg.M, cfg.sigma_n).support(q)
    assert support.min() >= cfg.min_support
    # the smallest such range within the step: one step further out lacks support
    step = 0.01 * np.ptp(q)
    wider = RBFBasis.equidistant(lo, hi + step, cfg.M, cfg.sigma_n).support(q)
    assert wider[-1] < cfg.min_support


def test_without_a_support_rule_the_data_range_is_kept():
    q = np.array([0.0, 1e-3, 5e-3])
    assert supported_range(q, IdentifyConfig(min_support=0)) == pytest.approx((0.0, 5e-3))
