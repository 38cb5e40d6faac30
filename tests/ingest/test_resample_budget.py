"""Resampling a log is refused before its grid exceeds the memory budget, naming key and file."""

from pathlib import Path

import numpy as np
import pytest

from debist.core.errors import ResourceError
from debist.core.preflight import BUDGET_ENV
from debist.ingest.assemble import _resample
from debist.ingest.spec import ResampleSpec


def test_a_grid_finer_than_the_budget_is_refused_before_it_is_built(monkeypatch):
    monkeypatch.setenv(BUDGET_ENV, "1")
    t = np.arange(0.0, 10.0, 0.01)  # 9.99 s
    values = np.c_[np.sin(t)]
    with pytest.raises(ResourceError) as info:
        _resample(t, values, ResampleSpec(1e-9, "linear"), Path("log.csv"), "`q` ('laser')")
    message = str(info.value)
    # 9.99e9 + 1 samples x (1 channel + time) x 4 copies x 8 bytes
    assert message.startswith("resample.sample_time = 1e-09 s (log.csv): resampling `q`")
    assert "onto 9990000001 samples needs about 639 GB" in message


def test_a_grid_within_the_budget_is_resampled(monkeypatch):
    monkeypatch.setenv(BUDGET_ENV, "1")
    t = np.arange(0.0, 1.0, 0.01)
    t_new, v_new = _resample(t, np.c_[2.0 * t], ResampleSpec(0.005, "linear"), Path("x"), "q")
    assert t_new.size == 199
    np.testing.assert_allclose(v_new[:, 0], 2.0 * t_new)
