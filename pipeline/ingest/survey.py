"""What a rig log holds, and a first guess of which channels are time, q, v1 and v2.

:func:`survey_file` lists a file's channels (name, unit, samples, value range) as the
ingest readers see them (:func:`debist.ingest.load.read_raw`); :func:`guess_mapping`
proposes the channel tables of an ``[ingest]`` section from the names and units:

- the time: a strictly increasing channel named ``t``, ``time``, ``time_s``, ``Time [s]``,
  ``zeit``, ``timestamp`` or declaring a time unit; none for a dSPACE or MF4 recording,
  whose time base the ingest uses;
- ``q``: a channel whose name holds ``q``, ``x``, ``laser``, ``pos``, ``position``,
  ``displacement``, ... with a length unit (or none);
- the inputs ``v1``, ``v2``: channels whose names hold ``HV``, ``volt``, ``v``, ``v1``,
  ``DE1``, ``left``, ``right``, ... with a voltage unit (or none); a measured voltage
  (``mon``, ``meas``) is preferred to a reference (``ref``, ``cmd``, ``set``). They are
  ordered by the number in their names, else left before right, else as in the file.

A unit comes from the file (dSPACE ``Unit``, MF4, Parquet field metadata), else from the
name (``time_s``, ``q [mm]``, ``x (mm)``), else it is assumed from the size of the values
on a DE rig (a peak displacement up to 0.5 in m, up to 500 in mm, larger in um; a peak
voltage up to 20 in kV, larger in V; a time in s), and the guess says so. Nothing here
reads a file except :func:`survey_file`; nothing prints.

References
----------
Masoud & Maas 2025, Sec. 5.1 (the rig: laser displacement q, two DE voltages v1, v2);
pint (https://pint.readthedocs.io), through :func:`debist.core.units.lookup_unit`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from debist.core.errors import RigLogError, WorkflowError
from debist.core.units import lookup_unit
from debist.ingest.cache import RawLogCache
from debist.ingest.channels import to_float
from debist.ingest.load import read_raw
from debist.ingest.raw import RawLog
from debist.ingest.spec import ChannelSpec, IngestSpec

__all__ = [
    "ChannelInfo",
    "FileSurvey",
    "Guess",
    "Mapping",
    "MappingRequest",
    "guess_mapping",
    "name_unit",
    "role_kind",
    "survey_file",
]

#: Read options of a survey: detect the format, the delimiter, the decimal and the header.
_READ = IngestSpec(channels=(ChannelSpec("q"),))
_TIME_WORDS = frozenset({"t", "time", "zeit", "timestamp"})
_TIME_EXTRA = frozenset({"s", "sec", "secs", "seconds", "ms", "abs", "rel"})
_Q_WORDS = frozenset(
    {"q", "x", "laser", "pos", "position", "displacement", "disp", "deflection", "stroke",
     "distance", "lvdt", "tip"}
)  # fmt: skip
_V_WORDS = frozenset(
    {"v", "u", "hv", "volt", "volts", "voltage", "de", "left", "right", "amp", "amplifier",
     "membrane", "vmon"}
)  # fmt: skip
_MEASURED = frozenset({"mon", "meas", "measured", "actual", "act", "ist", "fb", "feedback"})
_REFERENCE = frozenset(
    {"ref", "reference", "cmd", "command", "set", "setpoint", "sp", "demand", "soll",
     "target", "des", "desired"}
)  # fmt: skip
#: Units a name may end in after ``_`` (``time_s``, ``x_mm``, ``hv_kV``).
_NAME_UNITS = frozenset(
    {"s", "ms", "us", "m", "cm", "mm", "um", "V", "kV", "mV", "N", "mN", "deg", "rad"}
)
_BRACKETED = re.compile(r"^(?P<stem>.*?)\s*[\[(](?P<unit>[^\[\]()]+)[\])]\s*$")
_TOKEN = re.compile(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+")
_MIN_SAMPLES = 3


@dataclass(frozen=True)
class ChannelInfo:
    """One channel of a rig log, as :func:`survey_file` found it.

    Attributes
    ----------
    name : str
        The channel's name in the file (``"column <i>"`` in a headerless text file).
    selector : dict
        Its channel-table selector: ``{"name": name}``, or ``{"column": i}`` when the file
        has no names or the name is not unique.
    unit : str or None
        The unit the file declares, else the unit its name ends in, else None.
    unit_source : {"file", "name", ""}
        Where ``unit`` comes from.
    quantity : str or None
        What ``unit`` measures (``"length"``, ``"voltage"``, ``"time"``, ...), None when
        there is no unit pint parses.
    samples : int
        Number of samples.
    numeric : bool
        Whether the values are numbers.
    lo, hi : float
        Smallest and largest finite value [``unit``]; NaN when not numeric or none finite.
    increasing : bool
        Whether the values are finite and strictly increasing (a time can be).
    """

    name: str
    selector: dict[str, Any]
    unit: str | None
    unit_source: str
    quantity: str | None
    samples: int
    numeric: bool
    lo: float
    hi: float
    increasing: bool

    @property
    def peak(self) -> float:
        """Largest absolute value [``unit``] (NaN when not numeric)."""
        return float(max(abs(self.lo), abs(self.hi)))


@dataclass(frozen=True)
class FileSurvey:
    """The channels of one rig log.

    Attributes
    ----------
    path : pathlib.Path
        The file.
    format : str
        ``"mat-v5"``, ``"mat-v7.3"``, ``"mat-v4"``, ``"csv"``, ``"parquet"`` or ``"mf4"``.
    channels : tuple of ChannelInfo
        In file order.
    time_bases : tuple of str
        A dSPACE or MF4 recording's time bases (the ingest takes the time from them);
        empty for other files.
    """

    path: Path
    format: str
    channels: tuple[ChannelInfo, ...]
    time_bases: tuple[str, ...] = ()

    def channel(self, name: str) -> ChannelInfo | None:
        """Return the channel of this exact name (None if there is none)."""
        return next((c for c in self.channels if c.name == name), None)


@dataclass(frozen=True)
class Guess:
    """Which channel fills one column of the canonical table, and why.

    Attributes
    ----------
    role : str
        ``"time"``, ``"q"``, ``"v1"``, ``"v2"``, ...
    channel : ChannelInfo
        The channel.
    unit : str
        The unit its values are recorded in.
    why : str
        How the channel was chosen (``"by its name and unit"``, ``"given: --q"``).
    unit_why : str
        Where the unit comes from (``"from the file"``, ``"from its name"``, ``"assumed
        from the peak 9.8"`` of the values, ``"assumed"`` (a time in s), ``"given: --unit"``).
    """

    role: str
    channel: ChannelInfo
    unit: str
    why: str
    unit_why: str

    @property
    def assumed(self) -> bool:
        """Whether the unit is an assumption that the user should check."""
        return self.unit_why.startswith("assumed")

    def table(self) -> dict[str, Any]:
        """Return the ``[ingest]`` channel table, e.g. ``{"name": "x", "unit": "mm"}``."""
        return {**self.channel.selector, "unit": self.unit}


@dataclass(frozen=True)
class MappingRequest:
    """Channels and units given by the user instead of the guess (``debist init`` options).

    Attributes
    ----------
    time, q : str, optional
        Channel names (``"column <i>"`` for a headerless text file).
    inputs : tuple of str
        Channel names of ``v1``, ``v2``, ... in order (empty: guess them).
    units : dict of str to str
        Units per role: ``"time"``, ``"q"``, ``"v"`` (every input) or ``"v1"``, ``"v2"``, ...
    sample_time : float, optional
        [s] the sample time of a file without a time channel.
    """

    time: str | None = None
    q: str | None = None
    inputs: tuple[str, ...] = ()
    units: dict[str, str] | None = None
    sample_time: float | None = None


@dataclass(frozen=True)
class Mapping:
    """The channel mapping of one file.

    Attributes
    ----------
    survey : FileSurvey
        The file's channels.
    guesses : tuple of Guess
        ``time`` (absent for a recording with a time base or with ``sample_time``), ``q``,
        ``v1``, ``v2``, ... in that order.
    """

    survey: FileSurvey
    guesses: tuple[Guess, ...]

    def section(self) -> dict[str, dict[str, Any]]:
        """Return the channel tables of the ``[ingest]`` section (``time``, ``q``, ``v1``, ...)."""
        return {g.role: g.table() for g in self.guesses}


def _tokens(name: str) -> list[str]:
    """Split a channel name into lower-case words (``"HV_left"`` -> ``["hv", "left"]``)."""
    words = []
    for part in re.split(r"[^0-9A-Za-z]+", name):
        words += [w.lower() for w in _TOKEN.findall(part)]
        if re.fullmatch(r"[A-Za-z]+\d+", part):  # "DE1", "v2": also the whole part
            words.append(part.lower())
    return words


def name_unit(name: str) -> str | None:
    """Return the unit a channel's name ends in, or None.

    Parameters
    ----------
    name : str
        A channel name.

    Returns
    -------
    str or None
        The unit in trailing brackets or parentheses (``"Time [s]"``, ``"q (mm)"``) when
        pint parses it, or a common unit after a last ``_`` (``"time_s"``, ``"x_mm"``).

    Examples
    --------
    >>> [name_unit(n) for n in ["Time [s]", "q (mm)", "time_s", "HV_left", "x_mm", "v [bananas]"]]
    ['s', 'mm', 's', None, 'mm', None]
    """
    found = _BRACKETED.match(name)
    if found and lookup_unit(found["unit"]) is not None:
        return found["unit"].strip()
    stem, sep, last = name.rpartition("_")
    if sep and stem and last in _NAME_UNITS:
        return last
    return None


def _describe(raw, log: RawLog, names: list[str]) -> ChannelInfo:
    declared = raw.unit.strip() if raw.unit and raw.unit.strip() else None
    unit, source = (declared, "file") if declared else (name_unit(raw.name), "name")
    found = lookup_unit(unit) if unit else None
    try:
        values = to_float(raw, log)
        numeric = True
    except RigLogError:
        values, numeric = np.empty(0), False
    finite = values[np.isfinite(values)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (np.nan, np.nan)
    increasing = bool(
        finite.size == values.size >= 2 and np.all(np.diff(values) > 0)
    )  # fmt: skip
    if not log.has_names or names.count(raw.name) > 1:
        selector: dict[str, Any] = {"column": names.index(raw.name)}
        if not log.has_names:
            selector = {"column": int(raw.name.rpartition(" ")[2])}
    else:
        selector = {"name": raw.name}
    return ChannelInfo(
        name=raw.name,
        selector=selector,
        unit=unit,
        unit_source=source if unit else "",
        quantity=found.quantity if found else None,
        samples=int(np.size(raw.data)),
        numeric=numeric,
        lo=lo,
        hi=hi,
        increasing=increasing,
    )


def survey_file(path: str | Path, cache: RawLogCache | None = None) -> FileSurvey:
    r"""List the channels of a rig log with their units and value ranges.

    Parameters
    ----------
    path : str or path-like
        A rig log in any format the ingest reads (MAT v5/v7.3 with plain variables or a
        dSPACE recording, delimited text, Parquet, MF4); the format is detected.
    cache : RawLogCache, optional
        Keeps the read for a later :func:`debist.ingest.load.load_rig_log` of the same file
        with the default read options (``format``, ``delimiter``, ``decimal``, ``header``
        all ``"auto"``).

    Returns
    -------
    FileSurvey
        The channels in file order.

    Raises
    ------
    RigLogError
        Naming the file: missing, empty, unreadable, truncated or of an unknown format
        (:func:`debist.ingest.load.read_raw`).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     log = Path(tmp) / "log.csv"
    ...     _ = log.write_text("time_s,x [mm],HV1\n0,1,2\n0.1,2,3\n0.2,3,4\n")
    ...     found = survey_file(log)
    >>> [(c.name, c.unit, c.quantity, c.hi) for c in found.channels]
    [('time_s', 's', 'time', 0.2), ('x [mm]', 'mm', 'length', 3.0), ('HV1', None, None, 4.0)]
    """
    path = Path(path)
    log = read_raw(path, _READ) if cache is None else cache.read(path, _READ)
    names = log.names
    channels = tuple(_describe(raw, log, names) for raw in log.channels)
    return FileSurvey(path, log.format, channels, tuple(r.name for r in log.rasters))


# ---------------------------------------------------------------- guessing


def _is_time_name(words: list[str]) -> bool:
    return bool(words) and words[0] in _TIME_WORDS and set(words[1:]) <= _TIME_EXTRA


def _basis(named: bool, unit: bool, extra: str = "") -> str:
    """Say what a guess rests on: ``"its name and unit"``, ``"its unit"``, ..."""
    parts = [w for w, ok in (("name", named), ("unit", unit)) if ok]
    return "by its " + " and ".join(parts) + extra


def _time_score(c: ChannelInfo) -> tuple[int, str]:
    if not (c.numeric and c.increasing) or c.quantity not in (None, "time"):
        return 0, ""
    named, unit = _is_time_name(_tokens(c.name)), c.quantity == "time"
    return 2 * named + unit, _basis(named, unit)


def _q_score(c: ChannelInfo) -> tuple[int, str]:
    if not c.numeric or c.quantity not in (None, "length"):
        return 0, ""
    named, unit = bool(set(_tokens(c.name)) & _Q_WORDS), c.quantity == "length"
    return 2 * named + unit, _basis(named, unit)


def _v_score(c: ChannelInfo) -> tuple[int, str]:
    if not c.numeric or c.quantity not in (None, "voltage"):
        return 0, ""
    words = set(_tokens(c.name))
    named = bool(words & _V_WORDS) or any(re.fullmatch(r"(v|u|hv|de)\d+", w) for w in words)
    unit, measured, reference = c.quantity == "voltage", words & _MEASURED, words & _REFERENCE
    score = 2 * named + 2 * unit + bool(measured) - 3 * bool(reference)
    if score < 2:
        return 0, ""
    return score, _basis(named, unit, ", a measured voltage" if measured else "")


def _side(c: ChannelInfo) -> tuple[int, int]:
    """Order of an input: the number in its name, else left (1) before right (2)."""
    for w in _tokens(c.name):
        number = re.fullmatch(r"(?:v|u|hv|de|ch)?(\d+)", w)
        if number:
            return (0, int(number[1]))
    words = set(_tokens(c.name))
    return (1, 1 if "left" in words else 2 if "right" in words else 3)


def _refuse(survey: FileSurvey, what: str, option: str) -> WorkflowError:
    channels = ", ".join(repr(c.name) for c in survey.channels)
    return WorkflowError(f"file '{survey.path}': {what}; its channels: {channels}; pass {option}")


def _ranked(survey: FileSurvey, score, taken: set[str]) -> list[tuple[int, str, ChannelInfo]]:
    """Rank the channels not taken yet that score above 0, best first (then file order)."""
    found = []
    for c in survey.channels:
        if c.name in taken or c.samples < _MIN_SAMPLES:
            continue
        points, why = score(c)
        if points > 0:
            found.append((points, why, c))
    return sorted(found, key=lambda item: -item[0])


def _one(ranked, survey: FileSurvey, what: str, option: str) -> tuple[ChannelInfo, str]:
    """Return the best channel and why; refuse none or a tie."""
    if not ranked:
        raise _refuse(survey, f"no channel looks like {what}", option)
    tied = [c for points, _, c in ranked if points == ranked[0][0]]
    if len(tied) > 1:
        names = ", ".join(repr(c.name) for c in tied)
        raise _refuse(survey, f"{what.split(' (')[0]} is ambiguous (could be {names})", option)
    return ranked[0][2], ranked[0][1]


def _chosen(survey: FileSurvey, name: str, option: str) -> ChannelInfo:
    found = survey.channel(name)
    if found is None:
        raise _refuse(survey, f"no channel named {name!r} ({option})", f"{option} with one of them")
    return found


def role_kind(role: str) -> str:
    """Return the kind of a role: ``"v"`` for every input ``v1, v2, ...``, else the role."""
    return "v" if re.fullmatch(r"v\d+", role) else role


def _unit_for(
    role: str, c: ChannelInfo, units: dict[str, str], peaks: dict[str, float]
) -> tuple[str, str]:
    """Return the unit of a mapped channel and where it comes from."""
    given = units.get(role) or units.get(role_kind(role))
    if given is not None:
        return given, "given: --unit"
    if c.unit is not None and c.quantity is not None:
        return c.unit, "from the file" if c.unit_source == "file" else "from its name"
    if role == "time":
        return "s", "assumed"
    peak = max(c.peak, peaks.get(role_kind(role), 0.0))
    size = f"assumed from the peak {peak:.4g}"
    if role == "q":
        return ("m" if peak <= 0.5 else "mm" if peak <= 500 else "um"), size
    return ("kV" if peak <= 20 else "V"), size


def _check_units(units: dict[str, str]) -> None:
    for role, unit in units.items():
        if role not in ("time", "q", "v") and not re.fullmatch(r"v[1-9]\d*", role):
            raise WorkflowError(
                f"--unit {role}={unit}: expected time, q, v or v1, v2, ... before '='"
            )
        spec_role = "t" if role == "time" else "v1" if role == "v" else role
        ChannelSpec.from_dict(spec_role, {"name": "-", "unit": unit}, where="--unit")


_NO_TIME = "the time (a strictly increasing 't', 'time', 'time_s', ... or a time unit)"
_NO_Q = "q (a name with laser, pos, q, x, displacement ... and a length unit or none)"
_NO_V = (
    "an input voltage (a name with HV, volt, v1, DE1, left, right ... and a voltage unit or none)"
)
_V_OPTION = "--v NAME (once per input, v1 first)"


def guess_mapping(
    survey: FileSurvey,
    request: MappingRequest | None = None,
    peaks: dict[str, float] | None = None,
) -> Mapping:
    """Map a rig log's channels to ``time``, ``q``, ``v1``, ``v2``, ... by names and units.

    Parameters
    ----------
    survey : FileSurvey
        From :func:`survey_file`.
    request : MappingRequest, optional
        Channels and units the user gave; they replace the guess for their roles.
    peaks : dict of str to float, optional
        The largest peak of ``"q"`` and of the inputs ``"v"`` over every file of a
        workflow [recorded unit], so that a unit assumed from the values' size is the same
        for each file (a validation record that stays near rest would look like metres).

    Returns
    -------
    Mapping
        One :class:`Guess` per role (see the module docstring for the rules); ``time`` is
        absent when the file is a recording with time bases or ``sample_time`` is given.
        The inputs are the one or two channels of the best voltage score.

    Raises
    ------
    WorkflowError
        In one line naming the file and listing its channels, with the option that settles
        it: a role no channel fits (``pass --q NAME``), several channels fitting a role
        equally well (more than two inputs), a given channel the file does not have; a
        ``--unit`` of an unknown role, a unit pint does not parse or of a quantity the
        role cannot hold.

    Examples
    --------
    >>> def chan(name, unit=None, quantity=None, lo=0.0, hi=1.0, increasing=False):
    ...     return ChannelInfo(name, {"name": name}, unit, "file" if unit else "", quantity,
    ...                        100, True, lo, hi, increasing)
    >>> survey = FileSurvey(Path("log.mat"), "mat-v5", (
    ...     chan("time_s", "s", "time", 0.0, 9.9, True), chan("laser_pos", lo=-9.5, hi=9.7),
    ...     chan("HV_right", hi=3.0), chan("HV_left", hi=3.0)))
    >>> [f"{g.role}={g.channel.name} [{g.unit}]" for g in guess_mapping(survey).guesses]
    ['time=time_s [s]', 'q=laser_pos [mm]', 'v1=HV_left [kV]', 'v2=HV_right [kV]']
    """
    request = request or MappingRequest()
    units = dict(request.units or {})
    _check_units(units)
    guesses: list[Guess] = []
    taken: set[str] = set()

    def add(role: str, c: ChannelInfo, why: str) -> None:
        unit, unit_why = _unit_for(role, c, units, dict(peaks or {}))
        guesses.append(Guess(role, c, unit, why, unit_why))
        taken.add(c.name)

    if request.time is not None:
        add("time", _chosen(survey, request.time, "--time"), "given: --time")
    elif not survey.time_bases and request.sample_time is None:
        ranked = _ranked(survey, _time_score, taken)
        add("time", *_one(ranked, survey, _NO_TIME, "--time NAME, or --sample-time SECONDS"))
    if request.q is not None:
        add("q", _chosen(survey, request.q, "--q"), "given: --q")
    else:
        add("q", *_one(_ranked(survey, _q_score, taken), survey, _NO_Q, "--q NAME"))
    if request.inputs:
        for i, name in enumerate(request.inputs, start=1):
            add(f"v{i}", _chosen(survey, name, "--v"), "given: --v")
        return Mapping(survey, tuple(guesses))
    ranked = _ranked(survey, _v_score, taken)
    if not ranked:
        raise _refuse(survey, f"no channel looks like {_NO_V}", _V_OPTION)
    best = [(why, c) for points, why, c in ranked if points == ranked[0][0]]
    if len(best) > 2:
        names = ", ".join(repr(c.name) for _, c in best)
        raise _refuse(survey, f"the inputs are ambiguous (could be {names})", _V_OPTION)
    for i, (why, c) in enumerate(sorted(best, key=lambda item: _side(item[1])), start=1):
        add(f"v{i}", c, why)
    return Mapping(survey, tuple(guesses))
