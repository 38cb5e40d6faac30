"""The black-box peer: a polynomial NARX model chosen on the estimation data, run free.

A physics-informed model earns its place only if it predicts better than a stock black box
fitted to the same data. The black box here is the field's standard one: a polynomial NARX
model

    y(k) = sum_j theta_j prod (y(k - a), u_i(k - b))^powers,   total degree <= d,

with output ``y = q`` and inputs ``u_i = h(v_i)`` (``v_i^2`` for DE actuators, or ``v_i``),
its terms ordered by forward regression with orthogonal least squares (FROLS; SysIdentPy's
``FROLS``; Billings 2013, Ch. 3). The information criterion's minimum over the model sizes is
found (the window of sizes grows until the criterion rises, never capped) and bounds the sizes
tried; among those, the simulation error of the free run over the estimation records picks
the model (:func:`fit_narx`; Piroddi & Spinelli 2003: a one-step criterion alone keeps terms
that fit the sensor's coloured noise and lose the free run), after a screen on inputs the
estimation records imply but do not contain (:func:`stress_inputs`): a candidate whose free
run leaves the visited range under them is unstable where the data cannot vouch for it, and
is passed over unless it is the only kind that reproduces the estimation records (a free run
that loses a switch on its own data is no alternative). Validation data never enter the choice.

Data are scaled before the fit (``q`` about an origin, divided by its standard deviation;
each ``h(v_i)`` by its largest magnitude). A polynomial NARX is not invariant to the origin of
``q``, so the origin is searched like the degree (:func:`q_origins`); every candidate origin
moves with a shift of the data, so the model is independent of the sensor's zero. Each
record's regressor rows are built on that record alone (no lag reaches into another record).
Free runs use a compiled recursion (:mod:`debist.model.narx_kernel`) equal to SysIdentPy's
``predict``. Why each step: the NARX section of the implementation notes in the docs.

References
----------
Billings, S. A., Nonlinear System Identification: NARMAX Methods in the Time, Frequency, and
Spatio-Temporal Domains, Wiley 2013, Ch. 3 (FROLS); Piroddi, L. & Spinelli, W., "An
identification algorithm for polynomial NARX models based on simulation error minimization",
Int. J. Control 76(17), 1767-1781, 2003; Lacerda, W. R., Martins, L. P. C. &
Araujo, A. C., "SysIdentPy: A Python package for System Identification using NARMAX models",
JOSS 5(54), 2384, 2020; Masoud & Maas 2025, Eq. 41.
"""

from __future__ import annotations

import functools
import itertools
import pickle
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar, Literal

import lazy_loader as lazy
import numpy as np
import pydantic
from pydantic import Field, PositiveInt

from debist.core.config import CONFIG, AsTuple, SectionConfig
from debist.core.errors import DebistWarning, IdentificationError
from debist.core.metrics import POOR_SHARE, mean_baseline_nrmse
from debist.core.preflight import check_memory, narx_bytes
from debist.model.narx_kernel import factor_tables, narx_free_run
from debist.model.termtable import input_map as apply_input_map

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")
linalg = lazy.load("scipy.linalg", suppress_warning=True)

