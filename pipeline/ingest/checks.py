"""Validation of a selected rig-log table: selection size, finiteness, time base, gaps.

Pure functions on arrays. Each check raises :class:`~debist.core.errors.RigLogError` naming
the file, the channel and the offending value; sample indices in messages are 0-based
indices into the file (before slicing), times are in seconds as recorded.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from debist.core.errors import RigLogError

__all__ = [
    "GAP_RTOL",
    "MIN_SAMPLES",
    "TIME_RTOL",
    "TIME_RTOL_MAX",
    "check_enough",
    "check_finite",
    "check_sample_time",
    "check_time",
    "find_gaps",
    "gap_error",
    "printed_resolution",
    "slice_range",
    "split_segments",
    "time_rtol",
    "window_range",
]

#: Fewest samples a selection or segment may keep.
MIN_SAMPLES = 3
#: Relative margin above ``gap_tolerance * median(dt)`` (rounding of converted units).
GAP_RTOL = 1e-9
#: Smallest relative tolerance of a time step (float64 time bases written in full).
TIME_RTOL = 1e-6
#: Largest relative tolerance of a time step, however coarsely the time is written.
TIME_RTOL_MAX = 1e-3
#: Values sampled to find the digits a time column is written with.
_DIGIT_SAMPLES = 2000


def _t(value: float) -> str:
    # 13 significant digits: exact for recorded times, free of float rounding noise
    return f"{value:.13g} s"


def slice_range(n: int, sample_slice: tuple[int, int] | None, *, path: Path) -> tuple[int, int]:
    """Clip a 0-based end-exclusive sample slice to a log of ``n`` samples.

    Parameters
    ----------
    n : int
        Number of samples in the file.
    sample_slice : tuple of int or None
        ``(start, stop)`` from the ``slice`` key; None keeps everything.
    path : Path
        For messages.

    Returns
    -------
    tuple of int
        ``(start, stop)`` with ``0 <= start < stop <= n``.

    Raises
    ------
    RigLogError
        The slice keeps fewer than :data:`MIN_SAMPLES` samples.
    """
    if sample_slice is None:
        start, stop = 0, n
    else:
        start, stop = min(sample_slice[0], n), min(sample_slice[1], n)
    check_enough(
        stop - start, n, what=f"slice = [{start}, {stop}]" if sample_slice else "the log", path=path
    )
    return start, stop


def window_range(t: np.ndarray, window: tuple[float, float] | None) -> tuple[int, int]:
    """Index range of the samples inside a time window.

    Parameters
    ----------
    t : ndarray, shape (n_samples,) [s]
        Time (finite).
    window : tuple of float or None
        ``(start, stop)`` [s]; samples with ``start <= t < stop`` are kept.

    Returns
    -------
    tuple of int
        ``(a, b)``: from the first to one past the last sample inside the window
        (``a == b`` when none is). A time base going backwards inside that range is
        caught later by :func:`check_time`.

    Examples
    --------
    >>> window_range(np.arange(10.0), (2.0, 5.0))
    (2, 5)
    """
    if window is None:
        return 0, t.size
    inside = np.flatnonzero((t >= window[0]) & (t < window[1]))
    if inside.size == 0:
        return 0, 0
    return int(inside[0]), int(inside[-1]) + 1


def check_enough(count: int, total: int, *, what: str, path: Path) -> None:
    """Raise when a selection keeps fewer than :data:`MIN_SAMPLES` samples.

    Parameters
    ----------
    count : int
        Samples kept.
    total : int
        Samples available before the selection.
    what : str
        The selection, e.g. ``"slice = [0, 2]"``.
    path : Path
        For messages.

    Raises
    ------
    RigLogError
        ``count < MIN_SAMPLES``.
    """
    if count < MIN_SAMPLES:
        raise RigLogError(
            f"empty selection: {what} keeps {max(count, 0)} of {total} samples "
            f"(at least {MIN_SAMPLES} are needed)",
            path=path,
        )


def check_finite(
    values: np.ndarray, t: np.ndarray, index: np.ndarray, *, role: str, channel: str, path: Path
) -> None:
    """Raise on the first NaN or infinite value of a channel.

    Parameters
    ----------
    values : ndarray, shape (n_samples,)
        The channel (SI units).
    t : ndarray, shape (n_samples,) [s]
        Its time, for the message.
    index : ndarray of int, shape (n_samples,)
        File sample index of each value.
    role, channel : str
        Canonical column and source channel name.
    path : Path
        For messages.

    Raises
    ------
    RigLogError
        With the first bad sample's file index, time and value, and the count.
    """
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        i = int(bad[0])
        when = f"t = {_t(t[i])}" if np.isfinite(t[i]) else "time unknown"
        raise RigLogError(
            f"`{role}` is {values[i]} at sample {index[i]} ({when}); {bad.size} non-finite "
            "sample(s) in the selection",
            path=path,
            channel=channel,
            value=float(values[i]),
            sample=int(index[i]),
        )


#: Largest magnitude [SI] a channel of each quantity may take before ingest calls it absurd:
#: orders of magnitude beyond any bench rig debist serves (a 1e308 or a unit slip is caught,
#: a real reading never). Quantities not listed are not bounded here; `range` bounds them.
PLAUSIBLE = {
    "length": 100.0,  # [m]
    "angle": 1e4,  # [rad], ~1600 turns
    "voltage": 1e6,  # [V]
    "force": 1e7,  # [N]
    "acceleration": 1e6,  # [m/s^2], ~1e5 g
    "pressure": 1e10,  # [Pa]
    "current": 1e5,  # [A]
}
#: Decades of a unit slip that :func:`check_scale_jump` looks for (mm <-> m, um <-> m).
SCALE_DECADES = (3, 6)
#: Samples on each side of a candidate slip whose median level must confirm it.
_SLIP_WINDOW = 50


def check_plausible(
    values: np.ndarray,
    t: np.ndarray,
    index: np.ndarray,
    *,
    role: str,
    quantity: str | None,
    unit: str,
    channel: str,
    path: Path,
) -> None:
    """Raise on a value beyond the physical plausibility of its quantity (:data:`PLAUSIBLE`).

    Parameters
    ----------
    values : ndarray, shape (n_samples,)
        The channel in SI units (finite).
    t : ndarray, shape (n_samples,) [s]
        Its time, for the message.
    index : ndarray of int, shape (n_samples,)
        File sample index of each value.
    role, channel : str
        Canonical column and source channel name.
    quantity : str or None
        What the channel measures (``"length"``, ``"voltage"`` ...); None: not checked.
    unit : str
        The SI unit of ``values``, for the message.
    path : Path
        For messages.

    Raises
    ------
    RigLogError
        Naming the first such sample, its time and value, the limit and the count.
    """
    limit = PLAUSIBLE.get(quantity or "")
    if limit is None or values.size == 0:
        return
    bad = np.flatnonzero(np.abs(values) > limit)
    if bad.size:
        i = int(bad[0])
        raise RigLogError(
            f"`{role}` = {values[i]:.6g} {unit} at sample {index[i]} (t = {_t(t[i])}) is beyond "
            f"any plausible {quantity} (|{role}| <= {limit:g} {unit}); {bad.size} such "
            "sample(s): a sensor error code, a unit slip or a corrupt file",
            path=path,
            channel=channel,
            value=float(values[i]),
            sample=int(index[i]),
        )


def check_scale_jump(
    values: np.ndarray, t: np.ndarray, index: np.ndarray, *, role: str, channel: str, path: Path
) -> None:
    """Raise where a channel's scale jumps by 10^3 or 10^6 (a unit slip inside the record).

    A sample ``k`` is a slip when ``values[k] / values[k-1]`` is within 20 % of 10^d (or
    10^-d, d in :data:`SCALE_DECADES`, same sign) and the median magnitude of the
    :data:`_SLIP_WINDOW` samples after it differs from that of the ones before by the
    same power of ten within a factor 3. A motion moves continuously, so neighbouring
    samples of a real record never differ by three decades at the same sign while both
    sides keep their level.

    Parameters
    ----------
    values : ndarray, shape (n_samples,)
        The channel in SI units (finite).
    t, index : ndarray, shape (n_samples,)
        Time [s] and file sample index, for the message.
    role, channel : str
        Canonical column and source channel name.
    path : Path
        For messages.

    Raises
    ------
    RigLogError
        Naming the sample, its time, both values and the factor.

    Examples
    --------
    >>> q = np.r_[np.full(60, 10.0), np.full(60, 0.01)] + np.arange(120) * 1e-6
    >>> check_scale_jump(q, np.arange(120.0), np.arange(120), role="q", channel="x",
    ...                  path=Path("log.csv"))
    Traceback (most recent call last):
    ...
    debist.core.errors.RigLogError: file 'log.csv', channel 'x': `q` changes scale by 10^-3 ...
    """
    x = np.asarray(values, dtype=float)
    if x.size < 2 * _SLIP_WINDOW:
        return
    a, b = x[:-1], x[1:]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where((a != 0) & (np.sign(a) == np.sign(b)), b / a, np.nan)
        decades = np.log10(np.abs(ratio))
    for d in SCALE_DECADES:
        for sign in (1, -1):
            near = np.flatnonzero(np.abs(decades - sign * d) < np.log10(1.2))
            for k in near + 1:
                lo, hi = max(k - _SLIP_WINDOW, 0), min(k + _SLIP_WINDOW, x.size)
                before, after = np.median(np.abs(x[lo:k])), np.median(np.abs(x[k:hi]))
                if before == 0 or after == 0:
                    continue
                if abs(np.log10(after / before) - sign * d) < np.log10(3.0):
                    raise RigLogError(
                        f"`{role}` changes scale by 10^{sign * d} at sample {index[k]} "
                        f"(t = {_t(t[k])}): {x[k - 1]:.6g} then {x[k]:.6g}, and the levels "
                        "around it differ by the same factor: a unit slip inside the record "
                        "(e.g. mm and m); fix the log or cut it with `slice`/`time_window`",
                        path=path,
                        channel=channel,
                        value=float(x[k]),
                        sample=int(index[k]),
                    )


def check_varies(
    values: np.ndarray, *, role: str, unit: str, channel: str, path: Path, where: str = ""
) -> None:
    """Raise when a channel holds one value throughout (nothing to identify from it).

    Parameters
    ----------
    values : ndarray, shape (n_samples,)
        The channel in SI units.
    role, channel : str
        Canonical column and source channel name.
    unit : str
        The SI unit, for the message.
    path : Path
        For messages.
    where : str, optional
        Which part of the record (e.g. ``"segment at t = 3 s"``).

    Raises
    ------
    RigLogError
        With the constant value and the number of samples.
    """
    if values.size and np.ptp(values) == 0:
        part = f" in the {where}" if where else ""
        raise RigLogError(
            f"`{role}` is constant ({values[0]:.6g} {unit}) over all {values.size} samples"
            f"{part}: a stuck or disconnected sensor; there is no motion to identify",
            path=path,
            channel=channel,
            value=float(values[0]),
        )


def check_time(t: np.ndarray, index: np.ndarray, *, channel: str, path: Path) -> None:
    """Raise unless the time is finite and strictly increasing.

    Parameters
    ----------
    t : ndarray, shape (n_samples,) [s]
        Time as recorded.
    index : ndarray of int, shape (n_samples,)
        File sample index of each value.
    channel : str
        Source name of the time channel.
    path : Path
        For messages.

    Raises
    ------
    RigLogError
        A non-finite time (index and the previous time) or a step that is not positive
        (index and the two times; repeated or going back), with the count of such steps.
    """
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        i = int(bad[0])
        before = f"previous t = {_t(t[i - 1])}" if i > 0 else "first sample"
        raise RigLogError(
            f"time is {t[i]} at sample {index[i]} ({before})",
            path=path,
            channel=channel,
            value=float(t[i]),
            sample=int(index[i]),
        )
    steps = np.diff(t)
    bad = np.flatnonzero(steps <= 0.0)
    if bad.size:
        i = int(bad[0])
        kind = "repeated" if steps[i] == 0.0 else f"goes back by {_t(-steps[i])}"
        raise RigLogError(
            f"time is not strictly increasing at sample {index[i + 1]}: t[{index[i]}] = "
            f"{_t(t[i])}, t[{index[i + 1]}] = {_t(t[i + 1])} ({kind}); {bad.size} such step(s)",
            path=path,
            channel=channel,
            value=float(t[i + 1]),
            sample=int(index[i + 1]),
        )


def printed_resolution(values: np.ndarray) -> float:
    """Return the rounding step implied by the significant digits a column is written with.

    A time column written with ``N`` significant digits (``"%.9g"``: 0.000488281,
    1.99951172) is rounded to ``10**(e - N + 1)`` where ``e`` is the decimal exponent of
    its largest value; ``N`` is the most digits any value needs in its shortest round-trip
    form (at most 17 for float64, whose own spacing is the floor).

    Parameters
    ----------
    values : ndarray, shape (n,)
        The column as recorded (before any unit conversion, which would add digits).

    Returns
    -------
    float
        The rounding step in the recorded unit, ``>= 0`` (0 for an empty or all-zero
        column).

    References
    ----------
    G. L. Steele and J. L. White, "How to print floating-point numbers accurately",
    PLDI 1990 (the shortest round-trip form, :func:`numpy.format_float_scientific`).

    Examples
    --------
    >>> printed_resolution(np.array([0.000488281, 0.000976563, 1.99951172]))
    1e-08
    """
    x = np.asarray(values, dtype=np.float64)
    x = np.abs(x[np.isfinite(x) & (x != 0.0)])
    if x.size == 0:
        return 0.0
    picks = x[np.unique(np.linspace(0, x.size - 1, min(x.size, _DIGIT_SAMPLES)).astype(int))]
    digits = max(
        sum(ch.isdigit() for ch in np.format_float_scientific(v, unique=True).split("e")[0])
        for v in picks
    )
    largest = float(x.max())
    exponent = int(np.floor(np.log10(largest)))
    return float(max(10.0 ** (exponent - digits + 1), np.spacing(largest)))


def time_rtol(t: np.ndarray, resolution: float = 0.0) -> float:
    """Relative tolerance of the steps of a time base: uniformity, resampling, sample_time.

    Each step is a difference of two values rounded to ``resolution``, so it may be off
    by ``resolution`` (plus the float64 spacing of the largest time); relative to the
    mean step that is the tolerance, bounded by :data:`TIME_RTOL` below and
    :data:`TIME_RTOL_MAX` above. The same number decides whether a time base is uniform,
    whether ``resample.sample_time`` is a rational multiple of its step, and whether
    ``sample_time`` agrees with a time column.

    Parameters
    ----------
    t : ndarray, shape (n_samples,) [s]
        Time, at least 2 samples, increasing.
    resolution : float
        [s] the rounding step of the recorded time (:func:`printed_resolution` times the
        unit factor); 0 for a computed time base.

    Returns
    -------
    float
        The relative tolerance.

    Examples
    --------
    >>> t = np.round(np.arange(4096) / 2048.0, 8)      # 9 significant digits below 10 s
    >>> round(time_rtol(t, 1e-8), 7)
    4.1e-05
    """
    t = np.asarray(t, dtype=np.float64)
    step = (float(t[-1]) - float(t[0])) / (t.size - 1)
    rounding = max(resolution, float(np.spacing(np.max(np.abs(t)))))
    return float(min(TIME_RTOL_MAX, max(TIME_RTOL, 2.0 * rounding / step)))


def check_sample_time(
    t: np.ndarray,
    sample_time: float,
    *,
    channel: str,
    path: Path,
    resolution: float = 0.0,
    hint: str = "remove `sample_time` or fix the time unit",
) -> None:
    """Raise when ``sample_time`` disagrees with the median step of a time channel.

    Parameters
    ----------
    t : ndarray, shape (n_samples,) [s]
        Time, at least 2 samples.
    sample_time : float
        The ``sample_time`` key [s].
    channel : str
        Source name of the time channel.
    path : Path
        For messages.
    resolution : float
        [s] rounding step of the recorded time (see :func:`time_rtol`).
    hint : str
        The advice that ends the message.

    Raises
    ------
    RigLogError
        Relative difference above :func:`time_rtol`, naming both values.
    """
    median = float(np.median(np.diff(t)))
    rtol = time_rtol(t, resolution)
    if abs(median - sample_time) > rtol * sample_time:
        raise RigLogError(
            f"`sample_time` = {sample_time:.12g} s but the median step of the time channel is "
            f"{median:.12g} s (relative difference {abs(median / sample_time - 1):.3g}, "
            f"tolerance {rtol:.3g}); {hint}",
            path=path,
            channel=channel,
            value=float(median),
        )


def find_gaps(t: np.ndarray, tolerance: float) -> tuple[np.ndarray, float]:
    """Locate the gaps of a time base.

    Parameters
    ----------
    t : ndarray, shape (n_samples,) [s]
        Time, strictly increasing, at least 2 samples.
    tolerance : float
        A step larger than ``tolerance * median(dt)`` is a gap.

    Returns
    -------
    gaps : ndarray of int, shape (n_gaps,)
        Positions ``i`` such that the step ``t[i + 1] - t[i]`` is a gap.
    median_step : float
        ``median(dt)`` [s].

    Examples
    --------
    >>> gaps, dt = find_gaps(np.array([0.0, 1.0, 2.0, 10.0, 11.0]), 1.5)
    >>> gaps.tolist(), dt
    ([2], 1.0)
    """
    steps = np.diff(t)
    median = float(np.median(steps))
    # the relative margin keeps the decision independent of the recorded time unit
    return np.flatnonzero(steps > tolerance * median * (1.0 + GAP_RTOL)), median


def gap_error(
    t: np.ndarray,
    index: np.ndarray,
    gaps: np.ndarray,
    median_step: float,
    tolerance: float,
    *,
    channel: str,
    path: Path,
    hint: str = 'set gaps = "split" to read the gap-free segments separately, or raise '
    "`gap_tolerance`",
) -> RigLogError:
    """Build the error for a log with gaps under ``gaps = "error"``.

    Parameters
    ----------
    t : ndarray, shape (n_samples,) [s]
        Time.
    index : ndarray of int, shape (n_samples,)
        File sample index of each sample.
    gaps : ndarray of int
        From :func:`find_gaps`, non-empty.
    median_step : float
        From :func:`find_gaps` [s].
    tolerance : float
        The ``gap_tolerance`` key.
    channel : str
        Source name of the time channel.
    path : Path
        For messages.
    hint : str
        The advice that ends the message.

    Returns
    -------
    RigLogError
        Naming the first gap's start time, sample index and length and the gap count,
        ending with ``hint`` (by default: suggesting ``gaps = "split"``).
    """
    i = int(gaps[0])
    return RigLogError(
        f"{gaps.size} gap(s) in time longer than gap_tolerance = {tolerance:g} x the median "
        f"step {_t(median_step)}; the first starts at t = {_t(t[i])} (sample {index[i]}) "
        f"and lasts {_t(t[i + 1] - t[i])}; {hint}",
        path=path,
        channel=channel,
        value=float(t[i + 1] - t[i]),
        sample=int(index[i]),
    )


def split_segments(
    n: int, gaps: np.ndarray, min_segment: int
) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """Cut ``range(n)`` at the gaps into kept and dropped segments.

    Parameters
    ----------
    n : int
        Number of samples.
    gaps : ndarray of int
        Positions from :func:`find_gaps` (a gap lies between ``i`` and ``i + 1``).
    min_segment : int
        Segments with fewer samples are dropped.

    Returns
    -------
    kept, dropped : list of tuple of int
        ``(start, stop)`` end-exclusive ranges, in order.

    Examples
    --------
    >>> split_segments(10, np.array([0, 6]), 4)
    ([(1, 7)], [(0, 1), (7, 10)])
    """
    bounds = [0, *(int(g) + 1 for g in gaps), n]
    kept, dropped = [], []
    for start, stop in itertools.pairwise(bounds):
        (kept if stop - start >= min_segment else dropped).append((start, stop))
    return kept, dropped
