"""Regressor of the physics-informed RBF model (Masoud & Maas 2025, Eq. 37-40) with a backbone.

The model is written as a force balance,

    m_q q'' + F(q, z) theta_F = G(q, v) theta_G,

with the *force terms* F (restoring force c(q) q, friction d(q) z and the
backbone) on the left and the *input terms* G (g_i(q) h(v_i)) on the right.
Eq. 40 is this balance with only the RBF terms. One function builds both the
regressor rows for least squares and the right-hand side of the simulator, so
that the identified and the simulated model cannot disagree.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from debist.core.errors import WorkflowError
from debist.model.basis import RBFBasis
from debist.model.friction import creep_states
from debist.model.termtable import (
    S_CREEP,
    S_POW,
    S_TANH,
    TermTable,
    TermTableBuilder,
)

#: RBF-weighted curves: c(q) (spring), d(q) (friction), g(q) (input gains), and g_h(q) (``gh``:
#: the input force's second order in h(v), ``g_h,i(q) h(v_i)^2``).
RBF_TERMS = ("c", "d", "g", "gh")
#: Backbone force terms: name -> (description, unit of the coefficient per unit of q).
BACKBONE_TERMS = {
    "linear_spring": "k_1 q",
    "cubic_spring": "k_3 q^3",
    "viscous": "d_v z",
    "coulomb": "F_c tanh(z / v_c)",
    "offset": "F_0",
    "input_gain": "g_0,i h(v_i)",
    "input_quadratic": "g_h,i h(v_i)^2",
    "physics_spring": "s_c c_phys(q) q",
    "physics_damping": "s_d d_phys(q) z",
    "physics_gain": "s_g,i g_phys,i(q) h(v_i)",
    "physics_quadratic": "s_gh,i g_h,phys,i(q) h(v_i)^2",
    "physics_creep": "s_k,i k_phys,i(q) q_eps,i, q_eps,i' = k_phys,i(q) q_dot - lambda q_eps,i",
}
#: Backbone terms that take the analytical model's curves (a [physics] section).
PHYSICS_TERMS = (
    "physics_spring", "physics_damping", "physics_gain", "physics_quadratic", "physics_creep",
)  # fmt: skip


@dataclass(frozen=True)
class PhysicsPrior:
    """Characteristic curves of the analytical model used as the RBF model's backbone.

    The backbone terms ``physics_spring``, ``physics_damping`` and ``physics_gain`` are these
    curves times scale factors ``s_c``, ``s_d``, ``s_g,i`` identified in the same least
    squares; the RBF sums then model only the difference between prototype and analytical
    model. With ``m_q = 1`` (curves per unit mass) the scales come out near ``1 / m_q,phys``.
    ``physics_creep`` is the DEs' Maxwell creep of Eq. 26 in the analytical model's own form,
    ``s_k,i k_i(q) q_eps,i`` with the creep strains ``q_eps,i' = k_i(q) q_dot - lambda
    q_eps,i`` (extra states of a free run), linear in its scales once the analytical
    relaxation rate ``lambda = Y_MW / eta_MW`` is fixed.

    Parameters
    ----------
    q : ndarray, shape (n,)
        Ascending grid [m].
    c : ndarray, shape (n,)
        Stiffness of ``f(q) = c(q) q`` at ``v = 0`` [N/m] (Eq. 26 in the form of Eq. 33).
    d : ndarray, shape (n,)
        Damping ``d(q)`` [N s/m].
    g : ndarray, shape (n, n_inputs)
        Input gains ``g_i(q) = 1/2 dC_i/dq`` [N/V^2].
    k : ndarray, shape (n, n_inputs), optional
        Creep couplings ``k_i(q)`` of Eq. 26, the strain of DE i per unit of q [1/m]; None:
        no ``physics_creep``.
    k_bar : float, optional
        ``k_bar = V_DE Y_MW`` of Eq. 26 [N m]: the creep force is ``k_bar sum_i k_i(q)
        q_eps,i``.
    creep_rate : float, optional
        The analytical relaxation rate ``lambda = Y_MW / eta_MW`` of the creep strains [1/s].
    gh : ndarray, shape (n, n_inputs), optional
        Second order of the full model's static DE force in ``h = v_i^2``, ``g_h,i(q)``
        [N/V^4] (``physics_quadratic``): the holding-force change at ``v_i`` is ``g_i(q) v_i^2
        + g_h,i(q) v_i^4`` to 1.1 % of its largest value over 0.5-3 kV on the paper's prototype
        (:func:`debist.identify.physics_prior.quadratic_force`); None: not computed.

    References
    ----------
    Masoud & Maas 2025, Eq. 18 (Fig. 4: the force-displacement curves at held voltages), 26,
    33, 37.
    """

    q: np.ndarray
    c: np.ndarray
    d: np.ndarray
    g: np.ndarray
    k: np.ndarray | None = None
    k_bar: float = 0.0
    creep_rate: float = 0.0
    gh: np.ndarray | None = None

    def __call__(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Interpolate ``c, d`` (n,) and ``g`` (n, n_inputs) at ``q`` [m] (held outside)."""
        q = np.asarray(q, dtype=float)
        c = np.interp(q, self.q, self.c)
        d = np.interp(q, self.q, self.d)
        g = np.stack([np.interp(q, self.q, col) for col in self.g.T], axis=-1)
        return c, d, g

    def to_tree(self) -> dict[str, np.ndarray]:
        """Return the arrays for an HDF5 group (inverse: :meth:`from_tree`)."""
        tree = {"q": self.q, "c": self.c, "d": self.d, "g": self.g}
        if self.k is not None:  # only then: a prior without creep keeps its bytes
            tree.update(k=self.k, k_bar=np.array(self.k_bar), creep_rate=np.array(self.creep_rate))
        if self.gh is not None:  # only then: a prior without it keeps its bytes
            tree["gh"] = self.gh
        return tree

    @classmethod
    def from_tree(cls, tree) -> PhysicsPrior:
        """Rebuild from :meth:`to_tree` output (or its HDF5 round trip)."""
        arrays = {key: np.asarray(tree[key], dtype=float) for key in ("q", "c", "d", "g")}
        if "k" in tree:
            arrays["k"] = np.asarray(tree["k"], dtype=float)
            arrays["k_bar"] = float(np.asarray(tree["k_bar"]))
            arrays["creep_rate"] = float(np.asarray(tree["creep_rate"]))
        if "gh" in tree:
            arrays["gh"] = np.asarray(tree["gh"], dtype=float)
        return cls(**arrays)

    def quadratic(self, q: np.ndarray | None = None) -> np.ndarray:
        """Return the second-order curves ``g_h,i`` of ``physics_quadratic`` [N/V^4].

        Parameters
        ----------
        q : array_like, shape (m,), optional
            Positions [m] to interpolate at (held outside the grid); None: the grid's values.

        Returns
        -------
        ndarray, shape (n, n_inputs) or (m, n_inputs)

        Raises
        ------
        WorkflowError
            If the prior was built without them (``physics_quadratic`` not asked for).
        """
        if self.gh is None:
            raise WorkflowError(
                "backbone term physics_quadratic needs the full model's second-order DE force: "
                "a [physics] prototype and the term in [identify] backbone"
            )
        if q is None:
            return self.gh
        q = np.asarray(q, dtype=float)
        return np.stack([np.interp(q, self.q, col) for col in self.gh.T], axis=-1)

    def creep(self) -> tuple[np.ndarray, float]:
        """Return the couplings k_i (n, n_inputs) [1/m] and the rate [1/s] of ``physics_creep``.

        Raises
        ------
        WorkflowError
            If the prior has no creep curves or no positive rate (``eta_MW = 0``).
        """
        if self.k is None or not self.creep_rate > 0:
            raise WorkflowError(
                "backbone term physics_creep needs the analytical creep of Eq. 26: a [physics] "
                "prototype with Y_MW > 0 and eta_MW > 0"
            )
        return self.k, float(self.creep_rate)

    def strain(self, q: np.ndarray, q_dot: np.ndarray, dt: float) -> np.ndarray:
        """Creep strains of ``physics_creep`` along a record, from rest at its start.

        Parameters
        ----------
        q, q_dot : ndarray, shape (n,)
            Position [m] and velocity [m/s].
        dt : float
            Sample time [s].

        Returns
        -------
        ndarray, shape (n, n_inputs)
            ``q_eps,i`` with ``q_eps,i' = k_i(q) q_dot - lambda q_eps,i`` [-]
            (:func:`debist.model.friction.creep_states` with the couplings as the basis).

        Raises
        ------
        WorkflowError
            As :meth:`creep`.

        References
        ----------
        Masoud & Maas 2025, Eq. 26.
        """
        k_curves, rate = self.creep()
        k_q = np.column_stack([np.interp(q, self.q, k) for k in k_curves.T])
        return creep_states(k_q, np.asarray(q_dot, dtype=float), dt, rate)


