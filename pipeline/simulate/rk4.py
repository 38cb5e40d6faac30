"""The classical fourth-order Runge-Kutta step, written once for every free-run engine.

One step of size ``h`` from state ``x`` evaluates the right-hand side four times: at ``x``
(``k1``), at :func:`stage_state` ``(x, h, 1, k1)`` and ``(x, h, 2, k2)`` (``k2``, ``k3``, at the
half step) and at ``(x, h, 3, k3)`` (``k4``, at the full step), then moves to
:func:`advance` ``(x, h, increment(k1, k2, k3, k4))``. The inputs of stage ``i`` are read on the
grid of half sub-steps at ``j + INPUT_OFFSET[i]``. The NumPy engine
(:mod:`debist.simulate.freerun`) calls these functions on arrays; the compiled kernel
(:mod:`debist.simulate.kernel`) compiles the same functions with numba and calls them per
element, which gives the same floating-point operations in the same order, so both engines
and every kernel path (serial, lock-step batches, sensitivities) take the same step.

References
----------
Hairer, Norsett & Wanner, *Solving Ordinary Differential Equations I*, 2nd ed., Sec. II.1
(the classical RK4 tableau, Table 1.2).

Examples
--------
One step of x' = x from x = 1 with h = 0.1 (the exact value is e^0.1 = 1.105170918...):

>>> h, x = 0.1, 1.0
>>> k1 = x
>>> k2 = stage_state(x, h, 1, k1)
>>> k3 = stage_state(x, h, 2, k2)
>>> k4 = stage_state(x, h, 3, k3)
>>> round(advance(x, h, increment(k1, k2, k3, k4)), 9)
1.105170833
"""

from __future__ import annotations

__all__ = ["INPUT_OFFSET", "NODES", "advance", "increment", "stage_state"]

#: The tableau's nodes c_i: stage i evaluates the right-hand side at t + c_i h.
NODES = (0.0, 0.5, 0.5, 1.0)
#: Where stage i reads the inputs on the grid of half sub-steps: j, j + 1, j + 1, j + 2.
INPUT_OFFSET = (0, 1, 1, 2)


def stage_state(x, h, stage, d_prev):
    """Return the state at which stage ``stage`` (1, 2 or 3) evaluates the right-hand side.

    Parameters
    ----------
    x : float or ndarray
        The state at the start of the step.
    h : float
        Step size [s].
    stage : int
        1, 2 or 3 (stage 0 evaluates at ``x`` itself).
    d_prev : float or ndarray, same shape as ``x``
        The previous stage's derivative.

    Returns
    -------
    float or ndarray
        ``x + (c_stage h) d_prev``.
    """
    return x + (NODES[stage] * h) * d_prev


def increment(k1, k2, k3, k4):
    """Return the weighted sum of the four stage derivatives, ``k1 + 2 k2 + 2 k3 + k4``.

    Parameters
    ----------
    k1, k2, k3, k4 : float or ndarray
        The stage derivatives, all of one shape.

    Returns
    -------
    float or ndarray
        The sum, left to right.
    """
    return k1 + 2.0 * k2 + 2.0 * k3 + k4


def advance(x, h, incr):
    """Return the state after the step: ``x + (h / 6) incr``.

    Parameters
    ----------
    x : float or ndarray
        The state at the start of the step.
    h : float
        Step size [s].
    incr : float or ndarray
        :func:`increment` of the stage derivatives.

    Returns
    -------
    float or ndarray
        The state at the end of the step.
    """
    return x + (h / 6.0) * incr
