"""The NARX peer refuses a candidate regressor above the memory budget before building it."""

import numpy as np
import pytest

from debist.core.errors import ResourceError
from debist.core.preflight import BUDGET_ENV, narx_bytes
from debist.model.narx import NarxConfig, fit_narx


def test_the_largest_candidate_regressor_is_refused_naming_the_settings(monkeypatch):
    monkeypatch.setenv(BUDGET_ENV, "1")
    rng = np.random.default_rng(3)
    q, v = rng.standard_normal(5000), rng.standard_normal((5000, 2))
    cfg = NarxConfig.from_dict({"lags": [3, 10], "degree": [4], "max_samples": 4000})
    with pytest.raises(ResourceError) as info:
        fit_narx([q], [v], "v", cfg, 10.0)
    # lags 10 of q, v1, v2 up to degree 4: C(34, 4) = 46376 terms x 4000 samples x 5 copies
    assert narx_bytes(4000, 10, 4, 2) == 8 * 5 * 4000 * 46376
    assert str(info.value).startswith(
        "[compare.narx] max_samples = 4000 (with lags = 10, degree = 4): the NARX candidate "
        "regressor of 4000 samples needs about 7.42 GB"
    )
