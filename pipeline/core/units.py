"""Units of rig-log channels, parsed by pint, and their factors to SI.

Conversion to SI happens here and only here (SI inside, conversion at ingest): a value
``x`` recorded in unit ``u`` becomes ``x * lookup_unit(u).factor`` in ``lookup_unit(u).si``.

Any unit expression the pint default registry parses is accepted: SI prefixes
(``mm``, ``kV``, ``mN``, ``us`` or ``µs``), products and quotients (``mm/s``, ``m/s^2``,
``N*m``), long names (``millimeter``, ``degree``) and constants used as units (``g0`` or
``g_0``, standard gravity 9.80665 m/s^2). Square brackets around a unit (``[mm]``) and
``-`` for a dimensionless value are understood. Units with an offset (``degC``) are not
factors to SI and are refused (give ``scale`` and ``si_unit`` instead).

Which quantity a canonical column may hold is :func:`role_quantities`: the time an
interval, ``q`` a length, an angle (or dimensionless) or a voltage (an uncalibrated sensor
or an electrical analogue such as the Silverbox circuit), an input ``v1 ... vN`` a
voltage (a DE, an amplifier command), acceleration or force (a shaker, a motor), pressure
(a pneumatic piston), current, length or a dimensionless value; extra channels anything.

References
----------
H. E. Grecco et al., "Pint: makes units easy", https://pint.readthedocs.io (the unit
definitions and parser); BIPM, "The International System of Units (SI)", 9th edition
(2019), tables 2 and 4 (the coherent SI units the values are converted to).
"""

from __future__ import annotations

import functools
import hashlib
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING

from debist.core import cache as user_cache

if TYPE_CHECKING:
    import pint

__all__ = [
    "EXAMPLES",
    "INPUT_QUANTITIES",
    "Q_QUANTITIES",
    "UNITS",
    "Unit",
    "canonical_unit",
    "describe_quantities",
    "lookup_unit",
    "pretty_unit",
    "registry",
    "role_quantities",
    "si_symbol",
]


@dataclass(frozen=True)
class Unit:
    """One unit, as pint understands it.

    Parameters
    ----------
    symbol : str
        The unit as written (blanks and brackets stripped), e.g. ``"kV"``.
    factor : float
        Multiply a value in this unit by ``factor`` to get it in ``si``.
    si : str
        The coherent SI unit of the same quantity, e.g. ``"V"``, ``"m/s^2"``, ``"rad"``,
        ``"1"`` (dimensionless).
    quantity : str
        What the unit measures: ``"time"``, ``"length"``, ``"angle"``, ``"dimensionless"``,
        ``"voltage"``, ``"force"``, ``"acceleration"``, ... (see :data:`QUANTITIES`), or
        the pint dimensionality for other quantities (``"[mass] / [length]"``).
    """

    symbol: str
    factor: float
    si: str
    quantity: str


#: Coherent SI units by the quantity they measure; the first unit of a dimensionality
#: names it (``N*m`` and ``J`` share one: a value is reported in ``J``).
QUANTITIES: dict[str, str] = {
    "time": "s",
    "length": "m",
    "angle": "rad",
    "dimensionless": "1",
    "voltage": "V",
    "force": "N",
    "acceleration": "m/s^2",
    "velocity": "m/s",
    "angular velocity": "rad/s",
    "angular acceleration": "rad/s^2",
    "pressure": "Pa",
    "current": "A",
    "mass": "kg",
    "temperature": "K",
    "frequency": "Hz",
    "energy": "J",
    "power": "W",
    "charge": "C",
    "capacitance": "F",
    "resistance": "ohm",
    "magnetic flux density": "T",
}

#: Quantities the displacement ``q`` may hold.
Q_QUANTITIES = ("length", "angle", "dimensionless", "voltage")
#: Quantities an input ``v1 ... vN`` may hold (the input map ``h(v)`` is unit-agnostic).
INPUT_QUANTITIES = (
    "voltage",
    "acceleration",
    "force",
    "pressure",
    "current",
    "length",
    "angle",
    "dimensionless",
)
#: A few units, for messages (any unit pint parses is accepted).
EXAMPLES = ("s", "ms", "m", "mm", "um", "deg", "V", "kV", "N", "mN", "m/s^2", "g0", "1")

_INPUT = re.compile(r"v\d+")
_ALIASES = {"-": "1", "sec": "s", "msec": "ms", "usec": "us"}


@functools.cache
def registry() -> pint.UnitRegistry:
    """Return the one pint unit registry of debist (created on first use).

    Returns
    -------
    pint.UnitRegistry
        The default definitions. Importing pint takes about 0.25 s, so it is loaded only
        when a unit is looked up; its parsed definitions are kept in the user cache
        (:func:`debist.core.cache.cache_dir`, pint's own disk cache), which saves another
        0.2 s. A cache that cannot be created or read is passed over: the definitions are
        parsed again.

    References
    ----------
    pint, ``UnitRegistry`` and its ``cache_folder`` (https://pint.readthedocs.io).
    """
    import pint  # here, not at the top: only a unit lookup needs pint

    try:
        return pint.UnitRegistry(cache_folder=user_cache.cache_dir() / "pint")
    except Exception:
        return pint.UnitRegistry()


