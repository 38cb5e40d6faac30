"""Resampling of a gap-free segment onto a uniform grid ``t[0] + m * sample_time``.

Two methods (key ``resample.method``):

``"polyphase"``
    :func:`scipy.signal.resample_poly` with the rational ratio ``up / down =
    dt_in / dt_out`` (``down <= 100``; an integer ``down`` with ``up = 1`` is plain
    anti-aliased decimation). Its FIR low-pass (Kaiser window, cut-off at the lower of
    the two Nyquist frequencies) removes what the new rate cannot represent, and
    ``padtype = "line"`` keeps the ends free of the zero-padding transient. Needs a
    uniformly sampled input: every step within the time tolerance
    (:func:`debist.ingest.checks.time_rtol`: the larger of 1e-6 and what the digits the
    time is written with imply, at most 0.1 %) of the mean step, and a target step whose
    ratio to the mean step is a fraction with denominator <= 100 within the same
    tolerance. The mean step ``(t[-1] - t[0]) / (n - 1)`` is the estimate of the recorded
    step: rounding of the time values averages out of it.
``"linear"``
    :func:`numpy.interp` on the new grid. No anti-aliasing: use it for upsampling, for
    jittery time bases, or with a target step much shorter than the signal's time scales.

Resampling never crosses a gap: :func:`debist.ingest.load.load_rig_log` calls it once per
gap-free segment. The new grid starts at the segment's first time and ends at or before
its last.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from debist.core.errors import RigLogError
from debist.ingest.checks import TIME_RTOL_MAX, time_rtol

__all__ = ["MAX_DOWN", "UNIFORM_RTOL", "resample_segment", "uniform_grid"]

#: Largest denominator of the polyphase ratio.
MAX_DOWN = 100
#: Largest relative deviation of a step from the mean step for "polyphase" (the bound of
#: :func:`~debist.ingest.checks.time_rtol`, which gives the tolerance of a time base).
UNIFORM_RTOL = TIME_RTOL_MAX


def uniform_grid(t0: float, t1: float, dt: float) -> np.ndarray:
    """Return ``t0 + m * dt`` for ``m = 0, 1, ...`` up to ``t1`` (inclusive, to rounding).

    Parameters
    ----------
    t0, t1 : float
        First and last time [s], ``t1 >= t0``.
    dt : float
        Step [s].

    Returns
    -------
    ndarray, shape (n,) [s]
        The grid.

    Examples
    --------
    >>> uniform_grid(1.0, 1.3, 0.1).round(12).tolist()
    [1.0, 1.1, 1.2, 1.3]
    """
    count = int(np.floor((t1 - t0) / dt * (1.0 + 1e-12) + 1e-9)) + 1
    return t0 + dt * np.arange(count)


def resample_segment(
    t: np.ndarray,
    values: np.ndarray,
    sample_time: float,
    method: str,
    resolution: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Resample one gap-free segment.

    Parameters
    ----------
    t, values : ndarray, shapes (n_samples,) [s] and (n_samples, n_channels)
        Time, strictly increasing; the channels (any units, resampled alike).
    sample_time : float
        Target step [s].
    method : {"polyphase", "linear"}
        Rational-rate polyphase filter or linear interpolation.
    resolution : float, optional
        Rounding step of the recorded time [s] (:func:`~debist.ingest.checks.printed_resolution`);
        0 for a time base written in full or computed.

    Returns
    -------
    t_new : ndarray, shape (n_new,) [s]
        ``t[0] + m * sample_time``, ``t_new[-1] <= t[-1]``.
    values_new : ndarray, shape (n_new, n_channels)
        The resampled channels.

    Raises
    ------
    RigLogError
        ``"polyphase"`` on a non-uniform time base, or with a ratio ``dt_out / dt_in`` that
        is not a fraction with denominator <= :data:`MAX_DOWN` (the caller adds the file).

    References
    ----------
    Vaidyanathan 1993, Multirate Systems and Filter Banks, ch. 4 (polyphase rational-rate
    conversion, :func:`scipy.signal.resample_poly`).

    Examples
    --------
    >>> t = np.arange(0.0, 1.0, 0.001)
    >>> t2, y2 = resample_segment(t, np.c_[3.0 + 0.0 * t], 0.01, "polyphase")
    >>> t2.size, bool(np.allclose(y2, 3.0))
    (100, True)
    """
    if method == "linear":
        t_new = uniform_grid(float(t[0]), float(t[-1]), sample_time)
        columns = [np.interp(t_new, t, values[:, j]) for j in range(values.shape[1])]
        return t_new, np.column_stack(columns) if columns else np.empty((t_new.size, 0))
    steps = np.diff(t)
    dt_in = (float(t[-1]) - float(t[0])) / steps.size
    rtol = time_rtol(t, resolution)
    spread = float(np.max(np.abs(steps - dt_in)))
    if spread > rtol * dt_in:
        raise RigLogError(
            f'resample method "polyphase" needs uniform sampling, but the steps range from '
            f"{steps.min():.9g} s to {steps.max():.9g} s (mean {dt_in:.9g} s, tolerance "
            f'{rtol:.3g}); use method = "linear"'
        )
    exact = sample_time / dt_in
    ratio = Fraction(exact).limit_denominator(MAX_DOWN)
    if abs(float(ratio) - exact) > rtol * exact:
        raise RigLogError(
            f"resample.sample_time = {sample_time:g} s is not a simple fraction of the "
            f"recorded step {dt_in:.9g} s (ratio {exact:.9g}, tolerance {rtol:.3g}); "
            'choose a rational ratio or use method = "linear"'
        )
    down, up = ratio.numerator, ratio.denominator
    if up == down:
        return t.copy(), values.copy()
    import scipy.signal  # deferred: importing scipy.signal costs about a second

    resampled = scipy.signal.resample_poly(values, up, down, axis=0, padtype="line")
    t_new = float(t[0]) + sample_time * np.arange(resampled.shape[0])
    keep = t_new <= t[-1] + 1e-9 * sample_time
    return t_new[keep], resampled[keep]
