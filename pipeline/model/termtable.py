"""Models linear in their weights, written as plain arrays: the form every compared model takes.

A *term table* describes the acceleration of a one-coordinate model as a weighted sum of terms,

    q'' = (1 / m) sum_j w_j b_j(q) q^a_j S_j(s) prod_i h_i^c_ji,

where ``b_j`` is one of a few *bases* of q (the constant 1, a Gaussian RBF with its centre,
width and clipping range, or a table interpolated linearly and held outside its grid), ``S_j``
is 1, ``s^k`` or ``tanh(s / v_c)`` of the velocity-like variable ``s`` (the friction state z
of Eq. 37, or q_dot), or a *creep state* ``w_k``, and ``h_i = h(v_i)`` are the mapped inputs.
The creep states are first-order filters of a basis times the velocity,
``w_k' = b_(creep_base[k])(q) q_dot - lambda w_k`` with one relaxation rate lambda [1/s]: the
Maxwell creep of the DEs (Masoud & Maas 2025, Eq. 26) with k_i(q) written in the basis, so that
the creep force ``sum_k c_k w_k`` is linear in its weights once lambda is fixed. After the
creep states come the *slip states* ``delta_e`` of the Maxwell-slip friction elements with
break-away deflections ``Delta_e`` (:func:`debist.model.friction.slip_state_rate`, held to
``|delta_e| <= Delta_e`` after every step by :meth:`TableModel.project`), so that the friction
force ``sum_e k_e delta_e`` is linear in the stiffnesses k_e once the Delta_e are fixed; a
term's ``S_CREEP`` factor reads either kind of state (index k of ``[w_1..w_C, delta_1..]``).
An *inertia term* (``S_ACC``, q^a with a >= 1) is a part of the mass: its regressor column is
``q^a q'' + 1/2 a q^(a-1) q_dot^2``, the position-dependent inertia of a Lagrangian coordinate
(``d/dt(m(q) q_dot) - 1/2 m'(q) q_dot^2``) moved to the regressor, so that the mass
``m(q) = m - sum_(j inertia) w_j q^a_j`` is linear in its coefficients (a force-side weight is
minus its coefficient: ``m(q) = m_q + sum theta_a q^a``) and the acceleration is
``(sum_(j other) w_j column_j + sum_(j inertia) w_j 1/2 a_j q^(a_j - 1) q_dot^2) / m(q)``.
The RBF model
of Eq. 37 with its backbone and physics prior, and the SINDy polynomials, are such tables; the
same arrays give the regressor columns of a least squares (:meth:`TermTable.columns`), the NumPy
right-hand side (:class:`TableModel`) and the compiled one (:mod:`debist.simulate.kernel`), so the
fitted, the reference-simulated and the compiled-simulated model are one object.

References
----------
Masoud & Maas 2025, Eq. 37-40; Brunton, Proctor & Kutz 2016 (SINDy's library
Theta(X) Xi); de Silva et al. 2020, "PySINDy" (feature libraries).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from debist.core.errors import WorkflowError
from debist.model.basis import gaussian
from debist.model.friction import (
    creep_state_rate,
    friction_state_rate,
    slip_clip,
    slip_state_rate,
)

__all__ = [
    "BASE_GAUSS",
    "BASE_ONE",
    "BASE_TABLE",
    "INPUT_MAPS",
    "S_ACC",
    "S_CREEP",
    "S_ONE",
    "S_POW",
    "S_TANH",
    "TableModel",
    "TermTable",
]

#: Basis kinds: the constant 1, a Gaussian RBF (Eq. 38), a tabulated curve.
BASE_ONE, BASE_GAUSS, BASE_TABLE = 0, 1, 2
#: Velocity factors: none, ``s^k``, ``tanh(s / v_c)``, creep state ``w_k`` (k in ``spow``),
#: and the inertia factor (the term is a part of the mass, see the module docstring).
S_ONE, S_POW, S_TANH, S_CREEP, S_ACC = 0, 1, 2, 3, 4
#: Input maps h(v) of Eq. 37: ``"v2"`` is v^2 (DE actuators: the electrostatic force grows
#: with v^2), ``"v"`` is v (linear rigs). Every model, the fit and the kernel read this one.
INPUT_MAPS = ("v2", "v")


def input_map(v: np.ndarray, kind: str) -> np.ndarray:
    """Apply the input map h(v) of the model.

    Parameters
    ----------
    v : ndarray, shape (..., n_inputs)
        Inputs [V].
    kind : {"v2", "v"}
        ``"v2"``: h(v) = v^2 [V^2] (DE actuators, Eq. 37); ``"v"``: h(v) = v [V].

    Returns
    -------
    ndarray, same shape as ``v``

    Raises
    ------
    WorkflowError
        If ``kind`` is unknown.

    Examples
    --------
    >>> input_map(np.array([2.0, -3.0]), "v2")
    array([4., 9.])
    """
    if kind == "v2":
        return np.square(v)
    if kind == "v":
        return np.asarray(v, dtype=float)
    raise WorkflowError(f"`input_map` must be one of {INPUT_MAPS}, got {kind!r}")


def _int(a, shape=None) -> np.ndarray:
    out = np.ascontiguousarray(np.asarray(a, dtype=np.int64))
    return out.reshape(shape) if shape is not None else out


def _float(a) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64))


@dataclass(frozen=True)
class _Plan:
    """Index groups of a :class:`TermTable` (see :attr:`TermTable._plan`)."""

    gauss: np.ndarray
    table: np.ndarray
    # the Gaussians' clipping range, centres and widths, gathered once
    gauss_lo: np.ndarray
    gauss_hi: np.ndarray
    gauss_centre: np.ndarray
    gauss_width: np.ndarray
    # each term's factor as a column of the factor matrices :meth:`TermTable.columns` builds:
    # 0 is the factor 1 (x 1.0 is exact), k > 0 the k-th distinct power (or kind)
    qpow: tuple[int, ...]
    q_index: np.ndarray
    spow: tuple[int, ...]
    s_index: np.ndarray
    tanh: np.ndarray
    creep: np.ndarray
    creep_states: np.ndarray
    hpow: tuple[tuple[int, ...], ...]
    h_index: tuple[np.ndarray, ...]
    inertia: np.ndarray


def _powers(power: np.ndarray, among: np.ndarray) -> tuple[tuple[int, ...], np.ndarray]:
    """Return the distinct powers ``p != 0`` of the terms ``among`` (ascending), each term's index.

    The index of a term is ``k + 1`` for the k-th of those powers, 0 for the others (their
    factor is 1).
    """
    distinct = tuple(int(p) for p in np.unique(power[among]) if p)
    index = np.zeros(power.size, dtype=np.int64)
    for k, p in enumerate(distinct, start=1):
        index[among & (power == p)] = k
    return distinct, index


def _factors(x: np.ndarray, powers: Sequence[int], extra: int = 0) -> np.ndarray:
    """``[1, x^p_1, x^p_2, ...]`` as columns, shape (n, 1 + len(powers) + extra).

    The ``extra`` last columns are left for the caller to fill.
    """
    out = np.empty((x.size, 1 + len(powers) + extra))
    out[:, 0] = 1.0
    for k, p in enumerate(powers, start=1):
        out[:, k] = x**p
    return out


@dataclass(frozen=True, eq=False)
class TermTable:
    """The terms of a model linear in its weights, as arrays (see the module docstring).

    Parameters
    ----------
    names : tuple of str, length J
        One name per term (e.g. ``"c[3]"``, ``"linear_spring"``, ``"q^2 q_dot"``).
    base_kind : ndarray of int, shape (K,)
        :data:`BASE_ONE`, :data:`BASE_GAUSS` or :data:`BASE_TABLE` per basis.
    base_centre, base_width : ndarray, shape (K,)
        Centre xi [unit of q] and width sigma [unit of q] of a Gaussian basis.
    base_lo, base_hi : ndarray, shape (K,)
        A Gaussian basis is evaluated at q clipped to ``[lo, hi]`` (``-inf, inf``: not clipped).
    base_table : ndarray of int, shape (K,)
        Row of ``tables`` of a tabulated basis.
    table_q, tables : ndarray, shapes (G,) and (T, G)
        Ascending grid [unit of q] and tabulated curves (linear, held outside the grid).
    term_base, term_qpow : ndarray of int, shape (J,)
        Basis of each term; its power ``a_j >= 0`` of q.
    term_skind, term_spow : ndarray of int, shape (J,)
        Velocity factor of each term (:data:`S_ONE`, :data:`S_POW` with power ``term_spow``,
        :data:`S_TANH`, :data:`S_CREEP` with state ``term_spow`` of ``[w, delta]``,
        :data:`S_ACC` for an inertia term: constant basis, ``a_j >= 1``, no inputs).
    term_hpow : ndarray of int, shape (J, n_inputs)
        Powers ``c_ji >= 0`` of the mapped inputs.
    input_map, coulomb_velocity : {"v2", "v"}, float
        h(v) = v^2 [V^2] or v [V]; v_c of the ``tanh`` factor [unit of q / s].
    creep_base : ndarray of int, shape (C,)
        Basis of each creep state, ``w_k' = b_(creep_base[k])(q) q_dot - lambda w_k``
        [unit of q] (empty: no creep states).
    creep_rate : float
        The creep states' relaxation rate lambda = Y_MW / eta_MW [1/s].
    slip_width : ndarray, shape (E,)
        Break-away deflections Delta_e of the Maxwell-slip elements [unit of q] (empty: none).

    References
    ----------
    Masoud & Maas 2025, Eq. 26 (creep), 37-40 (RBF terms); Brunton, Proctor & Kutz 2016
    (library); Al-Bender, Lampaert & Swevers 2005 (Maxwell-slip elements).
    """

    names: tuple[str, ...]
    base_kind: np.ndarray
    base_centre: np.ndarray
    base_width: np.ndarray
    base_lo: np.ndarray
    base_hi: np.ndarray
    base_table: np.ndarray
    table_q: np.ndarray
    tables: np.ndarray
    term_base: np.ndarray
    term_qpow: np.ndarray
    term_skind: np.ndarray
    term_spow: np.ndarray
    term_hpow: np.ndarray
    input_map: str = "v2"
    coulomb_velocity: float = 1.0
    creep_base: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    creep_rate: float = 0.0
    slip_width: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @cached_property
    def n_creep(self) -> int:
        """Number of creep states C."""
        return int(self.creep_base.size)

    @cached_property
    def n_slip(self) -> int:
        """Number of Maxwell-slip elements E."""
        return int(self.slip_width.size)

    @cached_property
    def n_extra(self) -> int:
        """Number of states after ``[q, q_dot, z]``: the creep and the slip states, C + E."""
        return self.n_creep + self.n_slip

    @property
    def has_inertia(self) -> bool:
        """Whether some terms are inertia terms (a position-dependent mass)."""
        return self._plan.inertia.size > 0

    @cached_property
    def _plan(self) -> _Plan:
        """The bases and the index of each term's factors that :meth:`columns` gathers.

        Computed once per table (its arrays are not changed after construction). The
        NumPy engine calls :meth:`columns` for one state at a time, where the number of
        array operations, not their size, is the cost: each factor (q power, velocity
        factor, input power) is one gather from its distinct values, multiplied in the
        order of term by term, so the products are the same to the bit.
        """
        kind = self.base_kind
        every = np.ones(self.n_terms, dtype=bool)
        gauss = np.flatnonzero(kind == BASE_GAUSS)
        qpow, q_index = _powers(self.term_qpow, every)
        spow, s_index = _powers(self.term_spow, self.term_skind == S_POW)
        tanh = np.flatnonzero(self.term_skind == S_TANH)
        creep = np.flatnonzero(self.term_skind == S_CREEP)
        # the velocity factors' columns: [1, s^p.., tanh(s / v_c), the states of the creep terms]
        s_index[tanh] = 1 + len(spow)
        s_index[creep] = 1 + len(spow) + (tanh.size > 0) + np.arange(creep.size)
        hpow = [_powers(self.term_hpow[:, i], every) for i in range(self.n_inputs)]
        return _Plan(
            gauss=gauss,
            table=np.flatnonzero(kind == BASE_TABLE),
            gauss_lo=self.base_lo[gauss],
            gauss_hi=self.base_hi[gauss],
            gauss_centre=self.base_centre[gauss],
            gauss_width=self.base_width[gauss],
            qpow=qpow,
            q_index=q_index,
            spow=spow,
            s_index=s_index,
            tanh=tanh,
            creep=creep,
            creep_states=self.term_spow[creep],
            hpow=tuple(h[0] for h in hpow),
            h_index=tuple(h[1] for h in hpow),
            inertia=np.flatnonzero(self.term_skind == S_ACC),
        )

    def inertia_parts(self, q: np.ndarray, q_dot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return the inertia terms' part of the mass and their velocity-squared force.

        Parameters
        ----------
        q, q_dot : array_like, shape (n,)
            Positions [unit of q] and velocities [unit of q / s].

        Returns
        -------
        mass : ndarray, shape (n, J)
            ``q^a_j`` for the inertia terms (their weight times this adds to m), else 0.
        force : ndarray, shape (n, J)
            ``1/2 a_j q^(a_j - 1) q_dot^2`` for the inertia terms, else 0.

        References
        ----------
        Lagrange's equation of a coordinate with the kinetic energy 1/2 m(q) q_dot^2:
        ``m(q) q'' + 1/2 m'(q) q_dot^2`` (Goldstein, Classical Mechanics, Sec. 1.4).
        """
        q = np.asarray(q, dtype=float).reshape(-1)
        q_dot = np.asarray(q_dot, dtype=float).reshape(-1)
        mass = np.zeros((q.size, self.n_terms))
        force = np.zeros((q.size, self.n_terms))
        for j in self._plan.inertia:
            a = int(self.term_qpow[j])
            mass[:, j] = q**a
            force[:, j] = 0.5 * a * q ** (a - 1) * q_dot**2
        return mass, force

    @property
    def n_terms(self) -> int:
        """Number of terms J."""
        return len(self.names)

    @property
    def n_inputs(self) -> int:
        """Number of inputs."""
        return int(self.term_hpow.shape[1])

    def map_inputs(self, v: np.ndarray) -> np.ndarray:
        """Apply the input map: ``h(v)``, same shape as ``v`` [V^2 or V] (:func:`input_map`)."""
        return input_map(np.asarray(v, dtype=float), self.input_map)

    @property
    def squares_inputs(self) -> bool:
        """Whether the input map is ``h(v) = v^2`` (the compiled kernel's flag)."""
        return self.input_map == "v2"

    def bases(self, q: np.ndarray) -> np.ndarray:
        """Evaluate every basis.

        Parameters
        ----------
        q : array_like, shape (n,)
            Positions [unit of q].

        Returns
        -------
        ndarray, shape (n, K)
        """
        q = np.asarray(q, dtype=float).reshape(-1)
        out = np.empty((q.size, self.base_kind.size))
        out.fill(1.0)
        plan = self._plan
        if plan.gauss.size:  # every Gaussian at once: the same operations, element by element
            qc = np.minimum(np.maximum(q[:, None], plan.gauss_lo), plan.gauss_hi)
            out[:, plan.gauss] = gaussian(qc - plan.gauss_centre, plan.gauss_width)
        for k in plan.table:
            out[:, k] = np.interp(q, self.table_q, self.tables[self.base_table[k]])
        return out

    def position_part(self, q: np.ndarray, bases: np.ndarray | None = None) -> np.ndarray:
        """Evaluate every term's factors of q alone: its basis times its power of q.

        Parameters
        ----------
        q : array_like, shape (n,)
            Positions [unit of q].
        bases : ndarray, shape (n, K), optional
            :meth:`bases` of ``q``, where the caller needs them too (not modified); default:
            computed here.

        Returns
        -------
        ndarray, shape (n, J), C order
            ``b_j(q) q^a_j``: what :meth:`columns` multiplies by the other factors, given to
            it as ``position`` when only those change (a search over T_z, which moves z).
        """
        q = np.asarray(q, dtype=float)
        if bases is None:
            bases = self.bases(q)
        out = bases[:, self.term_base].copy()  # C order: the weighted sums' order
        if self._plan.qpow:
            out *= _factors(q, self._plan.qpow)[:, self._plan.q_index]
        return out

    def columns(
        self,
        q: np.ndarray,
        s: np.ndarray,
        hv: np.ndarray,
        w: np.ndarray | None = None,
        q_dot: np.ndarray | None = None,
        q_ddot: np.ndarray | None = None,
        position: np.ndarray | None = None,
    ) -> np.ndarray:
        """Evaluate every term: the regressor columns (without weights and mass).

        Parameters
        ----------
        q : array_like, shape (n,)
            Positions [unit of q].
        s : array_like, shape (n,)
            The velocity-like variable (friction state z or q_dot) [unit of q / s].
        hv : array_like, shape (n, n_inputs)
            Mapped inputs h(v_i).
        w : array_like, shape (n, C + E), optional
            The creep states, then the slip states [unit of q]
            (:func:`debist.model.friction.creep_states`, :func:`~debist.model.friction.slip_states`
            along a record); default 0 (at rest), so their terms vanish.
        q_dot, q_ddot : array_like, shape (n,), optional
            Velocity [unit of q / s] and acceleration [unit of q / s^2] of the inertia terms'
            columns ``q^a q'' + 1/2 a q^(a-1) q_dot^2`` (:meth:`inertia_parts`); without
            ``q_ddot`` those columns are 0 (the acceleration is what a simulation solves for).
        position : ndarray, shape (n, J), optional
            :meth:`position_part` of ``q``, computed once where only the other factors
            change (not modified); default: computed here.

        Returns
        -------
        ndarray, shape (n, J)
        """
        q = np.asarray(q, dtype=float)
        s = np.asarray(s, dtype=float)
        hv = np.asarray(hv, dtype=float).reshape(q.size, self.n_inputs)
        plan = self._plan
        # every term's factors in the order q power, velocity factor, inputs: the products of
        # term by term, each factor gathered from the distinct values (a missing one is 1)
        out = self.position_part(q) if position is None else position.copy()
        if plan.spow or plan.tanh.size or plan.creep.size:
            # the columns [1, s^p.., tanh(s / v_c), the creep terms' states] in one array
            S = _factors(s, plan.spow, extra=int(plan.tanh.size > 0) + plan.creep.size)
            k = 1 + len(plan.spow)
            if plan.tanh.size:
                S[:, k] = np.tanh(s / self.coulomb_velocity)
                k += 1
            if plan.creep.size and w is not None:
                S[:, k:] = np.asarray(w, dtype=float).reshape(q.size, -1)[:, plan.creep_states]
            elif plan.creep.size:  # no states given: the creep terms are 0 (set, as at rest)
                S[:, k:] = 1.0
            out *= S[:, plan.s_index]
            if plan.creep.size and w is None:
                out[:, plan.creep] = 0.0
        for i, powers in enumerate(plan.hpow):
            if powers:
                out *= _factors(hv[:, i], powers)[:, plan.h_index[i]]
        if plan.inertia.size:
            if q_ddot is None:
                out[:, plan.inertia] = 0.0
            else:
                mass, force = self.inertia_parts(q, q_dot)
                qdd = np.asarray(q_ddot, dtype=float).reshape(-1, 1)
                out[:, plan.inertia] = (mass * qdd + force)[:, plan.inertia]
        return out

    def select(self, keep: Sequence[int]) -> TermTable:
        """Return the table of a subset of the terms (in the given order)."""
        keep = _int(keep)
        return TermTable(
            tuple(self.names[j] for j in keep),
            self.base_kind,
            self.base_centre,
            self.base_width,
            self.base_lo,
            self.base_hi,
            self.base_table,
            self.table_q,
            self.tables,
            self.term_base[keep],
            self.term_qpow[keep],
            self.term_skind[keep],
            self.term_spow[keep],
            self.term_hpow[keep],
            self.input_map,
            self.coulomb_velocity,
            self.creep_base,
            self.creep_rate,
            self.slip_width,
        )


