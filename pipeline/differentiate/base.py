"""The differentiate stage: one contract for every differentiator, and the registry.

Every differentiator is a function ``f(x, dt, *, config) -> Derivatives`` with ``x`` of
shape (n,) in the signal's unit, ``dt`` the sample time [s] and ``config`` the method's
frozen config dataclass; :func:`differentiate` picks one by name and builds its config
from a workflow section, so a workflow switches method with one setting.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

from numpy.typing import ArrayLike

from debist.core.errors import WorkflowError
from debist.differentiate.result import Derivatives
from debist.differentiate.savgol import SavGolConfig, savgol_derivatives
from debist.differentiate.spectral import SpectralConfig, spectral_derivatives
from debist.differentiate.tvregdiff_method import TVRegDiffConfig, tvregdiff_derivatives

__all__ = ["CONFIGS", "DIFFERENTIATORS", "Derivatives", "differentiate"]

#: Differentiators by method name (read-only).
DIFFERENTIATORS: Mapping[str, Callable[..., Derivatives]] = MappingProxyType(
    {
        "tvregdiff": tvregdiff_derivatives,
        "spectral": spectral_derivatives,
        "savgol": savgol_derivatives,
    }
)

#: Config dataclass of each method, each with a ``from_dict`` classmethod (read-only).
CONFIGS: Mapping[str, Any] = MappingProxyType(
    {
        "tvregdiff": TVRegDiffConfig,
        "spectral": SpectralConfig,
        "savgol": SavGolConfig,
    }
)


def differentiate(
    x: ArrayLike, dt: float, *, method: str, params: Mapping[str, Any] | None = None
) -> Derivatives:
    """Run the differentiator ``method`` with the workflow parameters ``params``.

    Parameters
    ----------
    x : array_like, shape (n,) [unit]
        Uniformly sampled signal (e.g. the position q [m]), finite.
    dt : float
        Sample time [s].
    method : {"tvregdiff", "spectral", "savgol"}
        A key of :data:`DIFFERENTIATORS`.
    params : mapping of str to value, optional
        The method's settings (keys of its config dataclass); missing keys take the defaults.

    Returns
    -------
    Derivatives
        ``x_hat`` [unit], ``x_dot`` [unit/s], ``x_ddot`` [unit/s^2] and diagnostics.

    Raises
    ------
    WorkflowError
        If ``method`` is unknown, or ``params`` has an unknown key or an invalid value.
    ValueError
        If ``x`` or ``dt`` is invalid.

    Warns
    -----
    ConvergenceWarning
        If an iterative method stops before its tolerance (``converged`` False).

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(200) * 0.01
    >>> d = differentiate(t**2, 0.01, method="savgol", params={"window": 11})
    >>> bool(np.allclose(d.x_dot, 2 * t))
    True
    """
    if method not in DIFFERENTIATORS:
        raise WorkflowError(
            f"[differentiate] method: unknown method {method!r}; known methods: "
            + ", ".join(DIFFERENTIATORS),
            key="differentiate.method",
            value=method,
        )
    config = CONFIGS[method].from_dict({} if params is None else params)
    return DIFFERENTIATORS[method](x, dt, config=config)
