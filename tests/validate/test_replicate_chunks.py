"""The bootstrap replicates' band and scores do not depend on how many run at once."""

import numpy as np

from debist.stages.validate import run_validate
from debist.validate import freerun
from debist.validate.freerun import REPLICATE_CHUNK, REPLICATE_MIN_CHUNK, replicate_chunk
from tests.conftest import G, double_well, logged_tables


def test_a_chunk_of_replicates_stays_within_its_memory_budget():
    n_states, n_inputs = 7, 2
    for n in (100, 10_000, 100_000, 1_000_000, 10_000_000):
        n_fine = 8 * n
        chunk = replicate_chunk(n_fine, n_inputs, n, n_states)
        assert REPLICATE_MIN_CHUNK <= chunk <= REPLICATE_CHUNK
        per_replicate = 8 * n * (n_states + 5)  # states, acceleration, the band merge's 4 rows
        held = 8 * n_fine * n_inputs + chunk * per_replicate
        assert held <= freerun.REPLICATE_BUDGET or chunk == REPLICATE_MIN_CHUNK
        if chunk < REPLICATE_CHUNK:  # not smaller than the budget asks for
            assert held + per_replicate > freerun.REPLICATE_BUDGET
    assert replicate_chunk(8 * 100, 2, 100, 7) == REPLICATE_CHUNK
    assert replicate_chunk(8 * 10**7, 2, 10**7, 7) == REPLICATE_MIN_CHUNK


def test_the_band_and_the_scores_are_those_of_one_chunk_whatever_the_chunking(monkeypatch):
    """Seven replicates with scattered gains, once all in one chunk, once two at a time (the
    budget forced to nothing): every band sample and every score the same, bit for bit."""
    truth = double_well()
    tables, derivs = logged_tables(truth)
    rng = np.random.default_rng(5)
    dev = rng.normal(0.0, 0.1 * G, size=(7, 2))
    reps = (["input_gain1", "input_gain2"], dev)
    cfg = {"substeps": 1}
    one = run_validate(truth, tables, derivs, cfg, replicates=reps)
    monkeypatch.setattr(freerun, "REPLICATE_BUDGET", 0)
    assert replicate_chunk(10**3, 2, 10**3, 2) == REPLICATE_MIN_CHUNK
    pairs = run_validate(truth, tables, derivs, cfg, replicates=reps)
    spread = ["replicates", "nrmse_q_lo", "nrmse_q_hi", "replicates_poor", "replicates_hold_q"]
    assert one.table[spread].equals(pairs.table[spread])
    for name, sim in one.simulated.items():
        for col in ("q_sim_lo", "q_sim_hi"):
            assert np.array_equal(sim[col], pairs.simulated[name][col], equal_nan=True)
    val = one.table[(one.table.dataset == "val") & (one.table.model == "rbf")].iloc[0]
    assert val.replicates == 7 and val.nrmse_q_lo < val.nrmse_q_hi  # a band, not a line
    assert 0.0 < val.replicates_hold_q <= 1.0
