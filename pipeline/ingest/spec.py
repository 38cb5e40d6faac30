"""Configuration of the ingest stage: which file format, which channels, which checks.

:meth:`IngestSpec.from_dict` turns the ``[ingest]`` section of a workflow file (a dict
parsed from TOML) into frozen pydantic dataclasses (:mod:`debist.core.config`) and rejects
anything it does not understand with a one-line :class:`~debist.core.errors.WorkflowError`
naming the key and echoing the value (``[ingest] q.unit: expected ..., got 'bananas'``).

A channel table (``time``, ``q``, ``v1`` ..., extra channels) holds one selector (``name``,
``regex``, ``column`` or ``var``), a ``unit`` pint parses (:mod:`debist.core.units`), an
optional calibration (``scale``, ``si_unit``) and the sensor checks of
:mod:`debist.ingest.validity` (``range``, ``stuck``). The section at a glance, and the
quantities each column may hold: docs/reference/formats.md.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Callable, Mapping
from typing import Annotated, Any, Literal

import pydantic
from pydantic import (
    AfterValidator,
    BeforeValidator,
    Field,
    FiniteFloat,
    NonNegativeInt,
    PositiveFloat,
)

from debist.core.config import (
    CONFIG,
    AsTuple,
    ConfigValueError,
    Interval,
    config_from_section,
    dotted_key,
    unknown_key_message,
)
from debist.core.errors import WorkflowError
from debist.core.units import (
    EXAMPLES,
    canonical_unit,
    describe_quantities,
    lookup_unit,
    role_quantities,
    si_symbol,
)
from debist.ingest.patterns import check_pattern

__all__ = [
    "FAULT_POLICIES",
    "FORMATS",
    "GAP_POLICIES",
    "OPTION_KEYS",
    "RESAMPLE_METHODS",
    "ChannelSpec",
    "IngestSpec",
    "ResampleSpec",
]

#: Values of the ``format`` key.
FORMATS = ("auto", "mat", "csv", "parquet", "mf4")
#: Values of the ``gaps`` key.
GAP_POLICIES = ("error", "split")
#: Values of the ``faults`` key.
FAULT_POLICIES = ("error", "split")
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
    "decimal",
    "header",
    "faults",
)
_CHANNEL_KEYS = ("name", "regex", "column", "var", "unit", "scale", "si_unit", "range", "stuck")
_SELECTORS = ("name", "regex", "column", "var")
_SELECTOR_TEXT = "give exactly one of `name`, `regex`, `column`, `var` (`var` with `column`)"
_INPUT = re.compile(r"v(\d+)")
_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_DELIMITER_ALIASES = {"tab": "\t", "space": "whitespace", "\\s+": "whitespace"}
_UNIT_TEXT = (
    "a unit pint parses, with a factor to SI (e.g. " + ", ".join(f"'{u}'" for u in EXAMPLES) + ")"
)
_SI_TEXT = "a coherent SI unit (factor 1; e.g. 'm', 'rad', 'V', 'N', 'm/s^2', '1')"
_DELIMITER_TEXT = '"auto", "whitespace", "tab" or a single non-alphanumeric character'

#: ``where`` of the messages: a section label, or a function of the top-level key giving it.
Where = str | Callable[[str], str]


def _label(where: Where, key: str) -> str:
    return where(key) if callable(where) else where


def _canonical(value: object) -> object:
    return canonical_unit(value) if isinstance(value, str) else value


def _known_unit(unit: str) -> str:
    if lookup_unit(unit) is None:
        raise ConfigValueError(None, _UNIT_TEXT)
    return unit


def _si_unit(unit: str) -> str:
    si = si_symbol(unit)
    if si is None:
        raise ConfigValueError(None, _SI_TEXT)
    return si


def _regex(pattern: str) -> str:
    try:
        return check_pattern(pattern)
    except ValueError as exc:
        raise ConfigValueError(None, f"a valid regular expression ({exc})") from None


def _nonzero(value: float) -> float:
    if value == 0.0:
        raise ConfigValueError(None, "a non-zero factor")
    return value


def _delimiter(value: object) -> object:
    return _DELIMITER_ALIASES.get(value, value) if isinstance(value, str) else value


def _check_delimiter(value: str) -> str:
    if not (value in ("auto", "whitespace") or (len(value) == 1 and not value.isalnum())):
        raise ConfigValueError(None, _DELIMITER_TEXT)
    return value


def _header(value: object) -> object:
    return None if value == "auto" else value


def _ordered(pair: tuple[Any, Any]) -> tuple[Any, Any]:
    if not pair[0] < pair[1]:
        raise ConfigValueError(None, "[start, stop] with start < stop")
    return pair


def _stuck(k: int) -> int:
    if k == 1:
        raise ConfigValueError(None, "0 (no check) or a run length >= 2 [samples]")
    return k


_Unit = Annotated[str, BeforeValidator(_canonical), AfterValidator(_known_unit)]


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class ChannelSpec:
    """Where one canonical column comes from and in which unit it is recorded.

    At most one of ``name``, ``regex``, ``column``, ``var`` is set, except ``var`` with
    ``column``; a workflow's channel table gives exactly one (:meth:`from_dict`).

    Raises
    ------
    pydantic.ValidationError
        On a value of the wrong type or out of range, several selectors, a unit pint does
        not parse, or a unit (or ``si_unit``) of a quantity the role cannot hold, e.g. a
        time channel in ``mm`` (a ``ValueError``; :meth:`from_dict` raises a
        ``WorkflowError`` naming the key, the value and the expected quantity).

    Notes
    -----
    Each field is a key of a channel table, documented under its declaration.

    References
    ----------
    pint (https://pint.readthedocs.io) parses the units, see :mod:`debist.core.units`.
    """

    role: str
    """The canonical column it fills: "t", "q", "v1", ..., or an extra name."""
    name: Annotated[str, Field(min_length=1)] | None = None
    """Exact channel name (MAT variable, dSPACE Y(i).Name, CSV header, Parquet column)."""
    regex: Annotated[str, Field(min_length=1), AfterValidator(_regex)] | None = None
    """Pattern searched (re.search) in the channel names; must match exactly one."""
    column: NonNegativeInt | None = None
    """0-based column index of the file (text, Parquet), or with var of that variable (MAT)."""
    unit: Annotated[_Unit | None, Field(description=_UNIT_TEXT)] = None
    """Unit of the recorded values, any unit pint parses with a factor to SI; default the unit the
    file declares.
    """
    scale: Annotated[FiniteFloat, AfterValidator(_nonzero)] | None = None
    """Extra factor after the unit conversion: x_si = x * factor(unit) * scale."""
    si_unit: Annotated[
        str | None, BeforeValidator(_canonical), AfterValidator(lambda u: u and _si_unit(u))
    ] = None
    """SI unit of the result when scale changes the quantity (a calibration, e.g. unit = "V", scale
    = 2e-3, si_unit = "m").
    """
    range: Interval | None = None
    """[lo, hi] valid range of the sensor in the recorded unit; a sample at or beyond a limit is a
    fault.
    """
    stuck: Annotated[NonNegativeInt, AfterValidator(_stuck)] | None = None
    """[samples] k or more identical consecutive samples are a stuck sensor; 0: no check; default
    10 on q when it varies.
    """
    var: Annotated[str, Field(min_length=1)] | None = None
    """Name of a numeric MAT variable: a vector, or with column an n x k matrix (samples in rows).
    """

    def __post_init__(self) -> None:
        given = [k for k in _SELECTORS if getattr(self, k) is not None]
        if len(given) > 1 and set(given) != {"var", "column"}:
            raise ConfigValueError("", message=f"{_SELECTOR_TEXT}, got " + ", ".join(given))
        self._check_quantity()
        if self.role == "t":
            for key in ("range", "stuck"):
                if getattr(self, key) is not None:
                    raise ConfigValueError(
                        key,
                        message="the time channel has no sensor checks (checked: strictly "
                        "increasing, gaps)",
                    )

    def _check_quantity(self) -> None:
        """Raise unless the result (``si_unit``, else ``unit``) suits the role."""
        unit = lookup_unit(self.unit) if self.unit is not None else None
        if self.si_unit is not None:
            result = lookup_unit(self.si_unit)
            if unit is not None and unit.si != result.si and self.scale is None:
                raise ConfigValueError(
                    "si_unit",
                    message=f"expected `scale` with an `si_unit` of another quantity than "
                    f"`unit` (the calibration factor, {result.si} per {self.unit}), got "
                    f"unit = {self.unit!r} ({unit.quantity}), si_unit = {self.si_unit!r} "
                    f"({result.quantity})",
                )
            key, value, found = "si_unit", self.si_unit, result
        elif unit is not None:
            key, value, found = "unit", self.unit, unit
        else:
            return
        allowed = role_quantities(self.role)
        if allowed is not None and found.quantity not in allowed:
            what = "the time channel" if self.role == "t" else f"`{self.role}`"
            calibrate = "" if self.role == "t" else " (or `scale` and `si_unit` calibrating it)"
            raise ConfigValueError(
                key,
                message=f"expected {describe_quantities(allowed)} for {what}{calibrate}, got "
                f"{value!r} ({found.quantity} [{found.si}])",
            )

    @property
    def selector(self) -> str:
        """Human-readable selector, e.g. ``name 'vir'``, ``column 1``, ``var 'X3' column 1``."""
        if self.var is not None:
            return f"var '{self.var}'" + ("" if self.column is None else f" column {self.column}")
        if self.name is not None:
            return f"name '{self.name}'"
        if self.regex is not None:
            return f"regex '{self.regex}'"
        return f"column {self.column}"

    @classmethod
    def from_dict(cls, role: str, table: object, where: Where = "[ingest]") -> ChannelSpec:
        """Parse one channel table.

        Parameters
        ----------
        role : str
            The key of the table in the section (``"time"`` is stored as role ``"t"``).
        table : dict
            ``{name|regex|column|var = ..., unit = ..., scale = ..., si_unit = ...}``.
        where : str or callable, optional
            The workflow table holding the channel (or a function of its key giving it),
            for the messages.

        Returns
        -------
        ChannelSpec
            The parsed table.

        Raises
        ------
        WorkflowError
            Unknown key, not exactly one selector, bad regex, unknown unit, zero scale:
            ``[ingest] q.unit: expected ..., got ...``.

        Examples
        --------
        >>> ChannelSpec.from_dict("q", {"column": 1, "unit": "bananas"})  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        debist.core.errors.WorkflowError: [ingest] q.unit: expected a unit pint parses, ...'bananas'
        >>> ChannelSpec.from_dict("t", {"name": "t", "unit": "mm"})  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        debist.core.errors.WorkflowError: [ingest] time.unit: expected a time [s] unit ... [m])
        """
        key = "time" if role == "t" else role
        label = _label(where, key)
        if isinstance(table, Mapping) and not any(k in table for k in _SELECTORS):
            raise WorkflowError(
                f"{label} {key}: {_SELECTOR_TEXT}, got {dict(table)!r}",
                key=dotted_key(label, key),
                value=dict(table),
            )
        return config_from_section(
            cls, table, label, prefix=f"{key}.", internal=("role",), extra={"role": role}
        )

    def to_dict(self) -> dict[str, Any]:
        """Return the channel table this spec was parsed from (normalised).

        Returns
        -------
        dict
            Keys ``name|regex|column|var`` and, when set, ``unit``, ``scale``, ``si_unit``,
            ``range``, ``stuck``.
        """
        out: dict[str, Any] = {}
        for k in _CHANNEL_KEYS:
            v = getattr(self, k)
            if v is not None:
                out[k] = list(v) if isinstance(v, tuple) else v
        return out


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class ResampleSpec:
    """Resampling of every gap-free segment onto a uniform grid.

    Parameters
    ----------
    sample_time : float
        Target sample time [s], ``> 0``.
    method : {"polyphase", "linear"}
        ``"polyphase"``: :func:`scipy.signal.resample_poly` (anti-aliasing FIR, rational
        ratio up/down with down <= 100, uniformly sampled input); ``"linear"``: linear
        interpolation (:func:`numpy.interp`, no anti-aliasing; for jittery time bases).

    Raises
    ------
    pydantic.ValidationError
        On a value of the wrong type or out of range (a ``ValueError``; :meth:`from_dict`
        raises a ``WorkflowError`` naming the key).
    """

    sample_time: PositiveFloat
    method: Literal["polyphase", "linear"] = "polyphase"

    @classmethod
    def from_dict(cls, table: object, where: Where = "[ingest]") -> ResampleSpec:
        """Parse the ``resample`` table.

        Parameters
        ----------
        table : dict
            ``{sample_time = <s>, method = "polyphase" | "linear"}``.
        where : str or callable, optional
            The workflow table holding ``resample``, for the messages.

        Returns
        -------
        ResampleSpec
            The parsed table.

        Raises
        ------
        WorkflowError
            Not a table, unknown key, missing or non-positive ``sample_time``, bad method:
            ``[ingest] resample.method: expected ..., got ...``.
        """
        return config_from_section(cls, table, _label(where, "resample"), prefix="resample.")


def _channel(key: str, table: object, where: Where, extra: bool) -> ChannelSpec:
    """Parse a channel table; an extra channel that fails and resembles an option is a typo."""
    try:
        return ChannelSpec.from_dict(key, table, where)
    except WorkflowError:
        if extra and difflib.get_close_matches(key, OPTION_KEYS, n=1):
            message = unknown_key_message(
                _label(where, key), key, OPTION_KEYS, known_label="known options"
            )
            raise WorkflowError(message, key=dotted_key(_label(where, key), key)) from None
        raise


#: pydantic configuration of :class:`IngestSpec`: as :data:`~debist.core.config.CONFIG`, and
#: ``sample_slice`` may be given by its workflow key ``slice`` or by its name.
_INGEST_CONFIG = pydantic.ConfigDict(**CONFIG, populate_by_name=True)


@pydantic.dataclasses.dataclass(frozen=True, config=_INGEST_CONFIG)
class IngestSpec:
    """Frozen configuration of :func:`debist.ingest.load.load_rig_log`.

    Raises
    ------
    pydantic.ValidationError
        On a value of the wrong type or out of range, or a text or Parquet format
        without a time channel nor ``sample_time`` (a ``ValueError``; :meth:`from_dict`
        raises a ``WorkflowError`` naming the key).

    Notes
    -----
    Each field is a key of the ``[ingest]`` section (``sample_slice`` is ``slice``), documented
    under its declaration; the section at a glance: docs/reference/formats.md.
    """

    channels: tuple[ChannelSpec, ...]
    """q, v1, ..., vN, then the extra channels sorted by name."""
    format: Literal["auto", "mat", "csv", "parquet", "mf4"] = "auto"
    """"auto" detects by content, then extension; "mf4": ASAM MDF 3 and 4 (the mf4 extra)."""
    sample_time: PositiveFloat | None = None
    """Sample time [s]: t = k * sample_time without a time channel; with one, checked against its
    median step.
    """
    time: ChannelSpec | None = None
    """The time channel (not needed for dSPACE recordings, whose time base X is used)."""
    sample_slice: Annotated[
        Annotated[tuple[NonNegativeInt, NonNegativeInt], AsTuple, AfterValidator(_ordered)] | None,
        Field(alias="slice", description="[start, stop] [samples] with 0 <= start < stop"),
    ] = None
    """[start, stop], 0-based end-exclusive sample slice applied after reading."""
    time_window: Annotated[
        Annotated[tuple[float, float], AsTuple, AfterValidator(_ordered)] | None,
        Field(description="[start, stop] [s] with start < stop"),
    ] = None
    """[start, stop] [s]; keeps start <= t < stop, after the slice."""
    gap_tolerance: Annotated[float, Field(gt=1)] = 1.5
    """A time step larger than gap_tolerance * median(dt) is a gap; > 1."""
    gaps: Literal["error", "split"] = "error"
    """What a gap does: raise, or split the log into gap-free segments."""
    min_segment: Annotated[int, Field(ge=3)] = 100
    """[samples] Segments shorter than this are dropped when splitting; >= 3."""
    resample: ResampleSpec | None = None
    """Resampling of each segment."""
    delimiter: Annotated[
        str,
        BeforeValidator(_delimiter),
        AfterValidator(_check_delimiter),
        Field(description=_DELIMITER_TEXT),
    ] = "auto"
    """Text files: "auto", "whitespace" or a single character."""
    decimal: Literal["auto", ".", ","] = "auto"
    """Text files: the decimal separator; "auto" detects a decimal comma."""
    header: Annotated[
        bool | None, BeforeValidator(_header), Field(description='"auto", true or false')
    ] = None
    """Text files: whether the first line holds the channel names; none: detect."""
    faults: Literal["error", "split"] = "error"
    """What a sensor fault (range, stuck) does: raise, or cut the faulty samples out of every
    column and keep the segments in between.
    """

    def __post_init__(self) -> None:
        if self.time is None and self.sample_time is None and self.format in ("csv", "parquet"):
            raise ConfigValueError(
                "format",
                message=f"{self.format!r} needs a time channel (`time = {{ ... }}`) "
                "or `sample_time` [s]",
            )
        if self.decimal == "," and self.delimiter == ",":
            raise ConfigValueError(
                "decimal",
                message='`decimal = ","` needs another `delimiter` than ",", got both ","',
            )

    @property
    def columns(self) -> tuple[str, ...]:
        """Column order of the canonical table: ``t, q, v1, ..., vN, <extras sorted>``."""
        return ("t", *(c.role for c in self.channels))

    @property
    def n_inputs(self) -> int:
        """Number N of inputs ``v1 ... vN``."""
        return sum(1 for c in self.channels if _INPUT.fullmatch(c.role))

    @classmethod
    def from_dict(cls, section: Mapping[str, Any], where: Where = "[ingest]") -> IngestSpec:
        """Parse the ingest section of a workflow file.

        Parameters
        ----------
        section : dict
            The TOML-derived section; see the module docstring for the schema. Keys that
            are not options and hold a table are channels; ``q`` and ``v1`` are required,
            ``v2 ... vN`` must be contiguous, other names become extra columns.
        where : str or callable, optional
            The workflow table (or a function of the top-level key giving it, for a data
            set's ingest merged from ``[ingest]`` and ``[datasets.<name>]``), for the
            messages.

        Returns
        -------
        IngestSpec
            The frozen configuration.

        Raises
        ------
        WorkflowError
            Naming the bad key and value (``[ingest] key: expected ..., got ...``):
            unknown key (with a suggestion), wrong type, value out of range, missing
            ``q`` / ``v1``, a hole in ``v1 ... vN``, ``csv``/``parquet`` format without
            time channel nor ``sample_time``.

        Examples
        --------
        >>> spec = IngestSpec.from_dict({"sample_time": 1.6384e-3,
        ...     "q": {"column": 1, "unit": "V"}, "v1": {"column": 0, "unit": "V"}})
        >>> spec.columns
        ('t', 'q', 'v1')
        >>> IngestSpec.from_dict({"smaple_time": 1e-3})  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        debist.core.errors.WorkflowError: [ingest] unknown key 'smaple_time'; did you mean ...
        """
        if not isinstance(section, Mapping):
            raise WorkflowError(
                f"{_label(where, '')} expected a table, got {section!r}",
                key=dotted_key(_label(where, ""), ""),
                value=section,
            )
        for key, value in section.items():
            if key not in OPTION_KEYS and not isinstance(value, Mapping):
                raise WorkflowError(
                    unknown_key_message(
                        _label(where, key), str(key), OPTION_KEYS, known_label="known options"
                    )
                    + "; a channel is a table {name|regex|column = ..., unit = ...}",
                    key=dotted_key(_label(where, key), str(key)),
                    value=value,
                )
        channel_keys = [k for k in section if k not in OPTION_KEYS]
        for key in channel_keys:
            fail = f"{_label(where, key)} {key}:"
            if key == "t":
                raise WorkflowError(
                    f"{fail} map the time channel with `time = {{ ... }}`",
                    key=dotted_key(_label(where, key), key),
                )
            if not _IDENTIFIER.fullmatch(key):
                raise WorkflowError(
                    f"{fail} a channel key must be an identifier",
                    key=dotted_key(_label(where, key), key),
                )
        inputs = sorted((int(m.group(1)), k) for k in channel_keys if (m := _INPUT.fullmatch(k)))
        for number, key in inputs:
            if key != f"v{number}" or number == 0:
                raise WorkflowError(
                    f"{_label(where, key)} {key}: inputs are named v1, v2, ... (no v0, no zeros)",
                    key=dotted_key(_label(where, key), key),
                )
        for required in ("q", "v1"):
            if required not in section:
                raise WorkflowError(
                    f"{_label(where, required)} {required}: missing required channel "
                    f'(e.g. {required} = {{ name = "...", unit = "..." }})',
                    key=dotted_key(_label(where, required), required),
                )
        numbers = [n for n, _ in inputs]
        if numbers != list(range(1, len(numbers) + 1)):
            missing = min(set(range(1, max(numbers) + 1)) - set(numbers))
            raise WorkflowError(
                f"{_label(where, f'v{max(numbers)}')} v{max(numbers)}: inputs must be "
                f"contiguous v1 ... vN; `v{missing}` is missing",
                key=dotted_key(_label(where, f"v{max(numbers)}"), f"v{max(numbers)}"),
            )
        extras = sorted(k for k in channel_keys if k != "q" and not _INPUT.fullmatch(k))
        order = ["q", *(k for _, k in inputs), *extras]
        channels = tuple(_channel(k, section[k], where, k in extras) for k in order)
        options = {k: section[k] for k in OPTION_KEYS if k in section}
        if "time" in options:
            options["time"] = ChannelSpec.from_dict("t", options["time"], where)
        if "resample" in options:
            options["resample"] = ResampleSpec.from_dict(options["resample"], where)
        return config_from_section(
            cls, options, where, internal=("channels",), extra={"channels": channels}
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
        out["decimal"] = self.decimal
        out["header"] = "auto" if self.header is None else self.header
        out["faults"] = self.faults
        return out