__all__ = [
    "NARX_MISSING",
    "NarxConfig",
    "NarxModel",
    "fit_narx",
    "narx_available",
    "q_origins",
    "stress_inputs",
]

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
        Candidate total degrees of the polynomial (default 3: the cubic restoring force of a
        bistable structure).
    lags : tuple of int
        Candidate lags: output lags 1..n and input lags 1..n [samples].
    input_maps : tuple of {"v2", "v"}, optional
        Candidate input maps h(v); default: the identified model's (``["v2", "v"]`` adds
        the other one to the search).
    info_criteria : {"aic", "bic", "fpe", "lilc"}
        Information criterion of FROLS's number of terms.
    n_info_values : int
        First window of model sizes the criterion scores; it doubles while the criterion's
        minimum lies at its end, up to the number of candidate terms.
    holdout : float
        Unused, kept so that older workflows load.
    max_samples : int
        Most samples fitted per candidate (the first of each record).

    References
    ----------
    Billings 2013, Ch. 3; Lacerda et al. 2020 (SysIdentPy ``FROLS``).
    """

    SECTION: ClassVar[str] = "[compare.narx]"

    enabled: bool = True
    degree: Annotated[tuple[Annotated[int, Field(ge=1, le=4)], ...], AsTuple] = (3,)
    lags: Annotated[tuple[Annotated[int, Field(ge=1, le=10)], ...], AsTuple] = (3,)
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
    q_origin, q_std : float
        Output origin (:func:`q_origins`) and scale [unit of q].
    h_scale : ndarray, shape (n_inputs,)
        Input scaling [unit of h].
    q_limit : float
        A free run beyond ``|q| > q_limit`` [unit of q] counts as diverged.
    candidates : pandas.DataFrame
        The search: ``degree, lag, input_map, origin, n_terms, criterion_terms,
        free_run_nrmse_q, stress_excursion, status`` per structure and model size.
    """

    estimator: Any
    input_map: str
    degree: int
    lag: int
    q_origin: float
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
        y0 = (np.asarray(q, dtype=float)[: self.max_lag] - self.q_origin) / self.q_std
        y, _ = self.simulate_scaled(y0, x)
        q_sim = y * self.q_std + self.q_origin
        bad = ~np.isfinite(q_sim) | (np.abs(q_sim) > self.q_limit)
        at = int(np.argmax(bad)) if bad.any() else -1
        if at >= 0:
            q_sim[at:] = np.nan
        return q_sim, at

    def simulate_scaled(self, y: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, int]:
        """Run free in the scaled variables of the fit (``y`` scaled output, ``x`` scaled h(v)).

        Parameters
        ----------
        y : ndarray, shape (n,)
            Scaled output (only the first ``max_lag`` samples are read).
        x : ndarray, shape (n, n_inputs)
            Scaled inputs.

        Returns
        -------
        y_sim : ndarray, shape (n,)
            The free run; NaN from the first sample beyond the divergence bound.
        diverged_at : int
            That sample, -1 if none.
        """
        var, lag = factor_tables(self.estimator.final_model)
        theta = np.asarray(self.estimator.theta, dtype=float).ravel()
        bound = (self.q_limit + abs(self.q_origin)) / self.q_std
        y0 = np.ascontiguousarray(y[: self.max_lag], dtype=float)
        return narx_free_run(y0, np.ascontiguousarray(x, dtype=float), var, lag, theta, bound)

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
                "q_origin": self.q_origin,
                "q_std": self.q_std,
                "q_limit": self.q_limit,
            },
            "model": {
                "regressor_codes": np.asarray(est.final_model, dtype=np.int64),
                "theta": np.asarray(est.theta, dtype=float).ravel(),
                "h_scale": np.asarray(self.h_scale, dtype=float),
            },
        }


def prefix_criteria(psi: np.ndarray, y: np.ndarray, criterion: Any, *, qr: bool = False):
    """Information criterion of every nested least-squares model ``psi[:, :k]``, k = 1..n.

    One thin QR decomposition of ``psi`` gives each prefix's residual: with ``Q``'s columns
    ``q_j`` and ``c_j = q_j^T y``, the residual of the first ``k`` columns has the squared
    norm ``||y||^2 - sum_{j<k} c_j^2`` and the mean ``mean(y) - sum_{j<k} mean(q_j) c_j``, so
    its variance (``ddof = 1``, as SysIdentPy's ``information_criterion``) costs O(N) per size.

    Parameters
    ----------
    psi : ndarray, shape (N, n)
        Regressor columns in the order they enter (FROLS's ERR order).
    y : ndarray, shape (N,)
        Target.
    criterion : callable
        ``criterion(n_theta, n_samples, e_var)``, e.g. SysIdentPy's ``aic``.
    qr : bool, optional
        Also return ``R`` and ``c = Q^T y``: the least-squares parameters of the first ``k``
        columns are ``R[:k, :k]^-1 c[:k]``.

    Returns
    -------
    ndarray, shape (n,)
        The criterion for 1..n terms; ``inf`` from the first column that is numerically
        dependent on the ones before it. With ``qr``, the tuple ``(criterion, R, c)``.

    References
    ----------
    Billings 2013, Ch. 3 (orthogonal least squares, the model size by an information
    criterion); Golub & Van Loan, Matrix Computations, 4th ed., Sec. 5.3 (least squares by QR).
    """
    N, n = psi.shape
    Q, R = np.linalg.qr(psi)
    c = Q.T @ y
    rss = float(y @ y) - np.cumsum(c**2)
    mean = float(y.mean()) - np.cumsum(Q.mean(axis=0) * c)
    e_var = np.maximum(rss - N * mean**2, 0.0) / (N - 1)
    diag = np.abs(np.diag(R))
    dependent = diag <= max(N, n) * np.finfo(float).eps * (diag.max() if n else 0.0)
    out = np.array([criterion(k + 1, N, e_var[k]) if e_var[k] > 0 else -np.inf
                    for k in range(n)])  # fmt: skip
    if dependent.any():
        out[int(np.argmax(dependent)) :] = np.inf
    return (out, R, c) if qr else out


