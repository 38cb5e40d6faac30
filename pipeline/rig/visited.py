"""Where a rig experiment's data can inform each curve: wells, barrier, visited intervals.

The virtual rig knows what a real rig does not: the prototype's true restoring force and the
true tip velocity. From them and the log this module finds the q intervals that an
identification *should* mark identified, so that a check of the masks (a test, the band
calibration of ``benchmarks/calibrate_bands.py``) asks for exactly those:

* the rest wells and the barrier between them, the stable and unstable zeros of the true
  restoring force ``f(q)`` (:func:`rest_points`);
* for an input gain ``g_i``, the interval that input ``i``'s sub-threshold excitation visits
  near each well (:func:`visited_intervals`): the logged q during the profile's excitation
  blocks (its segments other than pulses and rest) at the samples where ``h(v_i)`` is at least
  a fraction ``active`` of its largest value in those blocks and the beam dwells
  (quasi-static by the true q_dot, :func:`debist.identify.excitation.quasi_static`), split at
  the barrier; the central percentiles of those positions (a point the beam reached for 1 %
  of the time at an edge is seen by the data from one side only, and an identification
  rightly does not mark an extrapolation).

References
----------
Masoud & Maas 2025, Sec. 4 and 5.1 (the identification profile: switching pulses and
sub-threshold excitation in each well, Fig. 11a).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.identify.excitation import quasi_static

__all__ = ["excitation_blocks", "rest_points", "visited_intervals"]


def rest_points(q: ArrayLike, f: ArrayLike) -> tuple[NDArray[np.float64], float]:
    """Return the rest wells and the barrier between them from a tabulated restoring force.

    Parameters
    ----------
    q : array_like, shape (n,)
        Positions [m], increasing.
    f : array_like, shape (n,)
        Restoring force at v = 0 [N] (``m_q q_ddot + ... + f(q) = ...``, Eq. 26).

    Returns
    -------
    wells : ndarray, shape (w,)
        The stable zeros (``df/dq > 0``) [m], increasing: grid points where ``f`` is 0, else
        by linear interpolation between the two grid points where it changes sign.
    barrier : float
        The unstable zero (``df/dq < 0``) nearest to q = 0 [m].

    Raises
    ------
    ValueError
        If ``f`` has no unstable zero on the grid (not a bistable curve).

    References
    ----------
    Masoud & Maas 2025, Eq. 26 and Fig. 3 (two stable equilibria and the unstable one).
    """
    q, f = np.asarray(q, dtype=float), np.asarray(f, dtype=float)
    i = np.flatnonzero(np.sign(f[:-1]) * np.sign(f[1:]) < 0)  # a sign change in between
    j = np.flatnonzero(f[1:-1] == 0.0) + 1  # a zero on an inner grid point
    roots = np.concatenate([q[i] - f[i] * (q[i + 1] - q[i]) / (f[i + 1] - f[i]), q[j]])
    rising = np.concatenate([f[i + 1] > f[i], f[j + 1] > f[j - 1]])
    order = np.argsort(roots)
    roots, rising = roots[order], rising[order]
    if not np.any(~rising):
        raise ValueError("the restoring force has no unstable zero on the grid (not bistable)")
    unstable = roots[~rising]
    return roots[rising], float(unstable[np.argmin(np.abs(unstable))])


def excitation_blocks(segments: Sequence[tuple[str, float, float]], t: ArrayLike) -> NDArray:
    """Flag the samples inside a profile's excitation blocks (not a pulse, not rest).

    Parameters
    ----------
    segments : sequence of (str, float, float)
        ``(label, start, stop)`` [s] of :attr:`debist.rig.profiles.Profile.segments`.
    t : array_like, shape (n,)
        Sample times of the log [s].

    Returns
    -------
    ndarray of bool, shape (n,)
        True where ``t`` lies in a segment whose label is neither ``rest`` nor ``pulse...``.
    """
    t = np.asarray(t, dtype=float)
    block = np.zeros(t.size, dtype=bool)
    for label, start, stop in segments:
        if label != "rest" and not label.startswith("pulse"):
            block |= (t >= start - 1e-9) & (t < stop - 1e-9)
    return block


def visited_intervals(
    q: ArrayLike,
    h: ArrayLike,
    block: ArrayLike,
    q_dot: ArrayLike,
    wells: ArrayLike,
    barrier: float,
    *,
    active: float = 0.1,
    percentiles: tuple[float, float] = (1.0, 99.0),
    min_samples: int = 20,
) -> list[tuple[float, float]]:
    """Return the q interval that an input's sub-threshold excitation visits near each well.

    Parameters
    ----------
    q : array_like, shape (n,)
        Logged positions [m].
    h : array_like, shape (n,)
        The input's mapped value ``h(v_i)`` along the log [V^2 or V].
    block : array_like of bool, shape (n,)
        The profile's excitation blocks (:func:`excitation_blocks`).
    q_dot : array_like, shape (n,)
        The true tip velocity [m/s] (the rig's ``states/q_dot``), for the dwell test.
    wells : array_like, shape (w,)
        Rest wells [m] (:func:`rest_points`).
    barrier : float
        The barrier between them [m].
    active : float
        The input counts as applied where ``h`` is at least this fraction of its largest
        value inside the blocks.
    percentiles : (float, float)
        The central part of the dwell positions kept [%].
    min_samples : int
        A well with fewer applied dwell samples gets no interval.

    Returns
    -------
    list of (float, float)
        ``(q_lo, q_hi)`` [m] per well where the input was applied, in the order of ``wells``.

    Raises
    ------
    ValueError
        If the arrays do not have one value per sample.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.1 (the sub-threshold excitation that identifies g_i).
    """
    q, h = np.asarray(q, dtype=float), np.asarray(h, dtype=float)
    block, q_dot = np.asarray(block, dtype=bool), np.asarray(q_dot, dtype=float)
    if not (q.shape == h.shape == block.shape == q_dot.shape):
        raise ValueError(
            f"q, h, block and q_dot need one value per sample: shapes {q.shape}, {h.shape}, "
            f"{block.shape}, {q_dot.shape}"
        )
    if not block.any():
        return []
    applied = block & (h >= active * h[block].max()) & quasi_static(q_dot)
    out = []
    for w in np.asarray(wells, dtype=float):
        near = applied & (np.sign(q - barrier) == np.sign(w - barrier))
        if near.sum() >= min_samples:
            lo, hi = np.percentile(q[near], percentiles)
            out.append((float(lo), float(hi)))
    return out
