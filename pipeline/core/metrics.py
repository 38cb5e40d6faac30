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

__all__ = ["mean_baseline_nrmse", "nan_percentiles", "nrmse", "rms"]


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
    last = np.maximum(count - 1, 0)
    out = np.empty((len(percentiles), x.shape[1]))
    for i, p in enumerate(percentiles):
        virtual = (count - 1) * (np.float64(p) / 100.0)
        prev = np.floor(virtual).astype(np.intp)
        above = virtual >= count - 1
        prev = np.where(above, last, prev)
        nxt = np.where(above, last, prev + 1)
        gamma = virtual - prev
        a = np.take_along_axis(srt, prev[None, :], axis=0)[0]
        b = np.take_along_axis(srt, nxt[None, :], axis=0)[0]
        diff = b - a  # numpy's _lerp, both branches, for the same rounding
        out[i] = np.where(gamma >= 0.5, b - diff * (1.0 - gamma), a + diff * gamma)
        out[i, count == 0] = np.nan
    return out
