"""Gaussian radial basis functions on equidistant centres (Masoud & Maas 2025, Eq. 35, 38, 39)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from debist.core.errors import WorkflowError


def gaussian(dq, sigma):
    """Return the Gaussian of Eq. 38 at distance ``dq`` from its centre.

    The one definition of the basis function: the fit's regressor, the curves, the
    excitation counts, the NumPy engine and (compiled by numba) the free-run kernel call it.

    Parameters
    ----------
    dq : float or ndarray
        ``q - xi_i`` [unit of q].
    sigma : float or ndarray
        The width sigma [unit of q], broadcast against ``dq``.

    Returns
    -------
    float or ndarray
        ``exp(-dq^2 / (2 sigma^2))``.

    References
    ----------
    Masoud & Maas 2025, Eq. 38.

    Examples
    --------
    >>> float(gaussian(0.0, 1.0)), round(float(gaussian(1.0, 1.0)), 6)
    (1.0, 0.606531)
    """
    return np.exp(-(dq * dq) / (2.0 * sigma * sigma))


@dataclass(frozen=True)
class RBFBasis:
    """Gaussian RBFs with equidistant centres over an operating range.

    Parameters
    ----------
    xi : ndarray, shape (M,)
        Centres xi_i [unit of q], increasing and equidistant (Eq. 39).
    sigma : float
        Width sigma = sigma_n * delta_xi [unit of q] (Eq. 38).
    outside : {"clip", "zero"}
        Evaluation outside [xi_1, xi_M]: ``"clip"`` holds the basis at the
        nearest end of the range (the identified curves stay at their edge
        values), ``"zero"`` lets the Gaussians decay as printed in Eq. 38.

    Notes
    -----
    Eq. 35 as printed lacks the minus sign of the exponent (docs/interpretation.md item 7); the
    Gaussian ``exp(-(q - xi_i)^2 / (2 sigma^2))`` of Eq. 38 is implemented.

    References
    ----------
    Masoud & Maas 2025, Eq. 35, 38, 39.
    """

    xi: np.ndarray
    sigma: float
    outside: str = "clip"

    @classmethod
    def equidistant(
        cls, q_min: float, q_max: float, M: int, sigma_n: float, outside: str = "clip"
    ) -> RBFBasis:
        """Build M equidistant centres over [q_min, q_max] (Eq. 39).

        Parameters
        ----------
        q_min, q_max : float
            Operating range [unit of q], ``q_max > q_min``.
        M : int
            Number of centres, at least 2.
        sigma_n : float
            Normalised width, ``sigma = sigma_n * delta_xi``, positive.
        outside : {"clip", "zero"}, optional
            Evaluation outside the range (see the class docstring).

        Returns
        -------
        RBFBasis

        Raises
        ------
        WorkflowError
            If M < 2, sigma_n <= 0, the range is empty or ``outside`` is unknown.

        Examples
        --------
        >>> b = RBFBasis.equidistant(-1.0, 1.0, M=5, sigma_n=0.5)
        >>> b.xi.tolist(), b.sigma
        ([-1.0, -0.5, 0.0, 0.5, 1.0], 0.25)
        """
        if int(M) != M or M < 2:
            raise WorkflowError(f"`M` must be an integer >= 2, got {M!r}")
        if not sigma_n > 0:
            raise WorkflowError(f"`sigma_n` must be positive, got {sigma_n!r}")
        if not (np.isfinite(q_min) and np.isfinite(q_max) and q_max > q_min):
            raise WorkflowError(f"operating range [{q_min!r}, {q_max!r}] is empty")
        if outside not in ("clip", "zero"):
            raise WorkflowError(f"`outside` must be 'clip' or 'zero', got {outside!r}")
        xi = np.linspace(q_min, q_max, int(M))
        return cls(xi=xi, sigma=float(sigma_n * (xi[1] - xi[0])), outside=outside)

    @property
    def M(self) -> int:
        """Number of centres."""
        return int(self.xi.size)

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """Evaluate all basis functions.

        Parameters
        ----------
        q : array_like, shape (n,)
            Positions [unit of q].

        Returns
        -------
        ndarray, shape (n, M)
            phi_i(q_k) of Eq. 38.
        """
        q = np.asarray(q, dtype=float)
        if self.outside == "clip":
            q = np.clip(q, self.xi[0], self.xi[-1])
        return gaussian(q[..., None] - self.xi, self.sigma)

    def support(self, q: np.ndarray) -> np.ndarray:
        """Count the samples within one width of each centre.

        Parameters
        ----------
        q : array_like, shape (n,)
            Positions [unit of q].

        Returns
        -------
        ndarray of int, shape (M,)
            Number of samples with ``|q - xi_i| <= sigma``.
        """
        q = np.asarray(q, dtype=float)
        return (np.abs(q[:, None] - self.xi) <= self.sigma).sum(axis=0)
