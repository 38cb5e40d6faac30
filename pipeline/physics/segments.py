"""Integration split at input discontinuities: one :func:`solve_ivp` call per smooth segment.

The full model, the reduced model and the virtual rig are driven by voltage steps. A step
inside an integrator's step makes the error control reject steps around it; splitting the
integration at the steps (and restarting from the end state) avoids that. This module is the
one place that does the splitting, for all three.

References
----------
Hairer & Wanner, Solving ODEs II, Sec. IV.8 (restarting at discontinuities); SciPy
``scipy.integrate.solve_ivp``.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import solve_ivp

from pipeline import progress

__all__ = ["SegmentedSolution", "solve_segments"]


@dataclass(frozen=True)
class SegmentedSolution:
    """Result of :func:`solve_segments`.

    Attributes
    ----------
    t : ndarray, shape (m,)
        Output times reached [s]: all of ``t_eval`` on success, a prefix after a failure.
    y : ndarray, shape (m, n_states)
        States at ``t``.
    success : bool
        Whether every segment succeeded.
    message : str
        The integrator's distinct messages, joined by "; ".
    nfev, njev : int
        Right-hand-side and Jacobian evaluations over all segments.
    """

    t: NDArray[np.float64]
    y: NDArray[np.float64]
    success: bool
    message: str
    nfev: int
    njev: int


def solve_segments(
    fun: Callable[..., NDArray[np.float64]],
    t_span: tuple[float, float],
    x0: ArrayLike,
    t_eval: ArrayLike,
    breakpoints: Sequence[float] = (),
    **options: Any,
) -> SegmentedSolution:
    """Integrate ``x' = fun(t, x)`` with :func:`scipy.integrate.solve_ivp`, split at breakpoints.

    Each segment ``[a, c)`` between consecutive breakpoints (the last one closed) is one
    ``solve_ivp`` call started from the previous segment's end state; output is at the points
    of ``t_eval`` inside it. Integration stops at the first failing segment.

    Parameters
    ----------
    fun : callable
        Right-hand side ``fun(t, x, *args)``.
    t_span : tuple of float
        Start and end time [s].
    x0 : array_like, shape (n_states,)
        Initial state.
    t_eval : array_like, shape (n,)
        Ascending output times within ``t_span`` [s].
    breakpoints : sequence of float
        Times of input discontinuities [s]; those outside ``t_span`` are ignored.
    **options
        Passed to ``solve_ivp`` (``method``, ``rtol``, ``atol``, ``jac``, ``args``, ...).

    Returns
    -------
    SegmentedSolution
        Output times and states, statistics and messages.
    """
    t0, t1 = map(float, t_span)
    fun = progress.tracking_time(fun, (t0, t1))  # unwrapped unless someone listens
    t_eval = np.asarray(t_eval, dtype=float)
    edges = [t0, *sorted(b for b in breakpoints if t0 < b < t1), t1]
    x = np.asarray(x0, dtype=float)
    ts, ys, msgs, ok, nfev, njev = [], [], [], True, 0, 0
    for a, c in itertools.pairwise(edges):
        sel = (t_eval >= a) & ((t_eval <= c) if c == t1 else (t_eval < c))
        te = t_eval[sel]
        te_ext = te if te.size and te[-1] == c else np.append(te, c)
        sol = solve_ivp(fun, (a, c), x, t_eval=te_ext, **options)
        nfev += sol.nfev
        njev += sol.njev
        ok &= bool(sol.success)
        msgs.append(sol.message)
        if not sol.success:
            break
        ts.append(sol.t[: te.size])
        ys.append(sol.y.T[: te.size])
        x = sol.y[:, -1]
    return SegmentedSolution(
        t=np.concatenate(ts) if ts else np.empty(0),
        y=np.concatenate(ys) if ys else np.empty((0, x.size)),
        success=bool(ok),
        message="; ".join(dict.fromkeys(msgs)),
        nfev=int(nfev),
        njev=int(njev),
    )
