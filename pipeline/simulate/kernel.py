"""The compiled free-run kernel: one fixed-step RK4 for every model that is compared.

The scheme is exactly that of :func:`debist.simulate.freerun.simulate` (classical RK4 with
sub-steps, the inputs interpolated once onto the grid of half sub-steps, divergence when a
state is not finite or ``|q|`` exceeds the limit), compiled with numba (nopython, cached on
disk) and run on threads over the trajectories of a batch (records, windows, parameter
vectors; :func:`on_threads`).
Models hand it plain arrays: a term table with weights per trajectory
(:class:`debist.model.termtable.TableModel`: the RBF model of Eq. 37 with its backbone and
physics prior, the SINDy polynomials) or the tabulated curves of the analytical reduced model
(Eq. 26), so one kernel integrates them all and "the same simulator for every model" holds by
construction.

A batch of more trajectories than threads runs in lockstep blocks, one per thread
(:func:`_lockstep`): each right-hand side evaluates one basis, factor or term for the whole
block, so the table's structure is read once per block and the products vectorise, with each
trajectory's arithmetic in the order of the one-trajectory integrator (the same numbers).

Every model reaches the kernel as three flat arrays: floats ``fp``, integers ``ip`` and a
layout ``lay`` of sizes and offsets (:class:`KernelArrays`). The table model's right-hand
side and its gradient (:func:`_rhs_table`, :func:`_grad_table`) are compiled once as
functions of their own, called by the one-trajectory integrator and the sensitivity
integrator, which keeps the first compile short at the price of the reference counting of
their array arguments. The other helpers are inlined; a lockstep block calls its own
right-hand side once per stage for the whole block.

References
----------
Hairer, Norsett & Wanner, Solving Ordinary Differential Equations I, Sec. II.1 (classical
RK4); Lam, Pitrou & Seibert 2015, "Numba: a LLVM-based Python JIT compiler" (numba
documentation: ``njit``, ``cache=True``, ``nogil=True``).
"""

from __future__ import annotations

import hashlib
import inspect
import math
import weakref
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba as nb
import numpy as np

from debist.core.forking import usable_cores
from debist.core.jitcache import prepare_cache
from debist.model import basis, friction
from debist.simulate import rk4
from debist.simulate.batch import mask_batch

prepare_cache(__file__)  # before the first cache=True: a folder numba can write

__all__ = [
    "CHUNK",
    "KIND_SPLINE",
    "KIND_TABLE",
    "KernelArrays",
    "free_run",
    "free_run_sensitivity",
    "kernel_threads",
    "on_threads",
]

#: Model kinds of the kernel.
KIND_TABLE, KIND_SPLINE = 0, 1
#: Samples integrated per kernel call when progress is reported between calls.
CHUNK = 50_000

# Layout of a table model: sizes, flags, offsets into fp, offsets into ip (positions in lay).
(_K, _J, _U, _H, _NI, _QMAX, _BW, _BM, _BT, _G, _SQUARE, _LAG,
 _P_CENTRE, _P_WIDTH, _P_LO, _P_HI, _P_TQ, _P_TAB, _P_W, _P_MASS, _P_TZ, _P_VC,
 _I_BKIND, _I_BTAB, _I_GQPOW, _I_GSIDX, _I_SUNIQ, _I_GHIDX, _I_HUNIQ, _NG,
 _I_RUN, _P_GAUSS, _UNIFORM, _I_GPTR, _I_TK, _NT, _P_INVSTEP,
 _TABLES, _NC, _I_CBASE, _P_CRATE, _NS, _P_SWIDTH, _NA, _N_LAYOUT) = range(45)  # fmt: skip
#: Gaussian values below this are taken as 0 by the recurrence (no subnormal arithmetic).
_TINY = 1e-290
# Layout of a spline model.
_S_N, _S_P_X, _S_P_C, _S_P_RELAX, _S_P_KBAR, _S_N_LAYOUT = range(6)


#: The functions of other modules this one compiles, and the constants they read.
_COMPILED_FROM = (
    rk4.stage_state,
    rk4.increment,
    rk4.advance,
    basis.gaussian,
    friction.friction_state_rate,
    friction.creep_state_rate,
    friction.slip_state_rate,
    friction.slip_clip,
)
#: sha256 of their source (and of rk4's NODES and INPUT_OFFSET). numba's on-disk cache is
#: invalidated by a change of this file only, not of theirs: a change there must change this
#: line, and importing this module refuses to go on until it does (:func:`_check_compiled_from`).
COMPILED_FROM_SHA256 = "a1bb89891c204b33418c8a9736258533cb36e86820b3d3115559b8e34b00cb6d"


def _compiled_from_sha256() -> str:
    """sha256 over the source of :data:`_COMPILED_FROM` and rk4's tableau constants."""
    text = "\n".join(inspect.getsource(f) for f in _COMPILED_FROM)
    text += repr((rk4.NODES, rk4.INPUT_OFFSET))
    return hashlib.sha256(text.encode()).hexdigest()


def _check_compiled_from() -> None:
    """Refuse stale compiled code: see :data:`COMPILED_FROM_SHA256`.

    Raises
    ------
    ImportError
        If a compiled function of another module changed since this file recorded it.
    """
    found = _compiled_from_sha256()
    if found != COMPILED_FROM_SHA256:
        raise ImportError(
            "debist.simulate.kernel compiles functions of debist.simulate.rk4, "
            "debist.model.basis and debist.model.friction that changed; numba's cache would "
            "keep the old code. Set COMPILED_FROM_SHA256 in debist/simulate/kernel.py to "
            f"'{found}' (numba then recompiles the kernels)."
        )


_check_compiled_from()

#: The RK4 step of :mod:`debist.simulate.rk4`, compiled: every kernel path takes the NumPy
#: engine's step, operation for operation.
_stage_state = nb.njit(cache=True)(rk4.stage_state)
_increment = nb.njit(cache=True)(rk4.increment)
_advance = nb.njit(cache=True)(rk4.advance)
_INPUT_OFFSET = rk4.INPUT_OFFSET
#: The model's own functions, compiled: the basis of Eq. 38 and the state equations of the
#: friction state (Eq. 37) and the creep states (Eq. 26).
_gaussian = nb.njit(cache=True)(basis.gaussian)
_friction_rate = nb.njit(cache=True)(friction.friction_state_rate)
_creep_state_rate = nb.njit(cache=True)(friction.creep_state_rate)
#: The slip states' rate is ``q_dot * _slip_sticks(...)``, as ``friction.slip_state_rate``
#: composes it (numba cannot call that function's uncompiled helper).
_slip_sticks = nb.njit(cache=True)(friction.slip_sticks)
_slip_clip = nb.njit(cache=True)(friction.slip_clip)


@dataclass(frozen=True)
class KernelArrays:
    """A model as the kernel takes it.

    Attributes
    ----------
    kind : int
        :data:`KIND_TABLE` or :data:`KIND_SPLINE`.
    n_states : int
        State dimension (first two: q, q_dot).
    fp : ndarray of float64
        Every real parameter (bases, tables, weights, masses, T_z; or spline coefficients).
    ip : ndarray of int64
        Every integer parameter (basis kinds, term structure).
    lay : ndarray of int64
        Sizes and offsets into ``fp`` and ``ip``.
    n_work : int
        Scratch floats per trajectory.
    term_order : ndarray of int or None
        For a term table: the table's term index of each term as the kernel stores them
        (grouped by their factors).
    """

    kind: int
    n_states: int
    fp: np.ndarray
    ip: np.ndarray
    lay: np.ndarray
    n_work: int
    term_order: np.ndarray | None = None


class _Packer:
    def __init__(self) -> None:
        self.f: list[np.ndarray] = []
        self.i: list[np.ndarray] = []
        self.nf = 0
        self.ni = 0

    def floats(self, a) -> int:
        a = np.ascontiguousarray(a, dtype=np.float64).ravel()
        self.f.append(a)
        self.nf += a.size
        return self.nf - a.size

    def ints(self, a) -> int:
        a = np.ascontiguousarray(a, dtype=np.int64).ravel()
        self.i.append(a)
        self.ni += a.size
        return self.ni - a.size

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        fp = np.concatenate(self.f) if self.f else np.zeros(1)
        ip = np.concatenate(self.i) if self.i else np.zeros(1, np.int64)
        return (fp if fp.size else np.zeros(1)), (ip if ip.size else np.zeros(1, np.int64))


