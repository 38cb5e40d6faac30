"""Error measures of the validation, defined once: NRMSE (Eq. 41), RMS and the mean baseline.

Every score debist prints (the validate and compare stages, the k-step prediction, the NARX
peer's order selection, the hyper-parameter search, the full-versus-reduced comparison of
the physics) comes from these functions.

References
----------
Masoud & Maas 2025, Eq. 41.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

__all__ = ["TailPercentiles", "mean_baseline_nrmse", "nan_percentiles", "nrmse", "rms"]


def nrmse(
    y_meas: np.ndarray,
    y_calc: np.ndarray,
    *,
    on_constant: Literal["raise", "nan"] = "raise",
) -> float:
    """Normalised root-mean-square error of Eq. 41.

    Parameters
    ----------
    y_meas : ndarray, shape (N,)
        Measured (reference) signal.
    y_calc : ndarray, shape (N,)
        Calculated (simulated) signal, same unit.
    on_constant : {"raise", "nan"}, optional
        What a constant measured signal (range 0, NRMSE undefined) gives: a ``ValueError``
        (scores of measurements, where it is a data error) or NaN (comparisons of two
        simulations, e.g. the full and reduced models at rest).

    Returns
    -------
    float
        ``sqrt(mean((y_meas - y_calc)^2)) / (max(y_meas) - min(y_meas))``
        [dimensionless]; NaN when ``y_calc`` has non-finite values (a diverged
        simulation is reported as such, not as a number).

    Raises
    ------
    ValueError
        If the shapes differ, or the measured signal is constant and ``on_constant`` is
        ``"raise"``.

    References
    ----------
    Masoud & Maas 2025, Eq. 41.

    Examples
    --------
    >>> nrmse(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0]))
    0.0
    >>> round(nrmse(np.array([0.0, 2.0]), np.array([1.0, 1.0])), 3)
    0.5
    >>> nrmse(np.ones(3), np.zeros(3), on_constant="nan")
    nan
    """
    y_meas = np.asarray(y_meas, dtype=float)
    y_calc = np.asarray(y_calc, dtype=float)
    if y_meas.shape != y_calc.shape:
        raise ValueError(f"shapes differ: {y_meas.shape} and {y_calc.shape}")
    span = float(np.max(y_meas) - np.min(y_meas))
    if span == 0:
        if on_constant == "nan":
            return float("nan")
        raise ValueError("measured signal is constant: NRMSE is undefined")
    if not np.all(np.isfinite(y_calc)):
        return float("nan")
    return float(np.sqrt(np.mean((y_meas - y_calc) ** 2)) / span)


def rms(error: np.ndarray) -> float:
    """Root-mean-square of an error signal (NaN if any value is not finite).

    Parameters
    ----------
    error : ndarray, shape (N,)
        Error samples [any unit].

    Returns
    -------
    float
        ``sqrt(mean(error^2))``, same unit as ``error``.

    Examples
    --------
    >>> rms(np.array([3.0, -3.0]))
    3.0
    """
    error = np.asarray(error, dtype=float)
    return float(np.sqrt(np.mean(error**2))) if np.all(np.isfinite(error)) else float("nan")


#: A free run whose NRMSE(q) exceeds this share of the mean baseline's is called poor: a lost
#: switch of a bistable beam leaves about half of the mean's error (:func:`mean_baseline_nrmse`).
POOR_SHARE = 0.5


def mean_baseline_nrmse(y_meas: np.ndarray) -> float:
    """NRMSE of the constant prediction ``mean(y_meas)``: the floor a model must beat.

    Parameters
    ----------
    y_meas : ndarray, shape (N,)
        Measured signal.

    Returns
    -------
    float
        ``nrmse(y_meas, mean(y_meas))``: ``std / range`` of the signal [dimensionless].

    Raises
    ------
    ValueError
        If the measured signal is constant.

    Examples
    --------
    >>> round(mean_baseline_nrmse(np.array([0.0, 2.0])), 3)
    0.5
    """
    y_meas = np.asarray(y_meas, dtype=float)
    return nrmse(y_meas, np.full(y_meas.size, np.mean(y_meas)))


def nan_percentiles(x: np.ndarray, percentiles: tuple[float, ...]) -> np.ndarray:
    """Percentiles over axis 0 ignoring NaN, vectorised over the other axis.

    The same numbers as :func:`numpy.nanpercentile` with ``axis=0`` and the default
    ``method="linear"``, bit for bit, computed by one sort over axis 0 instead of one call
    per column (numpy loops over the columns in Python when NaN is present).

    Parameters
    ----------
    x : ndarray, shape (B, n)
        Samples (e.g. B replicates of a curve of n points); NaN where missing.
    percentiles : tuple of float
        Percentiles in [0, 100].

    Returns
    -------
    ndarray, shape (len(percentiles), n)
        NaN in a column without a finite sample.

    References
    ----------
    Hyndman & Fan 1996, The American Statistician 50(4), 361-365 (definition 7, numpy's
    ``"linear"``).

    Examples
    --------
    >>> x = np.array([[1.0, np.nan], [3.0, 2.0], [np.nan, 4.0]])
    >>> nan_percentiles(x, (50.0,)).tolist()
    [[2.0, 3.0]]
    """
    x = np.asarray(x, dtype=float)
    srt = np.sort(x, axis=0)  # NaN last
    count = np.sum(~np.isnan(x), axis=0)
    out = np.empty((len(percentiles), x.shape[1]))
    for i, p in enumerate(percentiles):
        out[i] = _linear_order_statistic(
            lambda k: np.take_along_axis(srt, k[None, :], axis=0)[0], count, p
        )
    return out


def _linear_order_statistic(take, count: np.ndarray, p: float) -> np.ndarray:
    """Return the ``"linear"`` percentile ``p`` per column from ``take(k)``, the k-th smallest.

    ``take`` maps an index array of shape (n,) (ascending order, per column) to the values at
    those ranks; ``count`` is each column's number of finite samples (NaN where 0).
    """
    last = np.maximum(count - 1, 0)
    virtual = (count - 1) * (np.float64(p) / 100.0)
    prev = np.floor(virtual).astype(np.intp)
    above = virtual >= count - 1
    prev = np.where(above, last, prev)
    nxt = np.where(above, last, prev + 1)
    gamma = virtual - prev
    a, b = take(prev), take(nxt)
    diff = b - a  # numpy's _lerp, both branches, for the same rounding
    out = np.where(gamma >= 0.5, b - diff * (1.0 - gamma), a + diff * gamma)
    out[count == 0] = np.nan
    return out


class TailPercentiles:
    """Percentiles over rows that arrive in chunks, keeping only each column's extreme ranks.

    For the tail percentiles of a bootstrap band (2.5 and 97.5 of B replicates), the linear
    percentile needs only the ``k = floor((B - 1) min(p, 100 - p) / 100) + 2`` smallest or
    largest finite samples of a column. Each :meth:`add` merges a chunk into those, so the
    memory is ``2 k x n`` instead of ``B x n``; :meth:`result` gives the numbers of
    :func:`nan_percentiles` over all rows added, bit for bit.

    Parameters
    ----------
    n : int
        Columns (e.g. samples of a free run).
    rows : int
        Rows that will be added in all (e.g. replicates B), at least 1.
    percentiles : tuple of float
        The percentiles in [0, 100] that :meth:`result` returns.

    Raises
    ------
    ValueError
        If ``rows < 1``, a percentile is outside [0, 100], :meth:`add` gets more rows than
        ``rows`` or another number of columns, or :meth:`result` comes before any row.

    References
    ----------
    Hyndman & Fan 1996, The American Statistician 50(4), 361-365 (definition 7, numpy's
    ``"linear"``).

    Examples
    --------
    >>> tail = TailPercentiles(2, rows=3, percentiles=(50.0,))
    >>> tail.add(np.array([[1.0, np.nan], [3.0, 2.0]]))
    >>> tail.add(np.array([[np.nan, 4.0]]))
    >>> tail.result().tolist()
    [[2.0, 3.0]]
    """

    def __init__(self, n: int, rows: int, percentiles: tuple[float, ...]):
        if rows < 1 or not all(0.0 <= p <= 100.0 for p in percentiles):
            raise ValueError(f"rows >= 1 and percentiles in [0, 100]: {rows}, {percentiles}")
        self.percentiles = tuple(float(p) for p in percentiles)
        depth = max(min(p, 100.0 - p) for p in self.percentiles) / 100.0
        self.k = min(rows, int(np.floor((rows - 1) * depth)) + 2)
        self.rows, self.seen = rows, 0
        self.low = np.full((0, n), np.nan)  # the k smallest, ascending, NaN last
        self.neg = np.full((0, n), np.nan)  # the k smallest of -x: the k largest of x
        self.count = np.zeros(n, dtype=np.intp)

    def add(self, chunk: np.ndarray) -> None:
        """Merge rows of shape (c, n) (NaN where missing)."""
        chunk = np.asarray(chunk, dtype=float)
        if chunk.ndim != 2 or chunk.shape[1] != self.count.size:
            raise ValueError(f"chunk of shape (c, {self.count.size}) expected, got {chunk.shape}")
        if self.seen + chunk.shape[0] > self.rows:
            raise ValueError(f"more than the {self.rows} rows announced")
        self.seen += chunk.shape[0]
        self.count += np.sum(~np.isnan(chunk), axis=0)
        self.low = np.sort(np.concatenate([self.low, chunk]), axis=0)[: self.k]
        self.neg = np.sort(np.concatenate([self.neg, -chunk]), axis=0)[: self.k]

    def result(self) -> np.ndarray:
        """Percentiles of every row added; shape (len(percentiles), n), NaN where none finite."""
        if self.seen == 0:
            raise ValueError("no rows added")
        out = np.empty((len(self.percentiles), self.count.size))
        for i, p in enumerate(self.percentiles):
            take = self._from_below if p <= 50.0 else self._from_above
            out[i] = _linear_order_statistic(take, self.count, p)
        return out

    def _from_below(self, r: np.ndarray) -> np.ndarray:
        return np.take_along_axis(self.low, r[None, :], axis=0)[0]

    def _from_above(self, r: np.ndarray) -> np.ndarray:
        """Rank ``r`` from below is rank ``count - 1 - r`` from above."""
        above = np.maximum(self.count - 1 - r, 0)
        return -np.take_along_axis(self.neg, above[None, :], axis=0)[0]
