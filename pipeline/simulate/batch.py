"""A batch of free runs as arrays: what both engines return before any per-record copy.

The compiled kernel and the NumPy engine integrate every trajectory of a batch on one time
grid (padded to the longest). :func:`mask_batch` turns their raw arrays into the batch's
result: NaN from a trajectory's divergence on (the acceleration from one sample before it,
whose last stage already saw the diverged state) and beyond its length, and a divergence
after a trajectory's own end does not count. Callers that need one column of many short
trajectories (restarted windows, bootstrap replicates) read :class:`BatchRun` directly
instead of one :class:`~debist.simulate.freerun.SimulationResult` per trajectory.

References
----------
Hairer, Norsett & Wanner, *Solving Ordinary Differential Equations I*, 2nd ed., Sec. II.1
(the classical RK4 the engines step with).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BatchRun", "mask_batch"]


@dataclass(frozen=True)
class BatchRun:
    """Free runs of a batch on one grid, masked by :func:`mask_batch`.

    Attributes
    ----------
    states : ndarray, shape (B, n, n_states)
        States at the samples (q first, q_dot second); NaN from a divergence on and beyond
        each trajectory's length.
    acc : ndarray, shape (B, n)
        Acceleration at the samples [unit of q / s^2]; NaN from one sample before a
        divergence on and beyond each length.
    diverged_at : ndarray of int, shape (B,)
        First diverged sample of each trajectory, -1 if none within its length.
    lengths : ndarray of int, shape (B,)
        Samples of each trajectory.
    substeps : int
        RK4 steps per sample used.
    """

    states: np.ndarray
    acc: np.ndarray
    diverged_at: np.ndarray
    lengths: np.ndarray
    substeps: int

    @property
    def q(self) -> np.ndarray:
        """Simulated position, shape (B, n) [unit of q] (a view of ``states``)."""
        return self.states[:, :, 0]

    def last_q(self) -> np.ndarray:
        """Each trajectory's q at its last sample, shape (B,) (NaN if it diverged)."""
        return self.states[np.arange(self.lengths.size), self.lengths - 1, 0]


def mask_batch(
    states: np.ndarray,
    acc: np.ndarray,
    diverged_at: np.ndarray,
    lengths: np.ndarray,
    substeps: int,
) -> BatchRun:
    """Mask a batch's raw arrays in place: NaN after divergence and beyond each length.

    Parameters
    ----------
    states : ndarray, shape (B, n, n_states)
        Integrated states, written in place.
    acc : ndarray, shape (B, n)
        Accelerations, written in place.
    diverged_at : ndarray of int, shape (B,)
        First sample at which each trajectory left the allowed range, -1 if never.
    lengths : array-like of int, shape (B,)
        Samples of each trajectory (``<= n``).
    substeps : int
        RK4 steps per sample used.

    Returns
    -------
    BatchRun
        The masked batch; ``diverged_at`` is -1 where the divergence came at or after a
        trajectory's length (padding, not its own samples).
    """
    lengths = np.asarray(lengths, dtype=np.int64)
    dead = np.asarray(diverged_at, dtype=np.int64)
    dead = np.where((dead >= 0) & (dead < lengths), dead, -1)
    k = np.arange(states.shape[1])[None, :]
    stop = np.where(dead >= 0, dead, lengths)[:, None]  # first masked state sample
    acc_stop = np.where(dead >= 0, np.maximum(dead - 1, 0), lengths)[:, None]
    states[k >= stop] = np.nan
    acc[k >= acc_stop] = np.nan
    return BatchRun(states, acc, dead, lengths, int(substeps))