def canonical_unit(symbol: str) -> str:
    """Return a unit as written, without blanks and square brackets (``" [mm] "`` -> ``"mm"``).

    Parameters
    ----------
    symbol : str
        A unit as written in a workflow file or declared by a rig log.

    Returns
    -------
    str
        The stripped symbol; ``"-"`` becomes ``"1"`` (dimensionless), ``"sec"`` ``"s"``.

    Examples
    --------
    >>> canonical_unit(" [\u00b5m] ")
    '\u00b5m'
    >>> canonical_unit("-")
    '1'
    """
    s = symbol.strip()
    if s.startswith("[") and s.endswith("]"):
        s = s[1:-1].strip()
    return _ALIASES.get(s, s)


@functools.cache
def _si_units() -> dict[tuple, tuple[str, str]]:
    """Base-unit signature -> (quantity, SI symbol), from :data:`QUANTITIES`."""
    reg = registry()
    table: dict[tuple, tuple[str, str]] = {}
    for quantity, symbol in QUANTITIES.items():
        _, base = reg.get_base_units(reg.parse_units(symbol.replace("^", "**")))
        table.setdefault(_signature(base), (quantity, symbol))
    return table


def _signature(base: pint.Unit) -> tuple:
    return tuple(sorted((name, float(power)) for name, power in base._units.items()))


def _parse(symbol: str) -> pint.Unit | None:
    text = canonical_unit(symbol)
    if not text:
        return None
    try:
        # the parser raises many kinds of errors (undefined name, syntax, a number)
        return registry().parse_units(text.replace("^", "**"))
    except Exception:  # any parse failure means "not a unit"
        return None


def _fallback_symbol(base: pint.Unit) -> str:
    parts = []
    for name, power in sorted(base._units.items()):
        short = f"{registry().parse_units(name):~}"
        p = float(power)
        parts.append(short if p == 1 else f"{short}^{p:g}")
    return "*".join(parts)


@functools.cache
def lookup_unit(symbol: str) -> Unit | None:
    """Return the :class:`Unit` of a unit expression, or None when pint cannot use it.

    Parameters
    ----------
    symbol : str
        Any unit pint parses (``"mm/s"``, ``"g0"``, ``"kV"``, ``"m/s^2"``, ``"deg"``,
        ``"1"``); blanks and square brackets are ignored (see :func:`canonical_unit`).

    Returns
    -------
    Unit or None
        Factor to SI, SI symbol and quantity; None for text pint does not parse as a
        unit, a number (``"2 mm"``), an empty string, or a unit with an offset to SI
        (``"degC"``). pint's answer for each symbol is remembered in the user cache
        (:mod:`debist.core.cache`) under pint's version and this module's source, so a
        workflow loads without importing pint (0.25 s) once its units have been seen.

    Examples
    --------
    >>> lookup_unit("kV").factor
    1000.0
    >>> lookup_unit("g0").factor, lookup_unit("g0").si
    (9.80665, 'm/s^2')
    >>> lookup_unit("bananas") is None, lookup_unit("degC") is None
    (True, True)
    """
    key = canonical_unit(symbol)
    known = _answers("lookup")
    if key in known:
        found = known[key]
        return None if found is None else Unit(key, *found)
    unit = _pint_unit(symbol)
    _remember("lookup", key, None if unit is None else [unit.factor, unit.si, unit.quantity])
    return unit


def pretty_unit(expression: str) -> str:
    """Simplify a unit expression with pint and write it as the reports do.

    Parameters
    ----------
    expression : str
        Any unit expression pint parses (``"(m/s**2)/m"``).

    Returns
    -------
    str
        The simplified unit, products with a blank and powers with ``^`` (``"1/s^2"``,
        ``"N s/m"``); ``"1"`` for a dimensionless one. Remembered in the user cache like
        :func:`lookup_unit`.

    Raises
    ------
    pint.errors.UndefinedUnitError
        If pint does not know a unit of the expression.

    References
    ----------
    pint, unit formatting (https://pint.readthedocs.io).

    Examples
    --------
    >>> pretty_unit("(m/s**2)/m"), pretty_unit("N*s/m"), pretty_unit("m/m")
    ('1/s^2', 'N s/m', '1')
    """
    known = _answers("pretty")
    if isinstance(known.get(expression), str):
        return known[expression]
    unit = registry().parse_units(expression.replace("^", "**"))
    text = format(unit, "~C").replace("**", "^").replace("*", " ") or "1"
    _remember("pretty", expression, text)
    return text


#: The file in the user cache that remembers pint's answers (:func:`lookup_unit`,
#: :func:`pretty_unit`); a stamp of pint's version and this module's source guards it.
_ANSWERS_FILE = "units-v1.json"


def _valid_lookup(value: object) -> bool:
    return value is None or (
        isinstance(value, list)
        and len(value) == 3
        and isinstance(value[0], float)
        and isinstance(value[1], str)
        and isinstance(value[2], str)
    )


