"""The black-box peer: a polynomial NARX model chosen on the estimation data, run free.

A physics-informed model earns its place only if it predicts better than a stock black box
fitted to the same data. The black box here is the field's standard one: a polynomial NARX
model

    y(k) = sum_j theta_j prod (y(k - a), u_i(k - b))^powers,   total degree <= d,

with output ``y = q`` and inputs ``u_i = h(v_i)`` (``v_i^2`` for DE actuators, or ``v_i``),
its terms selected by forward regression with orthogonal least squares (FROLS) and the
number of terms by an information criterion (SysIdentPy's ``FROLS``; Billings 2013, Ch. 3).
Its structure (degree, lags, input map) is chosen on the estimation records alone: each
candidate is fitted on the first ``1 - holdout`` of every estimation record and run free
(from the measured first lags, driven by the measured inputs) on the rest; the candidate
with the smallest NRMSE(q) (Eq. 41) there is refitted on the whole estimation records.
Validation data never enter the choice.

Data are scaled before the fit (``q`` to zero mean and unit standard deviation over the
estimation records, each ``h(v_i)`` by its largest magnitude there), so that the polynomial
terms are of comparable size for the orthogonalisation; predictions are scaled back. Records
are joined end to end for the fit (the lags of a record's first samples then reach into the
previous record: ``max_lag`` samples per record, a negligible share); at most ``max_samples``
samples are fitted (the first of each record, in proportion to its length).

References
----------
Billings, S. A., Nonlinear System Identification: NARMAX Methods in the Time, Frequency, and
Spatio-Temporal Domains, Wiley 2013, Ch. 3 (FROLS); Lacerda, W. R., Martins, L. P. C. &
Araujo, A. C., "SysIdentPy: A Python package for System Identification using NARMAX models",
JOSS 5(54), 2384, 2020; Masoud & Maas 2025, Eq. 41.
"""

from __future__ import annotations

import functools
import itertools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar, Literal

import lazy_loader as lazy
import numpy as np
import pydantic
from pydantic import Field, PositiveInt

from debist.errors import DebistWarning, IdentificationError
from debist.metrics import nrmse
from debist.model.termtable import input_map as apply_input_map
from debist.workflow.config import CONFIG, AsTuple, SectionConfig

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = ["NARX_MISSING", "NarxConfig", "NarxModel", "fit_narx", "narx_available"]

#: The status of NARX rows when SysIdentPy is not installed.
NARX_MISSING = "not available (pip install 'debist[narx]')"


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class NarxConfig(SectionConfig):
    """Settings of the NARX peer (the workflow's ``[compare.narx]`` table).

    Parameters
    ----------
    enabled : bool
        Fit and run the NARX model (its rows join the NRMSE table).
    degree : tuple of int
        Candidate total degrees of the polynomial.
    lags : tuple of int
        Candidate lags: output lags 1..n and input lags 1..n [samples].
    input_maps : tuple of {"v2", "v"}, optional
        Candidate input maps h(v); default: the identified model's (``["v2", "v"]`` adds
        the other one to the search).
    info_criteria : {"aic", "bic", "fpe", "lilc"}
        Information criterion of FROLS's number of terms.
    n_info_values : int
        Largest number of terms FROLS considers.
    holdout : float
        Share of each estimation record held out (its end) to choose the structure.
    max_samples : int
        Most samples fitted per candidate (the first of each record).

    References
    ----------
    Billings 2013, Ch. 3; Lacerda et al. 2020 (SysIdentPy ``FROLS``).
    """

    SECTION: ClassVar[str] = "[compare.narx]"

    enabled: bool = True
    degree: Annotated[tuple[Annotated[int, Field(ge=1, le=4)], ...], AsTuple] = (2, 3)
    lags: Annotated[tuple[Annotated[int, Field(ge=1, le=10)], ...], AsTuple] = (2, 3)
    input_maps: Annotated[tuple[Literal["v2", "v"], ...], AsTuple] | None = None
    info_criteria: Literal["aic", "bic", "fpe", "lilc"] = "aic"
    n_info_values: PositiveInt = 40
    holdout: Annotated[float, Field(gt=0.0, lt=0.9)] = 0.25
    max_samples: Annotated[int, Field(ge=100)] = 20000


def _sysidentpy():
    """Import the parts of SysIdentPy used here, keeping matplotlib's settings unchanged.

    Importing SysIdentPy sets matplotlib's global ``axes.spines.right`` and
    ``axes.spines.top`` to False (``sysidentpy.utils.plotting``), which would make every
    figure debist draws later in the process differ by whether a NARX model was fitted
    before it (a batch member's bytes against its solo run's). The import runs inside
    ``matplotlib.rc_context``, which restores the settings.

    Returns
    -------
    tuple
        ``(FROLS, Polynomial, LeastSquares)``.

    Raises
    ------
    ImportError
        Without SysIdentPy (the ``narx`` extra).
    """
    import matplotlib

    with matplotlib.rc_context():
        from sysidentpy.basis_function import Polynomial
        from sysidentpy.model_structure_selection import FROLS
        from sysidentpy.parameter_estimation import LeastSquares
    return FROLS, Polynomial, LeastSquares


