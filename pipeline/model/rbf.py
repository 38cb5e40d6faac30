"""The identified physics-informed RBF model (Masoud & Maas 2025, Eq. 37), ready to simulate."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np

from debist.core.errors import ArtifactError
from debist.model.basis import RBFBasis
from debist.model.friction import (
    creep_states,
    friction_state,
    slip_states,
)
from debist.model.terms import PhysicsPrior, term_sign, term_table
from debist.model.termtable import TableModel, input_map

#: Backbone entries stored as vectors (one value per input).
_VECTORS = ("g_0", "g_h", "s_g", "s_gh", "s_k")


def _shape(group: Any, key: str, where: str) -> tuple[int, ...]:
    """Return the shape of a numeric dataset, or say in one line what is wrong with it."""
    if not isinstance(group, dict) or key not in group:
        raise ArtifactError(f"{where}/{key}: missing")
    try:
        return np.asarray(group[key], dtype=float).shape
    except (TypeError, ValueError):
        raise ArtifactError(f"{where}/{key}: not numeric") from None


def check_model_tree(tree: Any, source: str = "model.h5") -> None:
    """Check the shapes of a stored model's arrays against its centres and inputs.

    With M centres (``model/xi``, shape (M,)) and N = ``n_inputs``: ``theta_c``,
    ``theta_d`` and ``creep/theta_creep`` have shape (M,); ``theta_g`` and ``theta_gh``
    (N, M); the backbone's ``g_0``, ``g_h``, ``s_g``, ``s_gh`` one value or N values;
    ``slip/width`` and ``slip/theta_slip`` the same length E; ``inertia/theta_inertia``
    and ``backbone/s_k`` one axis.

    Parameters
    ----------
    tree : dict
        As read by :func:`debist.core.artifacts.read_h5` from an identify stage's
        ``model.h5``.
    source : str, optional
        The file, for the message.

    Raises
    ------
    ArtifactError
        Naming ``source`` and the first dataset or attribute that is missing, not numeric
        or of the wrong shape (e.g. ``model/theta_g has shape (2, 7), expected (2, 6)``).

    References
    ----------
    Masoud & Maas 2025, Eq. 38-40 (one weight per centre for each curve).
    """
    try:
        _check_model_tree(tree)
    except ArtifactError as exc:
        raise ArtifactError(f"'{source}': {exc}; not a model debist wrote") from None


def _check_model_tree(tree: Any) -> None:
    m = tree.get("model") if isinstance(tree, dict) else None
    if not isinstance(m, dict):
        raise ArtifactError("group 'model' missing")
    attrs = m.get("attrs", {})
    for key in ("sigma", "n_inputs", "m_q", "T_z", "coulomb_velocity", "q_min", "q_max"):
        if _shape(attrs, key, "model attribute") != ():
            raise ArtifactError(f"model attribute {key}: not one number")
    n = float(np.asarray(attrs["n_inputs"], dtype=float))
    if not (n >= 1 and n == int(n)):
        raise ArtifactError(f"model attribute n_inputs: {n:g}, expected a count >= 1")
    n = int(n)
    xi = _shape(m, "xi", "model")
    if len(xi) != 1 or xi[0] < 1:
        raise ArtifactError(f"model/xi has shape {xi}, expected (M,) with M >= 1")
    (M,) = xi
    wanted = {("model", "theta_c"): (M,), ("model", "theta_d"): (M,)}
    wanted[("model", "theta_g")] = (n, M)
    if "theta_gh" in m:
        wanted[("model", "theta_gh")] = (n, M)
    if m.get("creep") is not None:
        wanted[("model/creep", "theta_creep")] = (M,)
    for (where, key), shape in wanted.items():
        group = m if where == "model" else m["creep"]
        got = _shape(group, key, where)
        if got != shape:
            raise ArtifactError(f"{where}/{key} has shape {got}, expected {shape}")
    backbone = m.get("backbone")
    _shape(backbone, "g_0", "model/backbone")
    for key in ("g_0", "g_h", "s_g", "s_gh"):
        if key in backbone:
            got = _shape(backbone, key, "model/backbone")
            if got not in ((), (1,), (n,)):
                raise ArtifactError(f"model/backbone/{key} has shape {got}, expected ({n},)")
    if "s_k" in backbone and len(_shape(backbone, "s_k", "model/backbone")) > 1:
        raise ArtifactError("model/backbone/s_k: expected one axis")
    if m.get("slip") is not None:
        width = _shape(m["slip"], "width", "model/slip")
        theta = _shape(m["slip"], "theta_slip", "model/slip")
        if len(width) != 1 or theta != width:
            raise ArtifactError(
                f"model/slip/theta_slip has shape {theta}, model/slip/width {width}: "
                "expected the same (E,)"
            )
    if m.get("inertia") is not None:
        got = _shape(m["inertia"], "theta_inertia", "model/inertia")
        if len(got) != 1:
            raise ArtifactError(f"model/inertia/theta_inertia has shape {got}, expected (N,)")


@dataclass(frozen=True)
class RBFModel:
    """m_q q'' + d(q) z + c(q) q + F_c tanh(z/v_c) + F_0 = sum_i g_i(q) h(v_i), z' = (q' - z)/T_z.

    The fitted form of Eq. 37: RBF curves (Eq. 38) plus backbone terms, and optionally creep,
    Maxwell-slip and inertia terms (docs/explanation/terms.md). The stored g_i follow Eq. 33 and
    40, g_i = 1/2 dC_i/dq (docs/interpretation.md item 8).

    Parameters
    ----------
    basis : RBFBasis
        Centres and width; evaluation outside the range per ``basis.outside``.
    input_map, n_inputs : {"v2", "v"}, int
        h(v) = v^2 or v; number of inputs v_1..v_N.
    m_q, T_z : float
        Generalised mass [kg] (1: curves per unit mass); friction time constant [s] (0: z = q').
    coulomb_velocity : float
        v_c of the smoothed Coulomb term [unit of q / s].
    theta_c, theta_d : ndarray, shape (M,)
        RBF weights of c(q) [N/m] and d(q) [N s/m] (zeros when inactive).
    theta_g, theta_gh : ndarray, shape (n_inputs, M)
        RBF weights of g_i(q) [N/V^2 or N/V] and of g_h,i(q) [N/V^4] (None: no ``gh``).
    backbone : dict of str to float or list
        ``k_1`` [N/m], ``k_3`` [N/m^3], ``d_v`` [N s/m], ``F_c``, ``F_0`` [N], ``g_0``, ``g_h``
        (per input) and the scales ``s_c``, ``s_d``, ``s_g``, ``s_gh`` [-]; absent terms are 0.
    q_range : tuple of float
        Range of q in the estimation data [unit of q].
    prior : PhysicsPrior or None
        The analytical model's curves ``c_phys, d_phys, g_phys`` when the backbone uses them.
    creep_rate, theta_creep : float, ndarray of shape (M,) or None
        Relaxation rate lambda of the creep states [1/s] (0: none); their weights [N/unit of q].
    slip_width, theta_slip : tuple of float, ndarray of shape (E,) or None
        Break-away deflections Delta_e [unit of q] (empty: none); stiffnesses k_e [N/unit of q].
    theta_inertia : ndarray, shape (N,) or None
        Coefficients mu_a of m(q) = m_q + sum_a mu_a q^a [kg/unit of q^a]; None: constant m_q.

    References
    ----------
    Masoud & Maas 2025, Eq. 33, 37-40; Al-Bender, Lampaert & Swevers 2005 (slip elements).
    """

    basis: RBFBasis
    input_map: str
    n_inputs: int
    m_q: float
    T_z: float
    coulomb_velocity: float
    theta_c: np.ndarray
    theta_d: np.ndarray
    theta_g: np.ndarray
    backbone: dict[str, Any] = field(default_factory=dict)
    q_range: tuple[float, float] = (0.0, 0.0)
    prior: PhysicsPrior | None = None
    creep_rate: float = 0.0
    theta_creep: np.ndarray | None = None
    slip_width: tuple[float, ...] = ()
    theta_slip: np.ndarray | None = None
    theta_inertia: np.ndarray | None = None
    theta_gh: np.ndarray | None = None

    @property
    def has_inertia(self) -> bool:
        """Whether the mass depends on q (``theta_inertia`` given)."""
        return self.theta_inertia is not None and len(self.theta_inertia) > 0

    def mass(self, q: np.ndarray) -> np.ndarray:
        """Return the inertia m(q) = m_q + sum_a mu_a q^a [kg] at ``q`` (n,) [unit of q], (n,).

        References
        ----------
        Masoud & Maas 2025, Eq. 26 (the reduced model's m_q(q)); constant m_q in Eq. 37.
        """
        q = np.asarray(q, dtype=float)
        return self._table.mass_of(q.reshape(-1)).reshape(q.shape)  # the engines' m(q)

    @property
    def has_creep(self) -> bool:
        """Whether the model has the RBF creep states (``creep_rate > 0``, ``theta_creep``)."""
        return self.creep_rate > 0 and self.theta_creep is not None

    @property
    def has_physics_creep(self) -> bool:
        """Whether the model has the analytical creep strains (backbone ``physics_creep``)."""
        return "s_k" in self.backbone

    @property
    def has_slip(self) -> bool:
        """Whether the model has Maxwell-slip elements."""
        return len(self.slip_width) > 0

    @property
    def n_states(self) -> int:
        """States: 3, plus M with creep, plus n_inputs with ``physics_creep``, plus E slip.

        ``[q, q_dot, z]``, the RBF creep states, the creep strains of ``physics_creep`` (one
        per input) and the slip elements' deflections, in that order.
        """
        strains = self.n_inputs if self.has_physics_creep else 0
        return 3 + (self.basis.M if self.has_creep else 0) + strains + len(self.slip_width)

    def slip_elements(self) -> dict[str, np.ndarray]:
        """Return the Maxwell-slip elements as physics: deflection, stiffness and slip force.

        Returns
        -------
        dict
            ``Delta`` (E,) break-away deflections [unit of q], ``k`` (E,) stiffnesses
            [N per unit of q, or per unit mass with m_q = 1], ``F`` (E,) = k Delta, each
            element's slip force [N]; ``F_total`` their sum (the friction of gross sliding)
            and ``k_total`` the presliding stiffness at rest [N per unit of q]. Empty
            arrays without elements.

        References
        ----------
        Al-Bender, Lampaert & Swevers 2005, Sec. II.
        """
        width = np.asarray(self.slip_width, dtype=float)
        k = np.zeros(0) if self.theta_slip is None else np.asarray(self.theta_slip, float)
        force = k * width
        return {"Delta": width, "k": k, "F": force, "F_total": float(force.sum()),
                "k_total": float(k.sum())}  # fmt: skip

    def curves(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Evaluate the identified characteristic curves.

        Parameters
        ----------
        q : array_like, shape (n,)
            Positions [unit of q].

        Returns
        -------
        dict
            ``c`` (n,) [N/m], ``d`` (n,) [N s/m], ``g`` (n, n_inputs), ``cq``
            = c(q) q (n,) [N] and ``dC_dq`` = 2 g (n, n_inputs) [F/m when h = v^2].
        """
        q = np.asarray(q, dtype=float)
        phi = self.basis(q)
        bb = self.backbone
        c = phi @ self.theta_c + bb.get("k_1", 0.0) + bb.get("k_3", 0.0) * q**2
        d = phi @ self.theta_d + bb.get("d_v", 0.0)
        g = phi @ self.theta_g.T + np.asarray(bb.get("g_0", np.zeros(self.n_inputs)))
        if self.prior is not None:
            c_p, d_p, g_p = self.prior(q)
            c, d = c + bb.get("s_c", 0.0) * c_p, d + bb.get("s_d", 0.0) * d_p
            g = g + g_p * np.asarray(bb.get("s_g", 0.0))
        return {"c": c, "d": d, "g": g, "cq": c * q, "dC_dq": 2.0 * g}

    def static_force(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Return the static force at a held input level, zero where the beam is at rest.

        ``F(q; v) = c(q) q + F_0 - sum_i (g_i(q) h(v_i) + g_h,i(q) h(v_i)^2)``: the force-side
        terms at rest (z = 0, q_dot = 0, creep and slip states relaxed) minus the input terms.

        Parameters
        ----------
        q : array_like, shape (n,)
            Positions [unit of q].
        v : array_like, shape (n_inputs,)
            The held inputs [V].

        Returns
        -------
        ndarray, shape (n,)
            F [N, or unit of q / s^2 per unit mass]; its zeros are the equilibria at ``v``.

        References
        ----------
        Masoud & Maas 2025, Eq. 37 at rest, Fig. 4 (force-displacement curves).
        """
        q = np.atleast_1d(np.asarray(q, dtype=float))
        h = input_map(np.asarray(v, dtype=float).reshape(-1), self.input_map)
        cur = self.curves(q)
        quad = self.quadratic_gain(q) @ h**2
        return cur["cq"] + float(self.backbone.get("F_0", 0.0)) - cur["g"] @ h - quad

    def quadratic_gain(self, q: np.ndarray) -> np.ndarray:
        """Return the input force's second order in h(v_i), ``g_h,i(q)``, at ``q``.

        The input force of the model is ``sum_i (g_i(q) h(v_i) + g_h,i(q) h(v_i)^2)``: Eq. 37's
        separable ``g_i(q) h(v_i)`` (the small-signal gain, :meth:`curves`) and its next order,
        ``g_h,i(q) = g_h,i + Phi(q) theta_gh,i + s_gh,i g_h,phys,i(q)`` (the backbone terms
        ``input_quadratic`` and ``physics_quadratic``, the RBF term ``gh``). On a DE actuator
        the large-signal force departs from the separable one because the DEs' pull bends the
        beam off the v = 0 path (the force-displacement curves of Fig. 4 at 3 kV are 72-97 % of
        ``1/2 dC_i/dq v^2`` between q = 0 and the wells on the paper's prototype), by an amount
        that depends on q.

        Parameters
        ----------
        q : array_like, shape (n,)
            Positions [unit of q].

        Returns
        -------
        ndarray, shape (n, n_inputs)
            ``g_h,i(q)`` [N/V^4 with h = v^2]; zeros for a model with neither term.

        References
        ----------
        Masoud & Maas 2025, Eq. 37 (the separable input force) and Fig. 4.
        """
        q = np.atleast_1d(np.asarray(q, dtype=float))
        g_h = np.asarray(self.backbone.get("g_h", np.zeros(self.n_inputs)), dtype=float)
        out = np.broadcast_to(g_h, (q.size, self.n_inputs)).copy()
        if self.theta_gh is not None:
            out += self.basis(q) @ np.asarray(self.theta_gh, dtype=float).T
        if "s_gh" in self.backbone and self.prior is not None:
            out += self.prior.quadratic(q) * np.asarray(self.backbone["s_gh"], dtype=float)
        return out

    def accel(
        self,
        q: np.ndarray,
        z: np.ndarray,
        v: np.ndarray,
        creep: np.ndarray | None = None,
        q_dot: np.ndarray | None = None,
    ) -> np.ndarray:
        """Acceleration of Eq. 37 solved for q'', through the model's term table.

        Parameters
        ----------
        q : ndarray, shape (B,)
            Positions [unit of q].
        z : ndarray, shape (B,)
            Friction states [unit of q / s] (q_dot where ``T_z = 0``).
        v : ndarray, shape (B, n_inputs)
            Inputs [V].
        creep : ndarray, shape (B, M), optional
            Creep states w [unit of q] (models with creep); default 0 (at rest).
        q_dot : ndarray, shape (B,), optional
            Velocity [unit of q / s] of the Lagrangian force 1/2 m'(q) q_dot^2 (models with
            a position-dependent inertia; default z).

        Returns
        -------
        ndarray, shape (B,)
            q'' [unit of q / s^2]: :meth:`debist.model.termtable.TableModel.accel` of
            :meth:`table_model`, the one evaluation of Eq. 37 the engines share.
        """
        if q_dot is None and self.has_inertia:
            q_dot = z
        return self._table.accel(q, z, v, creep, q_dot)

    @cached_property
    def _table(self):
        """The term table of :meth:`table_model`, built once."""
        return self.table_model()

    def parameters(self) -> tuple[list[str], np.ndarray]:
        """Return the model's terms and their values, as regressor column names and parameters.

        Returns
        -------
        names : list of str
            Column names of the term library (:func:`debist.model.terms.term_table`):
            the RBF terms of every curve with a nonzero weight, then the backbone terms the
            model has.
        values : ndarray, shape (len(names),)
            Their parameters, in the sign convention of the regression (force terms on the
            left of the balance, input terms on the right).
        """
        names: list[str] = []
        values: list[float] = []
        M = self.basis.M

        def add(prefix: str, theta: np.ndarray) -> None:
            if np.any(theta):
                names.extend(f"{prefix}[{k}]" for k in range(M))
                values.extend(theta.tolist())

        add("c", self.theta_c)
        add("d", self.theta_d)
        if self.has_creep:  # every creep state, so that the state vector is [q, q_dot, z, w]
            names.extend(f"creep[{k}]" for k in range(M))
            values.extend(np.asarray(self.theta_creep, dtype=float).tolist())
        if self.has_slip:  # every element, so that the states are [.., delta_1..delta_E]
            names.extend(f"slip[{e}]" for e in range(len(self.slip_width)))
            values.extend(np.asarray(self.theta_slip, dtype=float).tolist())
        if self.has_inertia:  # the powers the fit had (a power left out has mu_a = 0)
            for a, mu in enumerate(np.asarray(self.theta_inertia, dtype=float), start=1):
                if mu:
                    names.append(f"inertia[{a}]")
                    values.append(float(mu))
        for j in range(self.n_inputs):
            add(f"g{j + 1}", self.theta_g[j])
        if self.theta_gh is not None:
            for j in range(self.n_inputs):
                add(f"gh{j + 1}", self.theta_gh[j])
        bb = self.backbone
        scalars = {"k_1": "linear_spring", "k_3": "cubic_spring", "d_v": "viscous",
                   "F_c": "coulomb", "F_0": "offset", "s_c": "physics_spring",
                   "s_d": "physics_damping"}  # fmt: skip
        for sym, name in scalars.items():
            if sym in bb:
                names.append(name)
                values.append(float(bb[sym]))
        pairs = (
            ("g_0", "input_gain"), ("g_h", "input_quadratic"), ("s_g", "physics_gain"),
            ("s_gh", "physics_quadratic"),
        )  # fmt: skip
        for sym, name in pairs:
            for j, value in enumerate(np.atleast_1d(bb.get(sym, ()))):
                if value:
                    names.append(f"{name}{j + 1}")
                    values.append(float(value))
        for j, value in enumerate(np.atleast_1d(bb.get("s_k", ()))):  # every strain's term
            names.append(f"physics_creep{j + 1}")
            values.append(float(value))
        return names, np.asarray(values, dtype=float)

    def table_model(self):
        """Return the model as a term table with its weights (a ``TableModel``).

        Returns
        -------
        TableModel
            Terms of :meth:`parameters`, weights ``-theta`` (force side) or ``+theta``
            (inputs), mass ``m_q``, this ``T_z``, with the friction state z (and the creep
            states with their rate lambda).

        References
        ----------
        Masoud & Maas 2025, Eq. 37.
        """
        return self.replicate_table([], np.zeros((1, 0)))  # the model itself: no deviation

    def replicate_table(self, columns: list[str], deviations: np.ndarray) -> TableModel:
        """Return the model with its parameters moved by each row of ``deviations``.

        One trajectory per row: the free-run model of a batch of parameter replicates (the
        block bootstrap of the least squares, :func:`debist.identify.bootstrap.block_bootstrap`),
        each the model's parameters plus one replicate's deviation from the estimate, so a
        refined model keeps its refinement and gets the bootstrap's spread around it.

        Parameters
        ----------
        columns : list of str
            Regressor column names of the fit (the term library's, as :meth:`parameters`;
            ``"m_q"`` moves the mass).
        deviations : ndarray, shape (B, len(columns))
            Replicate minus estimate, in the sign convention of the regression.

        Returns
        -------
        TableModel
            B trajectories of weights and masses (the same terms and ``T_z``).

        Raises
        ------
        ValueError
            If ``deviations`` does not have one column per name.

        References
        ----------
        Masoud & Maas 2025, Eq. 37-40; Efron & Tibshirani 1993, An Introduction to the
        Bootstrap, Ch. 6 (replicates of a statistic, here a free run).
        """
        dev = np.atleast_2d(np.asarray(deviations, dtype=float))
        if dev.shape[1] != len(columns):
            raise ValueError(f"deviations have {dev.shape[1]} columns for {len(columns)} names")
        names, values = self.parameters()
        extra = [c for c in columns if c not in names and c != "m_q"]
        names = names + extra
        index = {n: k for k, n in enumerate(names)}
        weights = np.tile(np.concatenate([values, np.zeros(len(extra))]), (dev.shape[0], 1))
        mass = np.full(dev.shape[0], self.m_q)
        for j, name in enumerate(columns):
            if name == "m_q":
                mass += dev[:, j]
            else:
                weights[:, index[name]] += dev[:, j]
        table = term_table(
            names, self.basis, self.n_inputs, self.input_map, self.coulomb_velocity, self.prior,
            creep_rate=self.creep_rate, slip_width=self.slip_width,
        )  # fmt: skip
        signs = np.array([term_sign(n) for n in names])
        return TableModel(table, signs * weights, mass, np.array([self.T_z]))

    @cached_property
    def kernel_table(self) -> TableModel:
        """The model as the compiled free-run kernel takes it (:meth:`table_model`), built once."""
        return self.table_model()

    def initial_state(self, q0: np.ndarray, q_dot0: np.ndarray) -> np.ndarray:
        """State ``[q, q_dot, z, w]`` at rest relative to the friction filter (z = q_dot).

        The creep states (with creep) start at rest, w = 0.

        Parameters
        ----------
        q0, q_dot0 : ndarray, shape (B,)
            Initial position [unit of q] and velocity [unit of q / s].

        Returns
        -------
        ndarray, shape (B, n_states)
        """
        q0 = np.asarray(q0, dtype=float)
        q_dot0 = np.asarray(q_dot0, dtype=float)
        cols = [q0, q_dot0, q_dot0]
        if self.has_creep:
            cols += [np.zeros_like(q0)] * self.basis.M
        if self.has_physics_creep:  # the creep strains relaxed
            cols += [np.zeros_like(q0)] * self.n_inputs
        cols += [np.zeros_like(q0)] * len(self.slip_width)  # the elements unloaded
        return np.stack(cols, axis=-1)

    def measured_states(self, q: np.ndarray, q_dot: np.ndarray, dt: float) -> np.ndarray:
        """States ``[q, q_dot, z]`` along a measured record, z filtered from the velocity.

        A prediction restarted at sample k needs the friction state the model would have
        there; z = q_dot (:meth:`initial_state`) holds only at rest. Here z is the measured
        velocity passed through the model's own filter z' = (q_dot - z) / T_z from the
        record's start (:func:`debist.model.friction.friction_state`), as the
        regression of Eq. 40 builds it. The creep states likewise filter phi_j(q) q_dot
        (:func:`debist.model.friction.creep_states`).

        Parameters
        ----------
        q, q_dot : ndarray, shape (n,)
            Measured position [unit of q] and velocity [unit of q / s].
        dt : float
            Sample time [s].

        Returns
        -------
        ndarray, shape (n, n_states)

        References
        ----------
        Masoud & Maas 2025, Eq. 26, 37.
        """
        q = np.asarray(q, dtype=float)
        q_dot = np.asarray(q_dot, dtype=float)
        out = np.stack([q, q_dot, friction_state(q_dot, dt, self.T_z)], axis=-1)
        if self.has_creep:
            w = creep_states(self.basis(q), q_dot, dt, self.creep_rate)
            out = np.concatenate([out, w], axis=1)
        if self.has_physics_creep:
            out = np.concatenate([out, self.prior.strain(q, q_dot, dt)], axis=1)
        if self.has_slip:
            slip = slip_states(q_dot, dt, np.asarray(self.slip_width))
            out = np.concatenate([out, slip], axis=1)
        return out

    def rhs(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """State derivative for the free-run simulator.

        Parameters
        ----------
        x : ndarray, shape (B, n_states)
            States ``[q, q_dot, z, w_1..w_M]`` (w with creep only).
        v : ndarray, shape (B, n_inputs)
            Inputs [V].

        Returns
        -------
        x_dot : ndarray, shape (B, n_states)
        q_ddot : ndarray, shape (B,)
            The acceleration (second column of ``x_dot``).
        """
        return self._table.rhs(x, v)

    def project(self, x: np.ndarray) -> np.ndarray:
        """Hold the slip states to their break-away range after a step (the stop operator).

        Parameters
        ----------
        x : ndarray, shape (B, n_states)

        Returns
        -------
        ndarray, shape (B, n_states)
            :meth:`debist.model.termtable.TableModel.project`.
        """
        return self._table.project(x)

    def max_step(self) -> float:
        """Largest stable RK4 step for the friction and creep filters [s] (inf without)."""
        out = np.inf if self.T_z == 0 else 1.5 * self.T_z
        return min(out, 1.5 / self.creep_rate) if self.creep_rate > 0 else out

    @property
    def n_params(self) -> int:
        """Number of nonzero parameters."""
        vals = [self.theta_c, self.theta_d, self.theta_g.ravel()]
        if self.has_creep:  # the weights and lambda
            vals += [np.asarray(self.theta_creep, dtype=float), np.array([self.creep_rate])]
        if self.has_slip:  # the stiffnesses (the deflections are a fixed grid)
            vals += [np.asarray(self.theta_slip, dtype=float)]
        if self.has_inertia:
            vals += [np.asarray(self.theta_inertia, dtype=float)]
        if self.theta_gh is not None:
            vals += [np.asarray(self.theta_gh, dtype=float).ravel()]
        vals += [np.atleast_1d(np.asarray(v, dtype=float)) for v in self.backbone.values()]
        # the analytical curves are given, not fitted: only their scales count
        return int(sum(np.count_nonzero(v) for v in vals))

    def scaled(self, factor: float) -> RBFModel:
        """Return the model with its mass and every weight of Eq. 37 multiplied by ``factor``.

        Every term of the balance scales alike, so the acceleration, and with it every free
        run, is unchanged; the curves, the backbone coefficients and the mass come out in the
        new scale. The analytical curves of the ``physics_*`` terms stay as given (their
        scales ``s_*`` are weights and scale).

        Parameters
        ----------
        factor : float
            The scale [-], positive.

        Returns
        -------
        RBFModel

        Raises
        ------
        ValueError
            If ``factor`` is not positive and finite.

        References
        ----------
        Masoud & Maas 2025, Eq. 37 (homogeneous of degree one in m_q and the weights).
        """
        s = float(factor)
        if not (np.isfinite(s) and s > 0):
            raise ValueError(f"scale factor {factor!r} is not positive and finite")

        def times(a):
            return None if a is None else np.asarray(a, dtype=float) * s

        backbone = {
            k: times(v) if k in _VECTORS else float(v) * s for k, v in self.backbone.items()
        }
        return replace(
            self, m_q=self.m_q * s, theta_c=times(self.theta_c), theta_d=times(self.theta_d),
            theta_g=times(self.theta_g), backbone=backbone, theta_creep=times(self.theta_creep),
            theta_slip=times(self.theta_slip), theta_inertia=times(self.theta_inertia),
            theta_gh=times(self.theta_gh),
        )  # fmt: skip

    def to_tree(self) -> dict[str, Any]:
        """Return the model as a nested mapping for an HDF5 artifact.

        Returns
        -------
        dict
            Arrays and attributes; :meth:`from_tree` restores the model.
        """
        g0 = np.asarray(self.backbone.get("g_0", np.zeros(self.n_inputs)), dtype=float)
        scalars = {k: float(v) for k, v in self.backbone.items() if k not in _VECTORS}
        backbone: dict[str, Any] = {"attrs": scalars, "g_0": g0}
        for key in ("g_h", "s_g", "s_gh", "s_k"):
            if key in self.backbone:
                backbone[key] = np.asarray(self.backbone[key], dtype=float)
        if self.prior is not None:
            backbone["prior"] = self.prior.to_tree()
        model: dict[str, Any] = {}
        if self.has_creep:  # only then: a model without creep keeps its bytes
            model["creep"] = {
                "attrs": {"creep_rate": self.creep_rate, "equation": "Masoud & Maas 2025, Eq. 26"},
                "theta_creep": np.asarray(self.theta_creep, dtype=float),
            }
        if self.has_slip:  # only then: a model without slip elements keeps its bytes
            model["slip"] = {
                "attrs": {"equation": "Al-Bender, Lampaert & Swevers 2005 (Maxwell-slip)"},
                "width": np.asarray(self.slip_width, dtype=float),
                "theta_slip": np.asarray(self.theta_slip, dtype=float),
            }
        if self.has_inertia:  # only then: a model with a constant mass keeps its bytes
            model["inertia"] = {
                "attrs": {"equation": "m(q) = m_q + sum_a theta_inertia[a-1] q^a"},
                "theta_inertia": np.asarray(self.theta_inertia, dtype=float),
            }
        if self.theta_gh is not None:
            model["theta_gh"] = np.asarray(self.theta_gh, dtype=float)
        return {
            "attrs": {"model": "rbf", "equation": "Masoud & Maas 2025, Eq. 37-40"},
            "model": {
                "attrs": {
                    "input_map": self.input_map,
                    "n_inputs": self.n_inputs,
                    "m_q": self.m_q,
                    "T_z": self.T_z,
                    "coulomb_velocity": self.coulomb_velocity,
                    "sigma": self.basis.sigma,
                    "outside": self.basis.outside,
                    "q_min": self.q_range[0],
                    "q_max": self.q_range[1],
                },
                "xi": self.basis.xi,
                "theta_c": self.theta_c,
                "theta_d": self.theta_d,
                "theta_g": self.theta_g,
                "backbone": backbone,
                **model,
            },
        }

    @classmethod
    def from_tree(cls, tree: dict[str, Any], source: str = "model.h5") -> RBFModel:
        """Rebuild a model from :meth:`to_tree` output (or its HDF5 round trip).

        Every array's shape is checked against the centres ``xi`` (M) and ``n_inputs`` first
        (:func:`check_model_tree`), so a file edited by hand fails here, naming the dataset,
        not later in a computation.

        Parameters
        ----------
        tree : dict
            As returned by :meth:`to_tree` or :func:`debist.core.artifacts.read_h5`.
        source : str, optional
            The file it was read from, for the message.

        Returns
        -------
        RBFModel

        Raises
        ------
        ArtifactError
            A dataset or attribute missing, not numeric, or of the wrong shape, naming
            ``source`` and the dataset.
        """
        check_model_tree(tree, source)
        m = tree["model"]
        a = m["attrs"]
        backbone: dict[str, Any] = dict(m["backbone"]["attrs"])
        backbone["g_0"] = np.asarray(m["backbone"]["g_0"], dtype=float)
        for key in ("g_h", "s_g", "s_gh", "s_k"):
            if key in m["backbone"]:
                backbone[key] = np.asarray(m["backbone"][key], dtype=float)
        prior = m["backbone"].get("prior")
        creep = m.get("creep")
        slip = m.get("slip")
        inertia = m.get("inertia")
        return cls(
            basis=RBFBasis(np.asarray(m["xi"], float), float(a["sigma"]), str(a["outside"])),
            input_map=str(a["input_map"]),
            n_inputs=int(a["n_inputs"]),
            m_q=float(a["m_q"]),
            T_z=float(a["T_z"]),
            coulomb_velocity=float(a["coulomb_velocity"]),
            theta_c=np.asarray(m["theta_c"], float),
            theta_d=np.asarray(m["theta_d"], float),
            theta_g=np.asarray(m["theta_g"], float),
            backbone=backbone,
            q_range=(float(a["q_min"]), float(a["q_max"])),
            prior=None if prior is None else PhysicsPrior.from_tree(prior),
            creep_rate=(
                float(creep["attrs"]["creep_rate"])
                if creep is not None
                else (float(np.asarray(prior["creep_rate"])) if "s_k" in m["backbone"] else 0.0)
            ),
            theta_creep=None if creep is None else np.asarray(creep["theta_creep"], float),
            slip_width=() if slip is None else tuple(np.asarray(slip["width"], float).tolist()),
            theta_slip=None if slip is None else np.asarray(slip["theta_slip"], float),
            theta_inertia=None if inertia is None else np.asarray(inertia["theta_inertia"], float),
            theta_gh=np.asarray(m["theta_gh"], float) if "theta_gh" in m else None,
        )
