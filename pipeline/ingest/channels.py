"""Mapping of a rig log's channels to the canonical columns, with unit conversion to SI.

Pure functions of a :class:`~debist.ingest.raw.RawLog` and an
:class:`~debist.ingest.spec.IngestSpec`: select each channel (by exact name, regex,
column index, or a MAT variable and its column), convert it to float64 and to SI
(``x * factor(unit) * scale``, the factor from pint, :mod:`debist.core.units`), check
that the result is a quantity the column can hold, and attach it to its time base.
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass

import lazy_loader as lazy
import numpy as np

from debist.core.errors import RigLogError, UnitMismatchWarning
from debist.core.units import (
    EXAMPLES,
    canonical_unit,
    describe_quantities,
    lookup_unit,
    role_quantities,
)
from debist.ingest.checks import printed_resolution
from debist.ingest.patterns import search_names
from debist.ingest.raw import RawChannel, RawLog
from debist.ingest.spec import ChannelSpec, IngestSpec

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = ["Column", "Mapped", "map_channels", "select_channel", "to_float"]

_MAX_LISTED = 20


@dataclass(frozen=True)
class Column:
    """One canonical column before assembly.

    Parameters
    ----------
    role : str
        Canonical column name (``"t"``, ``"q"``, ``"v1"``, ...).
    source : str
        Name of the channel it was read from.
    values : ndarray, shape (n_samples,)
        float64 values in SI units.
    unit : str
        The SI unit of ``values``.
    base : int or None
        Index of its time base in :attr:`Mapped.bases` (dSPACE raster), or None when
        every channel shares the file's single sample index.
    gain : float
        ``values = recorded * gain`` (unit factor times ``scale``), to state limits given
        in the recorded unit in SI.
    file_unit : str or None
        The recorded unit (the spec's or the file's), for messages.
    resolution : float
        Time columns: the rounding step of the recorded values in SI [s]
        (:func:`debist.ingest.checks.printed_resolution` times ``|gain|``); 0 elsewhere.
    """

    role: str
    source: str
    values: np.ndarray
    unit: str
    base: int | None = None
    gain: float = 1.0
    file_unit: str | None = None
    resolution: float = 0.0


@dataclass(frozen=True)
class Mapped:
    """The selected channels of a rig log, in SI units.

    Parameters
    ----------
    columns : tuple of Column
        ``q, v1, ..., vN, <extras>`` in canonical order.
    time : Column or None
        The time channel [s] of a file with a single sample index; None when the time is
        ``k * sample_time`` or comes from dSPACE time bases.
    bases : dict of int to Column
        dSPACE and MF4 recordings: the time bases [s] used by the columns, by raster index.
    file_time : Column or None
        With ``sample_time`` and no ``time`` mapped: a channel of the file named as a time
        in seconds (``t``, ``time``, ``Time [s]``, ...; see :data:`TIME_NAMES`), against
        which ``sample_time`` is checked; None otherwise.
    """

    columns: tuple[Column, ...]
    time: Column | None = None
    bases: dict[int, Column] | None = None
    file_time: Column | None = None


#: Names of an unmapped channel taken for a time in seconds (case-insensitive).
TIME_NAMES = re.compile(r"(t|time|zeit|timestamp)(\s*\[s\]|\s*\(s\)|_s)?", re.IGNORECASE)


def _listing(names: list[str]) -> str:
    shown = ", ".join(f"'{n}'" for n in names[:_MAX_LISTED])
    more = len(names) - _MAX_LISTED
    return shown + (f", ... ({more} more)" if more > 0 else "") if names else "none"


def _shape(data: np.ndarray) -> str:
    return " x ".join(str(n) for n in data.shape)


def _variable_column(spec: ChannelSpec, log: RawLog, key: str) -> RawChannel:
    """Return the vector, or the column of a matrix variable, that ``var`` selects."""
    if not log.format.startswith("mat") or log.rasters:
        kind = "dSPACE recording" if log.rasters else f"{log.format} file"
        raise RigLogError(
            f"`{key}` selects var '{spec.var}', but variables are selected in plain MAT "
            f"files only; select the channels of this {kind} by `name`, `regex`"
            + ("" if log.rasters else " or `column`"),
            path=log.path,
            channel=spec.var,
        )
    found = {v.name: np.asarray(v.data) for v in log.variables}
    if spec.var not in found:
        listing = _listing([f"{n} ({_shape(d)})" for n, d in found.items()])
        raise RigLogError(
            f"`{key}`: no numeric variable named '{spec.var}'; available: {listing}",
            path=log.path,
            channel=spec.var,
        )
    data = found[spec.var]
    matrix = data.reshape(-1, 1) if data.ndim == 1 else data
    if spec.column is None:
        if matrix.shape[1] != 1:
            raise RigLogError(
                f"`{key}`: variable '{spec.var}' is a {_shape(data)} matrix, not a vector; "
                f"add `column = i` (0-based, 0 ... {matrix.shape[1] - 1})",
                path=log.path,
                channel=spec.var,
            )
        return RawChannel(str(spec.var), matrix[:, 0])
    if spec.column >= matrix.shape[1]:
        raise RigLogError(
            f"`{key}` selects column {spec.column} of variable '{spec.var}', but its shape is "
            f"{_shape(data)} ({matrix.shape[1]} column(s), 0-based: 0 ... "
            f"{matrix.shape[1] - 1})",
            path=log.path,
            channel=spec.var,
        )
    return RawChannel(f"{spec.var}[:, {spec.column}]", matrix[:, spec.column])


def select_channel(
    candidates: tuple[RawChannel, ...], spec: ChannelSpec, log: RawLog, what: str = "channel"
) -> RawChannel:
    """Find the one channel a channel spec selects.

    Parameters
    ----------
    candidates : tuple of RawChannel
        Where to look (the channels, or the dSPACE time bases).
    spec : ChannelSpec
        The selector (``name``, ``regex``, ``column``, or ``var`` with an optional
        ``column``: a vector variable of a MAT file, or the 0-based column of an n x k
        matrix variable, named ``"<var>[:, <column>]"``).
    log : RawLog
        The rig log, for its path and capabilities in messages.
    what : str
        ``"channel"`` or ``"time base"``, for messages.

    Returns
    -------
    RawChannel
        The selected channel.

    Raises
    ------
    RigLogError
        Naming the file and the selector: no such name (with the available names,
        truncated), a regex matching none or several channels (named), a column index
        out of range or a column selection on a MAT file without ``var``; with ``var``:
        not a plain MAT file, no such variable (the variables and their shapes listed), a
        matrix without ``column``, a column index beyond the variable's shape (naming
        variable, shape and index).
    WorkflowError
        A regex that does not finish matching within
        :data:`~debist.ingest.patterns.MATCH_SECONDS` (naming the file, key and pattern).
    """
    key = "time" if spec.role == "t" else spec.role
    if spec.var is not None:
        return _variable_column(spec, log, key)
    names = [c.name for c in candidates]
    if spec.column is not None:
        if not log.by_column:
            hint = (
                f'; a column of a matrix variable is `{key} = {{ var = "...", column = '
                f"{spec.column} }}`"
                if log.variables and not log.rasters
                else ""
            )
            raise RigLogError(
                f"`{key}` selects column {spec.column}, but {log.format} {what}s are selected "
                f"by `name` or `regex`; available: {_listing(names)}{hint}",
                path=log.path,
                channel=f"column {spec.column}",
            )
        if spec.column >= len(candidates):
            raise RigLogError(
                f"`{key}` selects column {spec.column}, but the file has {len(candidates)} "
                f"columns (0 ... {len(candidates) - 1})",
                path=log.path,
                channel=f"column {spec.column}",
            )
        return candidates[spec.column]
    if spec.name is not None:
        hits = [c for c in candidates if c.name == spec.name]
        if not hits:
            matrix = {v.name: v.data for v in log.variables}.get(spec.name)
            hint = (
                "the file has no header line; select with `column = i`"
                if not log.has_names
                else f"available {what}s: {_listing(names)}"
            )
            if matrix is not None and np.ndim(matrix) == 2 and not log.rasters:
                hint = (
                    f"'{spec.name}' is a {_shape(np.asarray(matrix))} matrix variable; select "
                    f'a column with `{key} = {{ var = "{spec.name}", column = i }}`'
                )
            raise RigLogError(
                f"`{key}`: no {what} named '{spec.name}'; {hint}",
                path=log.path,
                channel=spec.name,
            )
        if len(hits) > 1:
            raise RigLogError(
                f"`{key}`: {len(hits)} {what}s are named '{spec.name}'; select with `regex` "
                "on a longer name or with `column`",
                path=log.path,
                channel=spec.name,
            )
        return hits[0]
    where = f"file '{log.path}': `{key}`"
    hits = [candidates[i] for i in search_names(str(spec.regex), names, where)]
    if len(hits) != 1:
        found = (
            f"matches {len(hits)} {what}s: {_listing([c.name for c in hits])}"
            if hits
            else f"matches no {what}; available: {_listing(names)}"
        )
        raise RigLogError(
            f"`{key}` = regex '{spec.regex}' {found}; it must match exactly one",
            path=log.path,
            channel=spec.regex,
        )
    return hits[0]


def to_float(channel: RawChannel, log: RawLog) -> np.ndarray:
    """Convert a raw channel to a float64 vector.

    Parameters
    ----------
    channel : RawChannel
        The channel; numeric, boolean or text that parses as numbers.
    log : RawLog
        For its path in messages.

    Returns
    -------
    ndarray, shape (n_samples,)
        The values as float64 (a copy).

    Raises
    ------
    RigLogError
        Not a vector, or a value that is not a number (first offending sample and value).
    """
    data = np.asarray(channel.data)
    if data.ndim == 0:
        data = data.reshape(1)
    if data.ndim != 1:
        raise RigLogError(
            f"data of shape {data.shape} is not a vector", path=log.path, channel=channel.name
        )
    if data.dtype.kind in "biuf":
        return data.astype(np.float64)
    numbers = pd.to_numeric(pd.Series(data), errors="coerce").to_numpy(dtype=np.float64)
    present = ~pd.isna(pd.Series(data)).to_numpy()
    bad = np.flatnonzero(np.isnan(numbers) & present)
    bad = [i for i in bad if str(data[i]).strip().lower() not in ("nan", "")]
    if bad:
        raise RigLogError(
            f"value {data[bad[0]]!r} at sample {bad[0]} is not a number",
            path=log.path,
            channel=channel.name,
            value=data[bad[0]],
            sample=int(bad[0]),
        )
    return numbers


def _same_unit(a: str, b: str) -> bool:
    """Whether two unit expressions are the same unit (``"mm"``, ``"millimeter"``)."""
    if a == b:
        return True
    ua, ub = lookup_unit(a), lookup_unit(b)
    return (
        ua is not None
        and ub is not None
        and ua.si == ub.si
        and math.isclose(ua.factor, ub.factor, rel_tol=1e-12)
    )


def _convert(
    channel: RawChannel, spec: ChannelSpec, log: RawLog
) -> tuple[np.ndarray, str, float, str | None]:
    key = "time" if spec.role == "t" else spec.role
    declared = canonical_unit(channel.unit) if channel.unit and channel.unit.strip() else None
    if spec.unit is not None and declared is not None and not _same_unit(declared, spec.unit):
        said, truth = lookup_unit(spec.unit), lookup_unit(declared)
        if said is None or truth is None or said.si != truth.si:
            raise RigLogError(
                f"wrong units for `{key}`: the file declares '{channel.unit}', the ingest spec "
                f"says '{spec.unit}', another quantity; fix `{key}.unit` (or `{key}.scale`)",
                path=log.path,
                channel=channel.name,
            )
        # the file's declared unit is the truth: convert from it (pint's factor), and keep the
        # workflow's unit for its limits (`range`) and the messages
        warnings.warn(
            f"{log.path}: channel '{channel.name}': the file declares '{channel.unit}', the "
            f"workflow says `{key}.unit` = '{spec.unit}'; converted from the file's unit",
            UnitMismatchWarning,
            stacklevel=2,
        )
        scale = 1.0 if spec.scale is None else spec.scale
        values = to_float(channel, log) * (truth.factor * scale)
        return values, spec.si_unit or truth.si, said.factor * scale, spec.unit
    unit = spec.unit if spec.unit is not None else declared
    if unit is None and spec.role == "t" and log.rasters:
        unit = "s"  # a recording's time base without a declared unit is in seconds
    examples = ", ".join(EXAMPLES)
    entry = lookup_unit(unit) if unit is not None else None
    if unit is None:
        if spec.scale is None or spec.si_unit is None:
            raise RigLogError(
                f"no unit for `{key}`: the file declares none; add `unit = ...` "
                f"(a unit pint parses, e.g. {examples}) to `{key}`",
                path=log.path,
                channel=channel.name,
            )
        factor, si = 1.0, spec.si_unit
    elif entry is not None:
        factor, si = entry.factor, spec.si_unit or entry.si
        if spec.si_unit is not None and entry.si != spec.si_unit and spec.scale is None:
            raise RigLogError(
                f"`{key}.si_unit` = '{spec.si_unit}' is another quantity than the declared "
                f"unit '{unit}' ({entry.quantity} [{entry.si}]); add `{key}.scale` (the "
                "calibration factor)",
                path=log.path,
                channel=channel.name,
            )
    elif spec.scale is not None and spec.si_unit is not None:
        factor, si = 1.0, spec.si_unit  # explicit calibration of a unit pint cannot use
    else:
        raise RigLogError(
            f"unknown unit '{unit}' declared by the file for `{key}` (pint does not parse "
            f"it as a unit with a factor to SI; e.g. {examples}); set `{key}.unit`, or give "
            f"`{key}.scale` (factor to SI) and `{key}.si_unit`",
            path=log.path,
            channel=channel.name,
        )
    allowed = role_quantities(spec.role)
    quantity = entry.quantity if entry is not None and spec.si_unit is None else None
    if allowed is not None and quantity is not None and quantity not in allowed:
        raise RigLogError(
            f"the file declares unit '{channel.unit}' ({quantity} [{si}]) for `{key}`, which "
            f"needs {describe_quantities(allowed)}; set `{key}.unit` (or `{key}.scale` and "
            f"`{key}.si_unit`)",
            path=log.path,
            channel=channel.name,
        )
    gain = factor * (1.0 if spec.scale is None else spec.scale)
    return to_float(channel, log) * gain, si, gain, unit


def _time_column(raw: RawChannel, spec: ChannelSpec, log: RawLog, index: int | None) -> Column:
    """Convert a time channel, with the rounding step of its recorded digits."""
    values, unit, gain, file_unit = _convert(raw, spec, log)
    resolution = printed_resolution(to_float(raw, log)) * abs(gain)
    return Column("t", raw.name, values, unit, index, gain, file_unit, resolution)


def _file_time(log: RawLog, spec: IngestSpec, used: set[str]) -> Column | None:
    """Return the unmapped time-named channel of a file read with ``sample_time``, if any."""
    for raw in log.channels:
        if raw.name in used or not TIME_NAMES.fullmatch(raw.name.strip()):
            continue
        declared = lookup_unit(raw.unit) if raw.unit and raw.unit.strip() else None
        if declared is not None and declared.quantity != "time":
            continue
        try:
            own = ChannelSpec("t", name=raw.name, unit=None if declared else "s")
            column = _time_column(raw, own, log, None)
        except RigLogError:
            continue  # not numeric: not a time
        if column.values.size >= 2 and np.all(np.isfinite(column.values)):
            return column
    return None


def _dspace_bases(log: RawLog, spec: IngestSpec, columns: list[Column]) -> dict[int, Column]:
    used = sorted({c.base for c in columns if c.base is not None})
    time_spec = spec.time or ChannelSpec("t")
    if spec.time is not None:
        chosen = select_channel(log.rasters, spec.time, log, what="time base")
        if spec.resample is None:
            for c in columns:
                if c.base != chosen.raster:
                    raise RigLogError(
                        f"`{c.role}` is on time base '{log.rasters[c.base].name}', but "
                        f"`time` selects '{chosen.name}'; set `resample` to combine rasters",
                        path=log.path,
                        channel=c.source,
                    )
    return {k: _time_column(log.rasters[k], time_spec, log, k) for k in used}


def map_channels(log: RawLog, spec: IngestSpec) -> Mapped:
    """Select, convert and align the channels an ingest spec asks for.

    Parameters
    ----------
    log : RawLog
        What a reader found in the file.
    spec : IngestSpec
        The configuration.

    Returns
    -------
    Mapped
        The canonical columns in SI units with their time base(s).

    Raises
    ------
    RigLogError
        Naming the file and the channel: a channel not found or ambiguous, wrong or
        unknown units, non-numeric data, channels of different lengths, a dSPACE channel
        whose time base is unknown or of another length, no time channel and no
        ``sample_time``.
    """
    columns = []
    for cspec in spec.channels:
        raw = select_channel(log.channels, cspec, log)
        values, unit, gain, file_unit = _convert(raw, cspec, log)
        if log.rasters:
            if raw.raster is None:
                raise RigLogError(
                    f"`{cspec.role}`: the recording has {len(log.rasters)} time bases X and "
                    "the channel names none (no XIndex, no matching Raster)",
                    path=log.path,
                    channel=raw.name,
                )
            n_time = np.size(log.rasters[raw.raster].data)
            if values.size != n_time:
                raise RigLogError(
                    f"`{cspec.role}` has {values.size} samples but its time base "
                    f"'{log.rasters[raw.raster].name}' has {n_time}",
                    path=log.path,
                    channel=raw.name,
                )
        columns.append(Column(cspec.role, raw.name, values, unit, raw.raster, gain, file_unit))
    if log.rasters:
        return Mapped(tuple(columns), bases=_dspace_bases(log, spec, columns))
    time = file_time = None
    if spec.time is not None:
        time = _time_column(select_channel(log.channels, spec.time, log), spec.time, log, None)
    elif spec.sample_time is not None:
        file_time = _file_time(log, spec, {c.source for c in columns})
    else:
        raise RigLogError(
            "no time channel is mapped and `sample_time` is not set; add "
            '`time = { name = "...", unit = "s" }` or `sample_time = <s>`',
            path=log.path,
        )
    reference = time or columns[0]
    for c in columns:
        if c.values.size != reference.values.size:
            raise RigLogError(
                f"`{c.role}` has {c.values.size} samples but `{reference.role}` "
                f"('{reference.source}') has {reference.values.size}",
                path=log.path,
                channel=c.source,
            )
    if file_time is not None and file_time.values.size != reference.values.size:
        file_time = None  # another length: not this table's time
    return Mapped(tuple(columns), time=time, file_time=file_time)
