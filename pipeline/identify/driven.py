"""Where the estimation data applied each input, and a record that applies it elsewhere.

A gain ``g_i(q)`` of Eq. 37 is informed only by samples at which ``v_i`` drives the beam
(:func:`debist.identify.excitation.input_active`), within about one RBF width of them: a
record that applies ``v_i`` at positions the estimation never did asks every model for a
force it was never shown, and its free run there is an extrapolation, however good or bad
it turns out. :func:`driven_ranges` gives the estimation's range per input and
:func:`beyond_driven` words what a record does outside it, for the ``extrapolated`` column of
the NRMSE tables (:func:`debist.report.tables.verdict`); :func:`undriven_centres` and
:func:`undriven_weights` name the gains' weights beyond that range, which the fit can tie to
the driven ones (``[identify] tie_undriven``).

References
----------
Masoud & Maas 2025, Eq. 37-40; L. Ljung, System Identification: Theory for the User, 2nd ed.,
Prentice Hall 1999, Sec. 16.6 (a model is validated only for the conditions of the data it
was estimated on).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from debist.identify.excitation import input_active
from debist.model.basis import RBFBasis

if TYPE_CHECKING:
    from debist.identify.config import IdentifyConfig
    from debist.identify.fit import Record

__all__ = [
    "MIN_SAMPLES",
    "TIE_RIPPLE",
    "basis_ripple",
    "beyond_driven",
    "driven_ranges",
    "undriven_centres",
    "undriven_weights",
]

#: Fewest samples outside the driven range that make a record an extrapolation (as the
#: default ``min_support`` of the RBF centres).
MIN_SAMPLES = 10
#: Largest :func:`basis_ripple` at which the gains' undriven weights are tied: a linear
#: continuation of the weights then continues the curve (3 % at ``sigma_n = 0.5``; 73 % at
#: 0.25, where the curve dips between the centres and the weights do not describe it).
TIE_RIPPLE = 0.1


def _active(q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return q (n,), v (n, n_inputs) and where each input is active; ValueError on lengths."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    if v.shape[0] != q.size:
        raise ValueError(f"q has {q.size} samples, v {v.shape[0]}")
    v = v if v.ndim == 2 else v.reshape(q.size, 1)
    return q, v, input_active(v) if q.size else np.zeros(v.shape, dtype=bool)


def driven_ranges(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Find the range of q over which the estimation data apply each input.

    Parameters
    ----------
    q : ndarray, shape (n,)
        Estimation positions, records concatenated [unit of q].
    v : ndarray, shape (n, n_inputs)
        Their inputs [V].

    Returns
    -------
    ndarray, shape (n_inputs, 2)
        Smallest and largest q at which input i is active; NaN for an input never applied.

    Raises
    ------
    ValueError
        If ``q`` and ``v`` differ in length.

    Examples
    --------
    >>> q = np.array([-0.01, -0.009, 0.0, 0.009, 0.01])
    >>> v = np.array([[0.0, 900.0], [0.0, 3000.0], [0.0, 0.0], [3000.0, 0.0], [900.0, 0.0]])
    >>> driven_ranges(q, v).tolist()
    [[0.009, 0.01], [-0.01, -0.009]]
    """
    q, v, active = _active(q, v)
    out = np.full((v.shape[1], 2), np.nan)
    for j in range(v.shape[1]):
        if active[:, j].any():
            out[j] = q[active[:, j]].min(), q[active[:, j]].max()
    return out


