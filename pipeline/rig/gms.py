"""One element of the virtual rig's tip friction, the generalised Maxwell-slip model, once.

Each element is a spring ``k_i`` in series with a block of slip force ``F_i``; its deflection
``z_i`` evolves as ``dz_i/dt = q_dot (1 - s_i |k_i z_i / F_i|^p)`` with ``s_i = 1`` while the
element loads (``q_dot z_i > 0``) and 0 while it unloads, a Bouc-Wen-type smoothing of the
ideal element (``p -> infinity``). The full plant (:mod:`debist.rig.plant`, NumPy), its
compiled kernels (:mod:`debist.rig.compiled`, which compile these functions) and the reduced
plant (:mod:`debist.rig.reduced`) all call them.

References
----------
Al-Bender, F., Lampaert, V. & Swevers, J. (2005). The generalized Maxwell-slip model: a novel
model for friction simulation and compensation. IEEE Trans. Automatic Control 50(11),
1883-1887; Ismail, Ikhouane & Rodellar (2009), "The hysteresis Bouc-Wen model, a survey".
"""

from __future__ import annotations

import math

__all__ = ["element_partials", "element_rate"]


def element_rate(qd, z, kF, p):
    """Return the deflection rate of one element, ``dz/dt`` [m/s].

    Parameters
    ----------
    qd : float
        Tip velocity q_dot [m/s].
    z : float
        The element's deflection [m].
    kF : float
        ``k_i / F_i`` [1/m], > 0.
    p : float
        Smoothing exponent, > 0.

    Returns
    -------
    float
        ``qd (1 - |z kF|^p)`` while the element loads, ``qd`` otherwise.

    Examples
    --------
    >>> element_rate(1.0, 0.5, 1.0, 2.0), element_rate(-1.0, 0.5, 1.0, 2.0)
    (0.75, -1.0)
    """
    slip = abs(z * kF) ** p if qd * z > 0.0 else 0.0
    return qd * (1.0 - slip)


def element_partials(qd, z, kF, p):
    """Return the partial derivatives of :func:`element_rate` in ``qd`` and in ``z``.

    Parameters
    ----------
    qd, z, kF, p : float
        As for :func:`element_rate`.

    Returns
    -------
    d_qd : float
        ``1 - |z kF|^p`` while the element loads, 1 otherwise.
    d_z : float
        ``-qd p |z kF|^(p - 1) sign(z) kF`` while it loads, 0 otherwise.

    Examples
    --------
    >>> element_partials(1.0, 0.5, 1.0, 2.0)
    (0.75, -1.0)
    """
    if qd * z > 0.0:
        u = abs(z * kF)
        return 1.0 - u**p, -qd * p * u ** (p - 1.0) * math.copysign(1.0, z) * kF
    return 1.0, 0.0