@dataclass(eq=False)
class TermTableBuilder:
    """Collects bases and terms and builds a :class:`TermTable` (bases are shared).

    Parameters
    ----------
    n_inputs : int
        Number of inputs.
    input_map : {"v2", "v"}
        h(v).
    coulomb_velocity : float
        v_c [unit of q / s].
    creep_rate : float
        Relaxation rate lambda of the creep states [1/s].
    """

    n_inputs: int
    input_map: str = "v2"
    coulomb_velocity: float = 1.0
    creep_rate: float = 0.0
    _bases: list[tuple] = field(default_factory=list)
    _tables: list[np.ndarray] = field(default_factory=list)
    _table_q: np.ndarray | None = None
    _terms: list[tuple] = field(default_factory=list)
    _creep: list[int] = field(default_factory=list)
    _slip: list[float] = field(default_factory=list)

    def creep(self, base: int) -> int:
        """Index of the creep state ``w' = b(q) q_dot - lambda w`` of basis ``base`` (shared)."""
        if base not in self._creep:
            if self._slip:
                raise ValueError("creep states come before the slip states: add them first")
            self._creep.append(int(base))
        return self._creep.index(base)

    def slip(self, width: float) -> int:
        """State index of a Maxwell-slip element of break-away deflection ``width`` (shared)."""
        width = float(width)
        if width not in self._slip:
            self._slip.append(width)
        return len(self._creep) + self._slip.index(width)

    def inertia(self, name: str, power: int) -> None:
        """Add an inertia term: ``q^power`` in the mass (``power >= 1``; module docstring)."""
        if int(power) < 1:
            raise ValueError(f"an inertia term needs a power of q >= 1, got {power}")
        self.term(name, self.one(), qpow=int(power), skind=S_ACC)

    def one(self) -> int:
        """Index of the constant basis."""
        return self._base((BASE_ONE, 0.0, 1.0, -np.inf, np.inf, -1))

    def gauss(self, centre: float, width: float, lo: float = -np.inf, hi: float = np.inf) -> int:
        """Index of a Gaussian basis ``exp(-(clip(q, lo, hi) - centre)^2 / (2 width^2))``."""
        return self._base((BASE_GAUSS, float(centre), float(width), float(lo), float(hi), -1))

    def table(self, q: np.ndarray, values: np.ndarray) -> int:
        """Index of a tabulated basis on the grid ``q`` (every table shares one grid)."""
        q = _float(q)
        if self._table_q is None:
            self._table_q = q
        elif not np.array_equal(self._table_q, q):
            raise ValueError("every tabulated basis of a term table shares one grid")
        self._tables.append(_float(values))
        return self._base((BASE_TABLE, 0.0, 1.0, -np.inf, np.inf, len(self._tables) - 1))

    def _base(self, spec: tuple) -> int:
        if spec in self._bases and spec[0] != BASE_TABLE:
            return self._bases.index(spec)
        self._bases.append(spec)
        return len(self._bases) - 1

    def term(
        self,
        name: str,
        base: int,
        *,
        qpow: int = 0,
        skind: int = S_ONE,
        spow: int = 0,
        hpow: Sequence[int] | None = None,
    ) -> None:
        """Add a term ``b(q) q^qpow S(s) prod h_i^hpow_i``."""
        h = np.zeros(self.n_inputs, dtype=np.int64) if hpow is None else _int(hpow)
        self._terms.append((name, base, int(qpow), int(skind), int(spow), h))

    def build(self) -> TermTable:
        """Return the table."""
        bases = self._bases or [(BASE_ONE, 0.0, 1.0, -np.inf, np.inf, -1)]
        kind, centre, width, lo, hi, tab = (np.array(col) for col in zip(*bases, strict=True))
        table_q = self._table_q if self._table_q is not None else np.zeros(1)
        tables = np.stack(self._tables) if self._tables else np.zeros((0, table_q.size))
        terms = self._terms
        return TermTable(
            names=tuple(t[0] for t in terms),
            base_kind=_int(kind),
            base_centre=_float(centre),
            base_width=_float(width),
            base_lo=_float(lo),
            base_hi=_float(hi),
            base_table=_int(tab),
            table_q=_float(table_q),
            tables=_float(tables),
            term_base=_int([t[1] for t in terms]),
            term_qpow=_int([t[2] for t in terms]),
            term_skind=_int([t[3] for t in terms]),
            term_spow=_int([t[4] for t in terms]),
            term_hpow=_int([t[5] for t in terms], (len(terms), self.n_inputs)),
            input_map=self.input_map,
            coulomb_velocity=float(self.coulomb_velocity),
            creep_base=_int(self._creep),
            creep_rate=float(self.creep_rate),
            slip_width=_float(np.asarray(self._slip, dtype=float).reshape(-1)),
        )


