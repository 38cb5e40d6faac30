"""The ``"tvregdiff"`` differentiator: TVRegDiff applied twice, for q_dot and q_ddot."""

from __future__ import annotations

import itertools
import warnings
from dataclasses import replace
from typing import Annotated, Any, ClassVar, Literal

import numpy as np
import pydantic
from numpy.typing import ArrayLike, NDArray
from pydantic import BeforeValidator, PositiveFloat, PositiveInt

from debist.core.config import CONFIG, ConfigValueError, SectionConfig
from debist.core.errors import ConvergenceWarning
from debist.core.metrics import rms
from debist.core.units import lookup_unit
from debist.differentiate.result import Derivatives, check_signal
from debist.differentiate.tvregdiff import TVRegDiffResult, tvregdiff


def unit_factor(symbol: str) -> float | None:
    """SI value of one ``symbol`` (e.g. 1e-3 for "mm"), or None for an unknown unit."""
    unit = lookup_unit(symbol)
    return None if unit is None else unit.factor


__all__ = ["AUTO_GRID_MM", "AUTO_SLOPE", "TVRegDiffConfig", "auto_alpha", "tvregdiff_derivatives"]


def _lower(value: object) -> object:
    return value.lower() if isinstance(value, str) else value


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class TVRegDiffConfig(SectionConfig):
    """Settings of the ``"tvregdiff"`` differentiator.

    Raises
    ------
    pydantic.ValidationError
        If a value has the wrong type or is out of range (a ``ValueError``;
        :meth:`from_dict` raises a ``WorkflowError`` naming the key instead).

    Notes
    -----
    Each field is one key of ``[differentiate]``, documented under its declaration. The default
    ``ep`` is the paper's ``1e-6`` for q in mm, converted to m; the paper's ``alpha = 0.01`` is
    ``alpha = 0.01, unit = "mm"``: docs/explanation/implementation.md.

    References
    ----------
    Chartrand 2011, ISRN Appl. Math. 2011, 164564; Masoud & Maas 2025, Section 5.

    Examples
    --------
    >>> TVRegDiffConfig.from_dict({"alpha": 1e-4, "iterations": 20}).iterations
    20
    """

    SECTION: ClassVar[str] = "[differentiate]"
    KNOWN_LABEL: ClassVar[str] = "known keys of method 'tvregdiff'"

    alpha: PositiveFloat | Literal["auto"] = "auto"
    """Regularisation weight of the first derivative [unit s], > 0; "auto" chooses it per record
    from alpha_grid.
    """
    iterations: PositiveInt = 10
    """Maximum lagged-diffusivity iterations of the first derivative, >= 1."""
    scale: Annotated[Literal["large", "small"], BeforeValidator(_lower)] = "large"
    """Chartrand's discretisation, for both passes."""
    ep: PositiveFloat = 1e-12
    """TV smoothing of the first pass, > 0 [(unit/s)^2 for "large", (unit/s^2)^2 for "small"].
    """
    alpha2: PositiveFloat | None = None
    """Regularisation weight of the second pass (x_dot -> x_ddot) [unit]; default alpha."""
    iterations2: PositiveInt | None = None
    """Maximum iterations of the second pass; default iterations."""
    ep2: PositiveFloat | None = None
    """TV smoothing of the second pass; default ep."""
    tol: PositiveFloat = 1e-6
    """Relative-change tolerance of both passes."""
    unit: str | None = None
    """Unit of x in which alpha and ep are stated, e.g. "mm" for the paper's alpha = 0.01, ep =
    1e-6; default the SI unit of x.
    """
    alpha_grid: tuple[PositiveFloat, ...] | None = None
    """Candidates of alpha = "auto" [unit s]; default the paper's alpha times 10^1 .. 10^-3 in half
    decades.
    """

    def __post_init__(self) -> None:
        if self.unit is not None and unit_factor(self.unit) is None:
            raise ConfigValueError("unit", "a known unit (e.g. 'mm', 'm', 'V')", self.unit)


_DEFAULT = TVRegDiffConfig()

#: The paper's alpha [mm s] (Masoud & Maas 2025, Sec. 5: 0.01 for q in mm, dx = dt).
PAPER_ALPHA_MM = 0.01
#: Default grid of ``alpha = "auto"``: the paper's alpha times 10^1 .. 10^-3 in half decades
#: [mm s], largest first.
AUTO_GRID_MM = tuple(PAPER_ALPHA_MM * 10.0 ** (k / 2) for k in range(2, -7, -1))
#: ``alpha = "auto"`` takes the largest alpha below which the residual rms(x - x_hat) falls
#: by less than this power of alpha (log-log slope; 0.1: a tenfold weaker regularisation
#: lowers the residual by less than 21 %).
AUTO_SLOPE = 0.1


