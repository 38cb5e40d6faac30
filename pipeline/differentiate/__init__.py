"""Differentiation stage: q -> (q_hat, q_dot, q_ddot) by TVRegDiff or an alternative.

Every method follows one contract, ``f(x, dt, *, config) -> Derivatives``; pick one by
name with :func:`debist.differentiate.base.differentiate` (:data:`~.base.CONFIGS` holds each
method's configuration class). :func:`debist.differentiate.tvregdiff.tvregdiff` is
Chartrand's algorithm with his interface and exact O(n) lagged-diffusivity steps; the
methods are :mod:`.tvregdiff_method`, :mod:`.spectral` and :mod:`.savgol`, their result
:mod:`.result`, and :mod:`.tables` runs one on every table of a run. This package's
``__init__`` imports none of its modules.

References
----------
Chartrand, R. (2011). Numerical differentiation of noisy, nonsmooth data.
ISRN Applied Mathematics 2011, 164564.
"""