def _prior(prior: PhysicsPrior | None) -> PhysicsPrior:
    if prior is None:
        raise WorkflowError(
            f"backbone terms {PHYSICS_TERMS} need the analytical model: add a [physics] section"
        )
    return prior


def check_terms(rbf: Sequence[str], backbone: Sequence[str]) -> None:
    """Validate term names.

    Parameters
    ----------
    rbf : sequence of str
        Subset of :data:`RBF_TERMS`.
    backbone : sequence of str
        Subset of :data:`BACKBONE_TERMS`.

    Raises
    ------
    WorkflowError
        Naming the unknown or duplicated term.
    """
    for name in rbf:
        if name not in RBF_TERMS:
            raise WorkflowError(f"unknown RBF term {name!r}; choose from {RBF_TERMS}")
    for name in backbone:
        if name not in BACKBONE_TERMS:
            raise WorkflowError(
                f"unknown backbone term {name!r}; choose from {tuple(BACKBONE_TERMS)}"
            )
    for seq in (rbf, backbone):
        if len(set(seq)) != len(seq):
            raise WorkflowError(f"duplicated term in {list(seq)}")


def column_names(
    rbf: Sequence[str],
    backbone: Sequence[str],
    M: int,
    n_inputs: int,
    creep: bool = False,
    n_slip: int = 0,
    inertia: Sequence[int] = (),
) -> tuple[list[str], list[str]]:
    """Names of the regressor columns of Eq. 40 with the backbone, in their order.

    Parameters
    ----------
    rbf, backbone : sequence of str
        Active terms.
    M : int
        Number of RBF centres.
    n_inputs : int
        Number of inputs.
    creep : bool, optional
        Whether the model has the creep force ``sum_i creep[i] w_i`` (Eq. 26 in the RBF
        basis: ``creep[i]`` after the ``d[i]``).
    n_slip : int, optional
        Number of Maxwell-slip elements: their force ``sum_e slip[e] delta_e`` follows the
        creep terms (Al-Bender, Lampaert & Swevers 2005).
    inertia : sequence of int, optional
        Powers a of the position-dependent inertia m(q) = m_q + sum_a inertia[a] q^a: its
        columns ``inertia[a]`` (``q^a q'' + 1/2 a q^(a-1) q_dot^2``) follow the slip terms.

    Returns
    -------
    force : list of str
        The force terms F(q, z) (left of the balance): ``c[i]``, ``d[i]``, then the
        backbone's ``linear_spring``, ``cubic_spring``, ``viscous``, ``coulomb``,
        ``offset``, ``physics_spring``, ``physics_damping`` (in the order given), then
        ``physics_creep<j>``.
    inputs : list of str
        The input terms G(q, v) (right of the balance): ``g<j>[i]``, ``gh<j>[i]``,
        ``input_gain<j>``, ``input_quadratic<j>``, ``physics_gain<j>``,
        ``physics_quadratic<j>``.

    References
    ----------
    Masoud & Maas 2025, Eq. 40.
    """
    force: list[str] = []
    if "c" in rbf:
        force += [f"c[{i}]" for i in range(M)]
    if "d" in rbf:
        force += [f"d[{i}]" for i in range(M)]
    if creep:
        force += [f"creep[{i}]" for i in range(M)]
    force += [f"slip[{e}]" for e in range(n_slip)]
    force += [f"inertia[{a}]" for a in inertia]
    force += [name for name in backbone if name in _FORCE_SCALARS or name in _PHYSICS_FORCE]
    if "physics_creep" in backbone:
        force += [f"physics_creep{j + 1}" for j in range(n_inputs)]
    inputs: list[str] = []
    if "g" in rbf:
        inputs += [f"g{j + 1}[{i}]" for j in range(n_inputs) for i in range(M)]
    if "gh" in rbf:
        inputs += [f"gh{j + 1}[{i}]" for j in range(n_inputs) for i in range(M)]
    if "input_gain" in backbone:
        inputs += [f"input_gain{j + 1}" for j in range(n_inputs)]
    if "input_quadratic" in backbone:
        inputs += [f"input_quadratic{j + 1}" for j in range(n_inputs)]
    if "physics_gain" in backbone:
        inputs += [f"physics_gain{j + 1}" for j in range(n_inputs)]
    if "physics_quadratic" in backbone:
        inputs += [f"physics_quadratic{j + 1}" for j in range(n_inputs)]
    return force, inputs