def narx_available() -> bool:
    """Whether SysIdentPy (the ``narx`` extra) can be imported."""
    try:
        _sysidentpy()
    except ImportError:
        return False
    return True


@dataclass
class NarxModel:
    """A fitted polynomial NARX model in the scaled variables of :func:`fit_narx`.

    Attributes
    ----------
    estimator : sysidentpy.model_structure_selection.FROLS
        The fitted model.
    input_map : {"v2", "v"}
        h(v) of its inputs.
    degree, lag : int
        Its polynomial degree and lags [samples].
    q_mean, q_std : float
        Output scaling [unit of q].
    h_scale : ndarray, shape (n_inputs,)
        Input scaling [unit of h].
    q_limit : float
        A free run beyond ``|q| > q_limit`` [unit of q] counts as diverged.
    candidates : pandas.DataFrame
        The structure search: ``degree, lag, input_map, n_terms, holdout_nrmse_q, status``.
    """

    estimator: Any
    input_map: str
    degree: int
    lag: int
    q_mean: float
    q_std: float
    h_scale: np.ndarray
    q_limit: float
    candidates: pd.DataFrame = field(default_factory=lambda: pd.DataFrame())

    @property
    def n_params(self) -> int:
        """Number of selected terms."""
        return len(self.estimator.final_model)

    @property
    def max_lag(self) -> int:
        """Samples of measured q a free run starts from."""
        return int(self.estimator.max_lag)

    def simulate(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, int]:
        """Run free over a record from its first ``max_lag`` measured samples.

        Parameters
        ----------
        q : ndarray, shape (n,)
            Measured position [unit of q] (only the first ``max_lag`` samples are read).
        v : ndarray, shape (n, n_inputs)
            Measured inputs [V] (or the inputs' unit).

        Returns
        -------
        q_sim : ndarray, shape (n,)
            Free-run position [unit of q]; NaN from the first sample that left the
            finite range or ``|q| <= q_limit``.
        diverged_at : int
            That sample, -1 if none.
        """
        x = apply_input_map(np.asarray(v, dtype=float), self.input_map) / self.h_scale
        y0 = ((np.asarray(q, dtype=float)[: self.max_lag] - self.q_mean) / self.q_std)[:, None]
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            y = self.estimator.predict(X=x, y=y0, steps_ahead=None)[:, 0]
        q_sim = y * self.q_std + self.q_mean
        bad = ~np.isfinite(q_sim) | (np.abs(q_sim) > self.q_limit)
        at = int(np.argmax(bad)) if bad.any() else -1
        if at >= 0:
            q_sim[at:] = np.nan
        return q_sim, at

    def to_tree(self) -> dict[str, Any]:
        """HDF5 layout: structure, terms (SysIdentPy's regressor codes) and parameters."""
        est = self.estimator
        return {
            "attrs": {
                "model": "narx",
                "method": "FROLS (Billings 2013, Ch. 3), SysIdentPy",
                "input_map": self.input_map,
                "degree": self.degree,
                "lag": self.lag,
                "q_mean": self.q_mean,
                "q_std": self.q_std,
                "q_limit": self.q_limit,
            },
            "model": {
                "regressor_codes": np.asarray(est.final_model, dtype=np.int64),
                "theta": np.asarray(est.theta, dtype=float).ravel(),
                "h_scale": np.asarray(self.h_scale, dtype=float),
            },
        }


@functools.cache
def _frols_class():
    """SysIdentPy's FROLS with the information criterion of every model size from one pass.

    FROLS adds terms greedily by their error reduction ratio, so the ``n``-term selection is
    the first ``n`` terms of the ``n_info_values``-term one; SysIdentPy's
    ``information_criterion`` reruns the selection for every ``n`` (quadratic in
    ``n_info_values``, 6 s of the 7 s fit on the paper experiment). This subclass runs it once
    and scores the nested prefixes by the same least squares and the same criterion, which
    gives the same values (``tests/test_narx.py`` compares them).
    """
    FROLS = _sysidentpy()[0]

    class NestedFROLS(FROLS):
        def information_criterion(self, x, y):
            n_info = min(self.n_info_values, x.shape[1])
            self.n_info_values = n_info
            _, _, psi, target = self._unpack_mss_output(self.run_mss_algorithm(x, y, n_info), y)
            n_samples = y.shape[0] - self.max_lag
            out = np.full(n_info, np.nan)
            for i in range(n_info):
                theta = self.estimator.optimize(psi[:, : i + 1], target)
                e_var = float(np.var(target - psi[:, : i + 1] @ theta, ddof=1))
                out[i] = self.info_criteria_function(i + 1, n_samples, e_var)
            return out

    return NestedFROLS


