"""Scores of an identification against the virtual rig's truth: curves, wells, lost switches.

Where the truth is known (the virtual rig, a plant zoo), an identified curve can be checked
where debist marks it identified: its largest error there as a share of the true curve's
range, and the share of those points whose band holds the truth (a band called 95 % should
hold it at about 95 %). A free run can be checked for the error a user notices first: the
beam resting in the other well than the measured one (a lost switch).

References
----------
Masoud & Maas 2025, Eq. 37 (the curves), Eq. 41 (NRMSE); Wasserman 2006, All of
Nonparametric Statistics, Sec. 5.7 (coverage of bands).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["CurveScore", "curve_score", "lost_switch", "marked_near"]


@dataclass(frozen=True)
class CurveScore:
    """One identified curve against its truth, over the points marked identified.

    Attributes
    ----------
    marked : int
        Grid points marked identified that lie on the truth's grid.
    max_error : float
        Largest ``|identified - true|`` over them as a fraction of the true curve's range
        over the truth grid [-]; NaN when none is marked.
    coverage : float
        Share of them whose band ``[lo, hi]`` holds the truth [-]; NaN when none is marked.
    """

    marked: int
    max_error: float
    coverage: float


def curve_score(
    q: ArrayLike,
    est: ArrayLike,
    lo: ArrayLike,
    hi: ArrayLike,
    marked: ArrayLike,
    q_true: ArrayLike,
    true: ArrayLike,
) -> CurveScore:
    """Score an identified curve against the truth where it is marked identified.

    Parameters
    ----------
    q : array_like, shape (n,)
        Grid of the identified curve [m], increasing.
    est, lo, hi : array_like, shape (n,)
        The curve and its band (same unit as ``true``).
    marked : array_like of bool, shape (n,)
        Where it is marked identified.
    q_true : array_like, shape (m,)
        Grid of the truth [m], increasing; identified points outside it are not scored.
    true : array_like, shape (m,)
        The true curve.

    Returns
    -------
    CurveScore

    Raises
    ------
    ValueError
        If the shapes differ.
    """
    q, est, lo, hi = (np.asarray(a, dtype=float) for a in (q, est, lo, hi))
    marked = np.asarray(marked, dtype=bool)
    q_true, true = np.asarray(q_true, dtype=float), np.asarray(true, dtype=float)
    if not (q.shape == est.shape == lo.shape == hi.shape == marked.shape):
        raise ValueError("the identified curve, its band and its mask differ in shape")
    if q_true.shape != true.shape:
        raise ValueError("the truth's grid and values differ in shape")
    use = marked & (q >= q_true[0]) & (q <= q_true[-1])
    if not use.any():
        return CurveScore(0, float("nan"), float("nan"))
    t = np.interp(q[use], q_true, true)
    span = float(np.ptp(true))
    err = np.abs(est[use] - t) / span if span > 0 else np.full(t.size, np.inf)
    inside = (lo[use] <= t) & (t <= hi[use])
    return CurveScore(int(use.sum()), float(err.max()), float(inside.mean()))


def marked_near(q: ArrayLike, marked: ArrayLike, wells: ArrayLike, within: float) -> bool:
    """Whether a curve is marked identified within ``within`` of every well.

    Parameters
    ----------
    q : array_like, shape (n,)
        Grid of the curve [m].
    marked : array_like of bool, shape (n,)
        Where it is marked identified.
    wells : array_like, shape (w,)
        Rest positions [m].
    within : float
        Distance [m].

    Returns
    -------
    bool
        True if for each well some marked point lies within ``within`` of it.
    """
    q = np.asarray(q, dtype=float)[np.asarray(marked, dtype=bool)]
    return bool(q.size) and all(np.any(np.abs(q - w) <= within) for w in np.atleast_1d(wells))


def lost_switch(
    q: ArrayLike,
    q_sim: ArrayLike,
    barrier: float,
    dt: float,
    *,
    margin: float = 2e-3,
    min_seconds: float = 0.5,
) -> bool:
    """Whether a free run rests in the other well than the measurement for a while.

    At the samples where the measured ``q`` is at least ``margin`` from the barrier (the
    beam is in a well), the free run is on the barrier's other side for at least
    ``min_seconds`` in a row; a free run that diverged (non-finite) counts as lost.

    Parameters
    ----------
    q, q_sim : array_like, shape (n,)
        Measured and simulated position [m].
    barrier : float
        Position of the barrier between the wells [m].
    dt : float
        Sample interval [s].
    margin : float, optional
        Distance from the barrier that counts as in a well [m].
    min_seconds : float, optional
        Shortest disagreement that counts [s] (a switch a little late is not lost).

    Returns
    -------
    bool

    Raises
    ------
    ValueError
        If the shapes differ or ``dt`` is not positive.

    References
    ----------
    Masoud & Maas 2025, Sec. 2 (two stable states and the barrier between them).
    """
    q, q_sim = np.asarray(q, dtype=float), np.asarray(q_sim, dtype=float)
    if q.shape != q_sim.shape:
        raise ValueError(f"q {q.shape} and q_sim {q_sim.shape} differ in shape")
    if not dt > 0:
        raise ValueError(f"dt must be positive, got {dt!r}")
    if not np.all(np.isfinite(q_sim)):
        return True
    in_well = np.abs(q - barrier) >= margin
    wrong = in_well & (np.sign(q - barrier) != np.sign(q_sim - barrier))
    return _longest_run(wrong) * dt >= min_seconds


def _longest_run(flags: NDArray[np.bool_]) -> int:
    """Length of the longest run of True."""
    if not flags.any():
        return 0
    padded = np.concatenate([[0], flags.astype(np.int8), [0]])
    edges = np.flatnonzero(np.diff(padded))
    return int(np.max(edges[1::2] - edges[::2]))