def force_table(
    basis: RBFBasis,
    rbf: Sequence[str],
    backbone: Sequence[str],
    coulomb_velocity: float,
    prior: PhysicsPrior | None = None,
    *,
    n_strain: int = 1,
    creep: bool = False,
    n_slip: int = 0,
    inertia: Sequence[int] = (),
) -> tuple[TermTable, list[str]]:
    """Build the term table of the force terms F(q, z) with its column names (Eq. 37).

    Parameters
    ----------
    basis : RBFBasis
        The RBF basis (Eq. 38).
    rbf, backbone : sequence of str
        Active terms.
    coulomb_velocity : float
        v_c of the smoothed Coulomb term [unit of q / s].
    prior : PhysicsPrior, optional
        The analytical model's curves (needed by the ``physics_*`` terms).
    n_strain : int, optional
        Number of creep strains of ``physics_creep``.
    creep : bool, optional
        Whether the RBF creep columns ``creep[i]`` are included.
    n_slip : int, optional
        Number of Maxwell-slip elements.
    inertia : sequence of int, optional
        Powers of the inertia columns.

    Returns
    -------
    table : TermTable
        One term per column, in the order of ``names`` (inputs: one, idle).
    names : list of str
        The column names (:func:`column_names`).

    Raises
    ------
    WorkflowError
        If a ``physics_*`` term lacks ``prior``.

    References
    ----------
    Masoud & Maas 2025, Eq. 37-40.
    """
    names, _ = column_names(
        rbf, backbone, basis.M, n_strain, creep=creep, n_slip=n_slip, inertia=inertia
    )
    return term_table(names, basis, 1, "v", coulomb_velocity, prior), names