def _estimator(degree: int, lag: int, n_inputs: int, cfg: NarxConfig):
    _, Polynomial, LeastSquares = _sysidentpy()
    return _frols_class()(
        order_selection=True,
        n_info_values=cfg.n_info_values,
        info_criteria=cfg.info_criteria,
        ylag=lag,
        xlag=[list(range(1, lag + 1))] * n_inputs if n_inputs > 1 else lag,
        basis_function=Polynomial(degree=degree),
        estimator=LeastSquares(),
        model_type="NARMAX",
    )


def _fit(pieces_q, pieces_x, degree, lag, cfg: NarxConfig):
    """Fit one structure on the scaled pieces (joined; capped at ``max_samples``)."""
    total = sum(p.size for p in pieces_q)
    keep = [max(lag + 2, int(cfg.max_samples * p.size / total)) for p in pieces_q]
    y = np.concatenate([p[:k] for p, k in zip(pieces_q, keep, strict=True)])[:, None]
    x = np.concatenate([p[:k] for p, k in zip(pieces_x, keep, strict=True)])
    est = _estimator(degree, lag, x.shape[1], cfg)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.fit(X=x, y=y)
    if not np.all(np.isfinite(np.asarray(est.theta, dtype=float))):
        raise IdentificationError("non-finite parameters")
    return est


def fit_narx(
    q: Sequence[np.ndarray],
    v: Sequence[np.ndarray],
    input_map: str,
    cfg: NarxConfig,
    q_limit: float,
) -> NarxModel:
    """Choose and fit the polynomial NARX model on the estimation records.

    Parameters
    ----------
    q : sequence of ndarray, each shape (n_k,)
        Measured position of each estimation record [unit of q].
    v : sequence of ndarray, each shape (n_k, n_inputs)
        Measured inputs [V] (or the inputs' unit).
    input_map : {"v2", "v"}
        The identified model's h(v); the candidates are ``cfg.input_maps`` or this one.
    cfg : NarxConfig
        The candidates and the search settings.
    q_limit : float
        Divergence bound of the free runs [unit of q].

    Returns
    -------
    NarxModel
        The chosen structure refitted on the whole records, with the search table.

    Raises
    ------
    IdentificationError
        If every candidate failed to fit or diverged on the held-out data.

    References
    ----------
    Billings 2013, Ch. 3 (FROLS); Masoud & Maas 2025, Eq. 41 (the score).
    """
    q = [np.asarray(r, dtype=float) for r in q]
    v = [np.asarray(r, dtype=float).reshape(r.shape[0], -1) for r in v]
    maps = cfg.input_maps or (input_map,)
    q_all = np.concatenate(q)
    q_mean, q_std = float(np.mean(q_all)), float(np.std(q_all)) or 1.0
    rows, best = [], None
    for h_map, degree, lag in itertools.product(maps, cfg.degree, cfg.lags):
        h = [apply_input_map(r, h_map) for r in v]
        scale = np.max(np.abs(np.concatenate(h)), axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        ys = [(r - q_mean) / q_std for r in q]
        xs = [r / scale for r in h]
        cut = [round((1.0 - cfg.holdout) * r.size) for r in q]
        row = {"degree": degree, "lag": lag, "input_map": h_map, "n_terms": 0,
               "holdout_nrmse_q": np.inf, "status": "ok"}  # fmt: skip
        try:
            est = _fit([y[:c] for y, c in zip(ys, cut, strict=True)],
                       [x[:c] for x, c in zip(xs, cut, strict=True)], degree, lag, cfg)  # fmt: skip
            model = NarxModel(est, h_map, degree, lag, q_mean, q_std, scale, q_limit)
            row["n_terms"] = model.n_params
            scores = []
            for r_q, r_v, c in zip(q, v, cut, strict=True):
                start = max(c - model.max_lag, 0)
                sim, _ = model.simulate(r_q[start:], r_v[start:])
                scores.append(nrmse(r_q[start:][model.max_lag :], sim[model.max_lag :]))
            score = float(np.mean(scores))
            row["holdout_nrmse_q"] = score if np.isfinite(score) else np.inf
            row["status"] = "ok" if np.isfinite(score) else "diverged"
        except (IdentificationError, np.linalg.LinAlgError, ValueError) as exc:
            row["status"] = f"fit failed: {exc}"
        rows.append(row)
        if np.isfinite(row["holdout_nrmse_q"]) and (
            best is None or row["holdout_nrmse_q"] < best["holdout_nrmse_q"]
        ):
            best = row
    candidates = pd.DataFrame(rows)
    if best is None:
        raise IdentificationError(
            "NARX: every candidate structure failed to fit or diverged on the held-out "
            "estimation data"
        )
    h = [apply_input_map(r, best["input_map"]) for r in v]
    scale = np.max(np.abs(np.concatenate(h)), axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    est = _fit([(r - q_mean) / q_std for r in q], [r / scale for r in h], best["degree"],
               best["lag"], cfg)  # fmt: skip
    if len(est.final_model) == 0:
        warnings.warn("NARX: the chosen structure selected no term", DebistWarning, stacklevel=2)
    return NarxModel(est, best["input_map"], best["degree"], best["lag"], q_mean, q_std,
                     scale, q_limit, candidates)  # fmt: skip