@functools.cache
def _frols_class():
    """SysIdentPy's FROLS fitted on several records, with the criterion's minimum found.

    :meth:`fit_records` builds each record's regressor matrix on its own (no lag reaches into
    another record), stacks them, orders the candidate terms by FROLS's error reduction ratio
    and scores every model size with the information criterion (:func:`prefix_criteria`). The
    window of sizes starts at ``n_info_values`` and doubles while the criterion's minimum lies
    at its end, up to the number of candidate terms: the term count is the criterion's
    minimum, never a cap. FROLS orders all candidates once; each window takes the first of
    them (greedy forward selection: the first ``n`` do not depend on how many are ordered).
    """
    FROLS = _sysidentpy()[0]
    from sysidentpy.utils.information_matrix import build_lagged_matrix

    class RecordsFROLS(FROLS):
        def fit_records(self, xs: list[np.ndarray], ys: list[np.ndarray]):
            self.max_lag = self._get_max_lag()
            psi, target = [], []
            for x, y in zip(xs, ys, strict=True):
                lagged = build_lagged_matrix(x, y, self.xlag, self.ylag, self.model_type)
                psi.append(
                    self.basis_function.fit(
                        lagged,
                        self.max_lag,
                        self.ylag,
                        self.xlag,
                        self.model_type,
                        predefined_regressors=None,
                    )
                )
                target.append(y[self.max_lag :, 0])  # fmt: skip
            psi, target = np.vstack(psi), np.concatenate(target)
            # SysIdentPy's routines drop the first max_lag rows of the target they are given
            padded = np.concatenate([np.zeros(self.max_lag), target])[:, None]
            self.n_inputs = xs[0].shape[1]
            self.regressor_code = self.regressor_space(self.n_inputs)
            n_cand, n = psi.shape[1], min(self.n_info_values, psi.shape[1])
            # FROLS's order is greedy: its first n terms do not depend on how many follow, so
            # one run over every candidate serves each window (its last steps are cheap)
            err, order, _ = self.run_mss_algorithm(psi, padded, n_cand)
            order = np.asarray(order, dtype=np.intp)
            while True:
                piv = order[:n]
                ic, R, c = prefix_criteria(psi[:, piv], target, self.info_criteria_function,
                                           qr=True)  # fmt: skip
                k = int(np.argmin(ic)) + 1
                if k < n or n == n_cand:
                    break
                n = min(2 * n, n_cand)
            self.info_values, self.err, self.pivv = ic, err[:n], piv
            self.n_terms_criterion = k
            self._qr = (R, c)
            return self.truncate(k)

        def truncate(self, k: int):
            """Keep the first ``k`` terms of FROLS's order, refitted by least squares.

            The least-squares solution of the first ``k`` ordered columns from the thin QR
            decomposition of :func:`prefix_criteria`: ``R[:k, :k] theta = c[:k]``.
            """
            R, c = self._qr
            piv = self.pivv[:k]
            self.n_terms = k
            self.final_model = self.regressor_code[piv, :].copy()
            self.theta = linalg.solve_triangular(R[:k, :k], c[:k])[:, None]
            return self

        def release(self):
            """Drop the decomposition kept for :meth:`truncate`."""
            self._qr = None
            return self

        def __reduce__(self):
            # a class made in a function pickles by its state: the model travels back from
            # the forked process the compare stage fits it in (debist.core.beside); the
            # state is pickled apart, so that its SysIdentPy classes load only after
            # _sysidentpy() has imported the package with matplotlib's settings kept
            return _frols_from_state, (pickle.dumps(self.__dict__),)

    return RecordsFROLS