def table_arrays(model) -> KernelArrays:
    """Kernel arrays of a :class:`debist.model.termtable.TableModel`.

    The terms are grouped by their factors other than the basis (power of q, velocity factor,
    input monomial): the acceleration is then ``sum_g q^a_g S_g(s) H_g(h) sum_(j in g) w_j
    b_j(q)``, so each right-hand side evaluates every basis, velocity factor and monomial
    once, then one product per term and three per group. Inertia terms (``S_ACC``) form the
    last groups (their number in the layout): they add ``w_j 1/2 a_j q^(a_j-1) q_dot^2`` to
    the sum and take ``w_j q^a_j`` from the mass, and a table without them skips the
    division by m(q). The table's part of the arrays is
    built once per :class:`debist.model.termtable.TermTable` (the refinement changes only the
    weights, masses and T_z).

    Parameters
    ----------
    model : TableModel
        Term table, weights (B or 1, J), masses, T_z and whether the friction lag is used.

    Returns
    -------
    KernelArrays
    """
    fixed = _TABLE_PARTS.get(model.table)
    if fixed is None:
        fixed = _TABLE_PARTS[model.table] = _table_part(model.table)
    fp_t, ip, lay_t, order, n_work = fixed
    lay = lay_t.copy()
    lay[_BW], lay[_BM], lay[_BT] = model.weights.shape[0], model.mass.size, model.T_z.size
    lay[_LAG] = int(model.lag)
    weights = np.ascontiguousarray(model.weights[:, order], dtype=np.float64)
    lay[_P_W] = fp_t.size
    lay[_P_MASS] = lay[_P_W] + weights.size
    lay[_P_TZ] = lay[_P_MASS] + model.mass.size
    parts = [fp_t, weights.ravel(), np.ravel(model.mass), np.ravel(model.T_z)]
    fp = np.concatenate(parts, dtype=np.float64)
    return KernelArrays(KIND_TABLE, model.n_states, fp, ip, lay, n_work, order)


#: The table's part of the kernel arrays, per term table (weakly: dropped with the table).
_TABLE_PARTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _table_part(t) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """Floats, integers, layout, term order and scratch size of a term table's structure."""
    n_in = t.n_inputs
    s_codes = np.stack([t.term_skind, t.term_spow], axis=1).reshape(-1, 2)
    s_unique, s_index = np.unique(s_codes, axis=0, return_inverse=True)
    h_unique, h_index = np.unique(t.term_hpow.reshape(-1, n_in), axis=0, return_inverse=True)
    keys = np.stack([t.term_qpow, s_index.reshape(-1), h_index.reshape(-1)], axis=1)
    groups, g_index = np.unique(keys.reshape(-1, 3), axis=0, return_inverse=True)
    K, G = t.base_kind.size, len(groups)
    # the inertia groups (their own s-code) go last: the right-hand sides take them apart
    inertia = s_unique[groups[:, 1], 0] == 4 if G else np.zeros(0, dtype=bool)  # S_ACC
    acc_terms = t.term_skind == 4
    if np.any(t.base_kind[t.term_base[acc_terms]] != 0) or np.any(t.term_qpow[acc_terms] < 1):
        raise ValueError("an inertia term has the constant basis and a power of q >= 1")
    if np.any(t.term_hpow.reshape(-1, n_in)[acc_terms] != 0):
        raise ValueError("an inertia term has no input powers")
    perm = np.argsort(inertia, kind="stable")
    groups = groups[perm]
    g_index = np.argsort(perm)[g_index.reshape(-1)]
    order = np.argsort(g_index.reshape(-1), kind="stable")  # terms group by group
    g_ptr = np.searchsorted(g_index.reshape(-1)[order], np.arange(G + 1))
    tables = t.tables if t.tables.size else np.zeros((1, t.table_q.size))
    pack = _Packer()
    lay = np.zeros(_N_LAYOUT, dtype=np.int64)
    lay[_K], lay[_J], lay[_U], lay[_H], lay[_NI] = K, t.n_terms, len(s_unique), len(h_unique), n_in
    lay[_NG] = G
    lay[_NA] = int(np.count_nonzero(inertia))
    lay[_QMAX] = int(t.term_qpow.max()) if t.n_terms else 0
    lay[_G] = t.table_q.size
    lay[_SQUARE] = int(t.squares_inputs)
    lay[_P_CENTRE] = pack.floats(t.base_centre)
    lay[_P_WIDTH] = pack.floats(t.base_width)
    lay[_P_LO] = pack.floats(t.base_lo)
    lay[_P_HI] = pack.floats(t.base_hi)
    lay[_P_TQ] = pack.floats(t.table_q)
    lay[_P_VC] = pack.floats([t.coulomb_velocity])
    lay[_I_BKIND] = pack.ints(t.base_kind)
    lay[_I_BTAB] = pack.ints(t.base_table)
    lay[_I_GQPOW] = pack.ints(groups[:, 0] if G else [0])
    lay[_I_GSIDX] = pack.ints(groups[:, 1] if G else [0])
    lay[_I_SUNIQ] = pack.ints(s_unique)
    lay[_I_GHIDX] = pack.ints(groups[:, 2] if G else [0])
    lay[_I_HUNIQ] = pack.ints(h_unique)
    lay[_I_GPTR] = pack.ints(g_ptr)
    lay[_I_TK] = pack.ints(t.term_base[order])
    run, spacing = _gauss_runs(t)
    lay[_I_RUN] = pack.ints(run)
    lay[_P_GAUSS] = pack.floats(_run_constants(t.base_width, spacing, run))
    grid = t.table_q
    step = (grid[-1] - grid[0]) / max(grid.size - 1, 1)
    regular = grid[0] + step * np.arange(grid.size)
    lay[_UNIFORM] = int(grid.size > 1 and np.allclose(grid, regular, rtol=0, atol=1e-9 * step))
    lay[_P_INVSTEP] = pack.floats([1.0 / step if step > 0 else 0.0])
    # per grid point: every table's value, then the slope of every table on the interval that
    # starts there (as numpy.interp computes it), so one interpolation reads one cache line
    T = tables.shape[0]
    rows = np.zeros((grid.size, 2 * T))
    rows[:, :T] = tables.T
    if grid.size > 1:
        rows[:-1, T:] = (np.diff(tables, axis=1) / np.diff(grid)).T
    lay[_NT] = T
    lay[_TABLES] = int(np.any(t.base_kind == 2))
    lay[_P_TAB] = pack.floats(rows)
    # creep states w_k' = b_(creep_base[k])(q) q_dot - lambda w_k (Eq. 26), after q, q_dot, z
    lay[_NC] = t.n_creep
    lay[_I_CBASE] = pack.ints(t.creep_base if t.n_creep else [0])
    lay[_P_CRATE] = pack.floats([t.creep_rate])
    # slip states delta_e' = slip_state_rate(q_dot, delta_e, Delta_e), after the creep states
    lay[_NS] = t.n_slip
    lay[_P_SWIDTH] = pack.floats(t.slip_width if t.n_slip else [1.0])
    fp, ip = pack.arrays()
    n_work = int(K + n_in + lay[_QMAX] + 1 + lay[_U] + lay[_H])
    return fp, ip, lay, order, n_work


def _run_constants(width: np.ndarray, spacing: np.ndarray, run: np.ndarray) -> np.ndarray:
    """Per basis: 1 / sigma, delta = spacing / sigma, 1 / delta, exp(-delta^2) of its run.

    Computed once here, as the kernel computed them at every right-hand side (IEEE division,
    the C library's ``exp``): the same numbers. Zeros for a basis that starts no run.
    """
    out = np.zeros((width.size, 4))
    for k in np.flatnonzero(run > 1):
        sigma, d = float(width[k]), float(spacing[k])
        delta = d / sigma
        out[k] = 1.0 / sigma, delta, sigma / d, math.exp(-delta * delta)
    return out


def _continues(t, k: int, n: int, spacing: float) -> bool:
    """Whether basis k + n continues the run of Gaussians that starts at basis k."""
    nxt, prev = k + n, k + n - 1
    if t.base_kind[nxt] != 1 or t.base_centre[nxt] <= t.base_centre[prev]:
        return False
    if any(a[nxt] != a[k] for a in (t.base_width, t.base_lo, t.base_hi)):
        return False
    step = t.base_centre[nxt] - t.base_centre[prev]
    return n == 1 or bool(np.isclose(step, spacing, rtol=1e-12, atol=0.0))


