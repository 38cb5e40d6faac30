"""Differentiation stage: q -> (q_hat, q_dot, q_ddot) by TVRegDiff or an alternative.

Every method follows one contract, ``f(x, dt, *, config) -> Derivatives``; pick one by
name with :func:`differentiate`. :func:`tvregdiff` is Chartrand's algorithm with his
interface and exact O(n) lagged-diffusivity steps.

References
----------
Chartrand, R. (2011). Numerical differentiation of noisy, nonsmooth data.
ISRN Applied Mathematics 2011, 164564.
"""

from debist.differentiate.base import CONFIGS, DIFFERENTIATORS, differentiate
from debist.differentiate.result import Derivatives
from debist.differentiate.savgol import SavGolConfig, savgol_derivatives
from debist.differentiate.spectral import SpectralConfig, spectral_derivatives
from debist.differentiate.tvregdiff import TVRegDiffResult, tv_functional, tvregdiff
from debist.differentiate.tvregdiff_method import TVRegDiffConfig, tvregdiff_derivatives

__all__ = [
    "CONFIGS",
    "DIFFERENTIATORS",
    "Derivatives",
    "SavGolConfig",
    "SpectralConfig",
    "TVRegDiffConfig",
    "TVRegDiffResult",
    "differentiate",
    "savgol_derivatives",
    "spectral_derivatives",
    "tv_functional",
    "tvregdiff",
    "tvregdiff_derivatives",
]
