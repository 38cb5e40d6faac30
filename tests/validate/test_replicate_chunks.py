"""The bootstrap replicates' band and scores do not depend on how many run at once, nor on
the segments a long record is run in."""

import numpy as np
import pytest

from debist.stages.validate import run_validate
from debist.validate import freerun
from debist.validate.freerun import REPLICATE_CHUNK, REPLICATE_MIN_SEGMENT, replicate_blocks
from tests.conftest import G, double_well, logged_tables


def test_a_chunk_of_replicates_stays_within_its_memory_budget():
    n_states, n_inputs, B = 7, 2, 100
    for n in (100, 10_000, 100_000, 1_000_000, 10_000_000):
        n_fine = 8 * n
        chunk, segment = replicate_blocks(n_fine, n_inputs, n, n_states, B)
        assert chunk == REPLICATE_CHUNK  # the lock step keeps its blocks at any length
        assert min(n, REPLICATE_MIN_SEGMENT) <= segment <= n
        per_sample = 8 * chunk * (n_states + 5)  # states, acceleration, the band merge's 4 rows
        held = 8 * n_fine * n_inputs + segment * per_sample
        assert held <= freerun.REPLICATE_BUDGET or segment == REPLICATE_MIN_SEGMENT
        if segment < n:  # not shorter than the budget asks for
            assert held + per_sample > freerun.REPLICATE_BUDGET
    assert replicate_blocks(8 * 100, 2, 100, 7, B) == (REPLICATE_CHUNK, 100)
    assert replicate_blocks(8 * 10**7, 2, 10**7, 7, B) == (REPLICATE_CHUNK, REPLICATE_MIN_SEGMENT)
    assert replicate_blocks(8 * 100, 2, 100, 7, 3) == (3, 100)


@pytest.mark.parametrize("engine", ["compiled", "numpy"])
def test_the_band_and_the_scores_are_those_of_one_run_whatever_the_chunks_and_segments(
    monkeypatch, engine
):
    """Seven replicates with scattered gains (one far enough off to diverge), once all in
    one chunk over the whole record, once four at a time in segments of 700 samples (the
    budget forced to nothing): every band sample the same, bit for bit, each score to
    rounding, the diverged one infinite both times."""
    truth = double_well()
    tables, derivs = logged_tables(truth)
    rng = np.random.default_rng(5)
    dev = rng.normal(0.0, 0.1 * G, size=(7, 2))
    dev[3] = [40.0 * G, 40.0 * G]  # pushed out of range on the first switching pulse
    reps = (["input_gain1", "input_gain2"], dev)
    cfg = {"substeps": 1, "engine": engine, "q_limit": 0.02}
    one = run_validate(truth, tables, derivs, cfg, replicates=reps)
    monkeypatch.setattr(freerun, "REPLICATE_BUDGET", 0)
    monkeypatch.setattr(freerun, "REPLICATE_CHUNK", 4)
    monkeypatch.setattr(freerun, "REPLICATE_MIN_SEGMENT", 700)
    assert replicate_blocks(10**3, 2, 3000, 2, 7) == (4, 700)
    pieces = run_validate(truth, tables, derivs, cfg, replicates=reps)
    exact = ["replicates", "replicates_poor", "replicates_hold_q"]
    assert one.table[exact].equals(pieces.table[exact])
    for col in ("nrmse_q_lo", "nrmse_q_hi"):
        np.testing.assert_allclose(pieces.table[col], one.table[col], rtol=1e-12)
    for name, sim in one.simulated.items():
        for col in ("q_sim_lo", "q_sim_hi"):
            assert np.array_equal(sim[col], pieces.simulated[name][col], equal_nan=True)
    val = one.table[(one.table.dataset == "val") & (one.table.model == "rbf")].iloc[0]
    assert val.replicates == 7 and val.nrmse_q_lo < val.nrmse_q_hi  # a band, not a line
    assert val.nrmse_q_hi == np.inf  # the 97.5th order statistic of 7: the diverged one
    assert 0.0 < val.replicates_hold_q <= 1.0