def auto_alpha(
    x: NDArray[np.float64], dt: float, config: TVRegDiffConfig
) -> tuple[float, list[dict[str, float]], Any]:
    """Choose TVRegDiff's alpha from the data: the strongest smoothing that still fits them.

    For each alpha of the grid (``config.alpha_grid``, in the unit of ``x`` given by
    ``config.unit``; default :data:`AUTO_GRID_MM` converted from mm s), the first pass
    gives ``x_dot`` and its integral ``x_hat``. The residual ``r = rms(x - x_hat)`` falls
    steeply while the regularisation distorts the signal and levels off once only noise is
    left to fit. The choice is the largest alpha at which the residual curve has levelled
    off: the first grid value (from the largest) whose log-log slope to the next smaller
    value, ``log(r_i / r_(i+1)) / log(alpha_i / alpha_(i+1))``, is below
    :data:`AUTO_SLOPE` (the corner of the L-curve, taken on the grid); the smallest alpha if
    the curve never levels off. No noise level is assumed: a laser's FIR-filtered noise is
    not white, and difference-based noise estimates miss it by up to 10x.

    Parameters
    ----------
    x : ndarray, shape (n,)
        Signal in the unit the grid is stated in [unit].
    dt : float
        Sample time [s].
    config : TVRegDiffConfig
        Iterations, scale, ``ep``, ``tol`` and the grid.

    Returns
    -------
    alpha : float
        The chosen alpha [unit s].
    search : list of dict
        Per grid value ``{"alpha", "residual"}`` (residual [unit]), largest alpha first.
    first : TVRegDiffResult
        The first pass at the chosen alpha (reused, not recomputed).

    References
    ----------
    Chartrand 2011, ISRN Applied Mathematics 2011, 164564 (TVRegDiff); Hansen 1992, SIAM
    Review 34(4), 561-580 (the L-curve); Masoud & Maas 2025, Sec. 5 (alpha = 0.01, q in mm).
    """
    if config.alpha_grid is not None:
        grid = sorted(config.alpha_grid, reverse=True)
    else:
        per_mm = float(unit_factor("mm")) / (
            1.0 if config.unit is None else float(unit_factor(config.unit))
        )
        grid = [a * per_mm for a in AUTO_GRID_MM]
    search, passes = [], []
    for a in grid:
        res = tvregdiff(x, config.iterations, a, scale=config.scale, ep=config.ep, dx=dt,
                        tol=config.tol)  # fmt: skip
        resid = x - _antiderivative(x, res.derivative, dt)
        search.append({"alpha": float(a), "residual": rms(resid)})
        passes.append(res)
    chosen = len(search) - 1
    for i, (hi, lo) in enumerate(itertools.pairwise(search)):
        if lo["residual"] <= 0.0 or hi["alpha"] <= lo["alpha"]:
            continue
        slope = np.log(hi["residual"] / lo["residual"]) / np.log(hi["alpha"] / lo["alpha"])
        if slope < AUTO_SLOPE:
            chosen = i
            break
    return search[chosen]["alpha"], search, passes[chosen]


def _antiderivative(x: NDArray[np.float64], x_dot: NDArray[np.float64], dt: float):
    """``x_hat``: the cumulative trapezoid integral of ``x_dot`` plus the constant fitting ``x``."""
    from scipy.integrate import cumulative_trapezoid

    integral = cumulative_trapezoid(x_dot, dx=dt, initial=0.0)
    return integral + np.mean(x - integral)


#: A stopped TVRegDiff is continued to this many times its iterations, to tell how far the
#: derivatives still move (:func:`longer_run`).
CHECK_FACTOR = 4
#: Relative change [-] of a derivative under :data:`CHECK_FACTOR` times the iterations
#: below which the iteration limit is said not to matter (debist's threshold, not the
#: paper's; the differentiate summary keeps the measured change for the user to judge).
SETTLED = 0.01


def longer_run(
    x: NDArray[np.float64],
    first: TVRegDiffResult,
    second: TVRegDiffResult,
    config: TVRegDiffConfig,
    dt: float,
) -> dict[str, float | int]:
    """Continue both passes of a stopped TVRegDiff and measure how far the derivatives move.

    Lagged diffusivity is a fixed-point iteration of ``u`` alone, so continuing from the last
    iterate for ``CHECK_FACTOR - 1`` times the iterations is a run with :data:`CHECK_FACTOR`
    times the count. The first pass is continued from its ``u``; the second is run again on
    the continued first derivative with :data:`CHECK_FACTOR` times its count: together the
    derivatives of :func:`tvregdiff_derivatives` with both counts times :data:`CHECK_FACTOR`.

    Parameters
    ----------
    x : ndarray, shape (n,)
        The data the first pass differentiated [unit].
    first, second : TVRegDiffResult
        The two passes as run (their ``u``, ``derivative``, ``alpha``, ``ep``, ``scale``).
    config : TVRegDiffConfig
        The settings (``iterations``, ``iterations2``, ``tol``).
    dt : float
        Sample time [s].

    Returns
    -------
    dict
        ``iterations`` (of the longer first pass), ``q_dot`` and ``q_ddot``: the relative
        change ``||d_long - d|| / ||d_long||`` of each derivative [-].

    References
    ----------
    Vogel & Oman 1996, SIAM J. Sci. Comput. 17(1), 227-238 (lagged diffusivity).
    """
    n1 = config.iterations
    n2 = config.iterations if config.iterations2 is None else config.iterations2
    with warnings.catch_warnings():  # the longer run may stop short of tol as well
        warnings.simplefilter("ignore", ConvergenceWarning)
        more = tvregdiff(x, (CHECK_FACTOR - 1) * n1, first.alpha, u0=first.u,
                         scale=first.scale, ep=first.ep, dx=dt, tol=config.tol)  # fmt: skip
        again = tvregdiff(more.derivative, CHECK_FACTOR * n2, second.alpha,
                          scale=second.scale, ep=second.ep, dx=dt, tol=config.tol)  # fmt: skip
    return {
        "iterations": CHECK_FACTOR * n1,
        "q_dot": _relative(first.derivative, more.derivative),
        "q_ddot": _relative(second.derivative, again.derivative),
    }