def _gauss_runs(t) -> tuple[np.ndarray, np.ndarray]:
    """Find the runs of equidistant Gaussian bases (same width and clipping) for the recurrence.

    Returns ``run`` (per basis: the run's length at its first basis, 0 inside a run, 1 for a
    basis on its own) and ``spacing`` (per basis: the centre spacing of its run).
    """
    K = t.base_kind.size
    run = np.ones(K, dtype=np.int64)
    spacing = np.zeros(K)
    k = 0
    while k < K:
        n = 1
        if t.base_kind[k] == 1:
            while k + n < K and _continues(t, k, n, spacing[k]):
                if n == 1:
                    spacing[k] = t.base_centre[k + 1] - t.base_centre[k]
                n += 1
        run[k] = n
        run[k + 1 : k + n] = 0
        k += n
    return run, spacing


def spline_arrays(x: np.ndarray, c: np.ndarray, relax: float, kbar: float) -> KernelArrays:
    """Kernel arrays of the analytical reduced model (Eq. 26) on its cubic splines.

    Parameters
    ----------
    x : ndarray, shape (n,)
        Breakpoints [m].
    c : ndarray, shape (4, n - 1, 8)
        Piecewise-cubic coefficients (highest power first, as
        :class:`scipy.interpolate.CubicSpline` stores them) of ``m_q, dm_q/dq, d, f, g1, g2,
        k1, k2``.
    relax : float
        Relaxation rate of the Maxwell elements ``Y_MW / eta_MW`` [1/s].
    kbar : float
        ``V_DE Y_MW`` [J].

    Returns
    -------
    KernelArrays

    References
    ----------
    Masoud & Maas 2025, Eq. 26.
    """
    if np.shape(c)[2] != 8 or np.shape(c)[0] != 4:
        raise ValueError(f"`c` must have shape (4, n - 1, 8), got {np.shape(c)}")
    pack = _Packer()
    lay = np.zeros(_S_N_LAYOUT, dtype=np.int64)
    lay[_S_N] = np.size(x)
    lay[_S_P_X] = pack.floats(x)
    lay[_S_P_C] = pack.floats(np.transpose(c, (1, 2, 0)))  # [interval, curve, power]
    lay[_S_P_RELAX] = pack.floats([relax])
    lay[_S_P_KBAR] = pack.floats([kbar])
    fp, ip = pack.arrays()
    return KernelArrays(KIND_SPLINE, 4, fp, ip, lay, 8)


def kernel_arrays(model) -> KernelArrays:
    """Kernel arrays of any model the compiled engine runs.

    Parameters
    ----------
    model : object
        A model with ``kernel_table`` (a :class:`debist.model.termtable.TableModel`: the RBF
        and SINDy models, a term table itself) or ``kernel_splines()`` (the analytical reduced
        model of :mod:`debist.physics.freerun`).

    Returns
    -------
    KernelArrays

    Raises
    ------
    TypeError
        If the model has neither.
    """
    splines = getattr(model, "kernel_splines", None)
    if splines is not None:
        return spline_arrays(*splines())
    if not hasattr(model, "kernel_table"):
        raise TypeError(f"{type(model).__name__} has no compiled form")
    return table_arrays(model.kernel_table)


# ------------------------------------------------------------------------------ right-hand sides


@nb.njit(cache=True, inline="always")
def _gauss_constants(fp, lay, k0):  # pragma: no cover - compiled
    """Read a run's clipping bounds, first centre and :func:`_run_constants`."""
    g = lay[_P_GAUSS] + 4 * k0
    return (fp[lay[_P_LO] + k0], fp[lay[_P_HI] + k0], fp[lay[_P_CENTRE] + k0], fp[g],
            fp[g + 1], fp[g + 2], fp[g + 3])  # fmt: skip


@nb.njit(cache=True, inline="always")
def _gauss_nearest(q, lo, hi, centre, inv_sigma, delta, inv_delta, n):  # pragma: no cover
    """Start the recurrence of :func:`_gauss_run` at the centre m nearest to q (clipped).

    Returns m, phi_m and the first upward ratio.
    """
    qc = q if q > lo else lo
    qc = qc if qc < hi else hi
    u = (qc - centre) * inv_sigma
    m = math.floor(u * inv_delta + 0.5)
    m = 0 if m < 0 else (n - 1 if m > n - 1 else m)
    du = u - m * delta
    return m, math.exp(-0.5 * du * du), math.exp(delta * du - 0.5 * delta * delta)


@nb.njit(cache=True, inline="always")
def _gauss_run(q, fp, lay, W, w_k, k0, n):  # pragma: no cover - compiled
    """phi_k = exp(-(q - xi_k)^2 / (2 sigma^2)) of n equidistant centres by recurrence.

    From the centre m nearest to q, phi_{k+1} = phi_k r_k with r_{k+1} = r_k exp(-delta^2)
    (delta = spacing / sigma), and likewise downwards (the first ratio downwards is
    exp(-delta^2) / r_m): two exponentials for the whole run (exp(-delta^2) is one of the
    run's constants, :func:`_run_constants`).
    """
    lo, hi, centre, inv_sigma, delta, inv_delta, step = _gauss_constants(fp, lay, k0)
    m, p, r_up = _gauss_nearest(q, lo, hi, centre, inv_sigma, delta, inv_delta, n)
    W[w_k + k0 + m] = p
    r = r_up
    pk = p
    for k in range(m + 1, n):
        pk = pk * r if pk > _TINY else 0.0
        W[w_k + k0 + k] = pk
        r *= step
    r = step / r_up  # exp(-delta du - delta^2 / 2)
    pk = p
    for k in range(m - 1, -1, -1):
        pk = pk * r if pk > _TINY else 0.0
        W[w_k + k0 + k] = pk
        r *= step


@nb.njit(cache=True, inline="always")
def _table_interval(q, fp, lay):  # pragma: no cover - compiled
    """Interval i of the table grid with grid[i] <= q < grid[i + 1] (q inside the grid)."""
    GQ = lay[_G]
    tq = lay[_P_TQ]
    if lay[_UNIFORM] == 1:  # the nearest guess, then corrected: the exact interval
        i = int((q - fp[tq]) * fp[lay[_P_INVSTEP]])
        i = 0 if i < 0 else (GQ - 2 if i > GQ - 2 else i)
        if q < fp[tq + i]:
            i -= 1
        elif q >= fp[tq + i + 1]:
            i += 1
        return i
    lo_i = 0
    hi_i = GQ - 1
    while hi_i - lo_i > 1:  # fp[tq + lo_i] <= q < fp[tq + hi_i]
        mid = (lo_i + hi_i) // 2
        if fp[tq + mid] <= q:
            lo_i = mid
        else:
            hi_i = mid
    return lo_i