@dataclass(frozen=True, eq=False)
class TableModel:
    """A term table with weights per trajectory, as a free-run model of either engine.

    States ``[q, q_dot, z, w_1..w_C, delta_1..delta_E]`` when ``lag`` (z' = (q_dot - z) /
    T_z, and z = q_dot where ``T_z = 0``), else ``[q, q_dot, w.., delta..]`` with
    ``s = q_dot``; the creep states ``w_k' = b_k(q) q_dot - lambda w_k`` and the slip states
    (:func:`debist.model.friction.slip_state_rate`) only when the table has them.

    Parameters
    ----------
    table : TermTable
        The terms.
    weights : ndarray, shape (B or 1, J)
        Weights per trajectory (one row: shared by all).
    mass : ndarray, shape (B or 1,)
        The divisor m (generalised mass [kg], 1 for curves per unit mass).
    T_z : ndarray, shape (B or 1,)
        Friction time constant per trajectory [s] (only with ``lag``).
    lag : bool
        Whether the model has the friction state z of Eq. 37.

    References
    ----------
    Masoud & Maas 2025, Eq. 26 (creep states), Eq. 37 (z' = (q' - z) / T_z);
    Al-Bender, Lampaert & Swevers 2005 (slip states).
    """

    table: TermTable
    weights: np.ndarray
    mass: np.ndarray
    T_z: np.ndarray
    lag: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "weights", np.atleast_2d(_float(self.weights)))
        object.__setattr__(self, "mass", np.atleast_1d(_float(self.mass)))
        object.__setattr__(self, "T_z", np.atleast_1d(_float(self.T_z)))

    @property
    def n_states(self) -> int:
        """2, plus 1 with the friction state, plus the creep and slip states C + E."""
        return (3 if self.lag else 2) + self.table.n_extra

    def initial_state(self, q0: np.ndarray, q_dot0: np.ndarray) -> np.ndarray:
        """States at ``q0``, ``q_dot0``: friction filter at rest (z = q_dot), w = delta = 0."""
        q0, q_dot0 = np.asarray(q0, float), np.asarray(q_dot0, float)
        cols = [q0, q_dot0, q_dot0] if self.lag else [q0, q_dot0]
        cols += [np.zeros_like(q0)] * self.table.n_extra
        return np.stack(cols, axis=-1)

    def max_step(self) -> float:
        """Largest stable RK4 step of the friction and creep filters [s] (inf without them)."""
        positive = self.T_z[self.T_z > 0]
        out = float(1.5 * positive.min()) if self.lag and positive.size else np.inf
        if self.table.n_creep and self.table.creep_rate > 0:
            out = min(out, 1.5 / self.table.creep_rate)
        return out

    @property
    def kernel_table(self) -> TableModel:
        """The model as the compiled free-run kernel takes it: itself."""
        return self

    def mass_of(self, q: np.ndarray) -> np.ndarray:
        """Return the mass m(q) = m - sum_(j inertia) w_j q^a_j (B,) [kg] at ``q`` (B,)."""
        q = np.asarray(q, dtype=float).reshape(-1)
        m = np.broadcast_to(self.mass, q.shape).astype(float)
        if not self.table.has_inertia:
            return m
        part, _ = self.table.inertia_parts(q, np.zeros_like(q))
        return m - np.einsum("bj,bj->b", part, np.broadcast_to(self.weights, part.shape))

    def accel(
        self,
        q: np.ndarray,
        s: np.ndarray,
        v: np.ndarray,
        w: np.ndarray | None = None,
        q_dot: np.ndarray | None = None,
        position: np.ndarray | None = None,
    ) -> np.ndarray:
        """Acceleration of the model (Eq. 37 solved for q''), evaluated with NumPy.

        Parameters
        ----------
        q : ndarray, shape (B,)
            Positions [unit of q].
        s : ndarray, shape (B,)
            The friction terms' velocity: the friction state z, or q_dot without lag.
        v : ndarray, shape (B, n_inputs)
            Inputs, before the input map h(v).
        w : ndarray, shape (B, C + E), optional
            Creep and slip states (tables with them); default 0, the actuator at rest.
        q_dot : ndarray, shape (B,), optional
            Velocity [unit of q / s] of the inertia terms' ``1/2 m'(q) q_dot^2``; needed
            only by a table with inertia terms.
        position : ndarray, shape (B, J), optional
            :meth:`TermTable.position_part` of ``q`` where the caller has it (not modified).

        Returns
        -------
        ndarray, shape (B,)
            q'' = (sum_j weight_j column_j) / m(q) [unit of q / s^2] (the inertia terms in
            m(q) and their velocity-squared force, :meth:`TermTable.inertia_parts`).

        Raises
        ------
        ValueError
            If the table has inertia terms and ``q_dot`` is not given.

        References
        ----------
        Masoud & Maas 2025, Eq. 37.
        """
        if self.table.n_extra and w is None:
            w = np.zeros((np.shape(q)[0], self.table.n_extra))
        cols = self.table.columns(q, s, self.table.map_inputs(v), w, position=position)
        # one row of weights (or masses) broadcasts over the trajectories: the same sums
        weights = self.weights
        acc = np.einsum("bj,bj->b", cols, weights)
        if not self.table.has_inertia:
            return acc / self.mass
        if q_dot is None:
            raise ValueError("a table with inertia terms needs q_dot for its acceleration")
        part, force = self.table.inertia_parts(q, q_dot)
        acc = acc + np.einsum("bj,bj->b", force, weights)
        mass = self.mass - np.einsum("bj,bj->b", part, weights)
        return acc / mass

    def rhs(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """State derivative (B, n_states) and acceleration (B,), evaluated with NumPy."""
        q, q_dot = x[:, 0], x[:, 1]
        if self.lag:  # one T_z (a row) or one per trajectory
            lagged = self.T_z > 0
            s = np.where(lagged, x[:, 2], q_dot)
            z_dot = np.where(
                lagged, friction_state_rate(q_dot, s, np.where(lagged, self.T_z, 1.0)), 0.0
            )
        else:
            s = q_dot
        c0 = 3 if self.lag else 2
        C = self.table.n_creep
        w = x[:, c0:] if self.table.n_extra else None
        bases = position = None
        if C:  # the creep states' rates need the bases too: evaluated once for both
            bases = self.table.bases(q)
            position = self.table.position_part(q, bases)
        acc = self.accel(q, s, v, w, q_dot, position)
        out = np.empty((q.size, c0 + self.table.n_extra))
        out[:, 0], out[:, 1] = q_dot, acc
        if self.lag:
            out[:, 2] = z_dot
        if C:
            b = bases[:, self.table.creep_base]
            out[:, c0 : c0 + C] = creep_state_rate(
                b, q_dot[:, None], self.table.creep_rate, w[:, :C]
            )
        if self.table.n_slip:
            out[:, c0 + C :] = slip_state_rate(q_dot[:, None], w[:, C:], self.table.slip_width)
        return out, acc

    def project(self, x: np.ndarray) -> np.ndarray:
        """Hold the slip states to their break-away range after a step (:func:`slip_clip`).

        Parameters
        ----------
        x : ndarray, shape (B, n_states)
            States after an RK4 step.

        Returns
        -------
        ndarray, shape (B, n_states)
            ``x`` itself without slip states, else a copy with ``|delta_e| <= Delta_e``.
        """
        if not self.table.n_slip:
            return x
        x = x.copy()
        c1 = (3 if self.lag else 2) + self.table.n_creep
        x[:, c1:] = slip_clip(x[:, c1:], self.table.slip_width)
        return x
