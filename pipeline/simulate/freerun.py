"""Free-run simulation shared by every model that is compared (identified, SINDy, analytical).

One fixed-step classical Runge-Kutta integrator with sub-steps, driven by the
measured inputs interpolated band-limited (polyphase FIR, the default) or
linearly, never by a zero-order hold that delays the input by half a sample.
Several records are simulated at once as a batch. Two engines run the same scheme: the
compiled kernel (:mod:`debist.simulate.kernel`, the default, for every model with a
``kernel_table`` or ``kernel_splines``) and the NumPy reference, vectorised over the batch and
calling the model's own ``rhs``; they agree to rounding.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from debist.core import preflight
from debist.core import progress as _progress
from debist.core.errors import WorkflowError
from debist.simulate import rk4
from debist.simulate.batch import BatchRun, mask_batch

INTERPOLATIONS = ("bandlimited", "linear")
#: Free-run engines: the compiled kernel and the NumPy reference.
ENGINES = ("compiled", "numpy")
#: Samples of odd-reflected extension at each end before band-limited interpolation.
EDGE_PAD = 32
#: The window of ``scipy.signal.resample_poly``'s FIR design for band-limited interpolation.
BANDLIMITED_WINDOW = ("kaiser", 8.0)


class FreeRunModel(Protocol):
    """What the simulator needs of a model.

    Attributes
    ----------
    n_states : int
        State dimension; the first two states are q and q_dot.
    """

    n_states: int

    def initial_state(self, q0: np.ndarray, q_dot0: np.ndarray) -> np.ndarray:
        """States (B, n_states) from initial position and velocity (B,)."""

    def rhs(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """State derivative (B, n_states) and acceleration (B,) at states x and inputs v."""

    def max_step(self) -> float:
        """Largest stable integration step [s]."""

    # optional: ``project(x) -> x``, applied after every step (the slip elements' stop
    # operator, :meth:`debist.model.termtable.TableModel.project`)


@dataclass(frozen=True)
class SimulationResult:
    """Free-run trajectory of one record.

    Attributes
    ----------
    q, q_dot, q_ddot : ndarray, shape (n,)
        Simulated position [unit of q], velocity [unit/s] and acceleration
        [unit/s^2] at the sample instants; NaN after a divergence.
    states : ndarray, shape (n, n_states)
        All states.
    diverged : bool
        Whether the trajectory left the finite or allowed range.
    diverged_at : int
        First sample index that diverged, -1 if none.
    substeps : int
        RK4 steps per sample actually used.
    """

    q: np.ndarray
    q_dot: np.ndarray
    q_ddot: np.ndarray
    states: np.ndarray
    diverged: bool
    diverged_at: int
    substeps: int


def upsample_inputs(v: np.ndarray, factor: int, method: str) -> np.ndarray:
    """Interpolate sampled inputs onto a grid ``factor`` times finer.

    Parameters
    ----------
    v : ndarray, shape (n, n_inputs)
        Inputs at the sample instants [V].
    factor : int
        Points per sample interval.
    method : {"bandlimited", "linear"}
        ``"bandlimited"``: polyphase FIR interpolation (``scipy.signal.resample_poly``
        with a Kaiser window, line-extended ends), which keeps the spectrum below
        Nyquist; ``"linear"``: piecewise linear.

    Returns
    -------
    ndarray, shape ((n - 1) * factor + 1, n_inputs)
        Values at ``t_0 + j dt / factor``.

    Raises
    ------
    WorkflowError
        If ``method`` is unknown.
    """
    n = v.shape[0]
    m = (n - 1) * factor + 1
    if factor == 1:
        return v.copy()
    if method == "linear":
        grid = np.arange(m) / factor
        return np.stack([np.interp(grid, np.arange(n), col) for col in v.T], axis=1)
    if method == "bandlimited":
        from scipy.signal import resample_poly

        # Odd reflection about both end points keeps value and slope continuous, so the
        # FIR filter sees no step at the record's ends; the extension is cut off again.
        pad = min(EDGE_PAD, n - 1)
        ext = np.concatenate([2 * v[:1] - v[pad:0:-1], v, 2 * v[-1:] - v[-2 : -pad - 2 : -1]])
        up = resample_poly(ext, factor, 1, axis=0, window=BANDLIMITED_WINDOW)
        return up[pad * factor : pad * factor + m]
    raise WorkflowError(f"`input_interpolation` must be one of {INTERPOLATIONS}, got {method!r}")


def bandlimited_phases(factor: int) -> np.ndarray:
    """Return the polyphase FIR taps of the band-limited interpolation of :func:`upsample_inputs`.

    Taken from ``scipy.signal.resample_poly`` itself (its response to a unit impulse, with
    the window :data:`BANDLIMITED_WINDOW`), so that they are the coefficients it applies,
    designed and aligned as it does. With ``e`` the odd-reflected record of
    :func:`upsample_inputs` (``EDGE_PAD`` samples on each side, zero beyond), its fine
    point ``J = factor c + r`` (``0 <= r < factor``) is
    ``sum_d taps[r, d] e[c + d - D]`` for ``d = 0 .. 2 D``.

    Parameters
    ----------
    factor : int
        Points per sample interval, >= 1.

    Returns
    -------
    ndarray, shape (factor, 2 D + 1)
        The taps of each phase r [1]; ``D`` (the filter's half length in samples) is
        ``(taps.shape[1] - 1) // 2``. ``factor = 1`` gives ``[[1.0]]`` (no interpolation).

    Raises
    ------
    WorkflowError
        If ``factor`` is below 1.

    References
    ----------
    SciPy, ``scipy.signal.resample_poly`` (firwin design of half length 10 ``factor``,
    zero-phase alignment); Crochiere & Rabiner, *Multirate Digital Signal Processing*
    (1983), Sec. 3.3 (polyphase structures).

    Examples
    --------
    >>> bandlimited_phases(4).shape  # scipy's 10 samples either side
    (4, 21)
    """
    if int(factor) < 1:
        raise WorkflowError(f"the interpolation factor must be >= 1, got {factor!r}")
    factor = int(factor)
    if factor == 1:
        return np.ones((1, 1))
    from scipy.signal import resample_poly

    half = 64  # input samples either side of the impulse: beyond scipy's 10 of them
    impulse = np.zeros(2 * half + 1)
    impulse[half] = 1.0
    # response at fine point J to a unit sample at i: g[J - factor i]; g[t] at index t + factor half
    g = resample_poly(impulse, factor, 1, window=BANDLIMITED_WINDOW)
    support = np.flatnonzero(g)
    reach = int(np.max(np.abs(support - factor * half)))
    d = -(-reach // factor)  # the half length in samples
    if d >= half:
        raise AssertionError(f"resample_poly's filter reaches {reach} fine points, beyond {half}")
    taps = np.zeros((factor, 2 * d + 1))
    for r in range(factor):
        for k in range(2 * d + 1):  # sample c + k - d contributes g[r - factor (k - d)]
            t = r - factor * (k - d)
            taps[r, k] = g[t + factor * half]
    return taps


@dataclass(frozen=True)
class FineInputs:
    """Inputs of a batch interpolated once onto the RK4 grid, for repeated simulations.

    Attributes
    ----------
    values : ndarray, shape (B, (n - 1) * 2 * substeps + 1, n_inputs), or one row
        Inputs at every RK4 stage instant [V]; shorter records padded with their
        last value. One row (shape (1, ...)) drives all B trajectories.
    lengths : list of int
        Samples of each record (B of them).
    substeps : int
        RK4 steps per sample interval the grid was made for.
    """

    values: np.ndarray
    lengths: list[int]
    substeps: int

    def tile(self, reps: int) -> FineInputs:
        """Repeat the batch ``reps`` times (record order: the whole batch, then again).

        A batch of one record keeps its one row, shared by the repeats (no copy).
        """
        values = self.values if self.values.shape[0] == 1 else np.tile(self.values, (reps, 1, 1))
        return FineInputs(values, self.lengths * reps, self.substeps)


def prepare_inputs(inputs: Sequence[np.ndarray], substeps: int, interpolation: str) -> FineInputs:
    """Interpolate input records onto the RK4 grid once.

    Parameters
    ----------
    inputs : sequence of ndarray, each shape (n_k, n_inputs)
        Input records [V].
    substeps : int
        RK4 steps per sample interval.
    interpolation : {"bandlimited", "linear"}
        See :func:`upsample_inputs`.

    Returns
    -------
    FineInputs

    Raises
    ------
    WorkflowError
        If the batch is empty or the interpolation unknown.
    """
    if not inputs:
        raise WorkflowError("nothing to simulate: no input records")
    lengths = [v.shape[0] for v in inputs]
    m = (max(lengths) - 1) * 2 * substeps + 1
    values = np.stack(
        [
            np.pad(
                upsample_inputs(v, 2 * substeps, interpolation),
                ((0, m - 1 - (v.shape[0] - 1) * 2 * substeps), (0, 0)),
                mode="edge",
            )
            for v in inputs
        ]
    )
    return FineInputs(values, lengths, int(substeps))


def substeps_needed(model: FreeRunModel, dt: float, substeps: int) -> int:
    """RK4 steps per sample interval a free run uses.

    Parameters
    ----------
    model : FreeRunModel
        The model (its ``max_step`` may ask for more steps).
    dt : float
        Sample time [s], positive.
    substeps : int
        Requested steps per sample interval, >= 1.

    Returns
    -------
    int
        ``max(substeps, ceil(dt / model.max_step()))``.

    References
    ----------
    Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (step size and stability).
    """
    return max(int(substeps), int(np.ceil(dt / model.max_step())))


def check_free_run(
    model: FreeRunModel,
    lengths: Sequence[int],
    n_inputs: int,
    dt: float,
    substeps: int,
    setting: str,
) -> int:
    """Refuse a free run whose fine input grid and trajectories exceed the memory budget.

    Parameters
    ----------
    model : FreeRunModel
        The model.
    lengths : sequence of int
        Samples of each record of the batch.
    n_inputs : int
        Inputs per record.
    dt : float
        Sample time [s].
    substeps : int
        Requested RK4 steps per sample interval.
    setting : str
        The workflow key to name, e.g. ``"[validate] substeps = 2"``.

    Returns
    -------
    int
        The sub-steps the free run will use (:func:`substeps_needed`).

    Raises
    ------
    ResourceError
        If :func:`debist.core.preflight.free_run_bytes` exceeds the budget, before any
        array is built.

    References
    ----------
    Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (classical RK4).
    """
    ns = substeps_needed(model, dt, substeps)
    if ns > substeps:
        setting += f" (the model's time constant needs {ns})"
    n = max(lengths) if len(lengths) else 0
    preflight.check_memory(
        preflight.free_run_bytes(lengths, n_inputs, model.n_states, ns),
        setting,
        f"the free run of {len(lengths)} record(s) of up to {n} samples with {ns} RK4 "
        "sub-steps per sample",
        "fine input grid and trajectories",
    )
    return ns


def simulate_batch(
    model: FreeRunModel,
    inputs: Sequence[np.ndarray] | FineInputs,
    dt: float,
    q0: np.ndarray,
    q_dot0: np.ndarray,
    *,
    substeps: int = 2,
    interpolation: str = "bandlimited",
    q_limit: float = np.inf,
    engine: str = "compiled",
    progress: Callable[[int, int], None] | None = None,
    x0: np.ndarray | None = None,
) -> BatchRun:
    """Simulate a batch of free runs driven by measured inputs, as arrays (:class:`BatchRun`).

    Parameters
    ----------
    model : FreeRunModel
        The model (e.g. :class:`debist.model.rbf.RBFModel`).
    inputs : sequence of ndarray, each shape (n_k, n_inputs), or FineInputs
        Input records [V] with sample time ``dt``, or already interpolated (:func:`prepare_inputs`).
    dt : float
        Sample time [s].
    q0, q_dot0 : ndarray, shape (B,)
        Initial position [unit of q] and velocity [unit/s] of each record.
    substeps : int, optional
        RK4 steps per sample interval (raised when the model's ``max_step`` requires it).
    interpolation, q_limit : {"bandlimited", "linear"}, float, optional
        Input interpolation (:func:`upsample_inputs`); bound on ``|q|`` beyond which a run stops.
    engine : {"compiled", "numpy"}, optional
        The compiled kernel (models with ``kernel_table`` or ``kernel_splines``) or the NumPy
        reference engine.
    progress : callable, optional
        ``progress(done, total)`` [samples] from the compiled engine; default the listener.
    x0 : ndarray, shape (B, n_states), optional
        Whole initial states; default ``model.initial_state(q0, q_dot0)``.

    Returns
    -------
    BatchRun
        The trajectories on one grid, masked after a divergence and beyond each length.

    Raises
    ------
    WorkflowError
        If ``dt`` or ``substeps`` is not positive, the batch is empty or the engine unknown.
    ResourceError
        If the fine input grid and trajectories would exceed the memory budget.

    References
    ----------
    Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (classical RK4).
    """
    if not dt > 0 or substeps < 1:
        raise WorkflowError(f"need dt > 0 and substeps >= 1, got dt={dt!r}, substeps={substeps!r}")
    if engine not in ENGINES:
        raise WorkflowError(f"`engine` must be one of {ENGINES}, got {engine!r}")
    if isinstance(inputs, FineInputs):
        ns = substeps_needed(model, dt, substeps)
        if inputs.substeps < ns:
            raise WorkflowError(
                f"prepared inputs have {inputs.substeps} sub-steps, the model needs {ns}"
            )
        prepared = inputs
    else:
        if not len(inputs):
            raise WorkflowError("nothing to simulate: no input records")
        lengths = [np.shape(v)[0] for v in inputs]
        ns = check_free_run(
            model, lengths, np.shape(inputs[0])[1], dt, substeps, f"substeps = {substeps}"
        )
        prepared = prepare_inputs(inputs, ns, interpolation)
    if progress is None:
        progress = _progress.reporter("free run")
    if x0 is None:
        x0 = model.initial_state(np.asarray(q0, float), np.asarray(q_dot0, float))
    x0 = np.atleast_2d(np.asarray(x0, dtype=float))
    if engine == "compiled" and (
        hasattr(model, "kernel_table") or hasattr(model, "kernel_splines")
    ):
        return _integrate_compiled(model, prepared, dt, x0, q_limit, progress)
    with np.errstate(over="ignore", invalid="ignore"):  # divergence is detected and reported below
        return _integrate(model, prepared, dt, x0, q_limit)


def simulate(
    model: FreeRunModel,
    inputs: Sequence[np.ndarray] | FineInputs,
    dt: float,
    q0: np.ndarray,
    q_dot0: np.ndarray,
    **options,
) -> list[SimulationResult]:
    """Simulate a model in free run, driven by measured inputs, from measured initial states.

    Parameters
    ----------
    model, inputs, dt, q0, q_dot0
        As :func:`simulate_batch`.
    **options
        The keyword options of :func:`simulate_batch`: ``substeps``, ``interpolation``,
        ``q_limit``, ``engine``, ``progress``, ``x0``.

    Returns
    -------
    list of SimulationResult
        One per record, each owning its arrays (length of its record).

    Raises
    ------
    WorkflowError, ResourceError
        As :func:`simulate_batch`.

    References
    ----------
    Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (classical RK4).
    """
    run = simulate_batch(model, inputs, dt, q0, q_dot0, **options)
    out = []
    for b, length in enumerate(run.lengths.tolist()):
        st = run.states[b, :length]
        d = int(run.diverged_at[b])
        out.append(
            SimulationResult(
                q=st[:, 0].copy(),
                q_dot=st[:, 1].copy(),
                q_ddot=run.acc[b, :length].copy(),
                states=st.copy(),
                diverged=d >= 0,
                diverged_at=d,
                substeps=run.substeps,
            )
        )
    return out


def _integrate_compiled(model, prepared, dt, x0, q_limit, progress):
    """Integrate with the compiled kernel over the prepared input grid (see :func:`simulate`)."""
    # here, not at the top: numba loads and compiles the kernel on first use only
    from debist.simulate.kernel import free_run, kernel_arrays

    lengths = np.asarray(prepared.lengths, dtype=np.int64)
    states, acc, dead = free_run(
        kernel_arrays(model), prepared.values, lengths, dt, prepared.substeps,
        x0, q_limit, progress,
    )  # fmt: skip
    return BatchRun(states, acc, dead, lengths, prepared.substeps)


def _integrate(model, prepared: FineInputs, dt, x0, q_limit) -> BatchRun:
    """Integrate with NumPy over the prepared input grid (see :func:`simulate`)."""
    ns = prepared.substeps
    h = dt / ns
    fine, lengths = prepared.values, prepared.lengths
    B, n = len(lengths), max(lengths)
    fine = np.broadcast_to(fine, (B, *fine.shape[1:]))  # one row may drive every trajectory
    x = x0
    states = np.full((B, n, model.n_states), np.nan)
    acc = np.full((B, n), np.nan)
    states[:, 0] = x
    alive = np.ones(B, dtype=bool)
    diverged_at = np.full(B, -1)
    project = getattr(model, "project", None)
    for k in range(n - 1):
        for s in range(ns):
            j = (k * ns + s) * 2
            k1, a1 = model.rhs(x, fine[:, j + rk4.INPUT_OFFSET[0]])
            if s == 0:
                acc[:, k] = a1
            k2, _ = model.rhs(rk4.stage_state(x, h, 1, k1), fine[:, j + rk4.INPUT_OFFSET[1]])
            k3, _ = model.rhs(rk4.stage_state(x, h, 2, k2), fine[:, j + rk4.INPUT_OFFSET[2]])
            k4, _ = model.rhs(rk4.stage_state(x, h, 3, k3), fine[:, j + rk4.INPUT_OFFSET[3]])
            x = rk4.advance(x, h, rk4.increment(k1, k2, k3, k4))
            if project is not None:  # the slip elements' catch-up step
                x = project(x)
        bad = alive & ~(np.isfinite(x).all(axis=1) & (np.abs(x[:, 0]) <= q_limit))
        if bad.any():
            diverged_at[bad] = k + 1
            alive &= ~bad
            x = np.where(alive[:, None], x, 0.0)
            if not alive.any():
                break
        states[alive, k + 1] = x[alive]
    _, a_last = model.rhs(np.nan_to_num(states[:, -1]), fine[:, -1])
    acc[:, -1] = np.where(alive, a_last, np.nan)
    return mask_batch(states, acc, diverged_at, lengths, ns)
