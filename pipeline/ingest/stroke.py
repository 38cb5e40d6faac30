"""A warning when the stroke of ``q`` fits another length unit than the one declared.

A DE bistable actuator moves between wells some millimetres apart (Masoud & Maas 2025,
Table 1 and Fig. 14: about +-10 mm); a rig for such actuators measures strokes from
micrometres to centimetres. A log written in mm but declared in m passes every hard check
up to 100 m (:data:`~debist.ingest.checks.PLAUSIBLE`), and one in m declared in um looks
like a motionless record. After conversion to SI, a peak-to-peak ``q`` above
:data:`STROKE_MAX` or below :data:`STROKE_MIN` is accepted but warned about
(:class:`~debist.core.errors.PlausibilityWarning`), naming the file, the channel, the declared
unit and the unit in which the stroke would be typical.

References
----------
Masoud & Maas 2025, Sec. 2 (the prototype), Table 1.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from debist.core.errors import PlausibilityWarning
from debist.core.units import lookup_unit

__all__ = ["STROKE_MAX", "STROKE_MIN", "check_stroke"]

#: Largest peak-to-peak q [m] taken as plausible for a DE bistable actuator.
STROKE_MAX = 0.5
#: Smallest peak-to-peak q [m] taken as plausible (below, a record in m declared in um).
STROKE_MIN = 1e-7
#: Length units suggested instead, and the stroke [m] taken as typical when choosing.
_CANDIDATES = ("m", "cm", "mm", "um", "nm")
_TYPICAL = 1e-2
_TYPICAL_RANGE = (1e-5, 0.1)


def _better_unit(ptp_si: float, declared_factor: float) -> tuple[str, float] | None:
    """Return the candidate unit reading the stroke nearest a typical one, and that stroke."""
    best = None
    for symbol in _CANDIDATES:
        entry = lookup_unit(symbol)
        if entry is None:
            continue
        stroke = ptp_si * entry.factor / declared_factor
        if not _TYPICAL_RANGE[0] <= stroke <= _TYPICAL_RANGE[1]:
            continue
        distance = abs(math.log10(stroke / _TYPICAL))
        if best is None or distance < best[0]:
            best = (distance, symbol, stroke)
    return None if best is None else (best[1], best[2])


def check_stroke(
    values: np.ndarray, *, unit: str | None, channel: str, path: Path | str, role: str = "q"
) -> None:
    """Warn when the peak-to-peak of ``q`` [m] is implausible for a DE bistable actuator.

    Parameters
    ----------
    values : ndarray, shape (n_samples,) [m]
        ``q`` in SI units (finite).
    unit : str or None
        The unit the record was declared in (``q.unit`` or the file's), for the message
        and the suggestion; None: no suggestion.
    channel : str
        The source channel, for the message.
    path : Path or str
        The rig log, for the message.
    role : str, optional
        The canonical column (``"q"``).

    Warns
    -----
    PlausibilityWarning
        When ``max(q) - min(q)`` exceeds :data:`STROKE_MAX` or is below
        :data:`STROKE_MIN` but not zero (a motionless record is the ingest checks' concern):
        ``"file 'rig.csv', channel 'laser': `q` spans 24 m peak to peak with `q.unit` =
        'm', implausible for a DE bistable actuator (0.1 um to 0.5 m); read in 'mm' it
        would span 24 mm: check `q.unit`"``.

    Examples
    --------
    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     check_stroke(np.array([-12.0, 12.0]), unit="m", channel="laser", path="rig.csv")
    >>> "read in 'mm' it would span 24 mm" in str(caught[0].message)
    True
    """
    if values.size == 0:
        return
    ptp = float(np.max(values) - np.min(values))
    if STROKE_MIN <= ptp <= STROKE_MAX or ptp == 0.0:
        return
    entry = lookup_unit(unit) if unit else None
    better = _better_unit(ptp, entry.factor) if entry is not None else None
    hint = ""
    if better is not None:
        symbol, stroke = better
        shown = stroke / lookup_unit(symbol).factor
        hint = f"; read in '{symbol}' it would span {shown:.3g} {symbol}"
    declared = f" with `{role}.unit` = '{unit}'" if unit else ""
    warnings.warn(
        f"file '{path}', channel '{channel}': `{role}` spans {ptp:.3g} m peak to peak"
        f"{declared}, implausible for a DE bistable actuator ({STROKE_MIN * 1e6:g} um to "
        f"{STROKE_MAX:g} m){hint}: check `{role}.unit`",
        PlausibilityWarning,
        stacklevel=2,
    )
