"""The result type shared by every differentiator, and the checks they share."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Derivatives", "check_int", "check_positive", "check_signal"]

_C = TypeVar("_C")


@dataclass(frozen=True, eq=False)
class Derivatives:
    """Smoothed signal and its first two time derivatives, from any differentiator.

    Attributes
    ----------
    x_hat : ndarray, shape (n,) [unit]
        Smoothed signal, in the unit of the input ``x``.
    x_dot : ndarray, shape (n,) [unit/s]
        First derivative at the sample instants.
    x_ddot : ndarray, shape (n,) [unit/s^2]
        Second derivative at the sample instants.
    method : str
        Name of the method in :data:`debist.differentiate.DIFFERENTIATORS`.
    converged : bool
        False when an iterative method stopped before its tolerance (direct methods: True).
    info : dict
        Method-specific diagnostics (iteration counts, functional values, filter settings).

    Examples
    --------
    >>> import numpy as np
    >>> d = Derivatives(np.zeros(3), np.zeros(3), np.zeros(3), method="none", converged=True)
    >>> d.x_dot.shape
    (3,)
    """

    x_hat: NDArray[np.float64]
    x_dot: NDArray[np.float64]
    x_ddot: NDArray[np.float64]
    method: str
    converged: bool
    info: dict[str, Any] = field(default_factory=dict)


def check_signal(x: ArrayLike, dt: float) -> tuple[NDArray[np.float64], float]:
    """Check the common inputs of a differentiator.

    Parameters
    ----------
    x : array_like, shape (n,) [unit]
        Uniformly sampled signal, ``n >= 3``, finite.
    dt : float
        Sample time [s], positive and finite.

    Returns
    -------
    x : ndarray, shape (n,) [unit]
        ``x`` as a float array.
    dt : float
        ``dt`` as a float [s].

    Raises
    ------
    ValueError
        If ``x`` is not 1-D, has fewer than 3 samples or non-finite values, or ``dt`` is
        not positive and finite.

    Examples
    --------
    >>> check_signal([0, 1, 2], 0.1)
    (array([0., 1., 2.]), 0.1)
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"`x` must be 1-D, got shape {x.shape}")
    if x.size < 3:
        raise ValueError(f"`x` must have at least 3 samples, got {x.size}")
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise ValueError(
            f"`x` must be finite, got {x[bad[0]]} at index {bad[0]} ({bad.size} non-finite)"
        )
    try:
        dt = float(dt)
    except (TypeError, ValueError):
        raise ValueError(f"`dt` must be a positive number of seconds, got {dt!r}") from None
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"`dt` must be positive and finite, got {dt!r}")
    return x, dt


def check_positive(name: str, value: float) -> float:
    """Return ``value`` as a float if it is positive and finite.

    Parameters
    ----------
    name : str
        Argument name, for the message.
    value : float
        The value to check.

    Returns
    -------
    float
        ``float(value)``.

    Raises
    ------
    ValueError
        If ``value`` is not a number, not finite or not positive.

    Examples
    --------
    >>> check_positive("alpha", 2)
    2.0
    """
    if isinstance(value, bool):
        raise ValueError(f"`{name}` must be a positive number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` must be a positive number, got {value!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"`{name}` must be positive and finite, got {value!r}")
    return v


def check_int(name: str, value: int, minimum: int) -> int:
    """Return ``value`` as an int if it is an integer ``>= minimum``.

    Parameters
    ----------
    name : str
        Argument name, for the message.
    value : int
        The value to check (``bool`` is refused).
    minimum : int
        Smallest allowed value.

    Returns
    -------
    int
        ``int(value)``.

    Raises
    ------
    ValueError
        If ``value`` is not an integer or is below ``minimum``.

    Examples
    --------
    >>> check_int("iterations", 10, 1)
    10
    """
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ValueError(f"`{name}` must be an integer >= {minimum}, got {value!r}")
    if value < minimum:
        raise ValueError(f"`{name}` must be >= {minimum}, got {value!r}")
    return int(value)
