"""Sensor validity checks of the selected channels: range limits and stuck values.

A sensor fault is a run of samples of one channel that cannot be a measurement:

- **range**: a sample at or beyond a limit of the channel's ``range = [lo, hi]`` (given in
  the recorded unit; when the workflow gives none and the channel's name names a known
  sensor, its documented range, :mod:`debist.ingest.sensors`, with a warning saying
  so). A laser triangulation sensor outputs its range limit when the target
  leaves the measuring range; a saturated amplifier sits at its rail. The limits are
  converted to SI with the channel's own factor (so a sample recorded exactly at the
  limit compares equal) and compared with a margin of :data:`RANGE_ULPS` units in the last
  place of the limit: ``x >= hi`` and ``x <= lo``.
- **stuck**: ``k`` or more identical consecutive samples of a channel that otherwise
  varies (a frozen sensor or a repeated last value of a broken link). ``k`` is the
  channel's ``stuck`` key; by default (:func:`stuck_length`) it is :data:`STUCK_DEFAULT`
  on ``q`` when the median absolute step of ``q`` is > 0 (a noisy or moving reading), and
  no check otherwise or on any other channel (a held input voltage is legitimate).
  A run that is also a range fault is reported as a range fault.

The data set's ``faults`` key chooses the policy: ``"error"`` raises a
:class:`~debist.core.errors.RigLogError` naming the file, the channel, the first run's sample
range, times and value; ``"split"`` removes every faulty sample (of any channel) from the
table and keeps the segments in between, dropping those shorter than ``min_segment``
exactly as gap splitting does (:func:`cut_faults`).

Sample indices in messages are 0-based file indices (inclusive), times in seconds as
recorded, values and limits in the recorded unit.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from debist.core.errors import RigLogError
from debist.ingest.channels import Column
from debist.ingest.sensors import SensorRangeWarning, default_range
from debist.ingest.spec import ChannelSpec, IngestSpec

__all__ = [
    "RANGE_ULPS",
    "STUCK_DEFAULT",
    "Fault",
    "cut_faults",
    "fault_mask",
    "find_faults",
    "stuck_length",
]

#: Margin of the range comparison, in units in the last place of the limit (rounding of
#: a text file or of the unit conversion).
RANGE_ULPS = 4
#: Default stuck-run length [samples] of ``q`` when ``q`` varies.
STUCK_DEFAULT = 10

_SPLIT_HINT = 'set faults = "split" to cut the faulty samples out'


@dataclass(frozen=True)
class Fault:
    """One run of faulty samples of one channel.

    Parameters
    ----------
    kind : {"range", "stuck"}
        At or beyond a range limit, or a stuck value.
    start, stop : int
        Positions of the run in the checked arrays (end-exclusive).
    detail : str
        ``"the range limit 25 mm"`` or ``"stuck = 10"``, for the message.
    """

    kind: str
    start: int
    stop: int
    detail: str


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """End-exclusive ``(start, stop)`` of the runs of True in a boolean vector."""
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def stuck_length(values: np.ndarray, role: str, stuck: int | None) -> int:
    """Return the stuck-run length ``k`` checked on a channel (0: no check).

    Parameters
    ----------
    values : ndarray, shape (n_samples,)
        The channel (finite).
    role : str
        Its canonical column (``"q"``, ``"v1"``, ...).
    stuck : int or None
        The channel's ``stuck`` key.

    Returns
    -------
    int
        ``stuck`` when given; else :data:`STUCK_DEFAULT` for ``q`` when
        ``median(|diff(q)|) > 0``; else 0. A channel that is mostly constant (median step
        0, e.g. a held input, a coarse encoder at rest) is not checked by default.

    Examples
    --------
    >>> stuck_length(np.array([0.0, 1.0, 0.0, 1.0]), "q", None)
    10
    >>> stuck_length(np.zeros(4), "q", None), stuck_length(np.arange(4.0), "v1", None)
    (0, 0)
    """
    if stuck is not None:
        return stuck
    if role == "q" and values.size > 1 and np.median(np.abs(np.diff(values))) > 0:
        return STUCK_DEFAULT
    return 0


def _unit(column: Column) -> str:
    return f" {column.file_unit}" if column.file_unit else ""


def find_faults(
    values: np.ndarray,
    column: Column,
    spec: ChannelSpec,
    default: tuple[float, float, str] | None = None,
) -> list[Fault]:
    """Find the range and stuck faults of one channel.

    Parameters
    ----------
    values : ndarray, shape (n_samples,)
        The channel in SI units (finite), as selected.
    column : Column
        For its role, ``gain`` (recorded -> SI factor) and recorded unit.
    spec : ChannelSpec
        For ``range`` and ``stuck``.
    default : tuple, optional
        ``(lo, hi, note)``: the range used when ``spec.range`` is None (a known sensor's
        documented range, :func:`debist.ingest.sensors.default_range`), in the recorded
        unit; ``note`` goes into the fault's detail.

    Returns
    -------
    list of Fault
        Ordered by start; range runs (one per limit side) and stuck runs that are not
        range faults.

    Examples
    --------
    >>> col = Column("q", "x", np.empty(0), "m", gain=1e-3, file_unit="mm")
    >>> x = np.array([1.0, 25.0, 25.0, 2.0]) * 1e-3
    >>> [(f.kind, f.start, f.stop) for f in find_faults(x, col, ChannelSpec("q", range=(0, 25)))]
    [('range', 1, 3)]
    """
    faults = []
    bad = np.zeros(values.size, dtype=bool)
    limits, note = spec.range, ""
    if limits is None and default is not None:
        limits, note = default[:2], f" ({default[2]})"
    if limits is not None:
        lo, hi = limits
        for limit, upper in ((lo, False), (hi, True)):
            limit_si = limit * column.gain  # the conversion of the samples themselves
            margin = RANGE_ULPS * np.spacing(abs(limit_si))
            if upper == (column.gain > 0):
                side = values >= limit_si - margin
            else:
                side = values <= limit_si + margin
            bad |= side
            detail = f"the range limit {limit:.6g}{_unit(column)}{note}"
            faults += [Fault("range", int(a), int(b), detail) for a, b in _runs(side)]
    k = stuck_length(values, column.role, spec.stuck)
    if k >= 2 and values.size >= k:
        change = np.flatnonzero(np.diff(values) != 0) + 1
        bounds = np.concatenate(([0], change, [values.size]))
        for a, b in itertools.pairwise(bounds):
            if b - a >= k and not bad[a]:
                faults.append(Fault("stuck", int(a), int(b), f"stuck = {k}"))
    return sorted(faults, key=lambda f: f.start)


def _message(fault: Fault, column: Column, values: np.ndarray, t: np.ndarray, index: np.ndarray):
    a, b = fault.start, fault.stop - 1
    recorded = values[fault.start : fault.stop] / column.gain
    lo, hi = float(recorded.min()), float(recorded.max())
    value = f"value {lo:.10g}" if lo == hi else f"values {lo:.10g} to {hi:.10g}"
    if fault.kind == "stuck":
        what, rule = "identical consecutive samples, a stuck sensor", f"; {fault.detail}"
    else:
        noun = "sample" if a == b else "samples"
        what = f"{noun} {'at' if lo == hi else 'at or beyond'} {fault.detail}"
        rule = ""
    return (
        f"`{column.role}`: {b - a + 1} {what} (samples {index[a]}-{index[b]}, "
        f"t = {t[a]:.13g}-{t[b]:.13g} s, {value}{_unit(column)}{rule})"
    )


def fault_mask(
    t: np.ndarray,
    values: np.ndarray,
    index: np.ndarray,
    columns: Sequence[Column],
    spec: IngestSpec,
    *,
    path: Path,
    split: bool = True,
) -> np.ndarray:
    """Check every channel; raise on a fault or return the faulty samples to cut.

    Parameters
    ----------
    t : ndarray, shape (n_samples,) [s]
        Time (finite, increasing), for messages.
    values : ndarray, shape (n_samples, n_columns)
        The channels in SI units (finite), in the order of ``columns``.
    index : ndarray of int, shape (n_samples,)
        File sample index of each sample.
    columns : sequence of Column
        The mapped channels (role, source name, gain, recorded unit).
    spec : IngestSpec
        For each channel's ``range`` / ``stuck`` and the ``faults`` policy.
    path : Path
        For messages.
    split : bool
        False where splitting is not available (channels on different rasters): a fault
        raises whatever ``faults`` says.

    Returns
    -------
    ndarray of bool, shape (n_samples,)
        True where any channel is faulty (all False under ``faults = "error"``, which
        raises instead).

    Raises
    ------
    RigLogError
        Under ``faults = "error"`` (or ``split=False``): the first channel (in column
        order) with a fault, its first run (length, limit or ``stuck``, file sample range,
        time range, value) and the number of runs and faulty samples of that channel.
    """
    channel_specs = {c.role: c for c in spec.channels}
    mask = np.zeros(t.size, dtype=bool)
    for j, column in enumerate(columns):
        cspec = channel_specs[column.role]
        default = None
        if cspec.range is None:
            default = default_range(column.source, column.unit, column.gain)
            if default is not None:
                text = (
                    f"`{column.role}` range {default[0]:.6g} to {default[1]:.6g}{_unit(column)}: "
                    f"{default[2]}"
                )
                warnings.warn(SensorRangeWarning([path], column.source, text), stacklevel=2)
        faults = find_faults(values[:, j], column, cspec, default)
        if not faults:
            continue
        if spec.faults == "error" or not split:
            n_bad = sum(f.stop - f.start for f in faults)
            hint = (
                _SPLIT_HINT
                if split
                else 'faults = "split" is not available for channels on different rasters; '
                "select a `time_window` without faults"
            )
            raise RigLogError(
                f"{_message(faults[0], column, values[:, j], t, index)}; {len(faults)} fault "
                f"run(s), {n_bad} sample(s) in all; {hint}, or check `{column.role}.range` / "
                f"`{column.role}.stuck`",
                path=path,
                channel=column.source,
            )
        for f in faults:
            mask[f.start : f.stop] = True
    return mask


def cut_faults(
    kept: list[tuple[int, int]],
    dropped: list[tuple[int, int]],
    faulty: np.ndarray,
    min_segment: int,
) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """Remove faulty samples from the segments of :func:`~debist.ingest.checks.split_segments`.

    Parameters
    ----------
    kept, dropped : list of tuple of int
        ``(start, stop)`` end-exclusive segments (gap-free).
    faulty : ndarray of bool, shape (n_samples,)
        From :func:`fault_mask`.
    min_segment : int
        Fault-free pieces with fewer samples are dropped (the gap splitting rule).

    Returns
    -------
    kept, dropped : list of tuple of int
        The fault-free pieces of ``kept`` with at least ``min_segment`` samples, and the
        previously dropped segments plus the shorter pieces, each in order. Faulty samples
        are in neither.

    Examples
    --------
    >>> bad = np.zeros(12, dtype=bool)
    >>> bad[5:7] = True
    >>> cut_faults([(0, 12)], [], bad, 4)
    ([(0, 5), (7, 12)], [])
    """
    new_kept, new_dropped = [], list(dropped)
    for start, stop in kept:
        for a, b in _runs(~faulty[start:stop]):
            piece = (start + int(a), start + int(b))
            (new_kept if b - a >= min_segment else new_dropped).append(piece)
    return new_kept, sorted(new_dropped)
