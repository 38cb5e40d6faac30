"""The ``"tvregdiff"`` differentiator: TVRegDiff applied twice, for q_dot and q_ddot."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any, Literal, Self

import numpy as np
import pydantic
from numpy.typing import ArrayLike
from pydantic import BeforeValidator, PositiveFloat, PositiveInt

from pipeline.config import CONFIG, ConfigValueError
from pipeline.differentiate.result import Derivatives, check_signal, config_from_dict
from pipeline.differentiate.tvregdiff import tvregdiff
from pipeline.ingest.units import lookup_unit


def unit_factor(symbol: str) -> float | None:
    """SI value of one ``symbol`` (e.g. 1e-3 for "mm"), or None for an unknown unit."""
    unit = lookup_unit(symbol)
    return None if unit is None else unit.factor


__all__ = ["TVRegDiffConfig", "tvregdiff_derivatives"]


def _lower(value: object) -> object:
    return value.lower() if isinstance(value, str) else value


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class TVRegDiffConfig:
    """Settings of the ``"tvregdiff"`` differentiator.

    The defaults are the paper's ``alpha = 0.01``, ``ep = 1e-6`` for a position in
    millimetres, converted to metres (scaling the data by ``c`` maps ``alpha -> c alpha``,
    ``ep -> c**2 ep``; here ``c = 1e-3``), with ``dx = dt``.

    Parameters
    ----------
    alpha : float, optional
        Regularisation weight of the first derivative [unit s], ``> 0``.
    iterations : int, optional
        Maximum lagged-diffusivity iterations of the first derivative, ``>= 1``.
    scale : {"large", "small"}, optional
        Chartrand's discretisation, for both passes.
    ep : float, optional
        TV smoothing of the first pass, ``> 0`` [(unit/s)^2 for ``"large"``,
        (unit/s^2)^2 for ``"small"``].
    alpha2 : float, optional
        Regularisation weight of the second pass (x_dot -> x_ddot) [unit], default
        ``alpha``. The second pass differentiates x_dot [unit/s], so the same number
        regularises differently: choose it for the velocity's scale.
    iterations2 : int, optional
        Maximum iterations of the second pass, default ``iterations``.
    ep2 : float, optional
        TV smoothing of the second pass, default ``ep``.
    tol : float, optional
        Relative-change tolerance of both passes.
    unit : str, optional
        Unit of ``x`` in which ``alpha``, ``ep`` (and the second-pass values) are stated,
        e.g. ``"mm"`` to use the paper's ``alpha = 0.01``, ``ep = 1e-6`` as printed: the SI
        signal is expressed in that unit for the computation and the derivatives are
        converted back, which is exactly the rescaling above. Default: the SI unit of ``x``.

    Raises
    ------
    pydantic.ValidationError
        If a value has the wrong type or is out of range (a ``ValueError``;
        :meth:`from_dict` raises a ``WorkflowError`` naming the key instead).

    Examples
    --------
    >>> TVRegDiffConfig.from_dict({"alpha": 1e-4, "iterations": 20}).iterations
    20
    """

    alpha: PositiveFloat = 1e-5
    iterations: PositiveInt = 10
    scale: Annotated[Literal["large", "small"], BeforeValidator(_lower)] = "large"
    ep: PositiveFloat = 1e-12
    alpha2: PositiveFloat | None = None
    iterations2: PositiveInt | None = None
    ep2: PositiveFloat | None = None
    tol: PositiveFloat = 1e-6
    unit: str | None = None

    def __post_init__(self) -> None:
        if self.unit is not None and unit_factor(self.unit) is None:
            raise ConfigValueError("unit", "a known unit (e.g. 'mm', 'm', 'V')", self.unit)

    @classmethod
    def from_dict(cls, params: Mapping[str, Any], where: str = "[differentiate]") -> Self:
        """Build from a workflow section.

        Parameters
        ----------
        params : mapping of str to value
            Keys among the attribute names.
        where : str, optional
            The workflow table, for the messages.

        Returns
        -------
        TVRegDiffConfig
            The config.

        Raises
        ------
        WorkflowError
            On an unknown key or an invalid value.
        """
        return config_from_dict(cls, params, "tvregdiff", where)


_DEFAULT = TVRegDiffConfig()


def tvregdiff_derivatives(
    x: ArrayLike, dt: float, *, config: TVRegDiffConfig = _DEFAULT
) -> Derivatives:
    """Smoothed signal and two derivatives by TVRegDiff, applied twice.

    ``x_dot`` is :func:`~pipeline.differentiate.tvregdiff.tvregdiff` of ``x``
    (``dx = dt``), ``x_ddot`` is ``tvregdiff`` of ``x_dot`` with the second-pass
    settings, both taken at the sample instants (``TVRegDiffResult.derivative``).
    ``x_hat`` is the cumulative trapezoid integral of ``x_dot`` plus the constant that
    fits ``x`` in least squares (so ``x_hat`` is consistent with ``x_dot``).

    Parameters
    ----------
    x : array_like, shape (n,) [unit]
        Uniformly sampled signal, ``n >= 3``, finite.
    dt : float
        Sample time [s].
    config : TVRegDiffConfig, optional
        Settings. ``alpha`` depends on the unit of ``x`` and on ``dt``: scaling ``x`` by
        ``c`` needs ``alpha -> c alpha`` and ``ep -> c**2 ep`` for the same result.

    Returns
    -------
    Derivatives
        ``x_hat`` [unit], ``x_dot`` [unit/s], ``x_ddot`` [unit/s^2]; ``converged`` is
        True when both passes met ``tol``; ``info`` holds ``n_iter``, ``n_iter2``,
        ``functional``, ``functional2`` (final values), ``rel_change``, ``rel_change2``
        and the settings used.

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
    .. [1] Chartrand, R. (2011). Numerical differentiation of noisy, nonsmooth data.
       ISRN Applied Mathematics 2011, 164564.
    .. [2] Masoud, A. & Maas, J. (2025). Front. Robot. AI 12, Section 5 (alpha = 0.01,
       ep = 1e-6).

    Examples
    --------
    >>> import numpy as np
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
    alpha2 = c.alpha if c.alpha2 is None else c.alpha2
    iterations2 = c.iterations if c.iterations2 is None else c.iterations2
    ep2 = c.ep if c.ep2 is None else c.ep2
    first = tvregdiff(x, c.iterations, c.alpha, scale=c.scale, ep=c.ep, dx=dt, tol=c.tol)
    x_dot = first.derivative
    second = tvregdiff(x_dot, iterations2, alpha2, scale=c.scale, ep=ep2, dx=dt, tol=c.tol)
    from scipy.integrate import cumulative_trapezoid

    integral = cumulative_trapezoid(x_dot, dx=dt, initial=0.0)
    x_hat = integral + np.mean(x - integral)
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
    return Derivatives(
        x_hat=s * x_hat,
        x_dot=s * x_dot,
        x_ddot=s * second.derivative,
        method="tvregdiff",
        converged=first.converged and second.converged,
        info=info,
    )