#: The answers of each kind, and how a remembered answer must look to be used.
_KINDS = {"lookup": _valid_lookup, "pretty": lambda value: isinstance(value, str)}


@functools.cache
def _stamp() -> str:
    """Return what pint's answers depend on: pint's version and this module's source."""
    source = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]
    try:
        return f"pint {metadata.version('pint')} units.py {source}"
    except metadata.PackageNotFoundError:
        return f"pint absent units.py {source}"


@functools.cache
def _all_answers() -> dict[str, dict[str, object]]:
    """Kind -> expression -> pint's answer, as remembered from earlier runs."""
    found = user_cache.read_json(_ANSWERS_FILE)
    if not isinstance(found, dict) or found.get("stamp") != _stamp():
        found = {}
    answers: dict[str, dict[str, object]] = {}
    for kind, valid in _KINDS.items():
        given = found.get(kind)
        given = given if isinstance(given, dict) else {}
        answers[kind] = {k: v for k, v in given.items() if valid(v)}
    return answers


def _answers(kind: str) -> dict[str, object]:
    return _all_answers()[kind]


def _remember(kind: str, expression: str, answer: object) -> None:
    _all_answers()[kind][expression] = answer
    user_cache.write_json(_ANSWERS_FILE, {"stamp": _stamp(), **_all_answers()})


def _pint_unit(symbol: str) -> Unit | None:
    """Ask pint (:func:`lookup_unit` without the user cache)."""
    unit = _parse(symbol)
    if unit is None:
        return None
    reg = registry()
    try:
        one = reg.Quantity(1.0, unit).to_base_units()
        zero = reg.Quantity(0.0, unit).to_base_units()
    except Exception:  # an offset unit inside a product (degC/s) cannot be converted
        return None
    if zero.magnitude != 0.0:  # an offset (degC): no factor to SI
        return None
    factor, base = one.magnitude, one.units
    quantity, si = _si_units().get(_signature(base), (None, None))
    if si is None:
        quantity, si = str(base.dimensionality), _fallback_symbol(base)
    return Unit(canonical_unit(symbol), float(factor), si, quantity)


def si_symbol(symbol: str) -> str | None:
    """Return the coherent SI unit that a unit expression names, or None if it is not one.

    Parameters
    ----------
    symbol : str
        A unit expression, e.g. ``"m"``, ``"meter"``, ``"m/s^2"``, ``"N"``.

    Returns
    -------
    str or None
        The SI symbol (``"m"``, ``"m/s^2"``, ``"N"``) when the unit's factor to SI is 1;
        None for an unknown unit or one with another factor (``"mm"``).

    Examples
    --------
    >>> si_symbol("meter"), si_symbol("mm")
    ('m', None)
    """
    unit = lookup_unit(symbol)
    if unit is None or abs(unit.factor - 1.0) > 1e-12:
        return None
    return unit.si


def role_quantities(role: str) -> tuple[str, ...] | None:
    """Return the quantities a canonical column may hold.

    Parameters
    ----------
    role : str
        ``"t"``, ``"q"``, ``"v1"``, ... or the name of an extra channel.

    Returns
    -------
    tuple of str or None
        ``("time",)`` for ``t``, :data:`Q_QUANTITIES` for ``q``,
        :data:`INPUT_QUANTITIES` for an input; None (anything) for an extra channel.
    """
    if role == "t":
        return ("time",)
    if role == "q":
        return Q_QUANTITIES
    if _INPUT.fullmatch(role):
        return INPUT_QUANTITIES
    return None


def describe_quantities(quantities: tuple[str, ...]) -> str:
    """Describe quantities for a message: ``"a length [m] or angle [rad] unit"``.

    Parameters
    ----------
    quantities : tuple of str
        Keys of :data:`QUANTITIES`.

    Returns
    -------
    str
        The text.
    """
    named = [f"{q} [{QUANTITIES[q]}]" for q in quantities]
    listed = named[0] if len(named) == 1 else ", ".join(named[:-1]) + " or " + named[-1]
    article = "an" if listed[0] in "aeiou" else "a"
    return f"{article} {listed} unit"


class _PintUnits(Mapping[str, Unit]):
    """Read-only mapping of unit expressions to :class:`Unit`, backed by pint.

    ``symbol in UNITS`` is true for every unit :func:`lookup_unit` accepts, and
    ``UNITS[symbol]`` returns its :class:`Unit`; iteration yields :data:`EXAMPLES` only.
    """

    def __getitem__(self, symbol: str) -> Unit:
        unit = lookup_unit(symbol) if isinstance(symbol, str) else None
        if unit is None:
            raise KeyError(symbol)
        return unit

    def __contains__(self, symbol: object) -> bool:
        return isinstance(symbol, str) and lookup_unit(symbol) is not None

    def __iter__(self) -> Iterator[str]:
        return iter(EXAMPLES)

    def __len__(self) -> int:
        return len(EXAMPLES)


#: Every unit pint parses, by expression: ``UNITS["mm"].factor == 1e-3`` (read-only;
#: iterating gives a few examples, :data:`EXAMPLES`).
UNITS: Mapping[str, Unit] = _PintUnits()