def _frols_from_state(state: bytes):
    """Rebuild a fitted ``RecordsFROLS`` from its pickled attributes."""
    cls = _frols_class()
    est = cls.__new__(cls)
    est.__dict__.update(pickle.loads(state))
    return est


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
    """Fit one structure on the scaled records (each capped in proportion, ``max_samples``)."""
    total = sum(p.size for p in pieces_q)
    keep = [max(lag + 2, int(cfg.max_samples * p.size / total)) for p in pieces_q]
    ys = [p[:k, None] for p, k in zip(pieces_q, keep, strict=True)]
    xs = [p[:k] for p, k in zip(pieces_x, keep, strict=True)]
    est = _estimator(degree, lag, xs[0].shape[1], cfg)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.fit_records(xs, ys)
    if not np.all(np.isfinite(np.asarray(est.theta, dtype=float))):
        raise IdentificationError("non-finite parameters")
    return est


#: Relative margin of the free-run score within which fewer terms are preferred.
SIMPLER_WITHIN = 0.25

#: Largest excursion of a free run on the stress inputs, in half-spans of the estimation
#: records' q about their midrange, that still counts as staying in the visited range.
STRESS_LIMIT = 2.0


def term_counts(k_criterion: int) -> list[int]:
    """Model sizes the free run compares: 4, 6, 12 and every multiple of 8 up to the criterion's.

    Parameters
    ----------
    k_criterion : int
        The information criterion's minimum (the largest size tried).

    Returns
    -------
    list of int
        Ascending sizes below ``k_criterion``, and ``k_criterion``.
    """
    sizes = {4, 6, 12, *range(8, k_criterion, 8)}
    return [*sorted(k for k in sizes if k < k_criterion), k_criterion]


def q_origins(q: np.ndarray) -> dict[str, float]:
    """Candidate origins of ``q`` for the polynomial: each moves with a shift of the data.

    Parameters
    ----------
    q : ndarray, shape (n,)
        The estimation records' positions, concatenated [unit of q].

    Returns
    -------
    dict
        ``"midrange"``: ``(max + min) / 2``; ``"halves"``: the mean of the medians of the
        samples below and at or above the midrange (the two wells' midpoint on a record that
        dwells in both).
    """
    mid = float(0.5 * (q.max() + q.min()))
    low, high = q[q < mid], q[q >= mid]
    halves = 0.5 * (np.median(low) + np.median(high)) if low.size and high.size else mid
    return {"midrange": mid, "halves": float(halves)}


