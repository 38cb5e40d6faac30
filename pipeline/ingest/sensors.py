"""Documented measuring ranges of known sensors, the default ``range`` of their channels.

A laser triangulation sensor whose target leaves the measuring range outputs an error
code (or its range limit) instead of a distance. When a workflow gives no ``range`` for a
channel whose name (the dSPACE block path, a column header) names a known sensor, the
sensor's documented range is used as the channel's ``range`` (and the ingest says so);
a ``range`` in the workflow always wins.

The warning that says so is a :class:`SensorRangeWarning`; :func:`one_range_warning`
gathers those of many files into one line per channel and range, naming the files.

The table :data:`KNOWN_SENSORS` holds one row per sensor: a pattern searched in the
channel name, the range with its unit, and the datasheet it comes from.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from debist.core.errors import DebistWarning
from debist.core.units import lookup_unit

__all__ = [
    "KNOWN_SENSORS",
    "KnownSensor",
    "SensorRangeWarning",
    "default_range",
    "known_sensor",
    "one_range_warning",
]


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
    sensor = known_sensor(channel, si_unit)
    if sensor is not None and gain != 0:
        unit = lookup_unit(sensor.unit)
        lo, hi = sorted((sensor.lo * unit.factor / gain, sensor.hi * unit.factor / gain))
        note = (
            f"the {sensor.name}'s documented range {sensor.lo:g} to {sensor.hi:g} {sensor.unit} "
            f"({sensor.source}), applied because the workflow gives no `range`"
        )
        return lo, hi, note
    return None


def known_sensor(channel: str, si_unit: str) -> KnownSensor | None:
    """Return the known sensor a channel's name names, of the channel's quantity.

    Parameters
    ----------
    channel : str
        The channel's name in the file (block path, header).
    si_unit : str
        SI unit of the channel's values (``"m"`` for a length).

    Returns
    -------
    KnownSensor or None
        The first row of :data:`KNOWN_SENSORS` whose pattern the name matches and whose
        range is of the same quantity; None when there is none.

    Examples
    --------
    >>> known_sensor("Model Root/Sensors/Laser/q", "m").lo
    -25.0
    >>> known_sensor("Model Root/Sensors/Laser/q", "V") is None
    True
    """
    for sensor in KNOWN_SENSORS:
        unit = lookup_unit(sensor.unit)
        if re.search(sensor.pattern, channel, re.IGNORECASE) and unit and unit.si == si_unit:
            return sensor
    return None


class SensorRangeWarning(DebistWarning):
    """A channel's range is a known sensor's documented one, as the workflow gives none.

    Parameters
    ----------
    files : sequence of str
        The rig logs the range applies to (as the workflow names them).
    channel : str
        The channel's name in the files.
    text : str
        What is applied, e.g. ``"`q` range -25 to 25 mm: the ...'s documented range ..."``.

    Attributes
    ----------
    files : tuple of str
    channel, text : str
    """

    def __init__(self, files, channel: str, text: str):
        self.files, self.channel, self.text = tuple(str(f) for f in files), channel, text
        named = ", ".join(f"'{f}'" for f in self.files)
        word = "file" if len(self.files) == 1 else "files"
        super().__init__(f"{word} {named}, channel '{channel}': {text}")


@contextmanager
def one_range_warning() -> Iterator[None]:
    """Give the :class:`SensorRangeWarning` of every file read inside as one per channel.

    A run of several rig logs of one rig would otherwise say the same sensor range once
    per file. Inside the block the range warnings are held back; at its end one warning per
    channel and range is given, naming every file (in the order read). Other warnings are
    passed on after the block, in their order (also when the block raises).

    Yields
    ------
    None

    References
    ----------
    Python documentation, :mod:`warnings` (``catch_warnings``, ``warn_explicit``).

    Examples
    --------
    >>> with warnings.catch_warnings(record=True) as shown:
    ...     warnings.simplefilter("always")
    ...     with one_range_warning():
    ...         for f in ("a.mat", "b.mat"):
    ...             warnings.warn(SensorRangeWarning([f], "Laser/q", "range -25 to 25 mm"))
    >>> [str(w.message) for w in shown]
    ["files 'a.mat', 'b.mat', channel 'Laser/q': range -25 to 25 mm"]
    """
    caught: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            yield
    finally:
        _pass_on(caught)


def _pass_on(caught) -> None:
    """Give the held warnings: the range warnings one per channel and range, others as they were."""
    groups: dict[tuple[str, str], list[str]] = {}
    for w in caught:
        if isinstance(w.message, SensorRangeWarning):
            files = groups.setdefault((w.message.channel, w.message.text), [])
            files += [f for f in w.message.files if f not in files]
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
    for (channel, text), files in groups.items():
        warnings.warn(SensorRangeWarning(files, channel, text), stacklevel=4)