def force_columns(
    q: np.ndarray,
    z: np.ndarray,
    basis: RBFBasis,
    rbf: Sequence[str],
    backbone: Sequence[str],
    coulomb_velocity: float,
    prior: PhysicsPrior | None = None,
    w: np.ndarray | None = None,
    slip: np.ndarray | None = None,
    inertia: Sequence[int] = (),
    q_dot: np.ndarray | None = None,
    q_ddot: np.ndarray | None = None,
    strain: np.ndarray | None = None,
) -> tuple[np.ndarray, list[str]]:
    """Columns of the force terms F(q, z) (left-hand side of the balance).

    Parameters
    ----------
    q, z : ndarray, shape (n,)
        Position [unit of q] and friction state [unit of q / s].
    basis : RBFBasis
        The RBF basis (Eq. 38).
    rbf, backbone : sequence of str
        Active terms.
    coulomb_velocity : float
        v_c of the smoothed Coulomb term [unit of q / s].
    prior : PhysicsPrior, optional
        The analytical model's curves (needed by the ``physics_*`` terms).
    w : ndarray, shape (n, M), optional
        The creep states [unit of q] (:func:`debist.model.friction.creep_states`): ``creep[i]``.
    slip : ndarray, shape (n, E), optional
        The Maxwell-slip deflections [unit of q] (:func:`debist.model.friction.slip_states`).
    inertia : sequence of int, optional
        Powers a of the inertia: columns ``q^a q'' + 1/2 a q^(a-1) q_dot^2``.
    q_dot, q_ddot : ndarray, shape (n,), optional
        Velocity [unit of q / s] and acceleration [unit of q / s^2] (needed with ``inertia``).
    strain : ndarray, shape (n, n_inputs), optional
        The creep strains q_eps,i of ``physics_creep`` [-].

    Returns
    -------
    columns : ndarray, shape (n, p_F)
        ``[Phi q, Phi z, W, q, q^3, z, tanh(z/v_c), 1, c_phys q, d_phys z]`` restricted to
        active terms; slip and inertia columns follow the creep columns ``W``.
    names : list of str
        One name per column (:func:`column_names`).

    Raises
    ------
    WorkflowError
        If a ``physics_*`` term lacks ``prior``, or ``physics_creep`` lacks ``strain``.
    """
    q = np.asarray(q, dtype=float)
    n_slip = 0 if slip is None else slip.shape[1]
    if "physics_creep" in backbone and strain is None:
        raise WorkflowError("the physics_creep columns need the creep strains along the record")
    n_strain = 1 if strain is None else strain.shape[1]
    if inertia and (q_dot is None or q_ddot is None):
        raise WorkflowError("the inertia columns need the velocity and the acceleration")
    table, names = force_table(
        basis, rbf, backbone, coulomb_velocity, prior,
        n_strain=n_strain, creep=w is not None, n_slip=n_slip, inertia=inertia,
    )  # fmt: skip
    # the states in the table's order: RBF creep, the physics creep strains, the slip elements
    states = [a for a in (w, strain, slip) if a is not None]
    extra = np.hstack(states) if states else None
    return table.columns(q, z, np.zeros((q.size, 1)), extra, q_dot, q_ddot), names