def stress_inputs(v: Sequence[np.ndarray]) -> dict[str, np.ndarray]:
    """Return inputs the estimation records imply but do not contain, for a stability screen.

    From the records' inputs, concatenated (``n`` samples, amplitudes ``v_max`` per input):
    the same sequence time-reversed (``"reversed"``) and at half speed (``"slow"``, the first
    ``n`` samples); each input in turn ramped from 0 to its ``v_max`` and back, three times
    (``"ramps"``); each input in turn stepped through 0, 1/4, ..., 1, ..., 0 of its
    ``v_max`` (``"stairs"``). A model of a rig that stays in its visited range for every input
    of that range must stay there under these too.

    Parameters
    ----------
    v : sequence of ndarray, each shape (n_k, n_inputs)
        The estimation records' inputs [V].

    Returns
    -------
    dict of str to ndarray, each shape (n, n_inputs)
    """
    v = np.concatenate([np.asarray(r, dtype=float) for r in v])
    n, k = v.shape
    v_max = np.max(np.abs(v), axis=0)
    t = np.arange(n) / n
    triangle = 1.0 - np.abs(2.0 * ((3.0 * t) % 1.0) - 1.0)
    turn = np.floor(3.0 * k * t).astype(int) % k
    ramps = np.where(turn[:, None] == np.arange(k), triangle[:, None], 0.0) * v_max
    levels = np.array([0.0, 0.25, 0.5, 0.75, 1.0, 0.75, 0.5, 0.25, 0.0])
    part = n // k
    stairs = np.zeros_like(v)
    for i in range(k):
        stairs[i * part : (i + 1) * part, i] = levels[np.arange(part) * levels.size // part]
    stairs *= v_max
    return {"reversed": v[::-1].copy(), "slow": v[np.arange(n) // 2], "ramps": ramps,
            "stairs": stairs}  # fmt: skip


def _scaled_inputs(v, h_map: str) -> tuple[list[np.ndarray], np.ndarray]:
    """Each record's ``h(v)`` divided by its largest magnitude over all records."""
    h = [apply_input_map(r, h_map) for r in v]
    scale = np.max(np.abs(np.concatenate(h)), axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    return [r / scale for r in h], scale


def _free_run_score(model: NarxModel, ys, xs, span: float) -> float:
    """NRMSE(q) of the free runs over the estimation records, pooled (inf if one diverged).

    Each record runs from its first ``max_lag`` samples; the root of the summed squared
    error over all records' samples, divided by the output span ``span`` (scaled units).
    """
    sse, count = 0.0, 0
    for y, x in zip(ys, xs, strict=True):
        sim, at = model.simulate_scaled(y, x)
        if at >= 0:
            return np.inf
        sse += float(np.sum((sim - y)[model.max_lag :] ** 2))
        count += y.size - model.max_lag
    return float(np.sqrt(sse / count) / span)


def _stress_excursion(model: NarxModel, y0: np.ndarray, stress, centre: float, half: float):
    """Largest ``|y - centre| / half`` of the stress inputs' free runs (inf if one diverged)."""
    worst = 0.0
    for x in stress:
        sim, at = model.simulate_scaled(y0, x)
        if at >= 0:
            return np.inf
        worst = max(worst, float(np.max(np.abs(sim - centre))) / half)
    return worst


def _simplest_near_best(candidates: pd.DataFrame, poor: float = np.inf) -> dict | None:
    """Pick the fewest terms whose free-run score is within :data:`SIMPLER_WITHIN` of the best.

    Among the candidates that reproduce the estimation records (free-run NRMSE(q) at most
    ``poor``; all that ran free if none does), those that stayed within :data:`STRESS_LIMIT`
    on the stress inputs; if none stayed, all of them. None if no candidate ran free to the
    end of the estimation records.

    Parameters
    ----------
    candidates : pandas.DataFrame
        The search table of :func:`fit_narx` (``n_terms, degree, lag, free_run_nrmse_q,
        stress_excursion``).
    poor : float, optional
        The estimation free run's NRMSE(q) above which a candidate does not reproduce its own
        data (a lost switch: :data:`~debist.core.metrics.POOR_SHARE` of the mean baseline's);
        default: no bound.

    Returns
    -------
    dict or None
        The chosen row.
    """
    ok = candidates[np.isfinite(candidates.free_run_nrmse_q)] if len(candidates) else candidates
    if ok.empty:
        return None
    good = ok[ok.free_run_nrmse_q <= poor]
    ok = good if len(good) else ok
    steady = ok[ok.stress_excursion <= STRESS_LIMIT]
    ok = steady if len(steady) else ok
    near = ok[ok.free_run_nrmse_q <= (1.0 + SIMPLER_WITHIN) * ok.free_run_nrmse_q.min()]
    order = ["n_terms", "degree", "lag", "free_run_nrmse_q"]
    return near.sort_values(order, kind="stable").iloc[0].to_dict()


def fit_narx(
    q: Sequence[np.ndarray],
    v: Sequence[np.ndarray],
    input_map: str,
    cfg: NarxConfig,
    q_limit: float,
) -> NarxModel:
    """Choose and fit the polynomial NARX model on the estimation records.

    Per candidate structure (input map, degree, lags, origin of :func:`q_origins`), FROLS
    orders the terms on the stacked records and the information criterion's minimum gives the
    largest model size; the sizes of :func:`term_counts` up to it run free over the estimation
    records from each record's first ``max_lag`` samples and over :func:`stress_inputs`. Of
    the candidates that reproduce the estimation records (their free run not "poor": at most
    :data:`~debist.core.metrics.POOR_SHARE` of the mean baseline's NRMSE(q)), those that stay
    within :data:`STRESS_LIMIT` half-spans on the stress inputs (all, if none does), the
    fewest terms within :data:`SIMPLER_WITHIN` of the best free-run NRMSE(q) win, over every
    structure (:func:`_simplest_near_best`). A stable candidate that loses a switch on its own
    data does not displace one that reproduces them.

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
        If every candidate failed to fit or diverged in its free run.
    ResourceError
        If the largest candidate regressor would exceed the memory budget
        (:func:`debist.core.preflight.narx_bytes`), before any is built.

    References
    ----------
    Billings 2013, Ch. 3 (FROLS); Piroddi & Spinelli 2003 (simulation error); Masoud & Maas
    2025, Eq. 41 (the score).
    """
    q = [np.asarray(r, dtype=float) for r in q]
    v = [np.asarray(r, dtype=float).reshape(r.shape[0], -1) for r in v]
    lag, degree = max(cfg.lags), max(cfg.degree)
    fitted = min(int(cfg.max_samples), sum(r.size for r in q))  # the fits' cap (_fit)
    check_memory(
        narx_bytes(fitted, lag, degree, v[0].shape[1]),
        f"[compare.narx] max_samples = {cfg.max_samples} (with lags = {lag}, degree = {degree})",
        f"the NARX candidate regressor of {fitted} samples",
        "the matrix and its orthogonalised copies",
    )
    maps = cfg.input_maps or (input_map,)
    q_all = np.concatenate(q)
    q_std = float(np.std(q_all)) or 1.0
    span = float(np.ptp(q_all)) / q_std or 1.0
    mid = float(0.5 * (q_all.max() + q_all.min()))
    stress = stress_inputs(v)
    poor = POOR_SHARE * mean_baseline_nrmse(q_all)
    rows, fits = [], {}
    for h_map, degree, lag, (origin, q_origin) in itertools.product(
        maps, cfg.degree, cfg.lags, q_origins(q_all).items()
    ):
        ys = [(r - q_origin) / q_std for r in q]
        xs, scale = _scaled_inputs(v, h_map)
        stress_x = [apply_input_map(s, h_map) / scale for s in stress.values()]
        base = {"degree": degree, "lag": lag, "input_map": h_map, "origin": origin}
        try:
            est = _fit(ys, xs, degree, lag, cfg)
        except (IdentificationError, np.linalg.LinAlgError, ValueError) as exc:
            rows.append({**base, "n_terms": 0, "criterion_terms": 0, "free_run_nrmse_q": np.inf,
                         "stress_excursion": np.inf, "status": f"fit failed: {exc}"})  # fmt: skip
            continue
        for size in term_counts(est.n_terms_criterion):
            model = NarxModel(est.truncate(size), h_map, degree, lag, q_origin, q_std, scale,
                              q_limit)  # fmt: skip
            score = _free_run_score(model, ys, xs, span)
            excursion = _stress_excursion(model, ys[0], stress_x, (mid - q_origin) / q_std,
                                          0.5 * span)  # fmt: skip
            status = "ok" if np.isfinite(score) else "diverged"
            if status == "ok" and score > poor:
                status = "poor on the estimation records"
            elif status == "ok" and excursion > STRESS_LIMIT:
                status = "left the visited range on the stress inputs"
            rows.append({**base, "n_terms": size, "criterion_terms": est.n_terms_criterion,
                         "free_run_nrmse_q": score, "stress_excursion": excursion,
                         "status": status})  # fmt: skip
        fits[h_map, degree, lag, origin] = est, scale, q_origin
    candidates = pd.DataFrame(rows)
    best = _simplest_near_best(candidates, poor)
    if best is None:
        raise IdentificationError(
            "NARX: every candidate structure failed to fit or diverged in its free run over "
            "the estimation records"
        )
    est, scale, q_origin = fits.pop((best["input_map"], best["degree"], best["lag"],
                                     best["origin"]))  # fmt: skip
    est.truncate(int(best["n_terms"])).release()
    for other, *_ in fits.values():
        other.release()
    if len(est.final_model) == 0:
        warnings.warn("NARX: the chosen structure selected no term", DebistWarning, stacklevel=2)
    return NarxModel(est, best["input_map"], best["degree"], best["lag"], q_origin, q_std,
                     scale, q_limit, candidates)  # fmt: skip