def undriven_centres(
    q: np.ndarray, v: np.ndarray, basis: RBFBasis, min_samples: int = MIN_SAMPLES
) -> np.ndarray:
    """Flag the RBF centres of each gain g_i beyond the range its input drives.

    A weight of ``g_i`` multiplies ``phi_k(q) h(v_i)`` in Eq. 40: it is informed by the
    samples at which ``v_i`` is active (:func:`debist.identify.excitation.input_active`),
    each in proportion to ``phi_k(q)^2``, not by the samples at which the input is off. A DE
    is typically driven from the well it pulls the beam out of, so that well lies at the edge
    of its input's driven range, and the centres beyond it see only the Gaussian tails of a
    few samples. A centre is flagged when it and every centre between it and the nearer end
    of the basis hold less than ``min_samples`` samples' worth of that information: each
    active sample within one width counts 1 (as :meth:`RBFBasis.support` counts), one
    farther out ``phi_k(q)^2 / phi_k(xi_k + sigma)^2`` (0.14 two widths away). A thin centre
    between informed ones (the barrier, crossed quickly with the input on) is not flagged.

    Parameters
    ----------
    q, v : ndarray, shapes (n,) and (n, n_inputs)
        Positions [unit of q] and inputs [V] of the estimation records, concatenated.
    basis : RBFBasis
        The basis of the fit (Eq. 38-39).
    min_samples : int, optional
        Information, in samples at the centre, that informs a centre (as ``min_support``).

    Returns
    -------
    ndarray of bool, shape (n_inputs, M)
        True where centre k of g_i lies beyond the informed centres.

    Raises
    ------
    ValueError
        If ``q`` and ``v`` differ in length.

    References
    ----------
    Masoud & Maas 2025, Eq. 38-40 and Sec. 5.2 (excite every centre's part of the range).

    Examples
    --------
    >>> from debist.model.basis import RBFBasis
    >>> q = np.linspace(-0.01, 0.01, 201)
    >>> v = np.column_stack([np.where(q > 0, 3000.0, 0.0), np.where(abs(q) > 0.006, 3e3, 0)])
    >>> basis = RBFBasis.equidistant(-0.01, 0.01, 5, 0.4, "clip")
    >>> undriven_centres(q, v, basis).astype(int).tolist()
    [[1, 1, 0, 0, 0], [0, 0, 0, 0, 0]]
    """
    q, v, active = _active(q, v)
    # within one width a sample counts 1 (as RBFBasis.support), beyond it phi^2 / phi(sigma)^2
    weight = [np.minimum(1.0, np.e * basis(q[active[:, j]]) ** 2) for j in range(v.shape[1])]
    information = np.stack([w.sum(axis=0) for w in weight])
    thin = information < min_samples
    # only the runs of thin centres at either end: a thin centre between informed ones lies
    # where the beam crosses the barrier with the input on, which the data do inform
    inner = np.cumsum(~thin, axis=1) > 0
    inner &= np.cumsum(~thin[:, ::-1], axis=1)[:, ::-1] > 0
    return thin & ~inner


def beyond_driven(
    ranges: np.ndarray,
    q: np.ndarray,
    v: np.ndarray,
    margin: float,
    scale: float = 1.0,
    unit: str = "m",
    min_samples: int = MIN_SAMPLES,
) -> str:
    """Say where a record applies an input outside the estimation's driven range, or ``""``.

    Parameters
    ----------
    ranges : ndarray, shape (n_inputs, 2)
        :func:`driven_ranges` of the estimation data [unit of q].
    q : ndarray, shape (n,)
        The record's positions [unit of q].
    v : ndarray, shape (n, n_inputs)
        The record's inputs [V].
    margin : float
        Distance beyond the range still taken as informed (one RBF width) [unit of q].
    scale, unit : float, str
        Display factor and unit of q in the words (e.g. ``1e3, "mm"``).
    min_samples : int
        Fewest active samples outside the range that count.

    Returns
    -------
    str
        Per input, e.g. ``"v2 applied at q = -23 to -16 mm (40 samples) and 1.2 to 8.9 mm
        (1199 samples), where the estimation applied it only at -14 to -8.1 mm"`` (each side
        of the range apart, inputs joined by ``"; "``); ``""`` when fewer than
        ``min_samples`` active samples of every input lie outside its range.

    Examples
    --------
    >>> ranges = np.array([[0.0, 0.01], [-0.01, 0.0]])
    >>> q = np.linspace(-0.01, 0.01, 41)
    >>> v = np.column_stack([np.where(q < 0, 3000.0, 0.0), np.zeros(41)])
    >>> words = beyond_driven(ranges, q, v, margin=0.002, scale=1e3, unit="mm")
    >>> for part in words.split(", "):
    ...     print(part)
    v1 applied at q = -10 to -2.5 mm (16 samples)
    where the estimation applied it only at 0 to 10 mm
    """
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float).reshape(q.size, -1)
    if q.size == 0:
        return ""
    active = input_active(v)
    words = []
    for j in range(v.shape[1]):
        lo, hi = ranges[j]
        on = q[active[:, j]]
        sides = [on] if np.isnan(lo) else [on[on < lo - margin], on[on > hi + margin]]
        if sum(side.size for side in sides) < min_samples:
            continue
        spans = " and ".join(
            f"{_two(scale * side.min())} to {_two(scale * side.max())} {unit} ({side.size} samples)"
            for side in sides
            if side.size
        )
        where = (
            "the estimation never applied it"
            if np.isnan(lo)
            else f"the estimation applied it only at {_two(scale * lo)} to {_two(scale * hi)} "
            f"{unit}"
        )
        words.append(f"v{j + 1} applied at q = {spans}, where {where}")
    return "; ".join(words)


