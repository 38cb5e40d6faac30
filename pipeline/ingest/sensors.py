"""Documented measuring ranges of known sensors, the default ``range`` of their channels.

A laser triangulation sensor whose target leaves the measuring range outputs an error
code (or its range limit) instead of a distance. When a workflow gives no ``range`` for a
channel whose name (the dSPACE block path, a column header) names a known sensor, the
sensor's documented range is used as the channel's ``range`` (and the ingest says so);
a ``range`` in the workflow always wins.

The table :data:`KNOWN_SENSORS` holds one row per sensor: a pattern searched in the
channel name, the range with its unit, and the datasheet it comes from.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from debist.core.units import lookup_unit

__all__ = ["KNOWN_SENSORS", "KnownSensor", "default_range"]


@dataclass(frozen=True)
class KnownSensor:
    """One known sensor and its documented measuring range.

    Parameters
    ----------
    name : str
        The sensor, for messages.
    pattern : str
        Regular expression searched (:func:`re.search`, case-insensitive) in a channel's name.
    lo, hi : float
        Measuring range in ``unit``, in the rig's convention (about the mid-range point).
    unit : str
        Unit of ``lo`` and ``hi`` (a length unit pint parses).
    source : str
        Where the range is documented.
    """

    name: str
    pattern: str
    lo: float
    hi: float
    unit: str
    source: str


#: Known sensors. The Micro-Epsilon optoNCDT ILD2300-50 measures 50 mm, i.e. +-25 mm about
#: its mid-range, which is the rig's q = 0 (the virtual rig, :mod:`debist.rig`, names its
#: channel ``Model Root/Sensors/Laser/q`` and clips at ``RigParams.sensor_range`` = 25 mm).
KNOWN_SENSORS: tuple[KnownSensor, ...] = (
    KnownSensor(
        name="Micro-Epsilon optoNCDT ILD2300 laser",
        pattern=r"ILD\s*-?\s*2300|(^|[/\"\s])Laser[\"/]",
        lo=-25.0,
        hi=25.0,
        unit="mm",
        source="Micro-Epsilon, optoNCDT 2300 datasheet (measuring range 50 mm, ILD2300-50)",
    ),
)


def default_range(channel: str, si_unit: str, gain: float) -> tuple[float, float, str] | None:
    """Return the documented range of the sensor a channel name names, in the recorded unit.

    Parameters
    ----------
    channel : str
        The channel's name in the file (block path, header).
    si_unit : str
        SI unit of the channel's values; only a sensor of the same quantity applies.
    gain : float
        ``values [SI] = recorded * gain``.

    Returns
    -------
    tuple or None
        ``(lo, hi, note)``: the limits in the recorded unit and a note naming the sensor,
        its range and source; None when no known sensor matches (or of another quantity).

    Examples
    --------
    >>> lo, hi, note = default_range("Model Root/Sensors/Laser/q", "m", 1e-3)
    >>> round(lo, 9), round(hi, 9)
    (-25.0, 25.0)
    >>> default_range("Model Root/HV Amplifier/DE1/v_mon", "V", 1e3) is None
    True
    """
    for sensor in KNOWN_SENSORS:
        if not re.search(sensor.pattern, channel, re.IGNORECASE):
            continue
        unit = lookup_unit(sensor.unit)
        if unit is None or unit.si != si_unit or gain == 0:
            continue
        lo, hi = sorted((sensor.lo * unit.factor / gain, sensor.hi * unit.factor / gain))
        note = (
            f"the {sensor.name}'s documented range {sensor.lo:g} to {sensor.hi:g} {sensor.unit} "
            f"({sensor.source}), applied because the workflow gives no `range`"
        )
        return lo, hi, note
    return None
