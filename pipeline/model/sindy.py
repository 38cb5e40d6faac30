"""SINDy baseline: a sparse polynomial model of q'' fitted with pysindy on the RBF model's data.

The library is built from the polynomials P_d(q, q_dot) of total degree <= ``degree``
(including 1), multiplied by ``[1, h(v_1), ..., h(v_N)]`` (``input_terms=True``), so it
can express the paper's structure c(q) q, d(q) q_dot and g_i(q) h(v_i) with polynomial
curves. The fit uses exactly the state (q, q_dot) and the derivatives
x_dot = [q_dot, q_ddot] the RBF model is estimated from, with u = h(v) as control.

Only the q_ddot equation is kept: the kinematic equation q' = q_dot is imposed when
simulating. :class:`SindyModel` evaluates the identified polynomial with its own numpy
code (exponent table times coefficients), so free-run simulation with
:func:`debist.simulate.freerun.simulate` costs about as much as for the RBF model.

References
----------
Brunton, Proctor & Kutz 2016, "Discovering governing equations from data by sparse
identification of nonlinear dynamical systems", PNAS 113(15), 3932-3937 (Eq. 2-5; SINDYc:
Brunton, Proctor & Kutz 2016, IFAC-PapersOnLine 49(18)).
de Silva et al. 2020, "PySINDy: A Python package for the sparse identification of
nonlinear dynamical systems from data", JOSS 5(49), 2104.
Kaptanoglu et al. 2022, "PySINDy: A comprehensive Python package for robust sparse system
identification", JOSS 7(69), 3994.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar, Literal

import numpy as np
import pydantic
from pydantic import NonNegativeFloat, PositiveInt

from debist.core.config import CONFIG, SectionConfig
from debist.core.errors import ConvergenceWarning, IdentificationError, WorkflowError
from debist.core.preflight import check_memory, sindy_bytes, sindy_terms
from debist.model.termtable import S_POW, TableModel, TermTableBuilder, input_map

OPTIMIZERS = ("STLSQ", "SR3")


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class SindyConfig(SectionConfig):
    """Hyper-parameters of the SINDy baseline (the workflow's ``[compare]`` section).

    Raises
    ------
    pydantic.ValidationError
        If a value has the wrong type or is out of range (a ``ValueError``;
        :meth:`from_dict` raises a ``WorkflowError`` naming the key instead).

    Notes
    -----
    Each field is one key, documented under its declaration; what the threshold means with and
    without normalised columns: docs/explanation/implementation.md.

    References
    ----------
    Brunton, Proctor & Kutz 2016, PNAS, Sec. "Sparse regression" (STLSQ); Champion et al.
    2020, IEEE Access 8 (SR3 for SINDy).
    """

    SECTION: ClassVar[str] = "[compare]"

    degree: PositiveInt = 3
    """Largest total degree of the polynomials in (q, q_dot)."""
    input_terms: bool = True
    """true: library P_d(q, q_dot) x [1, h(v_1), ..., h(v_N)] (state-dependent input gains); false:
    P_d(q, q_dot) + [h(v_1), ..., h(v_N)] (constant gains).
    """
    optimizer: Literal["STLSQ", "SR3"] = "STLSQ"
    """Sequentially thresholded ridge regression, or SR3 with an L0 penalty at the same threshold.
    """
    threshold: NonNegativeFloat = 1e-3
    """Sparsity threshold; with normalize_columns a term is kept if the RMS of its contribution is
    at least this fraction of the RMS of q_ddot.
    """
    alpha: NonNegativeFloat = 1e-10
    """Ridge weight of STLSQ on unit-norm columns (ignored by SR3)."""
    input_map: Literal["v2", "v"] = "v2"
    """h(v) = v^2 [V^2] (DE actuators) or v [V]."""
    normalize_columns: bool = True
    """Scale each library column to unit 2-norm before the sparse regression."""


@dataclass(frozen=True)
class SindyModel:
    """q'' = sum_j xi_j q^a_j q_dot^b_j prod_i h(v_i)^c_ij, q' = q_dot: the identified SINDy model.

    Implements :class:`debist.simulate.freerun.FreeRunModel` with states ``[q, q_dot]``.

    Parameters
    ----------
    feature_names : list of str
        pysindy's names of the library terms, in terms of ``q``, ``q_dot`` and
        ``h1 .. hN`` (h_i = h(v_i)).
    coefficients : ndarray, shape (n_features,)
        xi of the q_ddot equation [m/s^2 per unit of the term, e.g. 1/s^2 for q,
        1/s for q_dot, m/(s^2 V^2) for h_i with h = v^2]; zeros for dropped terms.
    exponents : ndarray of int, shape (n_features, 2 + n_inputs)
        Powers of q, q_dot, h_1, ..., h_N in each term.
    input_map : {"v2", "v"}
        h(v) = v^2 or v.
    n_inputs : int
        Number of inputs N.
    equations : str
        The model as text, e.g. ``"q_ddot = -1.000e+03 q + ..."``.
    fit_time : float
        Wall time of the pysindy fit [s].
    threshold : float
        Sparsity threshold the model was fitted with (see :class:`SindyConfig`).
    q_range : tuple of float
        Range of q in the estimation data [m].

    References
    ----------
    Brunton, Proctor & Kutz 2016, PNAS, Eq. 4 (Theta(X) Xi).
    """

    feature_names: list[str]
    coefficients: np.ndarray
    exponents: np.ndarray
    input_map: str
    n_inputs: int
    equations: str
    fit_time: float
    threshold: float = 0.0
    q_range: tuple[float, float] = (0.0, 0.0)

    n_states = 2

    @property
    def n_params(self) -> int:
        """Number of nonzero coefficients."""
        return int(np.count_nonzero(self.coefficients))

    def features(self, q: np.ndarray, q_dot: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Evaluate the whole library Theta(q, q_dot, h(v)).

        Parameters
        ----------
        q, q_dot : ndarray, shape (B,)
            Position [m] and velocity [m/s].
        v : ndarray, shape (B, n_inputs)
            Inputs [V].

        Returns
        -------
        ndarray, shape (B, n_features)
        """
        z = np.column_stack([q, q_dot, input_map(np.asarray(v, float), self.input_map)])
        return np.prod(z[:, None, :] ** self.exponents[None], axis=2)

    def accel(self, q: np.ndarray, q_dot: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Acceleration of the identified model, through its term table (the nonzero terms).

        Parameters
        ----------
        q, q_dot : ndarray, shape (B,)
            Position [m] and velocity [m/s].
        v : ndarray, shape (B, n_inputs)
            Inputs [V].

        Returns
        -------
        ndarray, shape (B,)
            q'' [m/s^2].
        """
        return self._table.accel(q, q_dot, v)

    @cached_property
    def _table(self):
        """The term table of :meth:`table_model`, built once: the model's one evaluation."""
        return self.table_model()

    def table_model(self):
        """Return the model as a term table (:class:`debist.model.termtable.TableModel`).

        Returns
        -------
        TableModel
            One term per nonzero coefficient: ``q^a q_dot^b prod h_i^c_i`` with weight xi,
            mass 1, no friction state.

        References
        ----------
        Brunton, Proctor & Kutz 2016, Eq. 4.
        """
        build = TermTableBuilder(self.n_inputs, self.input_map)
        one = build.one()
        keep = np.flatnonzero(self.coefficients)
        for j in keep:
            e = self.exponents[j]
            build.term(self.feature_names[j], one, qpow=e[0], skind=S_POW, spow=e[1], hpow=e[2:])
        table = build.build()
        return TableModel(table, self.coefficients[keep], np.ones(1), np.zeros(1), lag=False)

    @cached_property
    def kernel_table(self) -> TableModel:
        """The model as the compiled free-run kernel takes it (:meth:`table_model`), built once."""
        return self.table_model()

    def initial_state(self, q0: np.ndarray, q_dot0: np.ndarray) -> np.ndarray:
        """State ``[q, q_dot]``.

        Parameters
        ----------
        q0, q_dot0 : ndarray, shape (B,)
            Initial position [m] and velocity [m/s].

        Returns
        -------
        ndarray, shape (B, 2)
        """
        return np.stack([np.asarray(q0, float), np.asarray(q_dot0, float)], axis=-1)

    def rhs(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """State derivative for the free-run simulator.

        Parameters
        ----------
        x : ndarray, shape (B, 2)
            States ``[q, q_dot]`` [m, m/s].
        v : ndarray, shape (B, n_inputs)
            Inputs [V].

        Returns
        -------
        x_dot : ndarray, shape (B, 2)
            ``[q_dot, q_ddot]`` [m/s, m/s^2].
        q_ddot : ndarray, shape (B,)
            The acceleration [m/s^2].
        """
        return self._table.rhs(x, v)

    def max_step(self) -> float:
        """Largest stable step [s]: no internal time constant, so inf."""
        return np.inf

    def to_tree(self) -> dict[str, Any]:
        """Return the model as a nested mapping for an HDF5 artifact.

        Returns
        -------
        dict
            Arrays and attributes; :meth:`from_tree` restores the model. The wall
        time of the fit is left out so that the artifact is reproducible.
        """
        return {
            "attrs": {"model": "sindy", "equation": "Brunton, Proctor & Kutz 2016, Eq. 4"},
            "model": {
                "attrs": {
                    "input_map": self.input_map,
                    "n_inputs": self.n_inputs,
                    "equations": self.equations,
                    "threshold": self.threshold,
                    "q_min": self.q_range[0],
                    "q_max": self.q_range[1],
                },
                "feature_names": np.array(self.feature_names, dtype=str),
                "coefficients": np.asarray(self.coefficients, float),
                "exponents": np.asarray(self.exponents, np.int64),
            },
        }

    @classmethod
    def from_tree(cls, tree: Mapping[str, Any]) -> SindyModel:
        """Rebuild a model from :meth:`to_tree` output (or its HDF5 round trip).

        Parameters
        ----------
        tree : mapping
            As returned by :meth:`to_tree` or :func:`debist.core.artifacts.read_h5`.

        Returns
        -------
        SindyModel
        """
        m = tree["model"]
        a = m["attrs"]
        names = [
            n.decode() if isinstance(n, bytes) else str(n) for n in np.asarray(m["feature_names"])
        ]
        return cls(
            feature_names=names,
            coefficients=np.asarray(m["coefficients"], float),
            exponents=np.asarray(m["exponents"], np.int64),
            input_map=str(a["input_map"]),
            n_inputs=int(a["n_inputs"]),
            equations=str(a["equations"]),
            fit_time=float(a.get("fit_time", float("nan"))),
            threshold=float(a["threshold"]),
            q_range=(float(a["q_min"]), float(a["q_max"])),
        )


def _as_records(value: np.ndarray | Sequence[np.ndarray]) -> list[np.ndarray]:
    """One or several records as a list of float arrays."""
    if isinstance(value, np.ndarray):
        return [np.asarray(value, float)]
    return [np.asarray(r, float) for r in value]


def _parse_exponents(names: Sequence[str], variables: Sequence[str]) -> np.ndarray:
    """Exponent table (n_features, n_variables) from pysindy names such as ``"q^2 h1"``."""
    index = {v: j for j, v in enumerate(variables)}
    out = np.zeros((len(names), len(variables)), dtype=np.int64)
    for i, name in enumerate(names):
        for token in name.split():
            if token == "1":
                continue
            base, _, power = token.partition("^")
            if base not in index:
                raise IdentificationError(f"cannot parse SINDy feature {name!r}")
            out[i, index[base]] += int(power) if power else 1
    return out


def _input_legend(kind: str, units: Sequence[str]) -> str:
    """``h_i = v_i^2 [V^2], i = 1..N`` in the inputs' units (none for dimensionless ones)."""
    if not units:
        return "no inputs"

    def one(i: str, unit: str) -> str:
        base = unit if unit.isalnum() else f"({unit})"
        u = "" if unit in ("1", "") else f" [{base}^2]" if kind == "v2" else f" [{unit}]"
        return f"h_{i} = v_{i}" + ("^2" if kind == "v2" else "") + u

    if len(set(units)) == 1:
        return one("i", units[0]) + f", i = 1..{len(units)}"
    return ", ".join(one(str(i + 1), u) for i, u in enumerate(units))


def _equation_text(
    coef: np.ndarray,
    names: Sequence[str],
    kind: str,
    n_inputs: int,
    input_units: Sequence[str] | None = None,
) -> str:
    """``q_ddot = ...`` with the nonzero terms, plus the imposed kinematics and h."""
    terms = []
    for c, name in zip(coef, names, strict=True):
        if c == 0:
            continue
        sign = "-" if c < 0 else "+"
        term = name.removeprefix("1 ") if name != "1" else ""
        body = f"{abs(c):.6e}" + (f" {term}" if term else "")
        terms.append((sign, body))
    if not terms:
        rhs = "0"
    else:
        first_sign, first = terms[0]
        rhs = ("-" if first_sign == "-" else "") + first
        rhs += "".join(f" {s} {b}" for s, b in terms[1:])
    legend = _input_legend(kind, list(input_units or ["V"] * n_inputs)[:n_inputs])
    return f"q_dot = q_dot (imposed)\nq_ddot = {rhs}\n({legend})"


def fit_sindy(
    q: np.ndarray | Sequence[np.ndarray],
    q_dot: np.ndarray | Sequence[np.ndarray],
    q_ddot: np.ndarray | Sequence[np.ndarray],
    v: np.ndarray | Sequence[np.ndarray],
    dt: float,
    cfg: SindyConfig,
    input_units: Sequence[str] | None = None,
) -> SindyModel:
    """Fit the SINDy(c) baseline with pysindy on given states and derivatives.

    Parameters
    ----------
    q, q_dot, q_ddot : ndarray, shape (n,), or list of them (one per record)
        Position [m], velocity [m/s] and acceleration [m/s^2] (the RBF model's estimation
        data and derivatives); records are stacked row-wise.
    v : ndarray, shape (n, n_inputs) or (n,), or list of them
        Inputs [V]; the control is u = h(v).
    dt : float
        Sample time [s] (passed to pysindy as ``t``; unused since x_dot is given).
    cfg : SindyConfig
        Library and optimizer settings.
    input_units : sequence of str, optional
        Unit of each input (``"V"``, ``"1"``) for the equation's legend; default V.

    Returns
    -------
    SindyModel
        Coefficients of the q_ddot equation; q' = q_dot is imposed.

    Raises
    ------
    IdentificationError
        If the records disagree, contain non-finite values, or are shorter than the library.
    WorkflowError
        If ``dt`` is not positive.
    ResourceError
        If the library would exceed the memory budget (before pysindy builds it).

    Warns
    -----
    ConvergenceWarning
        If STLSQ or SR3 stopped at its iteration limit, or the threshold removed every
        term of the q_ddot equation.

    References
    ----------
    Brunton, Proctor & Kutz 2016, PNAS, Eq. 4-5; Kaptanoglu et al. 2022 (pysindy).
    """
    return fit_sindy_thresholds(q, q_dot, q_ddot, v, dt, cfg, (cfg.threshold,), input_units)[0]


def fit_sindy_thresholds(
    q: np.ndarray | Sequence[np.ndarray],
    q_dot: np.ndarray | Sequence[np.ndarray],
    q_ddot: np.ndarray | Sequence[np.ndarray],
    v: np.ndarray | Sequence[np.ndarray],
    dt: float,
    cfg: SindyConfig,
    thresholds: Sequence[float],
    input_units: Sequence[str] | None = None,
) -> list[SindyModel]:
    """Fit the SINDy(c) baseline at several sparsity thresholds on one library matrix.

    The first threshold is fitted by pysindy's ``SINDy.fit`` (the library, then the
    optimizer); each further one runs a new optimizer on the library matrix that fit built
    (the optimizer's ``Theta_``) and the same derivatives, as ``SINDy.fit`` would after
    building the library again: each model is the one :func:`fit_sindy` gives at its threshold.

    Parameters
    ----------
    q, q_dot, q_ddot, v, dt, input_units
        As :func:`fit_sindy`.
    cfg : SindyConfig
        Library and optimizer settings; its ``threshold`` is not used.
    thresholds : sequence of float
        Sparsity thresholds (:attr:`SindyConfig.threshold`), at least one.

    Returns
    -------
    list of SindyModel
        One per threshold, in their order.

    Raises
    ------
    IdentificationError, WorkflowError, ResourceError
        As :func:`fit_sindy`.
    ValueError
        If ``thresholds`` is empty.

    Warns
    -----
    ConvergenceWarning
        As :func:`fit_sindy`, per threshold.

    References
    ----------
    Brunton, Proctor & Kutz 2016, PNAS, Eq. 4-5; Kaptanoglu et al. 2022 (pysindy).
    """
    import pysindy as ps

    if not len(thresholds):
        raise ValueError("fit_sindy_thresholds needs at least one threshold")
    if not dt > 0:
        raise WorkflowError(f"`dt` must be > 0, got {dt!r}")
    qs, qds, qdds, vs = (_as_records(a) for a in (q, q_dot, q_ddot, v))
    if not len(qs) == len(qds) == len(qdds) == len(vs) or not qs:
        raise IdentificationError(
            f"need the same number (>= 1) of q, q_dot, q_ddot and v records, got "
            f"{len(qs)}, {len(qds)}, {len(qdds)}, {len(vs)}"
        )
    vs = [vk[:, None] if vk.ndim == 1 else vk for vk in vs]
    n_inputs = vs[0].shape[1]
    for k, (a, b, c, d) in enumerate(zip(qs, qds, qdds, vs, strict=True)):
        if not (
            a.ndim == b.ndim == c.ndim == 1
            and a.shape == b.shape == c.shape
            and d.shape[0] == a.shape[0]
        ):
            raise IdentificationError(
                f"record {k}: q, q_dot, q_ddot must be (n,) and v (n, n_inputs) of equal n, got "
                f"{a.shape}, {b.shape}, {c.shape}, {d.shape}"
            )
        if d.shape[1] != n_inputs:
            raise IdentificationError(f"record {k}: {d.shape[1]} inputs, record 0 has {n_inputs}")
    x = np.column_stack([np.concatenate(qs), np.concatenate(qds)])
    x_dot = np.column_stack([x[:, 1], np.concatenate(qdds)])
    u = input_map(np.concatenate(vs), cfg.input_map)
    if not (np.isfinite(x).all() and np.isfinite(x_dot).all() and np.isfinite(u).all()):
        raise IdentificationError("non-finite values in q, q_dot, q_ddot or v")

    variables = ["q", "q_dot"] + [f"h{i + 1}" for i in range(n_inputs)]
    poly = ps.PolynomialLibrary(degree=cfg.degree, include_bias=True)
    if n_inputs == 0:
        library = poly
    else:
        lin = ps.PolynomialLibrary(degree=1, include_bias=False)
        library = ps.GeneralizedLibrary(
            [poly, lin],
            tensor_array=[[1, 1]] if cfg.input_terms else None,
            inputs_per_library=[[0, 1], list(range(2, 2 + n_inputs))],
            exclude_libraries=[1] if cfg.input_terms else [],
        )
    n_features_expected = sindy_terms(cfg.degree, n_inputs, cfg.input_terms)
    if x.shape[0] < n_features_expected:
        raise IdentificationError(
            f"{x.shape[0]} samples for {n_features_expected} SINDy library terms "
            f"(degree {cfg.degree})"
        )

    check_memory(
        sindy_bytes(x.shape[0], n_features_expected),
        f"[compare] degree = {cfg.degree}",
        f"the SINDy library of {x.shape[0]} samples x {n_features_expected} terms",
        "pysindy's copies",
    )
    # Relative threshold: normalised coefficients are xi_j ||theta_j||_2; compare them with
    # threshold ||q_ddot||_2 (see SindyConfig.threshold).
    scale = float(np.linalg.norm(x_dot[:, 1])) if cfg.normalize_columns else 1.0
    thresholds = [float(th) for th in thresholds]
    model = ps.SINDy(optimizer=_optimizer(ps, cfg, thresholds[0] * scale), feature_library=library)
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model.fit(x, t=dt, x_dot=x_dot, u=u if n_inputs else None, feature_names=variables)
    fits = [(model.coefficients(), caught, time.perf_counter() - t0)]
    theta = model.optimizer.Theta_  # the library matrix of this fit, for the other thresholds
    for threshold in thresholds[1:]:
        optimizer = _optimizer(ps, cfg, threshold * scale)
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            optimizer.fit(theta, x_dot)
        fits.append((optimizer.coef_, caught, time.perf_counter() - t0))
    names = list(model.get_feature_names())
    exponents = _parse_exponents(names, variables)
    q_range = (float(x[:, 0].min()), float(x[:, 0].max()))
    results = []
    for threshold, (coefficients, caught, fit_time) in zip(thresholds, fits, strict=True):
        coef = np.asarray(coefficients, float)[1].copy()
        coef[np.abs(coef) == 0] = 0.0  # no negative zeros in the text
        _warn_convergence(cfg.optimizer, threshold, caught, coef)
        results.append(
            SindyModel(
                feature_names=names,
                coefficients=coef,
                exponents=exponents,
                input_map=cfg.input_map,
                n_inputs=n_inputs,
                equations=_equation_text(coef, names, cfg.input_map, n_inputs, input_units),
                fit_time=fit_time,
                threshold=threshold,
                q_range=q_range,
            )
        )
    # Own evaluation against pysindy's library on a few estimation rows: the exponent
    # table must reproduce pysindy's columns, or the simulated model is not the fitted one.
    rows = np.linspace(0, x.shape[0] - 1, min(16, x.shape[0])).astype(int)
    theta_ps = np.asarray(library.transform(np.column_stack([x[rows], u[rows]])))
    theta_own = results[0].features(x[rows, 0], x[rows, 1], np.concatenate(vs)[rows])
    if not np.allclose(theta_own, theta_ps, rtol=1e-10, atol=0.0):
        raise IdentificationError("SINDy exponent table disagrees with pysindy's library")
    return results


def _optimizer(ps, cfg: SindyConfig, threshold: float):
    """Make pysindy's STLSQ or SR3 at an absolute threshold (relative x ||q_ddot||_2)."""
    if cfg.optimizer == "STLSQ":
        return ps.STLSQ(
            threshold=threshold,
            alpha=cfg.alpha,
            normalize_columns=cfg.normalize_columns,
            max_iter=50,
        )
    return ps.SR3(
        reg_weight_lam=threshold**2 / 2.0,
        regularizer="L0",
        relax_coeff_nu=1.0,
        normalize_columns=cfg.normalize_columns,
        unbias=True,
        max_iter=200,
    )


def _warn_convergence(optimizer: str, threshold: float, caught, coef: np.ndarray) -> None:
    """Issue a fit's convergence warnings as ConvergenceWarning (the kinematic row's aside)."""
    for w in caught:
        msg = str(w.message)
        if "eliminated all coefficients" in msg:
            continue  # the kinematic row may drop out; checked for q_ddot below
        if "did not converge" in msg.lower() or "max_iter" in msg.lower():
            warnings.warn(f"SINDy {optimizer}: {msg}", ConvergenceWarning, stacklevel=4)
    if not np.any(coef):
        warnings.warn(
            f"SINDy threshold {threshold!r} removed every term of the q_ddot equation",
            ConvergenceWarning,
            stacklevel=4,
        )