# The right-hand sides and their gradient allocate nothing and compile without numba's
# reference counting (``_nrt=False``): the caller owns every array they read, and the atomic
# increments and decrements around each array alias in their branchy loops, which numba's
# pruning pass cannot remove, cost a quarter of a right-hand side (numba issue #2350).
@nb.njit(cache=True, _nrt=False)
def _rhs_table(x, fine, b, j, d, row, fp, ip, lay, W):  # pragma: no cover - compiled
    # Offsets are read into locals once: stores into W could alias lay for the compiler.
    K, U, H, NI, QMAX, G = lay[_K], lay[_U], lay[_H], lay[_NI], lay[_QMAX], lay[_NG]
    o_kind, o_run, o_tab_row = lay[_I_BKIND], lay[_I_RUN], lay[_I_BTAB]
    o_lo, o_hi, o_centre, o_width = lay[_P_LO], lay[_P_HI], lay[_P_CENTRE], lay[_P_WIDTH]
    o_sun, o_hun, o_gq, o_gs, o_gh = (
        lay[_I_SUNIQ],
        lay[_I_HUNIQ],
        lay[_I_GQPOW],
        lay[_I_GSIDX],
        lay[_I_GHIDX],
    )
    GQ, tq, o_tab, NT = lay[_G], lay[_P_TQ], lay[_P_TAB], lay[_NT]
    w_k, w_hv = 0, K
    w_qp = w_hv + NI
    w_sf = w_qp + QMAX + 1
    w_hm = w_sf + U
    tz = fp[lay[_P_TZ] + (b if lay[_BT] > 1 else 0)]
    lag = lay[_LAG] == 1
    c0 = 3 if lag else 2  # first creep state
    q = x[0]
    q_dot = x[1]
    s = x[2] if lag and tz > 0.0 else q_dot
    t_i = -1
    for k in range(K):
        kind = ip[o_kind + k]
        run = ip[o_run + k]
        if kind == 0:
            W[w_k + k] = 1.0
        elif kind == 1:
            if run > 1:
                _gauss_run(q, fp, lay, W, w_k, k, run)
            elif run == 1:
                lo = fp[o_lo + k]
                hi = fp[o_hi + k]
                qc = q if q > lo else lo
                qc = qc if qc < hi else hi
                dq = qc - fp[o_centre + k]
                wk = fp[o_width + k]
                W[w_k + k] = _gaussian(dq, wk)
        else:  # tabulated: linear interpolation, held outside (numpy.interp)
            tab = o_tab + ip[o_tab_row + k]
            if q <= fp[tq]:
                W[w_k + k] = fp[tab]
            elif q >= fp[tq + GQ - 1]:
                W[w_k + k] = fp[tab + (GQ - 1) * 2 * NT]
            else:
                if t_i < 0:  # one interval for all tables (one grid)
                    t_i = _table_interval(q, fp, lay)
                at = tab + t_i * 2 * NT
                W[w_k + k] = fp[at + NT] * (q - fp[tq + t_i]) + fp[at]
    W[w_qp] = 1.0
    for a in range(1, QMAX + 1):
        W[w_qp + a] = W[w_qp + a - 1] * q
    vc = fp[lay[_P_VC]]
    for u in range(U):
        skind = ip[o_sun + 2 * u]
        if skind == 2:
            W[w_sf + u] = math.tanh(s / vc)
        elif skind == 3:  # creep state w_k, k in the power's place
            W[w_sf + u] = x[c0 + ip[o_sun + 2 * u + 1]]
        else:
            val = 1.0
            if skind == 1:
                for _ in range(ip[o_sun + 2 * u + 1]):
                    val *= s
            W[w_sf + u] = val
    square = lay[_SQUARE] == 1
    fb = b if fine.shape[0] > 1 else 0  # one input row may drive every trajectory
    for i in range(NI):
        vi = fine[fb, j, i]
        W[w_hv + i] = vi * vi if square else vi
    for u in range(H):
        val = 1.0
        for i in range(NI):
            for _ in range(ip[o_hun + u * NI + i]):
                val *= W[w_hv + i]
        W[w_hm + u] = val
    acc = 0.0
    w0 = lay[_P_W] + (b if lay[_BW] > 1 else 0) * lay[_J]
    o_ptr, o_tk = lay[_I_GPTR], lay[_I_TK]
    NA = lay[_NA]
    for g in range(G - NA):
        inner = 0.0
        for m in range(ip[o_ptr + g], ip[o_ptr + g + 1]):
            inner += fp[w0 + m] * W[w_k + ip[o_tk + m]]
        acc += inner * (W[w_qp + ip[o_gq + g]] * W[w_sf + ip[o_gs + g]] * W[w_hm + ip[o_gh + g]])
    if NA > 0:  # inertia groups: m(q) = m - sum w q^a, force sum w 1/2 a q^(a-1) q_dot^2
        part = 0.0
        for g in range(G - NA, G):
            inner = 0.0
            for m in range(ip[o_ptr + g], ip[o_ptr + g + 1]):
                inner += fp[w0 + m] * W[w_k + ip[o_tk + m]]
            a = ip[o_gq + g]
            acc += inner * (0.5 * a * W[w_qp + a - 1] * q_dot * q_dot)
            part += inner * W[w_qp + a]
        acc /= fp[lay[_P_MASS] + (b if lay[_BM] > 1 else 0)] - part
    else:
        acc /= fp[lay[_P_MASS] + (b if lay[_BM] > 1 else 0)]
    d[row, 0] = q_dot
    d[row, 1] = acc
    if lag:
        d[row, 2] = _friction_rate(q_dot, x[2], tz) if tz > 0.0 else 0.0
    rate = fp[lay[_P_CRATE]]
    o_cb = lay[_I_CBASE]
    for i in range(lay[_NC]):
        d[row, c0 + i] = _creep_state_rate(W[w_k + ip[o_cb + i]], q_dot, rate, x[c0 + i])
    c1 = c0 + lay[_NC]
    o_sw = lay[_P_SWIDTH]
    for e in range(lay[_NS]):
        d[row, c1 + e] = q_dot * _slip_sticks(q_dot, x[c1 + e], fp[o_sw + e])
    return acc


@nb.njit(cache=True, inline="always")
def _project_table(x, lay, fp):  # pragma: no cover - compiled
    """Hold the slip states to their break-away range after a step (the stop operator)."""
    c1 = (3 if lay[_LAG] == 1 else 2) + lay[_NC]
    o_sw = lay[_P_SWIDTH]
    for e in range(lay[_NS]):
        x[c1 + e] = _slip_clip(x[c1 + e], fp[o_sw + e])


@nb.njit(cache=True, _nrt=False)
def _grad_table(x, b, fp, ip, lay, W, V, tv, ae, acc):  # pragma: no cover - compiled
    """Differentiate the table model's acceleration ``acc``, after :func:`_rhs_table` filled W.

    Returns d acc / d q, d acc / d s, d acc / d q_dot through the inertia terms' force and
    the mass m(q) (m without inertia terms); fills ``tv`` with d acc / d w_j (a term's value
    over m(q); an inertia term's ``(1/2 a q^(a-1) q_dot^2 + acc q^a) / m(q)``), in the
    kernel's term order, and ``ae`` with d acc / d x_(c0 + k) for the creep and slip states
    k. ``V`` is scratch whose first K entries are left holding the basis derivatives (then
    derivatives of the q powers and velocity factors).
    """
    K, U, NI, QMAX, G = lay[_K], lay[_U], lay[_NI], lay[_QMAX], lay[_NG]
    w_k, w_hv = 0, K
    w_qp = w_hv + NI
    w_sf = w_qp + QMAX + 1
    w_hm = w_sf + U
    v_qp = K
    v_sf = v_qp + QMAX + 1
    tz = fp[lay[_P_TZ] + (b if lay[_BT] > 1 else 0)]
    lag = lay[_LAG] == 1
    q = x[0]
    s = x[2] if lag and tz > 0.0 else x[1]
    GQ, tq, o_tab = lay[_G], lay[_P_TQ], lay[_P_TAB]
    for k in range(K):
        kind = ip[lay[_I_BKIND] + k]
        V[k] = 0.0
        if kind == 1:
            lo = fp[lay[_P_LO] + k]
            hi = fp[lay[_P_HI] + k]
            if lo < q < hi:
                wk = fp[lay[_P_WIDTH] + k]
                V[k] = -(q - fp[lay[_P_CENTRE] + k]) / (wk * wk) * W[w_k + k]
        elif kind == 2 and fp[tq] < q < fp[tq + GQ - 1]:
            i = _table_interval(q, fp, lay)
            NT = lay[_NT]
            V[k] = fp[o_tab + i * 2 * NT + NT + ip[lay[_I_BTAB] + k]]
    V[v_qp] = 0.0
    for a in range(1, QMAX + 1):
        V[v_qp + a] = a * W[w_qp + a - 1]
    vc = fp[lay[_P_VC]]
    for u in range(U):
        skind = ip[lay[_I_SUNIQ] + 2 * u]
        power = ip[lay[_I_SUNIQ] + 2 * u + 1]
        if skind == 2:
            th = W[w_sf + u]
            V[v_sf + u] = (1.0 - th * th) / vc
        elif skind == 1 and power > 0:
            val = float(power)
            for _ in range(power - 1):
                val *= s
            V[v_sf + u] = val
        else:
            V[v_sf + u] = 0.0
    mass = fp[lay[_P_MASS] + (b if lay[_BM] > 1 else 0)]
    w0 = lay[_P_W] + (b if lay[_BW] > 1 else 0) * lay[_J]
    o_ptr, o_tk = lay[_I_GPTR], lay[_I_TK]
    NA = lay[_NA]
    dq = 0.0
    ds = 0.0
    dv = 0.0
    if NA > 0:  # m(q) as _rhs_table forms it, then the inertia groups' derivatives
        part = 0.0
        for g in range(G - NA, G):
            inner = 0.0
            for m in range(ip[o_ptr + g], ip[o_ptr + g + 1]):
                inner += fp[w0 + m] * W[w_k + ip[o_tk + m]]
            part += inner * W[w_qp + ip[lay[_I_GQPOW] + g]]
        mass = mass - part
        q_dot = x[1]
        for g in range(G - NA, G):
            a_g = ip[lay[_I_GQPOW] + g]
            fm = V[v_qp + a_g]  # d q^a / d q = a q^(a-1)
            col = 0.5 * fm * q_dot * q_dot + acc * W[w_qp + a_g]
            inner = 0.0
            for m in range(ip[o_ptr + g], ip[o_ptr + g + 1]):
                k = ip[o_tk + m]
                inner += fp[w0 + m] * W[w_k + k]
                tv[m] = W[w_k + k] * col / mass
            dq += inner * (0.5 * a_g * V[v_qp + a_g - 1] * q_dot * q_dot + acc * fm)
            dv += inner * fm * q_dot
    for k in range(lay[_NC] + lay[_NS]):
        ae[k] = 0.0
    for g in range(G - NA):
        a_g = ip[lay[_I_GQPOW] + g]
        s_g = ip[lay[_I_GSIDX] + g]
        fq, fqd = W[w_qp + a_g], V[v_qp + a_g]
        fs, fsd = W[w_sf + s_g], V[v_sf + s_g]
        fh = W[w_hm + ip[lay[_I_GHIDX] + g]]
        inner = 0.0
        innerd = 0.0
        for m in range(ip[o_ptr + g], ip[o_ptr + g + 1]):
            k = ip[o_tk + m]
            inner += fp[w0 + m] * W[w_k + k]
            innerd += fp[w0 + m] * V[k]
            tv[m] = W[w_k + k] * fq * fs * fh / mass
        dq += (innerd * fq + inner * fqd) * fs * fh
        ds += inner * fq * fsd * fh
        if ip[lay[_I_SUNIQ] + 2 * s_g] == 3:  # the factor is the extra state x_(c0 + k)
            ae[ip[lay[_I_SUNIQ] + 2 * s_g + 1]] += inner * fq * fh / mass
    return dq / mass, ds / mass, dv / mass, mass


