"""The ``"spectral"`` differentiator: band-limited differentiation by FFT."""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

import numpy as np
import pydantic
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, PositiveFloat

from debist.core.config import CONFIG, SectionConfig
from debist.differentiate.result import Derivatives, check_signal

__all__ = ["SpectralConfig", "lowpass_gain", "spectral_derivatives"]


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class SpectralConfig(SectionConfig):
    """Settings of the ``"spectral"`` differentiator.

    Parameters
    ----------
    cutoff_hz : float or None, optional
        Low-pass cutoff [Hz]: the gain is 0 at and above it. ``None``: no low-pass
        (pure spectral differentiation up to the Nyquist frequency).
    taper : float, optional
        Relative width of the raised-cosine transition, in ``[0, 1]``: the gain is 1 up
        to ``(1 - taper) * cutoff_hz`` and falls smoothly to 0 at ``cutoff_hz``.
    extension : {"odd", "periodic"}, optional
        How the record is made periodic. ``"odd"`` (default): subtract the straight line
        through the first and last samples, then extend the remainder (zero at both
        ends) oddly, which gives a continuous periodic signal with a continuous first
        derivative, so a non-periodic record does not ring at its ends.
        ``"periodic"``: use the record as one period, as it is (exact for a band-limited
        periodic record, rings for any other).

    Raises
    ------
    pydantic.ValidationError
        If a value has the wrong type or is out of range (a ``ValueError``;
        :meth:`from_dict` raises a ``WorkflowError`` naming the key instead).

    Examples
    --------
    >>> SpectralConfig.from_dict({"cutoff_hz": 5.0}).taper
    0.2
    """

    SECTION: ClassVar[str] = "[differentiate]"
    KNOWN_LABEL: ClassVar[str] = "known keys of method 'spectral'"

    cutoff_hz: PositiveFloat | None = 10.0
    taper: Annotated[float, Field(ge=0, le=1, description="a number in [0, 1]")] = 0.2
    extension: Literal["odd", "periodic"] = "odd"


def lowpass_gain(freq: ArrayLike, cutoff_hz: float | None, taper: float) -> NDArray[np.float64]:
    """Gain of the raised-cosine low-pass used by :func:`spectral_derivatives`.

    Parameters
    ----------
    freq : array_like, shape (m,) [Hz]
        Non-negative frequencies.
    cutoff_hz : float or None
        Frequency [Hz] from which the gain is 0; ``None`` for all-pass.
    taper : float
        Relative transition width in ``[0, 1]``.

    Returns
    -------
    ndarray, shape (m,)
        1 below ``(1 - taper) * cutoff_hz``, ``(1 + cos(pi s)) / 2`` across the
        transition (``s`` from 0 to 1), 0 from ``cutoff_hz`` on.

    Examples
    --------
    >>> lowpass_gain([0.0, 4.0, 4.5, 5.0, 6.0], 5.0, 0.2)
    array([1. , 1. , 0.5, 0. , 0. ])
    """
    f = np.asarray(freq, dtype=float)
    if cutoff_hz is None:
        return np.ones_like(f)
    f_pass = (1.0 - taper) * cutoff_hz
    gain = (f < cutoff_hz).astype(float)
    if taper > 0:
        band = (f > f_pass) & (f < cutoff_hz)
        s = (f[band] - f_pass) / (cutoff_hz - f_pass)
        gain[band] = 0.5 * (1.0 + np.cos(np.pi * s))
    return gain


_DEFAULT = SpectralConfig()


def spectral_derivatives(
    x: ArrayLike, dt: float, *, config: SpectralConfig = _DEFAULT
) -> Derivatives:
    """Smoothed signal and two derivatives by low-pass spectral differentiation.

    The (extended) record is transformed by a real FFT, multiplied by the low-pass gain
    and by ``i omega`` (``x_dot``) or ``-omega^2`` (``x_ddot``), and transformed back.
    Extensions and accuracy at the ends: docs/explanation/implementation.md.

    Parameters
    ----------
    x : array_like, shape (n,) [unit]
        Uniformly sampled signal, ``n >= 3``, finite.
    dt : float
        Sample time [s].
    config : SpectralConfig, optional
        Cutoff, taper and extension.

    Returns
    -------
    Derivatives
        ``x_hat`` [unit] (low-passed), ``x_dot`` [unit/s], ``x_ddot`` [unit/s^2];
        ``converged`` is True; ``info`` the FFT length and settings.

    Raises
    ------
    ValueError
        If ``x`` or ``dt`` is invalid.

    References
    ----------
    Trefethen, L. N. (2000). Spectral Methods in MATLAB. SIAM, Ch. 3.

    Examples
    --------
    >>> t = np.arange(100) * 0.01
    >>> x = np.sin(2 * np.pi * t)
    >>> d = spectral_derivatives(x, 0.01, config=SpectralConfig(extension="periodic"))
    >>> bool(np.allclose(d.x_dot, 2 * np.pi * np.cos(2 * np.pi * t)))
    True
    """
    x, dt = check_signal(x, dt)
    n = x.size
    if config.extension == "odd":
        slope = (x[-1] - x[0]) / ((n - 1) * dt)
        trend = x[0] + slope * dt * np.arange(n)
        r = x - trend
        ext = np.concatenate((r, -r[-2:0:-1]))
    else:
        slope = 0.0
        trend = np.zeros(n)
        ext = x
    m = ext.size
    spectrum = np.fft.rfft(ext) * lowpass_gain(
        np.fft.rfftfreq(m, d=dt), config.cutoff_hz, config.taper
    )
    omega = 2.0 * np.pi * np.fft.rfftfreq(m, d=dt)
    d1 = 1j * omega
    if m % 2 == 0:
        d1[-1] = 0.0
    x_hat = np.fft.irfft(spectrum, m)[:n] + trend
    x_dot = np.fft.irfft(spectrum * d1, m)[:n] + slope
    x_ddot = np.fft.irfft(spectrum * -(omega**2), m)[:n]
    info = {
        "n_fft": m,
        "cutoff_hz": config.cutoff_hz,
        "taper": config.taper,
        "extension": config.extension,
    }
    return Derivatives(x_hat, x_dot, x_ddot, method="spectral", converged=True, info=info)
