"""The batch masking both free-run engines share: NaN after a divergence and beyond a length."""

import numpy as np

from debist.simulate.batch import mask_batch


def test_a_batch_is_masked_from_its_divergence_and_beyond_each_length():
    states = np.ascontiguousarray(np.broadcast_to(np.arange(6.0)[None, :, None], (3, 6, 2)))
    acc = np.tile(np.arange(6.0), (3, 1))
    # diverged at 3 within its 6 samples; at 4, past its own 4 samples (padding); never
    run = mask_batch(states, acc, np.array([3, 4, -1]), np.array([6, 4, 5]), 2)
    assert run.diverged_at.tolist() == [3, -1, -1]
    assert np.isfinite(run.states[:, :, 0]).sum(axis=1).tolist() == [3, 4, 5]
    assert np.isfinite(run.acc).sum(axis=1).tolist() == [2, 4, 5]  # one sample before
    assert run.q[0, :3].tolist() == [0.0, 1.0, 2.0]
    last = run.last_q()
    assert np.isnan(last[0]) and last[1:].tolist() == [3.0, 4.0]
    assert run.substeps == 2 and run.lengths.tolist() == [6, 4, 5]


def test_a_divergence_at_the_first_sample_masks_every_acceleration():
    run = mask_batch(np.ones((1, 4, 2)), np.ones((1, 4)), np.array([0]), np.array([4]), 1)
    assert np.isnan(run.states).all() and np.isnan(run.acc).all()