@nb.njit(cache=True, inline="always")
def _rhs_spline(x, fine, b, j, d, row, fp, lay, W):  # pragma: no cover - compiled
    n = lay[_S_N]
    px = lay[_S_P_X]
    q = x[0]
    lo_i = 0
    hi_i = n - 1
    if q < fp[px]:
        hi_i = 1
    elif q >= fp[px + n - 1]:
        lo_i = n - 2
    else:
        while hi_i - lo_i > 1:  # the interval of q, as scipy's PPoly finds it
            mid = (lo_i + hi_i) // 2
            if fp[px + mid] <= q:
                lo_i = mid
            else:
                hi_i = mid
    s = q - fp[px + lo_i]
    base = lay[_S_P_C] + lo_i * 32
    for m in range(8):  # sum_k c[k] s^(3-k), from the constant term on, as PPoly does
        res = 0.0
        z = 1.0
        for kp in range(4):
            res += fp[base + m * 4 + 3 - kp] * z
            z *= s
        W[m] = res
    relax = fp[lay[_S_P_RELAX]]
    kbar = fp[lay[_S_P_KBAR]]
    qd = x[1]
    fb = b if fine.shape[0] > 1 else 0  # one input row may drive every trajectory
    v1 = fine[fb, j, 0]
    v2 = fine[fb, j, 1]
    force = W[4] * v1**2 + W[5] * v2**2
    force -= 0.5 * W[1] * qd * qd + W[2] * qd + W[3] + kbar * (W[6] * x[2] + W[7] * x[3])
    acc = force / W[0]
    d[row, 0] = qd
    d[row, 1] = acc
    d[row, 2] = W[6] * qd - relax * x[2]
    d[row, 3] = W[7] * qd - relax * x[3]
    return acc


# ---------------------------------------------------------------------------------- the kernel


@nb.njit(cache=True, inline="always")
def _trajectory(
    kind, fp, ip, lay, n_work, fine, lengths, h, ns, q_limit, k0, k1, states, acc, dead, b
):  # pragma: no cover - compiled
    """RK4 steps k0 .. k1 - 1 of trajectory b (at its last sample: the acceleration only)."""
    S = states.shape[2]
    L = lengths[b]
    if dead[b] >= 0 or k0 >= L:
        return  # diverged, or finished in an earlier chunk
    x = states[b, k0].copy()
    xt = np.empty(S)
    d = np.empty((4, S))
    W = np.empty(max(n_work, 8))
    for k in range(k0, min(k1, L)):
        last = k == L - 1
        for s in range(1 if last else ns):
            j = (k * ns + s) * 2
            for stage in range(1 if last else 4):
                for i in range(S):
                    xt[i] = x[i] if stage == 0 else _stage_state(x[i], h, stage, d[stage - 1, i])
                js = j + _INPUT_OFFSET[stage]
                if kind == 0:
                    a = _rhs_table(xt, fine, b, js, d, stage, fp, ip, lay, W)
                else:
                    a = _rhs_spline(xt, fine, b, js, d, stage, fp, lay, W)
                if stage == 0 and s == 0:
                    acc[b, k] = a
            if not last:
                for i in range(S):
                    x[i] = _advance(x[i], h, _increment(d[0, i], d[1, i], d[2, i], d[3, i]))
                if kind == 0:
                    _project_table(x, lay, fp)
        if last:
            break
        ok = abs(x[0]) <= q_limit
        for i in range(S):
            ok = ok and math.isfinite(x[i])
        if not ok:
            dead[b] = k + 1
            break
        for i in range(S):
            states[b, k + 1, i] = x[i]


@nb.njit(cache=True, nogil=True)
def _integrate(
    kind, fp, ip, lay, n_work, fine, lengths, h, ns, q_limit, k0, k1, states, acc, dead, bidx
):  # pragma: no cover - compiled
    """Integrate the trajectories ``bidx`` in turn, without the GIL (one call per thread)."""
    for c in range(bidx.size):
        _trajectory(kind, fp, ip, lay, n_work, fine, lengths, h, ns, q_limit, k0, k1, states,
                    acc, dead, bidx[c])  # fmt: skip


# ------------------------------------------------------------- lockstep batches of one table model


@nb.njit(cache=True, _nrt=False)
def _bases_lock(XT, fp, ip, lay, Wk, Ti, Tq, nb_):  # pragma: no cover - compiled
    """Every basis of the table at the q of each trajectory of a lockstep block (W[k, c])."""
    K = lay[_K]
    GQ, tq, o_tab = lay[_G], lay[_P_TQ], lay[_P_TAB]
    o_kind, o_run = lay[_I_BKIND], lay[_I_RUN]
    if lay[_TABLES] == 1:  # one interval for all tables (one grid); -1 below it, -2 above
        q_first, q_last = fp[tq], fp[tq + GQ - 1]
        for c in range(nb_):
            q = XT[0, c]
            if q <= q_first:
                Ti[c] = -1
            elif q >= q_last:
                Ti[c] = -2
            else:
                i = _table_interval(q, fp, lay)
                Ti[c] = i
                Tq[c] = q - fp[tq + i]
    for k in range(K):
        kind = ip[o_kind + k]
        run = ip[o_run + k]
        if kind == 0:
            for c in range(nb_):
                Wk[k, c] = 1.0
        elif kind == 1 and run > 1:
            lo, hi, centre, inv_sigma, delta, inv_delta, step = _gauss_constants(fp, lay, k)
            for c in range(nb_):  # the recurrence of _gauss_run, per trajectory
                m, p, r_up = _gauss_nearest(XT[0, c], lo, hi, centre, inv_sigma, delta, inv_delta,
                                            run)  # fmt: skip
                Wk[k + m, c] = p
                r = r_up
                pk = p
                for i in range(m + 1, run):
                    pk = pk * r if pk > _TINY else 0.0
                    Wk[k + i, c] = pk
                    r *= step
                r = step / r_up
                pk = p
                for i in range(m - 1, -1, -1):
                    pk = pk * r if pk > _TINY else 0.0
                    Wk[k + i, c] = pk
                    r *= step
        elif kind == 1 and run == 1:
            lo, hi = fp[lay[_P_LO] + k], fp[lay[_P_HI] + k]
            centre, wk = fp[lay[_P_CENTRE] + k], fp[lay[_P_WIDTH] + k]
            for c in range(nb_):
                q = XT[0, c]
                qc = q if q > lo else lo
                qc = qc if qc < hi else hi
                dq = qc - centre
                Wk[k, c] = _gaussian(dq, wk)
        elif kind == 2:  # tabulated: linear interpolation, held outside (numpy.interp)
            NT = lay[_NT]
            tab = o_tab + ip[lay[_I_BTAB] + k]
            y_first, y_last = fp[tab], fp[tab + (GQ - 1) * 2 * NT]
            for c in range(nb_):
                t_i = Ti[c]
                if t_i >= 0:
                    at = tab + t_i * 2 * NT
                    Wk[k, c] = fp[at + NT] * Tq[c] + fp[at]
                else:
                    Wk[k, c] = y_first if t_i == -1 else y_last


