"""Helpers of the model-term tests: a truth with a term and its record, the curves' error."""

from __future__ import annotations

import numpy as np

from debist.identify.fit import Record
from tests.conftest import inside_class_record, truth_model


def truth_and_record(build):
    """``build(truth_model(seed 2))`` and its noise-free 13 s record (:func:`inside_class_record`)
    as an estimation :class:`~debist.identify.fit.Record`."""
    truth = build(truth_model(np.random.default_rng(2)))
    rec = inside_class_record(truth, np.arange(0.0, 13.0, 0.002))
    return truth, Record("sim", rec["q"], rec["q_dot"], rec["q_ddot"], rec["v"], rec["dt"])


def curve_error(model, truth, grid=None) -> float:
    """Largest error of ``c(q) q`` and ``g_i`` of ``model`` against ``truth``, relative to the
    truth's largest magnitude, on ``grid`` (default 50 points over +-12 mm)."""
    grid = np.linspace(-0.012, 0.012, 50) if grid is None else grid
    got, want = model.curves(grid), truth.curves(grid)
    return max(np.max(np.abs(got[k] - want[k])) / np.max(np.abs(want[k])) for k in ("cq", "g"))