def input_columns(
    q: np.ndarray,
    hv: np.ndarray,
    basis: RBFBasis,
    rbf: Sequence[str],
    backbone: Sequence[str],
    prior: PhysicsPrior | None = None,
) -> tuple[np.ndarray, list[str]]:
    """Columns of the input terms G(q, v) (right-hand side of the balance).

    Parameters
    ----------
    q : ndarray, shape (n,)
        Position [unit of q].
    hv : ndarray, shape (n, n_inputs)
        Mapped inputs h(v_i) [V^2 or V].
    basis : RBFBasis
        The RBF basis.
    rbf, backbone : sequence of str
        Active terms (``"g"``, ``"input_gain"`` and ``"physics_gain"`` matter here).
    prior : PhysicsPrior, optional
        The analytical model's curves (needed by ``physics_gain``).

    Returns
    -------
    columns : ndarray, shape (n, p_G)
        ``[Phi h(v_1), ..., Phi h(v_N), h(v_1), ..., h(v_N), g_phys,i h(v_i)]`` for the
        active terms (:func:`term_table`).
    names : list of str
        ``"g1[i]"``, ``"input_gain1"`` and ``"physics_gain1"`` style names.

    Raises
    ------
    WorkflowError
        If ``physics_gain`` is active without ``prior``.
    """
    q = np.asarray(q, dtype=float)
    hv = np.asarray(hv, dtype=float)
    _, names = column_names(rbf, backbone, basis.M, hv.shape[1])
    table = term_table(names, basis, hv.shape[1], "v", 1.0, prior)
    return table.columns(q, np.zeros_like(q), hv), names


#: Analytical-curve terms on the force side.
_PHYSICS_FORCE = ("physics_spring", "physics_damping")
#: Backbone terms on the force side (left of the balance), with their (qpow, s factor).
_FORCE_SCALARS = {
    "linear_spring": (1, None),
    "cubic_spring": (3, None),
    "viscous": (0, "z"),
    "coulomb": (0, "tanh"),
    "offset": (0, None),
}


#: Name prefixes of the input terms G(q, v), right of the balance (weight +theta).
INPUT_TERMS = ("g", "input_gain", "input_quadratic", "physics_gain", "physics_quadratic")


def term_sign(name: str) -> float:
    """Sign of a term's weight in the acceleration: -1 on the force side, +1 for inputs.

    Parameters
    ----------
    name : str
        A regressor column name (``"c[3]"``, ``"g2[0]"``, ``"viscous"``, ``"input_gain1"``).

    Returns
    -------
    float
        ``+1.0`` for the input terms (:data:`INPUT_TERMS`), else ``-1.0``.
    """
    return 1.0 if name.startswith(INPUT_TERMS) else -1.0


