"""Integration split at input discontinuities: one integrator call per smooth segment.

The full model, the reduced model and the virtual rig are driven by voltage steps. A step
inside an integrator's step makes the error control reject steps around it; splitting the
integration at the steps (and restarting from the end state) avoids that. This module is the
one place that does the splitting, for all three.

Each segment is integrated by :func:`scipy.integrate.solve_ivp` (its methods, stepping in
Python) or, with ``method = "odeint"``, by :func:`scipy.integrate.odeint`: ODEPACK's LSODA,
whose step loop runs in Fortran and calls back only for the right-hand side and the
Jacobian (stiff problems with a cheap, compiled right-hand side).

References
----------
Hairer & Wanner, Solving ODEs II, Sec. IV.8 (restarting at discontinuities); SciPy
``scipy.integrate.solve_ivp`` and ``scipy.integrate.odeint``; Hindmarsh, A. C. (1983).
ODEPACK, a systematized collection of ODE solvers. In Scientific Computing, IMACS Trans.
Sci. Comput. 1, 55-64; Petzold, L. (1983). Automatic selection of methods for solving stiff
and nonstiff systems of ordinary differential equations. SIAM J. Sci. Stat. Comput. 4(1),
136-148 (LSODA).
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import lazy_loader as lazy
import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.core import progress

# the libraries below load on first use (lazy_loader): start-up of the CLI
integrate = lazy.load("scipy.integrate", suppress_warning=True)

__all__ = ["ODEINT", "SegmentedSolution", "solve_segments"]

#: The ``method`` of :func:`solve_segments` that integrates with :func:`scipy.integrate.odeint`.
ODEINT = "odeint"
#: LSODA steps allowed per output interval unless ``mxstep`` is given (``odeint``'s own
#: default, 500, is meant for sparse output; ``solve_ivp`` has no such limit).
ODEINT_MXSTEP = 100_000


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


class _Segment(NamedTuple):
    """One segment's output: ``y`` (m, n) at the first m of the requested times."""

    y: NDArray[np.float64]
    success: bool
    message: str
    nfev: int
    njev: int


def _ivp_segment(fun, span, x, t_out, options) -> _Segment:
    """Integrate one segment with :func:`scipy.integrate.solve_ivp`."""
    sol = integrate.solve_ivp(fun, span, x, t_eval=t_out, **options)
    return _Segment(sol.y.T, bool(sol.success), sol.message, sol.nfev, sol.njev)


def _odeint_segment(fun, span, x, t_out, options) -> _Segment:
    """Integrate one segment with :func:`scipy.integrate.odeint` (LSODA), not beyond its end.

    ``tcrit`` keeps LSODA from stepping past the segment's end (beyond it lies the next
    input step). After a failure ``odeint`` leaves the rows from the failing output time on
    undefined; the rows before it are those whose internal time ``tcur`` reached them.
    """
    a, c = span
    opts = dict(options)
    opts.pop("method", None)
    jac = opts.pop("jac", None)
    max_step = opts.pop("max_step", math.inf)
    kw = {
        "args": tuple(opts.pop("args", ())),
        "h0": float(opts.pop("first_step", None) or 0.0),
        "hmax": 0.0 if math.isinf(max_step) else float(max_step),
        "mxstep": int(opts.pop("mxstep", ODEINT_MXSTEP)),
        **opts,
    }
    lead = not (t_out.size and t_out[0] == a)
    tt = np.concatenate([[a], t_out]) if lead else t_out
    if tt.size == 1:  # output at the start only
        return _Segment(np.asarray(x, dtype=float)[None, :], True, "Integration successful.", 0, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", integrate.ODEintWarning)
        y, info = integrate.odeint(
            fun, x, tt, Dfun=jac, tfirst=True, full_output=True, tcrit=np.array([c]), **kw
        )
    slack = 1e-10 * max(abs(a), abs(c), c - a)  # LSODA stops within roundoff of tcrit
    reached = info["tcur"] >= tt[1:] - slack
    bad = np.flatnonzero(~reached)
    n_ok = int(bad[0]) if bad.size else tt.size - 1  # output intervals completed
    k = min(n_ok, tt.size - 2)  # the statistics are cumulative, last written at k
    return _Segment(
        y[int(lead) : n_ok + 1],
        not bad.size,
        str(info["message"]),
        int(info["nfe"][k]),
        int(info["nje"][k]),
    )


def solve_segments(
    fun: Callable[..., NDArray[np.float64]],
    t_span: tuple[float, float],
    x0: ArrayLike,
    t_eval: ArrayLike,
    breakpoints: Sequence[float] = (),
    **options: Any,
) -> SegmentedSolution:
    """Integrate ``x' = fun(t, x)`` segment by segment, split at breakpoints.

    Each segment ``[a, c)`` between consecutive breakpoints (the last one closed) is one
    integrator call started from the previous segment's end state; output is at the points
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
        ``method`` (default ``"RK45"``): a :func:`scipy.integrate.solve_ivp` method, the
        other options passed to it; or :data:`ODEINT`: :func:`scipy.integrate.odeint`
        (LSODA) with ``rtol``, ``atol``, ``jac(t, x, *args)`` (shape (n_states, n_states)),
        ``args``, ``first_step``, ``max_step`` and its own keywords (``mxstep``, default
        :data:`ODEINT_MXSTEP`). No step crosses a segment's end.

    Returns
    -------
    SegmentedSolution
        Output times and states, statistics and messages. After an ``odeint`` failure the
        output reaches up to the last output time before it, a prefix of the failing
        segment; after a ``solve_ivp`` failure, up to the failing segment.

    References
    ----------
    Hairer & Wanner, Solving ODEs II, Sec. IV.8; SciPy ``solve_ivp``, ``odeint``;
    Hindmarsh 1983 (ODEPACK); Petzold 1983 (LSODA).
    """
    t0, t1 = map(float, t_span)
    fun = progress.tracking_time(fun, (t0, t1))  # unwrapped unless someone listens
    t_eval = np.asarray(t_eval, dtype=float)
    step = _odeint_segment if options.get("method") == ODEINT else _ivp_segment
    edges = [t0, *sorted({float(b) for b in breakpoints if t0 < b < t1}), t1]
    x = np.asarray(x0, dtype=float)
    ts, ys, msgs, ok, nfev, njev = [], [], [], True, 0, 0
    for a, c in itertools.pairwise(edges):
        sel = (t_eval >= a) & ((t_eval <= c) if c == t1 else (t_eval < c))
        te = t_eval[sel]
        te_ext = te if te.size and te[-1] == c else np.append(te, c)
        seg = step(fun, (a, c), x, te_ext, options)
        nfev += seg.nfev
        njev += seg.njev
        ok &= seg.success
        msgs.append(seg.message)
        if not seg.success:
            if step is _odeint_segment:  # the output times reached before the failure
                m = min(seg.y.shape[0], te.size)
                ts.append(te[:m])
                ys.append(seg.y[:m])
            break
        ts.append(te)
        ys.append(seg.y[: te.size])
        x = seg.y[-1]
    return SegmentedSolution(
        t=np.concatenate(ts) if ts else np.empty(0),
        y=np.concatenate(ys) if ys else np.empty((0, x.size)),
        success=bool(ok),
        message="; ".join(dict.fromkeys(msgs)),
        nfev=int(nfev),
        njev=int(njev),
    )
