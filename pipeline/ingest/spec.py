"""Configuration of the ingest stage: which file format, which channels, which checks.

:meth:`IngestSpec.from_dict` turns the ``[ingest]`` section of a workflow file (a dict
parsed from TOML) into frozen dataclasses and rejects anything it does not understand
with a :class:`~pipeline.errors.WorkflowError` naming the key and echoing the value.

Schema (every key optional unless marked required)::

    format = "auto"            # auto | mat | csv | parquet
    sample_time = 0.0016384    # [s] t = k * sample_time when no time channel is mapped
    time = { name = "t", unit = "s" }         # the time channel
    q  = { column = 1, unit = "V" }           # required: the displacement / output
    v1 = { name = "vir", unit = "V" }         # required: first input
    v2 = { regex = "Model Root/.*/v_DE2$", unit = "kV" }   # further inputs v2..vN, no holes
    v1_ref = { regex = "...", unit = "kV" }   # any other key holding a table: an extra channel
    slice = [40650, 105712]    # 0-based, end-exclusive sample slice of the file
    time_window = [0.0, 30.0]  # [s] keep start <= t < stop
    gap_tolerance = 1.5        # a step > gap_tolerance * median(dt) is a gap
    gaps = "error"             # error | split
    min_segment = 100          # [samples] shorter segments are dropped when splitting
    resample = { sample_time = 0.01, method = "polyphase" }   # polyphase | linear
    delimiter = "auto"         # text files: auto | whitespace | a single character
    header = "auto"            # text files: auto | true | false

A channel table holds exactly one selector, ``name`` (exact channel name), ``regex``
(:func:`re.search` on the channel name, must match exactly one channel) or ``column``
(0-based column index, text and Parquet files), plus ``unit`` (see
:data:`pipeline.ingest.units.UNITS`), ``scale`` (extra factor) and ``si_unit`` (the SI
unit of the result when ``scale`` changes the quantity, e.g. a V -> m calibration).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from pipeline.errors import WorkflowError
from pipeline.ingest.units import SI_UNITS, UNITS, canonical_unit

__all__ = [
    "FORMATS",
    "GAP_POLICIES",
    "OPTION_KEYS",
    "RESAMPLE_METHODS",
    "ChannelSpec",
    "IngestSpec",
    "ResampleSpec",
]

#: Values of the ``format`` key.
FORMATS = ("auto", "mat", "csv", "parquet")
#: Values of the ``gaps`` key.
GAP_POLICIES = ("error", "split")
#: Values of ``resample.method``.
RESAMPLE_METHODS = ("polyphase", "linear")
#: Keys of the section that are options, not channels.
OPTION_KEYS = (
    "format",
    "sample_time",
    "time",
    "slice",
    "time_window",
    "gap_tolerance",
    "gaps",
    "min_segment",
    "resample",
    "delimiter",
    "header",
)
_CHANNEL_KEYS = ("name", "regex", "column", "unit", "scale", "si_unit")
_INPUT = re.compile(r"v(\d+)")
_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_DELIMITER_ALIASES = {"tab": "\t", "space": "whitespace", "\\s+": "whitespace"}


def _fail(key: str, value: object, expected: str) -> WorkflowError:
    return WorkflowError(f"ingest `{key}` = {value!r}: {expected}")


def _number(key: str, value: object, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _fail(key, value, "expected a number")
    x = float(value)
    if not math.isfinite(x):
        raise _fail(key, value, "expected a finite number")
    if positive and x <= 0.0:
        raise _fail(key, value, "expected a number > 0")
    return x


def _integer(key: str, value: object, *, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise _fail(key, value, "expected an integer")
    if value < minimum:
        raise _fail(key, value, f"expected an integer >= {minimum}")
    return int(value)


def _choice(key: str, value: object, choices: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise _fail(key, value, "expected one of " + ", ".join(f'"{c}"' for c in choices))
    return value


def _pair(key: str, value: object) -> tuple[object, object]:
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise _fail(key, value, "expected a list of two values [start, stop]")
    return value[0], value[1]


@dataclass(frozen=True)
class ChannelSpec:
    """Where one canonical column comes from and in which unit it is recorded.

    Parameters
    ----------
    role : str
        The canonical column it fills: ``"t"``, ``"q"``, ``"v1"``, ..., or an extra name.
    name : str, optional
        Exact channel name (MAT variable, dSPACE ``Y(i).Name``, CSV header, Parquet column).
    regex : str, optional
        Pattern searched (:func:`re.search`) in the channel names; must match exactly one.
    column : int, optional
        0-based column index (text and Parquet files).
    unit : str, optional
        Unit of the recorded values, a key of :data:`~pipeline.ingest.units.UNITS`. When
        omitted the unit the file declares (dSPACE ``Unit``) is used.
    scale : float, optional
        Extra factor applied after the unit conversion: ``x_si = x * factor(unit) * scale``.
    si_unit : str, optional
        SI unit of the result, needed only when ``scale`` changes the quantity (a sensor
        calibration, e.g. ``unit = "V", scale = 2e-3, si_unit = "m"`` for 2 mm/V).

    Exactly one of ``name``, ``regex``, ``column`` is set (checked by :meth:`from_dict`).
    """

    role: str
    name: str | None = None
    regex: str | None = None
    column: int | None = None
    unit: str | None = None
    scale: float | None = None
    si_unit: str | None = None

    @property
    def selector(self) -> str:
        """Human-readable selector, e.g. ``name 'vir'`` or ``column 1``."""
        if self.name is not None:
            return f"name '{self.name}'"
        if self.regex is not None:
            return f"regex '{self.regex}'"
        return f"column {self.column}"

    @classmethod
    def from_dict(cls, role: str, table: object) -> ChannelSpec:
        """Parse one channel table.

        Parameters
        ----------
        role : str
            The key of the table in the section (``"time"`` is stored as role ``"t"``).
        table : dict
            ``{name|regex|column = ..., unit = ..., scale = ..., si_unit = ...}``.

        Returns
        -------
        ChannelSpec
            The parsed table.

        Raises
        ------
        WorkflowError
            Unknown key, not exactly one selector, bad regex, unknown unit, zero scale.
        """
        key = "time" if role == "t" else role
        if not isinstance(table, Mapping):
            raise _fail(key, table, "expected a table {name|regex|column = ..., unit = ...}")
        unknown = sorted(set(table) - set(_CHANNEL_KEYS))
        if unknown:
            raise _fail(
                f"{key}.{unknown[0]}",
                table[unknown[0]],
                "unknown key in a channel table; known keys are "
                + ", ".join(_CHANNEL_KEYS)
                + (
                    f" (if `{key}` is meant as an option, known options are "
                    + ", ".join(OPTION_KEYS)
                    + ")"
                    if role not in ("t", "q")
                    else ""
                ),
            )
        selectors = [k for k in ("name", "regex", "column") if k in table]
        if len(selectors) != 1:
            raise _fail(key, dict(table), "give exactly one of `name`, `regex`, `column`")
        name = regex = column = None
        if "name" in table:
            name = table["name"]
            if not isinstance(name, str) or not name:
                raise _fail(f"{key}.name", name, "expected a non-empty string")
        if "regex" in table:
            regex = table["regex"]
            if not isinstance(regex, str) or not regex:
                raise _fail(f"{key}.regex", regex, "expected a non-empty regular expression")
            try:
                re.compile(regex)
            except re.error as exc:
                raise _fail(f"{key}.regex", regex, f"invalid regular expression ({exc})") from None
        if "column" in table:
            column = _integer(f"{key}.column", table["column"], minimum=0)
        unit = None
        if "unit" in table:
            raw = table["unit"]
            unit = canonical_unit(raw) if isinstance(raw, str) else raw
            if not isinstance(unit, str) or unit not in UNITS:
                raise _fail(f"{key}.unit", raw, "unknown unit; known units are " + ", ".join(UNITS))
        scale = None
        if "scale" in table:
            scale = _number(f"{key}.scale", table["scale"])
            if scale == 0.0:
                raise _fail(f"{key}.scale", table["scale"], "expected a non-zero factor")
        si_unit = None
        if "si_unit" in table:
            si_unit = table["si_unit"]
            if not isinstance(si_unit, str) or si_unit not in SI_UNITS:
                raise _fail(
                    f"{key}.si_unit", si_unit, "expected one of " + ", ".join(sorted(SI_UNITS))
                )
        if role == "t":
            for k, si in (("unit", unit and UNITS[unit].si), ("si_unit", si_unit)):
                if si is not None and si != "s":
                    raise _fail(f"time.{k}", table[k], "the time channel needs a time unit")
        return cls(role, name, regex, column, unit, scale, si_unit)

    def to_dict(self) -> dict[str, Any]:
        """Return the channel table this spec was parsed from (normalised).

        Returns
        -------
        dict
            Keys ``name|regex|column`` and, when set, ``unit``, ``scale``, ``si_unit``.
        """
        out: dict[str, Any] = {}
        for k in _CHANNEL_KEYS:
            v = getattr(self, k)
            if v is not None:
                out[k] = v
        return out


@dataclass(frozen=True)
class ResampleSpec:
    """Resampling of every gap-free segment onto a uniform grid.

    Parameters
    ----------
    sample_time : float
        Target sample time [s].
    method : {"polyphase", "linear"}
        ``"polyphase"``: :func:`scipy.signal.resample_poly` (anti-aliasing FIR, rational
        ratio up/down with down <= 100, uniformly sampled input); ``"linear"``: linear
        interpolation (:func:`numpy.interp`, no anti-aliasing; for jittery time bases).
    """

    sample_time: float
    method: str = "polyphase"

    @classmethod
    def from_dict(cls, table: object) -> ResampleSpec:
        """Parse the ``resample`` table.

        Parameters
        ----------
        table : dict
            ``{sample_time = <s>, method = "polyphase" | "linear"}``.

        Returns
        -------
        ResampleSpec
            The parsed table.

        Raises
        ------
        WorkflowError
            Not a table, unknown key, missing or non-positive ``sample_time``, bad method.
        """
        if not isinstance(table, Mapping):
            raise _fail("resample", table, "expected a table {sample_time = ..., method = ...}")
        unknown = sorted(set(table) - {"sample_time", "method"})
        if unknown:
            raise _fail(f"resample.{unknown[0]}", table[unknown[0]], "unknown key")
        if "sample_time" not in table:
            raise _fail("resample", dict(table), "missing `sample_time` [s]")
        dt = _number("resample.sample_time", table["sample_time"], positive=True)
        method = _choice("resample.method", table.get("method", "polyphase"), RESAMPLE_METHODS)
        return cls(dt, method)


@dataclass(frozen=True)
class IngestSpec:
    """Frozen configuration of :func:`pipeline.ingest.load_rig_log`.

    Parameters
    ----------
    channels : tuple of ChannelSpec
        ``q``, ``v1``, ..., ``vN``, then the extra channels sorted by name.
    format : {"auto", "mat", "csv", "parquet"}
        ``"auto"``: detect by magic bytes, then by extension.
    sample_time : float, optional
        Sample time [s]; the time is ``k * sample_time`` (k the 0-based sample index of the
        file) when no time channel is mapped. With a time channel it is checked against
        the median step (1 % tolerance).
    time : ChannelSpec, optional
        The time channel (role ``"t"``). Not needed for dSPACE recordings, whose time base
        ``X`` is used.
    sample_slice : tuple of int, optional
        ``(start, stop)``, 0-based end-exclusive sample slice applied after reading.
    time_window : tuple of float, optional
        ``(start, stop)`` [s]; keeps ``start <= t < stop``; applied after the slice.
    gap_tolerance : float
        A time step larger than ``gap_tolerance * median(dt)`` is a gap; > 1.
    gaps : {"error", "split"}
        What a gap does: raise, or split the log into gap-free segments.
    min_segment : int
        [samples] segments shorter than this are dropped when splitting; >= 3.
    resample : ResampleSpec, optional
        Resampling of each segment.
    delimiter : str
        Text files: ``"auto"``, ``"whitespace"`` or a single character.
    header : bool or None
        Text files: whether the first line holds the channel names; None = detect.
    """

    channels: tuple[ChannelSpec, ...]
    format: str = "auto"
    sample_time: float | None = None
    time: ChannelSpec | None = None
    sample_slice: tuple[int, int] | None = None
    time_window: tuple[float, float] | None = None
    gap_tolerance: float = 1.5
    gaps: str = "error"
    min_segment: int = 100
    resample: ResampleSpec | None = None
    delimiter: str = "auto"
    header: bool | None = None

    @property
    def columns(self) -> tuple[str, ...]:
        """Column order of the canonical table: ``t, q, v1, ..., vN, <extras sorted>``."""
        return ("t", *(c.role for c in self.channels))

    @property
    def n_inputs(self) -> int:
        """Number N of inputs ``v1 ... vN``."""
        return sum(1 for c in self.channels if _INPUT.fullmatch(c.role))

    @classmethod
    def from_dict(cls, section: Mapping[str, Any]) -> IngestSpec:
        """Parse the ingest section of a workflow file.

        Parameters
        ----------
        section : dict
            The TOML-derived section; see the module docstring for the schema. Keys that
            are not options and hold a table are channels; ``q`` and ``v1`` are required,
            ``v2 ... vN`` must be contiguous, other names become extra columns.

        Returns
        -------
        IngestSpec
            The frozen configuration.

        Raises
        ------
        WorkflowError
            Naming the bad key and value: unknown key, wrong type, value out of range,
            missing ``q`` / ``v1``, a hole in ``v1 ... vN``, ``csv``/``parquet`` format
            without time channel nor ``sample_time``.

        Examples
        --------
        >>> spec = IngestSpec.from_dict({"sample_time": 1.6384e-3,
        ...     "q": {"column": 1, "unit": "V"}, "v1": {"column": 0, "unit": "V"}})
        >>> spec.columns
        ('t', 'q', 'v1')
        """
        if not isinstance(section, Mapping):
            raise WorkflowError(f"ingest section: expected a table, got {section!r}")
        for key, value in section.items():
            if not isinstance(key, str):
                raise _fail(str(key), value, "keys must be strings")
            if key not in OPTION_KEYS and not isinstance(value, Mapping):
                raise _fail(
                    key,
                    value,
                    "unknown option; known options are "
                    + ", ".join(OPTION_KEYS)
                    + " (a channel is a table {name|regex|column = ..., unit = ...})",
                )
        channel_keys = [k for k in section if k not in OPTION_KEYS]
        for key in channel_keys:
            if key == "t":
                raise _fail(key, section[key], "map the time channel with `time = {...}`")
            if not _IDENTIFIER.fullmatch(key):
                raise _fail(key, section[key], "a channel key must be an identifier")
        inputs = sorted((int(m.group(1)), k) for k in channel_keys if (m := _INPUT.fullmatch(k)))
        for number, key in inputs:
            if key != f"v{number}" or number == 0:
                raise _fail(key, section[key], "inputs are named v1, v2, ... (no v0, no zeros)")
        for required in ("q", "v1"):
            if required not in section:
                raise WorkflowError(
                    f"ingest: missing required channel `{required}` "
                    f'(e.g. {required} = {{ name = "...", unit = "..." }})'
                )
        numbers = [n for n, _ in inputs]
        if numbers != list(range(1, len(numbers) + 1)):
            missing = min(set(range(1, max(numbers) + 1)) - set(numbers))
            raise WorkflowError(
                f"ingest: inputs must be contiguous v1 ... vN; `v{missing}` is missing "
                f"but `v{max(numbers)}` is given"
            )
        extras = sorted(k for k in channel_keys if k != "q" and not _INPUT.fullmatch(k))
        order = ["q", *(k for _, k in inputs), *extras]
        channels = tuple(ChannelSpec.from_dict(k, section[k]) for k in order)

        fmt = _choice("format", section.get("format", "auto"), FORMATS)
        sample_time = None
        if "sample_time" in section:
            sample_time = _number("sample_time", section["sample_time"], positive=True)
        time = ChannelSpec.from_dict("t", section["time"]) if "time" in section else None
        if time is None and sample_time is None and fmt in ("csv", "parquet"):
            raise WorkflowError(
                f"ingest: format = {fmt!r} needs a time channel (`time = {{ ... }}`) "
                "or `sample_time` [s]"
            )
        sample_slice = None
        if "slice" in section:
            a, b = _pair("slice", section["slice"])
            start = _integer("slice", a, minimum=0)
            stop = _integer("slice", b, minimum=0)
            if stop <= start:
                raise _fail("slice", section["slice"], "expected [start, stop] with start < stop")
            sample_slice = (start, stop)
        time_window = None
        if "time_window" in section:
            a, b = _pair("time_window", section["time_window"])
            t0, t1 = _number("time_window", a), _number("time_window", b)
            if t1 <= t0:
                raise _fail("time_window", section["time_window"], "expected start < stop [s]")
            time_window = (t0, t1)
        gap_tolerance = _number("gap_tolerance", section.get("gap_tolerance", 1.5))
        if gap_tolerance <= 1.0:
            raise _fail("gap_tolerance", section["gap_tolerance"], "expected a number > 1")
        gaps = _choice("gaps", section.get("gaps", "error"), GAP_POLICIES)
        min_segment = _integer("min_segment", section.get("min_segment", 100), minimum=3)
        resample = ResampleSpec.from_dict(section["resample"]) if "resample" in section else None
        delimiter = section.get("delimiter", "auto")
        if isinstance(delimiter, str):
            delimiter = _DELIMITER_ALIASES.get(delimiter, delimiter)
        if not isinstance(delimiter, str) or not (
            delimiter in ("auto", "whitespace") or (len(delimiter) == 1 and not delimiter.isalnum())
        ):
            raise _fail(
                "delimiter",
                section.get("delimiter"),
                'expected "auto", "whitespace", "tab" or a single non-alphanumeric character',
            )
        header_value = section.get("header", "auto")
        if header_value == "auto" or header_value is None:
            header = None
        elif isinstance(header_value, bool):
            header = header_value
        else:
            raise _fail("header", header_value, 'expected "auto", true or false')
        return cls(
            channels=channels,
            format=fmt,
            sample_time=sample_time,
            time=time,
            sample_slice=sample_slice,
            time_window=time_window,
            gap_tolerance=gap_tolerance,
            gaps=gaps,
            min_segment=min_segment,
            resample=resample,
            delimiter=delimiter,
            header=header,
        )

    def to_dict(self) -> dict[str, Any]:
        """Return the section this spec was parsed from, normalised (defaults filled in).

        Returns
        -------
        dict
            A section ``s`` with ``IngestSpec.from_dict(s) == self``.
        """
        out: dict[str, Any] = {"format": self.format}
        if self.sample_time is not None:
            out["sample_time"] = self.sample_time
        if self.time is not None:
            out["time"] = self.time.to_dict()
        for c in self.channels:
            out[c.role] = c.to_dict()
        if self.sample_slice is not None:
            out["slice"] = list(self.sample_slice)
        if self.time_window is not None:
            out["time_window"] = list(self.time_window)
        out["gap_tolerance"] = self.gap_tolerance
        out["gaps"] = self.gaps
        out["min_segment"] = self.min_segment
        if self.resample is not None:
            out["resample"] = {
                "sample_time": self.resample.sample_time,
                "method": self.resample.method,
            }
        out["delimiter"] = self.delimiter
        out["header"] = "auto" if self.header is None else self.header
        return out
