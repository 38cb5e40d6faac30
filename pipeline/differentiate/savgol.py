"""The ``"savgol"`` differentiator: Savitzky-Golay local polynomial fits."""

from __future__ import annotations

from typing import Annotated, ClassVar

import pydantic
from numpy.typing import ArrayLike
from pydantic import Field

from debist.core.config import CONFIG, ConfigValueError, SectionConfig
from debist.differentiate.result import Derivatives, check_signal

__all__ = ["SavGolConfig", "savgol_derivatives"]


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class SavGolConfig(SectionConfig):
    """Settings of the ``"savgol"`` differentiator.

    Parameters
    ----------
    window : int, optional
        Window length [samples], odd (so the fit is centred on the sample), ``> polyorder``.
    polyorder : int, optional
        Degree of the local polynomial, ``>= 2`` (``x_ddot`` needs it).

    Raises
    ------
    pydantic.ValidationError
        If a value has the wrong type or is out of range (a ``ValueError``;
        :meth:`from_dict` raises a ``WorkflowError`` naming the key instead).

    Examples
    --------
    >>> SavGolConfig.from_dict({"window": 31}).polyorder
    3
    """

    SECTION: ClassVar[str] = "[differentiate]"
    KNOWN_LABEL: ClassVar[str] = "known keys of method 'savgol'"

    window: Annotated[int, Field(ge=3)] = 21
    polyorder: Annotated[int, Field(ge=2)] = 3

    def __post_init__(self) -> None:
        if self.window % 2 == 0:
            raise ConfigValueError("window", "an odd integer", self.window)
        if self.polyorder >= self.window:
            raise ConfigValueError(
                "polyorder", f"an integer < window = {self.window}", self.polyorder
            )


_DEFAULT = SavGolConfig()


def savgol_derivatives(x: ArrayLike, dt: float, *, config: SavGolConfig = _DEFAULT) -> Derivatives:
    """Smoothed signal and two derivatives by Savitzky-Golay filtering.

    Value and derivatives of the least-squares polynomial of degree ``polyorder`` over the
    centred ``window`` (:func:`scipy.signal.savgol_filter`, ``mode="interp"`` at the ends):
    exact for polynomials of degree ``<= polyorder``, everywhere including the ends.

    Parameters
    ----------
    x : array_like, shape (n,) [unit]
        Uniformly sampled signal, ``n >= window``, finite.
    dt : float
        Sample time [s].
    config : SavGolConfig, optional
        Window and polynomial degree.

    Returns
    -------
    Derivatives
        ``x_hat`` [unit], ``x_dot`` [unit/s], ``x_ddot`` [unit/s^2]; ``converged`` is
        True; ``info`` holds ``window``, ``polyorder`` and ``window_s`` [s].

    Raises
    ------
    ValueError
        If ``x`` or ``dt`` is invalid or ``x`` is shorter than the window.

    References
    ----------
    Savitzky & Golay 1964, Anal. Chem. 36(8), 1627-1639.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(50) * 0.1
    >>> d = savgol_derivatives(t**3, 0.1, config=SavGolConfig(window=7, polyorder=3))
    >>> bool(np.allclose(d.x_ddot, 6 * t))
    True
    """
    x, dt = check_signal(x, dt)
    w, p = config.window, config.polyorder
    if x.size < w:
        raise ValueError(f"`x` must have at least `window`={w} samples, got {x.size}")
    from scipy.signal import savgol_filter

    x_hat = savgol_filter(x, w, p, deriv=0, mode="interp")
    x_dot = savgol_filter(x, w, p, deriv=1, delta=dt, mode="interp")
    x_ddot = savgol_filter(x, w, p, deriv=2, delta=dt, mode="interp")
    info = {"window": w, "polyorder": p, "window_s": w * dt}
    return Derivatives(x_hat, x_dot, x_ddot, method="savgol", converged=True, info=info)