def term_table(
    names: Sequence[str],
    basis: RBFBasis,
    n_inputs: int,
    input_map_kind: str,
    coulomb_velocity: float,
    prior: PhysicsPrior | None = None,
    creep_rate: float = 0.0,
    slip_width: Sequence[float] | None = None,
) -> TermTable:
    """Build the term library of Eq. 37: one term per regressor column name, as a term table.

    The one definition of the model's terms (regressor columns, right-hand sides, refinement).

    Parameters
    ----------
    names : sequence of str
        Column names as :func:`force_columns` and :func:`input_columns` give them (``c[i]``,
        ``d[i]``, ``g<j>[i]``, backbone and ``physics_*`` names, ``creep[i]``, ``slip[e]``,
        ``inertia[a]``; the table: docs/explanation/terms.md).
    basis : RBFBasis
        Centres and width (Eq. 38-39); ``outside = "clip"`` holds q at the range's edge.
    n_inputs, input_map_kind : int, {"v2", "v"}
        Number of inputs; h(v).
    coulomb_velocity : float
        v_c [unit of q / s].
    prior : PhysicsPrior, optional
        The analytical curves of the ``physics_*`` terms.
    creep_rate : float, optional
        Relaxation rate lambda = Y_MW / eta_MW of the creep states [1/s].
    slip_width : sequence of float, optional
        Break-away deflections Delta_e [unit of q], one per ``slip[e]``; None: a table for
        regressor columns only (the ``slip[e]`` terms read their states by index).

    Returns
    -------
    TermTable
        Terms in the order of ``names``; the velocity-like variable ``s`` is z.

    Raises
    ------
    WorkflowError
        For an unknown name, or a ``physics_*`` term without ``prior``.

    References
    ----------
    Masoud & Maas 2025, Eq. 37-40.
    """
    lo, hi = (basis.xi[0], basis.xi[-1]) if basis.outside == "clip" else (-np.inf, np.inf)
    build = TermTableBuilder(n_inputs, input_map_kind, coulomb_velocity, creep_rate)
    prior_base: dict[str, int] = {}

    def gauss(k: int) -> int:
        return build.gauss(basis.xi[k], basis.sigma, lo, hi)  # shared by c, d, g of centre k

    if any(name.startswith("creep[") for name in names):
        for k in range(basis.M):  # creep state k filters Phi_k q_dot, whichever terms are kept
            build.creep(gauss(k))

    def tabulated(key: str, column: np.ndarray) -> int:
        if key not in prior_base:
            prior_base[key] = build.table(_prior(prior).q, column)
        return prior_base[key]

    strain: list[int] = []
    if any(name.startswith("physics_creep") for name in names):
        k_curves, _ = _prior(prior).creep()  # strain i filters k_i(q) q_dot (Eq. 26)
        strain = [build.creep(tabulated(f"k{j}", k)) for j, k in enumerate(k_curves.T)]
        k_bar = _prior(prior).k_bar

    def h(j: int) -> list[int]:
        out = [0] * n_inputs
        out[j] = 1
        return out

    for name in names:
        rbf, _, index = name.partition("[")
        if index:
            k = int(index[:-1])
            if rbf == "c":
                build.term(name, gauss(k), qpow=1)
            elif rbf == "d":
                build.term(name, gauss(k), skind=S_POW, spow=1)
            elif rbf == "creep":
                build.term(name, build.one(), skind=S_CREEP, spow=k)
            elif rbf == "slip":
                if slip_width is None:  # columns only: distinct stand-in deflections
                    build.term(name, build.one(), skind=S_CREEP, spow=build.slip(k + 1.0))
                    continue
                if k >= len(slip_width):
                    raise WorkflowError(f"term {name!r} has no break-away deflection")
                build.term(name, build.one(), skind=S_CREEP, spow=build.slip(slip_width[k]))
            elif rbf == "inertia":
                build.inertia(name, k)
            elif rbf.startswith("g") and rbf[1:].isdigit():
                build.term(name, gauss(k), hpow=h(int(rbf[1:]) - 1))
            elif rbf.startswith("gh") and rbf[2:].isdigit():
                build.term(name, gauss(k), hpow=[2 * p for p in h(int(rbf[2:]) - 1)])
            else:
                raise WorkflowError(f"unknown term {name!r}")
        elif name in _FORCE_SCALARS:
            qpow, s = _FORCE_SCALARS[name]
            skind = {None: 0, "z": S_POW, "tanh": S_TANH}[s]
            build.term(name, build.one(), qpow=qpow, skind=skind, spow=int(s == "z"))
        elif name.startswith("input_gain"):
            build.term(name, build.one(), hpow=h(int(name[len("input_gain") :]) - 1))
        elif name.startswith("input_quadratic"):
            j = int(name[len("input_quadratic") :]) - 1
            build.term(name, build.one(), hpow=[2 * p for p in h(j)])
        elif name == "physics_spring":
            build.term(name, tabulated("c", _prior(prior).c), qpow=1)
        elif name == "physics_damping":
            build.term(name, tabulated("d", _prior(prior).d), skind=S_POW, spow=1)
        elif name.startswith("physics_gain"):
            j = int(name[len("physics_gain") :]) - 1
            build.term(name, tabulated(f"g{j}", _prior(prior).g[:, j]), hpow=h(j))
        elif name.startswith("physics_quadratic"):
            j = int(name[len("physics_quadratic") :]) - 1
            curve = _prior(prior).quadratic()[:, j]
            build.term(name, tabulated(f"gh{j}", curve), hpow=[2 * p for p in h(j)])
        elif name.startswith("physics_creep") and strain:
            j = int(name[len("physics_creep") :]) - 1
            force_j = tabulated(f"k_bar k{j}", k_bar * _prior(prior).k[:, j])
            build.term(name, force_j, skind=S_CREEP, spow=strain[j])
        else:
            raise WorkflowError(f"unknown term {name!r}")
    return build.build()
