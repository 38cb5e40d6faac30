"""Assembly of mapped channels into canonical tables: selection, checks, gaps, resampling.

Order of operations on a log whose channels share one sample index:

1. time ``t`` from the time channel, or ``k * sample_time`` (k the file sample index);
2. ``slice`` (sample indices), then ``time_window`` (``start <= t < stop``);
3. at least 3 samples left; time finite and strictly increasing; every channel finite;
   ``sample_time`` (if also given) equal to the median step of the time channel within
   the time tolerance (:func:`debist.ingest.checks.time_rtol`), and so is that of an
   unmapped time-named channel when the time is ``k * sample_time``; sensor faults (a
   channel's ``range`` / ``stuck``, :mod:`debist.ingest.validity`) under
   ``faults = "error"``;
4. gaps (a step > ``gap_tolerance * median(dt)``): error, or split into gap-free
   segments; under ``faults = "split"`` the faulty samples are cut out too; segments
   shorter than ``min_segment`` are dropped;
5. ``resample`` each segment on its own.

Channels of a dSPACE recording on *different* rasters (time bases) need ``resample``:
every raster is checked (finite, increasing, no gap), every channel is resampled from
its own raster, and the results are put on the common grid (linear interpolation of the
resampled channels where the rasters' phases differ). ``slice`` is refused there
(sample indices differ between rasters); ``time_window`` applies to the common grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import lazy_loader as lazy
import numpy as np

from debist.core.errors import RigLogError
from debist.core.preflight import RESAMPLE_COPIES, check_memory
from debist.core.units import lookup_unit
from debist.ingest.channels import Mapped
from debist.ingest.checks import (
    check_enough,
    check_finite,
    check_plausible,
    check_sample_time,
    check_scale_jump,
    check_time,
    find_gaps,
    gap_error,
    slice_range,
    split_segments,
    window_range,
)
from debist.ingest.resample import resample_segment, uniform_grid
from debist.ingest.spec import IngestSpec, ResampleSpec
from debist.ingest.stroke import check_stroke
from debist.ingest.validity import cut_faults, fault_mask

#: Bytes of one float64.
_F8 = 8

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = ["Segment", "assemble", "to_frame"]


@dataclass(frozen=True)
class Segment:
    """One gap-free stretch of the canonical table, before it becomes a DataFrame.

    Parameters
    ----------
    t : ndarray, shape (n_samples,) [s]
        Time as recorded (or the resampled grid).
    values : ndarray, shape (n_samples, n_columns)
        ``q, v1, ..., vN, <extras>`` in SI units.
    first_index : int
        File sample index of the segment's first (original) sample.
    dropped : list of dict
        Segments dropped for being shorter than ``min_segment``: ``first_index``,
        ``n_samples``, ``t_start`` [s].
    """

    t: np.ndarray
    values: np.ndarray
    first_index: int
    dropped: list[dict[str, float | int]] = field(default_factory=list)


def _with_path(exc: RigLogError, path: Path, channel: str | None = None) -> RigLogError:
    return RigLogError(str(exc), path=path, channel=channel)


def _resample(
    t: np.ndarray,
    values: np.ndarray,
    resample: ResampleSpec,
    path: Path,
    what: str,
    resolution: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    span = float(t[-1] - t[0]) if t.size else 0.0
    count = math.floor(span / resample.sample_time) + 1
    check_memory(
        _F8 * RESAMPLE_COPIES * count * (values.shape[1] + 1),
        f"resample.sample_time = {resample.sample_time:g} s ({path})",
        f"resampling {what} over {span:.6g} s onto {count} samples",
        "the grid, the resampled channels and their copies",
    )
    try:
        t_new, v_new = resample_segment(
            t, values, resample.sample_time, resample.method, resolution
        )
    except RigLogError as exc:
        raise _with_path(exc, path, what) from None
    check_enough(t_new.size, t.size, what=f"resampling {what}", path=path)
    return t_new, v_new


def _check_values(c, values: np.ndarray, t: np.ndarray, index: np.ndarray, path: Path) -> None:
    """Plausible magnitudes for every channel; q keeps one scale and a plausible stroke."""
    entry = lookup_unit(c.unit)
    quantity = entry.quantity if entry is not None else None
    check_plausible(values, t, index, role=c.role, quantity=quantity, unit=c.unit,
                    channel=c.source, path=path)  # fmt: skip
    if c.role == "q":
        check_scale_jump(values, t, index, role="q", channel=c.source, path=path)
        if quantity == "length":
            check_stroke(values, unit=c.file_unit, channel=c.source, path=path)


def _single_base(mapped: Mapped, spec: IngestSpec, path: Path) -> list[Segment]:
    n = mapped.columns[0].values.size
    start, stop = slice_range(n, spec.sample_slice, path=path)
    index = np.arange(start, stop)
    resolution = 0.0
    if mapped.time is not None:
        t, t_name = mapped.time.values[start:stop], mapped.time.source
        resolution = mapped.time.resolution
    else:
        t, t_name = index * float(spec.sample_time), f"k * {spec.sample_time:g} s"
    values = np.column_stack([c.values[start:stop] for c in mapped.columns])
    a, b = window_range(t, spec.time_window)
    if spec.time_window is not None:
        check_enough(b - a, t.size, what=f"time_window = {list(spec.time_window)} s", path=path)
    t, values, index = t[a:b], values[a:b], index[a:b]
    check_time(t, index, channel=t_name, path=path)
    for j, c in enumerate(mapped.columns):
        check_finite(values[:, j], t, index, role=c.role, channel=c.source, path=path)
        _check_values(c, values[:, j], t, index, path)
    if mapped.time is not None and spec.sample_time is not None:
        check_sample_time(t, spec.sample_time, channel=t_name, path=path, resolution=resolution)
    elif mapped.file_time is not None and spec.sample_time is not None:
        own = mapped.file_time
        check_sample_time(
            own.values[start:stop][a:b],
            spec.sample_time,
            channel=own.source,
            path=path,
            resolution=own.resolution,
            hint=f"the time is k * sample_time; map the file's time with `time = {{ name = "
            f'"{own.source}", unit = "s" }}` or fix `sample_time`',
        )
    faulty = fault_mask(t, values, index, mapped.columns, spec, path=path)
    gaps, median = find_gaps(t, spec.gap_tolerance)
    if gaps.size and spec.gaps == "error":
        raise gap_error(t, index, gaps, median, spec.gap_tolerance, channel=t_name, path=path)
    if spec.gaps == "split":
        kept, dropped = split_segments(t.size, gaps, spec.min_segment)
    else:
        kept, dropped = [(0, t.size)], []
    if faulty.any():
        kept, dropped = cut_faults(kept, dropped, faulty, spec.min_segment)
    dropped_info = [
        {"first_index": int(index[i]), "n_samples": j - i, "t_start": float(t[i])}
        for i, j in dropped
    ]
    if not kept:
        raise RigLogError(
            f"all {len(dropped)} gap-free segments are shorter than min_segment = "
            f"{spec.min_segment} samples (longest: {max(j - i for i, j in dropped)})",
            path=path,
            channel=t_name,
        )
    segments = []
    for i, j in kept:
        seg_t, seg_v = t[i:j], values[i:j]
        if spec.resample is not None:
            what = f"segment at t = {t[i]:.6g} s"
            seg_t, seg_v = _resample(seg_t, seg_v, spec.resample, path, what, resolution)
        segments.append(Segment(seg_t, seg_v, int(index[i]), dropped_info))
    return segments


def _mixed_bases(
    mapped: Mapped, spec: IngestSpec, resample: ResampleSpec, path: Path
) -> list[Segment]:
    bases = mapped.bases or {}
    if spec.sample_slice is not None:
        raise RigLogError(
            f"slice = {list(spec.sample_slice)} cannot apply to channels on different rasters "
            "(their sample indices differ); use `time_window` [s]",
            path=path,
        )
    for base in bases.values():
        index = np.arange(base.values.size)
        check_time(base.values, index, channel=base.source, path=path)
        gaps, median = find_gaps(base.values, spec.gap_tolerance)
        if gaps.size:
            raise gap_error(
                base.values,
                index,
                gaps,
                median,
                spec.gap_tolerance,
                channel=base.source,
                path=path,
                hint='gaps = "split" is not available for channels on different rasters; '
                "select a `time_window` without gaps",
            )
    pieces = []
    for c in mapped.columns:
        t = bases[c.base].values
        idx = np.arange(t.size)
        check_finite(c.values, t, idx, role=c.role, channel=c.source, path=path)
        _check_values(c, c.values, t, idx, path)
        fault_mask(t, c.values[:, None], np.arange(t.size), (c,), spec, path=path, split=False)
        what = f"`{c.role}` ('{c.source}')"
        resolution = bases[c.base].resolution
        pieces.append(_resample(t, c.values[:, None], resample, path, what, resolution))
    t0 = max(float(p[0][0]) for p in pieces)
    t1 = min(float(p[0][-1]) for p in pieces)
    grid = uniform_grid(t0, t1, resample.sample_time) if t1 > t0 else np.empty(0)
    # np.interp returns the samples themselves where a raster's grid coincides
    columns = [np.interp(grid, t_c, v_c[:, 0]) for t_c, v_c in pieces]
    check_enough(grid.size, grid.size, what="the overlap of the rasters", path=path)
    values = np.column_stack(columns)
    a, b = window_range(grid, spec.time_window)
    if spec.time_window is not None:
        check_enough(b - a, grid.size, what=f"time_window = {list(spec.time_window)} s", path=path)
    return [Segment(grid[a:b], values[a:b], 0)]


def _same_base(mapped: Mapped) -> bool:
    bases = mapped.bases or {}
    used = {c.base for c in mapped.columns}
    first = bases[next(iter(used))].values
    return all(np.array_equal(bases[k].values, first) for k in used)


def assemble(mapped: Mapped, spec: IngestSpec, path: Path) -> tuple[list[Segment], str]:
    """Turn mapped channels into checked, split and resampled segments.

    Parameters
    ----------
    mapped : Mapped
        From :func:`debist.ingest.channels.map_channels`.
    spec : IngestSpec
        The configuration.
    path : Path
        The file, for messages.

    Returns
    -------
    segments : list of Segment
        One per gap-free segment kept (exactly one when ``gaps = "error"``).
    time_source : str
        Name of the time channel (or ``"k * <sample_time> s"``).

    Raises
    ------
    RigLogError
        Any check of :mod:`debist.ingest.checks`, channels on different rasters without
        ``resample`` (naming both), or a failed resampling.
    """
    if mapped.bases is None:
        time = mapped.time
        source = time.source if time is not None else f"k * {spec.sample_time:g} s"
        return _single_base(mapped, spec, path), source
    if _same_base(mapped):
        base = mapped.bases[mapped.columns[0].base]
        single = Mapped(mapped.columns, time=base)
        return _single_base(single, spec, path), base.source
    if spec.resample is None:
        first = mapped.columns[0]
        other = next(c for c in mapped.columns if c.base != first.base)
        tb1, tb2 = mapped.bases[first.base], mapped.bases[other.base]
        raise RigLogError(
            f"`{first.role}` ('{first.source}', raster '{tb1.source}', {tb1.values.size} "
            f"samples) and `{other.role}` ('{other.source}', raster '{tb2.source}', "
            f"{tb2.values.size} samples) are on different time bases; set "
            "`resample = { sample_time = ..., method = ... }` to put them on one grid",
            path=path,
            channel=other.source,
        )
    names = sorted({mapped.bases[c.base].source for c in mapped.columns})
    return _mixed_bases(mapped, spec, spec.resample, path), " + ".join(names)


def to_frame(
    segment: Segment,
    *,
    number: int,
    n_segments: int,
    mapped: Mapped,
    spec: IngestSpec,
    path: Path,
    fmt: str,
    time_source: str,
) -> pd.DataFrame:
    """Build the canonical DataFrame of one segment.

    Parameters
    ----------
    segment : Segment
        The data.
    number : int
        0-based segment number (``attrs["segment"]``).
    n_segments : int
        Number of segments returned.
    mapped : Mapped
        For column names, sources and units.
    spec : IngestSpec
        For the resampling record.
    path : Path
        The file (``attrs["source"]``).
    fmt : str
        Detected format (``attrs["format"]``).
    time_source : str
        Name of the time channel.

    Returns
    -------
    pandas.DataFrame
        Columns ``t, q, v1, ..., vN, <extras>``, float64, RangeIndex; ``attrs`` holds
        ``units``, ``source``, ``channels``, ``segment``, ``n_segments``, ``format``,
        ``first_index``, ``dropped_segments`` and ``resample``.
    """
    data = {"t": segment.t.astype(np.float64)}
    for j, c in enumerate(mapped.columns):
        data[c.role] = segment.values[:, j].astype(np.float64)
    frame = pd.DataFrame(data)
    frame.attrs = {
        "units": {"t": "s", **{c.role: c.unit for c in mapped.columns}},
        "source": str(path),
        "channels": {"t": time_source, **{c.role: c.source for c in mapped.columns}},
        "segment": number,
        "n_segments": n_segments,
        "format": fmt,
        "first_index": segment.first_index,
        "dropped_segments": [dict(d) for d in segment.dropped],
        "resample": None
        if spec.resample is None
        else {"sample_time": spec.resample.sample_time, "method": spec.resample.method},
    }
    return frame