@nb.njit(cache=True, _nrt=False)
def _rhs_table_lock(
    XT, fine, frow, nb_, js, D, row, fp, ip, lay, work, Ti, wts, mass, tz
):  # pragma: no cover - compiled
    """:func:`_rhs_table` for a block of trajectories at once (rows of ``work`` over the block).

    ``frow[c]`` is the row of ``fine`` that drives trajectory ``c`` of the block.

    Every loop over the block runs one term, basis or factor for all trajectories, so the
    table's structure is read once per block and the products vectorise; the arithmetic of
    each trajectory is that of :func:`_rhs_table`, in the same order (the same numbers).
    """
    K, U, H, NI, QMAX, G = lay[_K], lay[_U], lay[_H], lay[_NI], lay[_QMAX], lay[_NG]
    w_hv = K
    w_qp = w_hv + NI
    w_sf = w_qp + QMAX + 1
    w_hm = w_sf + U
    w_s = w_hm + H
    w_in = w_s + 1
    w_acc = w_in + 1
    w_tq = w_acc + 1
    w_part = w_tq + 1
    lag = lay[_LAG] == 1
    c0 = 3 if lag else 2  # first creep state
    for c in range(nb_):
        work[w_s, c] = XT[2, c] if lag and tz[c] > 0.0 else XT[1, c]
    _bases_lock(XT, fp, ip, lay, work, Ti, work[w_tq], nb_)
    for c in range(nb_):
        work[w_qp, c] = 1.0
    for a in range(1, QMAX + 1):
        for c in range(nb_):
            work[w_qp + a, c] = work[w_qp + a - 1, c] * XT[0, c]
    vc = fp[lay[_P_VC]]
    o_sun = lay[_I_SUNIQ]
    for u in range(U):
        skind = ip[o_sun + 2 * u]
        if skind == 2:
            for c in range(nb_):
                work[w_sf + u, c] = math.tanh(work[w_s, c] / vc)
        elif skind == 3:  # creep state w_k, k in the power's place
            r_w = c0 + ip[o_sun + 2 * u + 1]
            for c in range(nb_):
                work[w_sf + u, c] = XT[r_w, c]
        else:
            for c in range(nb_):
                work[w_sf + u, c] = 1.0
            for _ in range(ip[o_sun + 2 * u + 1] if skind == 1 else 0):
                for c in range(nb_):
                    work[w_sf + u, c] *= work[w_s, c]
    square = lay[_SQUARE] == 1
    for i in range(NI):
        for c in range(nb_):
            vi = fine[frow[c], js, i]
            work[w_hv + i, c] = vi * vi if square else vi
    o_hun = lay[_I_HUNIQ]
    for u in range(H):
        for c in range(nb_):
            work[w_hm + u, c] = 1.0
        for i in range(NI):
            for _ in range(ip[o_hun + u * NI + i]):
                for c in range(nb_):
                    work[w_hm + u, c] *= work[w_hv + i, c]
    o_ptr, o_tk = lay[_I_GPTR], lay[_I_TK]
    o_gq, o_gs, o_gh = lay[_I_GQPOW], lay[_I_GSIDX], lay[_I_GHIDX]
    for c in range(nb_):
        work[w_acc, c] = 0.0
    NA = lay[_NA]
    for g in range(G - NA):
        for c in range(nb_):
            work[w_in, c] = 0.0
        for m in range(ip[o_ptr + g], ip[o_ptr + g + 1]):
            k = ip[o_tk + m]
            for c in range(nb_):
                work[w_in, c] += wts[m, c] * work[k, c]
        r_q, r_s, r_h = w_qp + ip[o_gq + g], w_sf + ip[o_gs + g], w_hm + ip[o_gh + g]
        for c in range(nb_):
            factor = work[r_q, c] * work[r_s, c] * work[r_h, c]
            work[w_acc, c] += work[w_in, c] * factor
    if NA > 0:  # the inertia groups, as in _rhs_table: m(q) = m - part
        for c in range(nb_):
            work[w_part, c] = 0.0
        for g in range(G - NA, G):
            for c in range(nb_):
                work[w_in, c] = 0.0
            for m in range(ip[o_ptr + g], ip[o_ptr + g + 1]):
                k = ip[o_tk + m]
                for c in range(nb_):
                    work[w_in, c] += wts[m, c] * work[k, c]
            pw = ip[o_gq + g]
            r_q = w_qp + pw
            for c in range(nb_):
                q_dot = XT[1, c]
                work[w_acc, c] += work[w_in, c] * (0.5 * pw * work[r_q - 1, c] * q_dot * q_dot)
                work[w_part, c] += work[w_in, c] * work[r_q, c]
        for c in range(nb_):
            work[w_part, c] = mass[c] - work[w_part, c]
    for c in range(nb_):
        a = work[w_acc, c] / (work[w_part, c] if NA > 0 else mass[c])
        D[row, 0, c] = XT[1, c]
        D[row, 1, c] = a
        if lag:
            D[row, 2, c] = _friction_rate(XT[1, c], XT[2, c], tz[c]) if tz[c] > 0.0 else 0.0
    rate = fp[lay[_P_CRATE]]
    o_cb = lay[_I_CBASE]
    for i in range(lay[_NC]):
        k = ip[o_cb + i]
        for c in range(nb_):
            D[row, c0 + i, c] = _creep_state_rate(work[k, c], XT[1, c], rate, XT[c0 + i, c])
    c1 = c0 + lay[_NC]
    o_sw = lay[_P_SWIDTH]
    for e in range(lay[_NS]):
        for c in range(nb_):
            D[row, c1 + e, c] = XT[1, c] * _slip_sticks(XT[1, c], XT[c1 + e, c], fp[o_sw + e])


@nb.njit(cache=True, nogil=True)
def _lockstep(
    fp, ip, lay, fine, lengths, h, ns, q_limit, k0, k1, states, acc, dead, bidx
):  # pragma: no cover - compiled
    """RK4 steps k0 .. k1 - 1 of the trajectories ``bidx`` of a table model, in lockstep.

    The block advances sample by sample together; a trajectory that has diverged or ended
    is held at the origin (its results are not stored), so every trajectory gets exactly the
    numbers of :func:`_trajectory`.
    """
    S = states.shape[2]
    nb_ = bidx.size
    K, U, H, NI, QMAX, J = lay[_K], lay[_U], lay[_H], lay[_NI], lay[_QMAX], lay[_J]
    X = np.zeros((S, nb_))
    XT = np.empty((S, nb_))
    D = np.zeros((4, S, nb_))
    work = np.empty((K + NI + QMAX + 1 + U + H + 5, nb_))
    Ti = np.empty(nb_, dtype=np.int64)
    wts = np.empty((max(J, 1), nb_))
    mass = np.empty(nb_)
    tz = np.empty(nb_)
    L = np.empty(nb_, dtype=np.int64)
    frow = np.empty(nb_, dtype=np.int64)  # input row: one row may be shared by every trajectory
    n_max = 0
    for c in range(nb_):
        b = bidx[c]
        frow[c] = b if fine.shape[0] > 1 else 0
        w0 = lay[_P_W] + (b if lay[_BW] > 1 else 0) * J
        for m in range(J):
            wts[m, c] = fp[w0 + m]
        mass[c] = fp[lay[_P_MASS] + (b if lay[_BM] > 1 else 0)]
        tz[c] = fp[lay[_P_TZ] + (b if lay[_BT] > 1 else 0)]
        L[c] = lengths[b]
        n_max = max(n_max, L[c])
        if dead[b] < 0 and k0 < L[c]:
            for i in range(S):
                X[i, c] = states[b, k0, i]
    for k in range(k0, min(k1, n_max)):
        stepping = False
        for c in range(nb_):
            stepping = stepping or (dead[bidx[c]] < 0 and k < L[c] - 1)
        for s in range(ns if stepping else 1):
            j = (k * ns + s) * 2
            for stage in range(4 if stepping else 1):
                js = j + _INPUT_OFFSET[stage]
                for i in range(S):
                    for c in range(nb_):
                        XT[i, c] = (
                            X[i, c]
                            if stage == 0
                            else _stage_state(X[i, c], h, stage, D[stage - 1, i, c])
                        )
                _rhs_table_lock(XT, fine, frow, nb_, js, D, stage, fp, ip, lay, work, Ti, wts,
                                mass, tz)  # fmt: skip
                if stage == 0 and s == 0:
                    for c in range(nb_):
                        if dead[bidx[c]] < 0 and k < L[c]:
                            acc[bidx[c], k] = D[0, 1, c]
            if stepping:
                for i in range(S):
                    for c in range(nb_):
                        incr = _increment(D[0, i, c], D[1, i, c], D[2, i, c], D[3, i, c])
                        X[i, c] = _advance(X[i, c], h, incr)
                c1 = (3 if lay[_LAG] == 1 else 2) + lay[_NC]
                for e in range(lay[_NS]):
                    width = fp[lay[_P_SWIDTH] + e]
                    for c in range(nb_):
                        X[c1 + e, c] = _slip_clip(X[c1 + e, c], width)
        for c in range(nb_):
            b = bidx[c]
            if dead[b] < 0 and k < L[c] - 1:
                ok = abs(X[0, c]) <= q_limit
                for i in range(S):
                    ok = ok and math.isfinite(X[i, c])
                if ok:
                    for i in range(S):
                        states[b, k + 1, i] = X[i, c]
                    continue
                dead[b] = k + 1
            for i in range(S):  # diverged or ended: held at the origin from now on
                X[i, c] = 0.0