def _two(x: float) -> str:
    """Two significant digits, without an exponent below 1e6 (``-300``, not ``-3e+02``)."""
    return f"{float(f'{x:.2g}'):g}"


def basis_ripple(basis: RBFBasis, n_grid: int = 201) -> float:
    """Ripple of the basis's sum of equal weights between its two middle centres.

    ``1 - min S / max S`` for ``S(q) = sum_k phi_k(q)`` on ``[xi_a, xi_b]``, the two centres
    nearest the middle of the basis: how far a curve whose weights are all equal is from flat.
    Small where neighbouring Gaussians overlap (``sigma`` about half the spacing or wider);
    there the weights sample the curve, and a rule on the weights (a tie, a difference
    penalty) acts on the curve.

    Parameters
    ----------
    basis : RBFBasis
        The basis (Eq. 38-39), at least 2 centres.
    n_grid : int, optional
        Points of the interval evaluated.

    Returns
    -------
    float
        The ripple [-], in [0, 1).

    References
    ----------
    Masoud & Maas 2025, Eq. 38-39; Buhmann, Radial Basis Functions, Cambridge University Press
    2003, Sec. 2 (quasi-interpolation: a sum of shifted Gaussians approximates a constant
    within a ripple that falls with the width).

    Examples
    --------
    >>> from debist.model.basis import RBFBasis
    >>> round(basis_ripple(RBFBasis.equidistant(-1.0, 1.0, 9, 0.5)), 3)
    0.028
    """
    a = (basis.M - 1) // 2
    grid = np.linspace(basis.xi[a], basis.xi[a + 1], int(n_grid))
    total = basis(grid).sum(axis=1)
    return float(1.0 - total.min() / total.max())


def undriven_weights(
    records: Sequence[Record], basis: RBFBasis, cfg: IdentifyConfig
) -> tuple[list[str], str]:
    """Name the weights of the gains g_i whose centres the estimation does not drive.

    Parameters
    ----------
    records : sequence of debist.identify.fit.Record
        The estimation records (``q``, ``v``).
    basis : RBFBasis
        The basis of the fit.
    cfg : IdentifyConfig
        ``tie_undriven`` (False: none), ``rbf`` (only ``"g"`` curves have such weights) and
        ``min_support``.

    Returns
    -------
    names : list of str
        ``"g<j>[k]"`` for centre k of g_j beyond the centres that ``min_support`` samples
        with v_j active inform (:func:`undriven_centres`); the fit
        ties them to their neighbours (:func:`debist.identify.regularise.tie_rows`).
    text : str
        Empty, or e.g. ``"g2 continued from its neighbours at centre(s) 9, 10 of 10: less
        than 10 samples' worth of data with v2 applied there"``, one clause per input joined
        by ``"; "``. On a basis whose :func:`basis_ripple` exceeds :data:`TIE_RIPPLE` nothing
        is tied and the text says so (``"... left free: ..."``).

    References
    ----------
    Masoud & Maas 2025, Eq. 38-40.
    """
    if not cfg.tie_undriven or "g" not in cfg.rbf or cfg.m_q == "identify":
        return [], ""
    q = np.concatenate([r.q for r in records])
    thin = undriven_centres(q, np.vstack([r.v for r in records]), basis, cfg.min_support)
    ripple, sigma_n = basis_ripple(basis), basis.sigma / (basis.xi[1] - basis.xi[0])
    names, words = [], []
    for j, row in enumerate(thin):
        k = np.flatnonzero(row)
        if k.size == 0:
            continue
        at = ", ".join(str(i + 1) for i in k)
        why = f"less than {cfg.min_support} samples' worth of data with v{j + 1} applied there"
        if ripple > TIE_RIPPLE:
            words.append(
                f"g{j + 1} left free at centre(s) {at} of {basis.M} ({why}): the Gaussians "
                f"(sigma_n = {sigma_n:.3g}) leave a {100 * ripple:.0f} % ripple between centres, "
                "so continuing the weights would not continue the curve"
            )
            continue
        names += [f"g{j + 1}[{i}]" for i in k]
        words.append(
            f"g{j + 1} continued from its neighbours at centre(s) {at} of {basis.M}: " + why
        )
    return names, "; ".join(words)
