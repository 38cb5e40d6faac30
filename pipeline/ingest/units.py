"""Table of the units a rig-log channel may be recorded in, and their factors to SI.

Conversion to SI happens here and only here (STYLE: SI inside, conversion at ingest):
a recorded value ``x`` in unit ``u`` becomes ``x * UNITS[u].factor`` in ``UNITS[u].si``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType

__all__ = ["SI_UNITS", "UNITS", "Unit", "canonical_unit", "lookup_unit"]


@dataclass(frozen=True)
class Unit:
    """One known unit.

    Parameters
    ----------
    symbol : str
        Canonical symbol, e.g. ``"kV"``.
    factor : float
        Multiply a value in this unit by ``factor`` to get it in ``si``.
    si : str
        The SI unit of the same quantity, e.g. ``"V"``.
    quantity : str
        What the unit measures (``"time"``, ``"length"``, ``"voltage"``, ...).
    """

    symbol: str
    factor: float
    si: str
    quantity: str


_TABLE = (
    Unit("s", 1.0, "s", "time"),
    Unit("ms", 1e-3, "s", "time"),
    Unit("us", 1e-6, "s", "time"),
    Unit("m", 1.0, "m", "length"),
    Unit("mm", 1e-3, "m", "length"),
    Unit("um", 1e-6, "m", "length"),
    Unit("V", 1.0, "V", "voltage"),
    Unit("kV", 1e3, "V", "voltage"),
    Unit("mV", 1e-3, "V", "voltage"),
    Unit("N", 1.0, "N", "force"),
    Unit("mN", 1e-3, "N", "force"),
    Unit("rad", 1.0, "rad", "angle"),
    Unit("deg", math.pi / 180.0, "rad", "angle"),
    Unit("Pa", 1.0, "Pa", "pressure"),
    Unit("kPa", 1e3, "Pa", "pressure"),
    Unit("bar", 1e5, "Pa", "pressure"),
    Unit("1", 1.0, "1", "dimensionless"),
)

#: Known units by canonical symbol (read-only).
UNITS = MappingProxyType({u.symbol: u for u in _TABLE})

#: The SI units the table converts to.
SI_UNITS = frozenset(u.si for u in _TABLE)

# Other spellings of the same units (the micro sign and the Greek mu, long names).
_ALIASES = MappingProxyType(
    {
        "\u00b5s": "us",
        "\u03bcs": "us",
        "\u00b5m": "um",
        "\u03bcm": "um",
        "sec": "s",
        "msec": "ms",
        "-": "1",
    }
)


def canonical_unit(symbol: str) -> str:
    """Return the canonical spelling of a unit symbol (``"µm"`` -> ``"um"``).

    Parameters
    ----------
    symbol : str
        A unit as written in a workflow file or declared by a rig log; surrounding
        blanks and square brackets (``"[mm]"``) are ignored.

    Returns
    -------
    str
        The canonical symbol if the unit is known (or an alias of one), else the
        stripped input unchanged.

    Examples
    --------
    >>> canonical_unit(" [\u00b5m] ")
    'um'
    >>> canonical_unit("furlong")
    'furlong'
    """
    s = symbol.strip()
    if s.startswith("[") and s.endswith("]"):
        s = s[1:-1].strip()
    return _ALIASES.get(s, s)


def lookup_unit(symbol: str) -> Unit | None:
    """Return the :class:`Unit` of a symbol, or None when it is not in the table.

    Parameters
    ----------
    symbol : str
        A unit symbol or one of its aliases (see :func:`canonical_unit`).

    Returns
    -------
    Unit or None
        The table entry.

    Examples
    --------
    >>> lookup_unit("kV").factor
    1000.0
    >>> lookup_unit("ms").si
    's'
    """
    return UNITS.get(canonical_unit(symbol))