@nb.njit(cache=True, inline="always")
def _trajectory_sens(
    fp, ip, lay, n_work, fine, lengths, h, ns, q_limit, states, acc, dead, sens, pmap, b
):  # pragma: no cover - compiled
    """RK4 of trajectory b with the forward sensitivities of its states to the parameters.

    The sensitivities S = dx/dp obey S' = (df/dx) S + df/dp, integrated by the same RK4
    stages as the states (so they are the exact derivatives of the discrete free run). The
    creep states' rows follow w_k' = b_k(q) q_dot - lambda w_k; a slip state's rate is
    q_dot while its element sticks (slope 1) and 0 while it slips, and a step's catch-up
    clip (:func:`_project_table`) fixes the state at its break-away value, so its
    sensitivity is 0 there. With inertia terms the acceleration also depends on q_dot
    through 1/2 m'(q) q_dot^2, and every derivative is over m(q) (:func:`_grad_table`).
    """
    S = states.shape[2]
    P = sens.shape[2]
    J = lay[_J]
    L = lengths[b]
    lag = lay[_LAG] == 1
    c0 = 3 if lag else 2  # first creep state
    NC, NS = lay[_NC], lay[_NS]
    c1 = c0 + NC  # first slip state
    rate = fp[lay[_P_CRATE]]
    o_cb, o_sw = lay[_I_CBASE], lay[_P_SWIDTH]
    tz = fp[lay[_P_TZ] + (b if lay[_BT] > 1 else 0)]
    inertia = lay[_NA] > 0
    p_mass = pmap[2 * J]
    p_tz = pmap[2 * J + 1]
    x = states[b, 0].copy()
    xt = np.empty(S)
    d = np.empty((4, S))
    Sx = np.zeros((S, P))
    St = np.empty((S, P))
    dS = np.empty((4, S, P))
    W = np.empty(max(n_work, 8))
    V = np.empty(max(n_work, 8))
    tv = np.empty(max(J, 1))
    ae = np.empty(max(NC + NS, 1))
    for k in range(L):
        last = k == L - 1
        for s in range(1 if last else ns):
            j = (k * ns + s) * 2
            for stage in range(1 if last else 4):
                js = j + _INPUT_OFFSET[stage]
                for i in range(S):
                    if stage == 0:
                        xt[i] = x[i]
                        for p in range(P):
                            St[i, p] = Sx[i, p]
                    else:
                        xt[i] = _stage_state(x[i], h, stage, d[stage - 1, i])
                        for p in range(P):
                            St[i, p] = _stage_state(Sx[i, p], h, stage, dS[stage - 1, i, p])
                a = _rhs_table(xt, fine, b, js, d, stage, fp, ip, lay, W)
                if stage == 0 and s == 0:
                    acc[b, k] = a
                    for p in range(P):
                        sens[b, k, p] = St[0, p]
                if last:
                    break
                a_q, a_s, a_v, den = _grad_table(xt, b, fp, ip, lay, W, V, tv, ae, a)
                lagged = lag and tz > 0.0
                r_s = 2 if lagged else 1  # the friction factor's state: z, or q_dot itself
                # row 1 (d acc) summed term by term in the order of _grad_table's factors, each a
                # loop over the parameters (no inner loop or branch in them: they vectorise)
                for p in range(P):
                    dS[stage, 0, p] = St[1, p]
                    dS[stage, 1, p] = a_q * St[0, p] + a_s * St[r_s, p]
                if inertia:
                    for p in range(P):
                        dS[stage, 1, p] += a_v * St[1, p]
                for e in range(NC + NS):
                    a_e = ae[e]
                    for p in range(P):
                        dS[stage, 1, p] += a_e * St[c0 + e, p]
                if lagged:
                    for p in range(P):
                        dS[stage, 2, p] = _friction_rate(St[1, p], St[2, p], tz)
                elif lag:
                    for p in range(P):
                        dS[stage, 2, p] = 0.0
                for i in range(NC):  # V[k]: the basis derivatives left by _grad_table
                    cb = ip[o_cb + i]
                    for p in range(P):
                        dS[stage, c0 + i, p] = (
                            V[cb] * St[0, p] * xt[1] + W[cb] * St[1, p] - rate * St[c0 + i, p]
                        )
                for e in range(NS):
                    stick = _slip_sticks(xt[1], xt[c1 + e], fp[o_sw + e])
                    for p in range(P):
                        dS[stage, c1 + e, p] = stick * St[1, p]
                for m in range(J):  # d acc / d w_m = tv[m]; w_m = sign * parameter
                    p = pmap[m]
                    if p >= 0:
                        dS[stage, 1, p] += pmap[J + m] * tv[m]
                if p_mass >= 0:  # d acc / d m = -acc / m(q)
                    dS[stage, 1, p_mass] -= a / den
                if p_tz >= 0 and lagged:  # parameter log T_z: d z' / d log T_z
                    dS[stage, 2, p_tz] -= _friction_rate(xt[1], xt[2], tz)
            if not last:
                for i in range(S):
                    x[i] = _advance(x[i], h, _increment(d[0, i], d[1, i], d[2, i], d[3, i]))
                    for p in range(P):
                        sincr = _increment(dS[0, i, p], dS[1, i, p], dS[2, i, p], dS[3, i, p])
                        Sx[i, p] = _advance(Sx[i, p], h, sincr)
                for e in range(NS):  # the catch-up clip holds a state at Delta_e: S = 0 there
                    held = _slip_clip(x[c1 + e], fp[o_sw + e])
                    if held != x[c1 + e]:
                        x[c1 + e] = held
                        for p in range(P):
                            Sx[c1 + e, p] = 0.0
        if last:
            break
        ok = abs(x[0]) <= q_limit
        for i in range(S):
            ok = ok and math.isfinite(x[i])
        if not ok:
            dead[b] = k + 1
            break
        for i in range(S):
            states[b, k + 1, i] = x[i]


@nb.njit(cache=True, nogil=True)
def _sensitivities(
    fp, ip, lay, n_work, fine, lengths, h, ns, q_limit, states, acc, dead, sens, pmap, bidx
):  # pragma: no cover - compiled
    """Integrate the trajectories ``bidx`` with their sensitivities, without the GIL."""
    for c in range(bidx.size):
        _trajectory_sens(fp, ip, lay, n_work, fine, lengths, h, ns, q_limit, states, acc, dead,
                         sens, pmap, bidx[c])  # fmt: skip


def kernel_threads() -> int:
    """Threads a batch of free runs may use: numba's thread count, at most the usable cores.

    ``NUMBA_NUM_THREADS`` (numba's setting, read without starting numba's thread pool) bounds
    it, so a batch's worker processes, which set it to 1, integrate on their own thread.

    Returns
    -------
    int
        At least 1.
    """
    return max(1, min(int(nb.config.NUMBA_NUM_THREADS), usable_cores()))