def _relative(d: NDArray[np.float64], reference: NDArray[np.float64]) -> float:
    """``||d - reference|| / ||reference||`` (0 for a zero reference equal to ``d``)."""
    norm = float(np.linalg.norm(reference))
    diff = float(np.linalg.norm(d - reference))
    return diff / norm if norm > 0 else (0.0 if diff == 0 else float("inf"))


def tvregdiff_derivatives(
    x: ArrayLike, dt: float, *, config: TVRegDiffConfig = _DEFAULT
) -> Derivatives:
    """Smoothed signal and two derivatives by TVRegDiff, applied twice.

    Parameters
    ----------
    x : array_like, shape (n,) [unit]
        Uniformly sampled signal, ``n >= 3``, finite.
    dt : float
        Sample time [s].
    config : TVRegDiffConfig, optional
        Settings; ``alpha`` depends on the unit of ``x`` and on ``dt``.

    Returns
    -------
    Derivatives
        ``x_dot`` [unit/s] (:func:`~debist.differentiate.tvregdiff.tvregdiff` of ``x``),
        ``x_ddot`` [unit/s^2] (of ``x_dot``, second-pass settings), ``x_hat`` [unit] (the
        integral of ``x_dot`` fitted to ``x``); ``converged``; ``info`` (with ``check``, what
        :func:`longer_run` measured, when a pass stopped before ``tol``).

    Raises
    ------
    ValueError
        If ``x`` or ``dt`` is invalid.

    Warns
    -----
    ConvergenceWarning
        For each pass that stops before ``tol``.

    References
    ----------
    Chartrand 2011, ISRN Appl. Math. 2011, 164564; Masoud & Maas 2025, Section 5.

    Examples
    --------
    >>> t = np.arange(300) * 0.01
    >>> cfg = TVRegDiffConfig(alpha=1e-6, iterations=50, ep=1e-8, tol=1e-3)
    >>> d = tvregdiff_derivatives(0.5 * t**2, 0.01, config=cfg)
    >>> bool(np.allclose(d.x_dot[30:270], t[30:270], atol=1e-3))
    True
    """
    x, dt = check_signal(x, dt)
    c = config
    s = 1.0 if c.unit is None else float(unit_factor(c.unit))
    x = x / s
    search = None
    if c.alpha == "auto":  # the search ran the first pass at every alpha: keep the chosen one
        alpha, search, first = auto_alpha(x, dt, c)
        c = replace(c, alpha=alpha)
    else:
        first = tvregdiff(x, c.iterations, c.alpha, scale=c.scale, ep=c.ep, dx=dt, tol=c.tol)
    alpha2 = c.alpha if c.alpha2 is None else c.alpha2
    iterations2 = c.iterations if c.iterations2 is None else c.iterations2
    ep2 = c.ep if c.ep2 is None else c.ep2
    x_dot = first.derivative
    second = tvregdiff(x_dot, iterations2, alpha2, scale=c.scale, ep=ep2, dx=dt, tol=c.tol)
    x_hat = _antiderivative(x, x_dot, dt)
    info = {
        "n_iter": first.n_iter,
        "n_iter2": second.n_iter,
        "functional": float(first.functional[-1]),
        "functional2": float(second.functional[-1]),
        "rel_change": float(first.rel_change[-1]),
        "rel_change2": float(second.rel_change[-1]),
        "scale": first.scale,
        "alpha": c.alpha,
        "alpha2": alpha2,
        "ep": c.ep,
        "ep2": ep2,
    }
    info["unit"] = c.unit
    if not (first.converged and second.converged):  # did the limit matter? run on
        info["check"] = longer_run(x, first, second, c, dt)
    if search is not None:
        info["alpha_search"] = search
    return Derivatives(
        x_hat=s * x_hat,
        x_dot=s * x_dot,
        x_ddot=s * second.derivative,
        method="tvregdiff",
        converged=first.converged and second.converged,
        info=info,
    )
