"""The stop operators of the Maxwell-slip elements along a record, compiled.

:func:`debist.model.friction.slip_states` runs one recursion per sample and element:
``delta[k+1] = clip(delta[k] + step[k], -Delta, Delta)``. In Python that loop costs about a
microsecond per sample, and the least squares evaluates it for every fit of the held-out
search; compiled (numba, cached on disk) it runs at the speed of the arithmetic. The clip is
:func:`debist.model.friction.slip_clip`'s ``minimum(maximum(delta, -Delta), Delta)``, written
out so that numba's cache, keyed on this file, holds the whole recursion; a test holds the two
equal bit for bit.

References
----------
Al-Bender, Lampaert & Swevers 2005, IEEE Trans. Autom. Control 50(11), 1883-1887 (the
Maxwell-slip model); Moreau 1977 (the catch-up algorithm of the stop operator); Lam, Pitrou &
Seibert 2015 (numba).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray

from debist.core.jitcache import prepare_cache

prepare_cache(__file__)  # before the first cache=True: a folder numba can write

__all__ = ["stop_operator"]


@nb.njit(cache=True)
def stop_operator(step: NDArray[np.float64], widths: NDArray[np.float64]) -> NDArray[np.float64]:
    """Deflections of stop operators driven by position increments, from zero.

    Parameters
    ----------
    step : ndarray, shape (n - 1,)
        Position increments between samples [unit of q].
    widths : ndarray, shape (E,)
        Break-away deflections Delta_e > 0 [unit of q] (not checked here:
        :func:`debist.model.friction.slip_states` checks them).

    Returns
    -------
    ndarray, shape (n, E)
        ``out[0] = 0`` and ``out[k + 1, e] = minimum(maximum(out[k, e] + step[k],
        -widths[e]), widths[e])`` [unit of q].

    References
    ----------
    Al-Bender, Lampaert & Swevers 2005; Moreau 1977.

    Examples
    --------
    >>> stop_operator(np.array([1.0, 1.0, -1.0]), np.array([1.5])).ravel().tolist()
    [0.0, 1.0, 1.5, 0.5]
    """
    out = np.zeros((step.size + 1, widths.size))
    for e in range(widths.size):
        width = widths[e]
        delta = 0.0
        for k in range(step.size):
            delta = np.minimum(np.maximum(delta + step[k], -width), width)
            out[k + 1, e] = delta
    return out