def on_threads(call: Callable[[np.ndarray], None], blocks: Sequence[np.ndarray]) -> None:
    """Call ``call(block)`` for every block, each on a thread of its own.

    The compiled integrators release the GIL (``nogil=True``) and write disjoint rows of
    shared arrays, so the blocks run in parallel and the numbers do not depend on how the
    trajectories were split. Python threads instead of numba's ``prange``: a ``parallel=True``
    kernel costs seconds more to compile on the first run and starts numba's threading layer,
    which a forked process may not inherit. The threads end before the call returns.

    Parameters
    ----------
    call : callable
        Takes one block of trajectory indices (ndarray of int64).
    blocks : sequence of ndarray
        The blocks; empty ones are skipped.

    Raises
    ------
    Exception
        The first exception a call raised, after every thread has ended.
    """
    blocks = [b for b in blocks if b.size]
    if len(blocks) <= 1:
        for b in blocks:
            call(b)
        return
    with ThreadPoolExecutor(max_workers=len(blocks), thread_name_prefix="debist-rk4") as pool:
        for future in [pool.submit(call, b) for b in blocks]:
            future.result()


def free_run_sensitivity(
    arrays: KernelArrays,
    fine: np.ndarray,
    lengths: np.ndarray,
    dt: float,
    substeps: int,
    x0: np.ndarray,
    q_limit: float,
    term_param: np.ndarray,
    term_sign: np.ndarray,
    mass_param: int,
    tz_param: int,
    n_params: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Free runs of a term-table model and the sensitivities of q to its parameters.

    Weights ``term_sign[j] * p[term_param[j]]``, mass ``p[mass_param]``, ``T_z =
    exp(p[tz_param])``; the sensitivities are the exact derivative of the discrete RK4 run.

    Parameters
    ----------
    arrays : KernelArrays
        A term-table model (its weights, mass and T_z at the parameter values).
    fine : ndarray, shape (B, (n - 1) * 2 * substeps + 1, n_inputs)
        Inputs on the grid of half sub-steps [V].
    lengths : ndarray of int, shape (B,)
        Samples of each trajectory.
    dt, substeps : float, int
        Sample time [s]; RK4 steps per sample.
    x0 : ndarray, shape (B, n_states)
        Initial states (independent of the parameters).
    q_limit : float
        Divergence bound on ``|q|`` [unit of q].
    term_param, term_sign : ndarray, shape (J,)
        Parameter of each term (-1: fixed weight); sign of its weight relative to it.
    mass_param, tz_param, n_params : int
        Parameter index of the mass and of log T_z (-1 when fixed); number P of parameters.

    Returns
    -------
    q : ndarray, shape (B, n)
        Simulated positions; NaN from a divergence on.
    dq_dp : ndarray, shape (B, n, P)
        Their derivatives with respect to the parameters; NaN from a divergence on.

    Raises
    ------
    ValueError
        If the model is not a term table.

    References
    ----------
    Hairer, Norsett & Wanner, Solving ODEs I, Sec. I.14; Ljung 1999, Sec. 10.3.
    """
    if arrays.kind != KIND_TABLE:
        raise ValueError("sensitivities are computed for term-table models only")
    B, n = fine.shape[0], int(np.max(lengths))
    J = int(arrays.lay[_J])
    order = arrays.term_order
    pmap = np.concatenate([np.asarray(term_param, np.int64)[order],
                           np.asarray(term_sign, np.float64)[order].astype(np.int64),
                           [int(mass_param), int(tz_param)]]).astype(np.int64)  # fmt: skip
    if not np.all(np.isin(np.asarray(term_sign)[order], (-1.0, 1.0))):
        raise ValueError("`term_sign` must hold -1 or +1")
    states = np.full((B, n, arrays.n_states), np.nan)
    acc = np.full((B, n), np.nan)
    dead = np.full(B, -1, dtype=np.int64)
    sens = np.full((B, n, int(n_params)), np.nan)
    states[:, 0] = x0
    lengths = np.ascontiguousarray(lengths, np.int64)
    fine = np.ascontiguousarray(fine, np.float64)
    threads = min(B, kernel_threads())
    by_length = np.argsort(-lengths, kind="stable").astype(np.int64)  # longest first, dealt out
    on_threads(
        lambda bidx: _sensitivities(arrays.fp, arrays.ip, arrays.lay, arrays.n_work, fine,
                                    lengths, float(dt) / int(substeps), int(substeps),
                                    float(q_limit), states, acc, dead, sens, pmap, bidx),
        [np.ascontiguousarray(by_length[i::threads]) for i in range(threads)],
    )  # fmt: skip
    q = states[:, :, 0]
    for b in range(B):
        if dead[b] >= 0:
            q[b, dead[b] :] = np.nan
            sens[b, dead[b] :] = np.nan
        q[b, lengths[b] :] = np.nan
    assert len(order) == J
    return q, sens


def free_run(
    arrays: KernelArrays,
    fine: np.ndarray,
    lengths: np.ndarray,
    dt: float,
    substeps: int,
    x0: np.ndarray,
    q_limit: float,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integrate a batch of free runs with the compiled RK4.

    Parameters
    ----------
    arrays : KernelArrays
        The model.
    fine : ndarray, shape (B or 1, (n - 1) * 2 * substeps + 1, n_inputs)
        Inputs on the grid of half sub-steps [V] (:func:`debist.simulate.freerun.prepare_inputs`);
        one row drives every trajectory.
    lengths : ndarray of int, shape (B,)
        Samples of each trajectory (``<= n``).
    dt : float
        Sample time [s].
    substeps : int
        RK4 steps per sample.
    x0 : ndarray, shape (B, n_states)
        Initial states.
    q_limit : float
        ``|q|`` beyond which a trajectory counts as diverged [unit of q].
    progress : callable, optional
        Called as ``progress(done, total)`` (samples of the longest trajectory) between
        chunks of :data:`CHUNK` samples.

    Returns
    -------
    states : ndarray, shape (B, n, n_states)
        States at the samples; NaN from a trajectory's divergence on and beyond its length.
    acc : ndarray, shape (B, n)
        Acceleration at the samples; NaN from one sample before a divergence on.
    diverged_at : ndarray of int, shape (B,)
        First diverged sample, -1 if none.

    Raises
    ------
    ValueError
        If ``fine`` has neither B rows nor one.

    References
    ----------
    Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (classical RK4).
    """
    B, n = np.size(lengths), int(np.max(lengths))
    if fine.shape[0] not in (1, B):
        raise ValueError(f"inputs for {fine.shape[0]} trajectories, not {B} or one shared")
    states = np.full((B, n, arrays.n_states), np.nan)
    acc = np.full((B, n), np.nan)
    dead = np.full(B, -1, dtype=np.int64)
    states[:, 0] = x0
    lengths = np.ascontiguousarray(lengths, dtype=np.int64)
    fine = np.ascontiguousarray(fine, dtype=np.float64)
    h = float(dt) / int(substeps)
    step = n if progress is None else CHUNK
    threads = kernel_threads()
    if arrays.kind == KIND_TABLE and threads < B:
        # blocks of similar length, one per thread, each integrated in lockstep
        by_length = np.argsort(-lengths, kind="stable").astype(np.int64)
        bounds = np.linspace(0, B, threads + 1).round().astype(np.int64)
        blocks = [by_length[bounds[i] : bounds[i + 1]] for i in range(threads)]

        def block(k0: int, k1: int, bidx: np.ndarray) -> None:
            _lockstep(arrays.fp, arrays.ip, arrays.lay, fine, lengths, h, int(substeps),
                      float(q_limit), k0, k1, states, acc, dead, bidx)  # fmt: skip
    else:
        blocks = np.array_split(np.arange(B, dtype=np.int64), min(B, threads))

        def block(k0: int, k1: int, bidx: np.ndarray) -> None:
            _integrate(arrays.kind, arrays.fp, arrays.ip, arrays.lay, arrays.n_work, fine,
                       lengths, h, int(substeps), float(q_limit), k0, k1, states, acc, dead,
                       bidx)  # fmt: skip

    for k0 in range(0, n, step):
        k1 = min(k0 + step, n)
        on_threads(lambda bidx, k0=k0, k1=k1: block(k0, k1, bidx), blocks)
        if progress is not None:
            progress(k1, n)
    run = mask_batch(states, acc, dead, lengths, substeps)
    return run.states, run.acc, run.diverged_at
