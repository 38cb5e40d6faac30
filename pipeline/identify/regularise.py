"""Regularised and sign-constrained least squares for the RBF model (Eq. 40 with a penalty).

The paper solves Eq. 40 by plain least squares. Three additions make the curves more
trustworthy where the data are thin (the penalty is optional; the signs and the ties are
defaults that a workflow can turn off):

* a smoothness penalty ``lambda sum_curves ||D_2 theta_curve||^2`` on the second differences
  of each curve's RBF weights (``c``, ``d``, ``g_i``; neighbouring centres should carry
  similar weights), with ``lambda`` chosen by generalised cross-validation (Golub, Heath &
  Wahba 1979) on a logarithmic grid; and
* sign constraints from physics (``d >= 0``: passive damping; ``g1 >= 0``, ``g2 <= 0``:
  the two DEs pull in opposite directions with ``h = v^2``), imposed on the curve's RBF
  weights and its backbone scale (a sum of non-negative Gaussians with non-negative weights
  is non-negative: a sufficient condition), solved with :func:`scipy.optimize.lsq_linear`;
* with ``tie_undriven`` (the default), ties of the weights the data do not reach (a gain's
  centres beyond where its input was applied) to the driven ones (:func:`tie_rows`): without
  them those weights are free and bend the curve at the edge of the data, where a DE's own
  well lies.

Everything works on the column-scaled regressor ``A = Psi / s`` through its QR factors
``A = Q R``: a (weighted) least-squares problem becomes the small system ``C x ~ d`` with
``C = L^T R`` for the Cholesky factor ``L`` of the weighted Gram ``Q^T W Q`` (``C = R`` with
unit weights), so the point estimate and every bootstrap replicate use the same estimator at
the cost of a ``p x p`` problem. The penalty is written on the curve's weights theta and
carried over to the scaled weights ``x = s theta`` (:func:`weight_penalty`), each curve's rows
multiplied by the geometric mean of its column norms, so ``lambda`` is dimensionless and a
centre the data hardly reach (small ``s``) cannot carry a wild weight at no cost.

The residuals of Eq. 40 are correlated (derivatives, the zero-phase low-pass), so GCV's
count of ``n`` independent rows overstates the information and leans towards little
smoothing; the choice is conservative in that direction.

References
----------
Masoud & Maas 2025, Eq. 37-40; Golub, Heath & Wahba 1979, Technometrics 21(2), 215-223
(GCV); Eilers & Marx 1996, Statist. Sci. 11(2), 89-121 (difference penalties on basis
weights); Stark & Parker 1995, Comput. Statist. 10, 129-141 (bounded-variable least squares,
``scipy.optimize.lsq_linear``).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from debist.core.errors import WorkflowError

#: Accepted constraint statements: "d >= 0", "g1 >= 0", "g2 <= 0".
CONSTRAINT = re.compile(r"^\s*(d|g\d+)\s*(>=|<=)\s*0\s*$")
#: Weight of the rows of :func:`tie_rows` on the unit-norm columns of the scaled
#: regressor: stiff against the thin data of an undriven centre.
TIE_WEIGHT = 1.0e4
#: Logarithmic grid of lambda searched by GCV.
LAMBDA_GRID = np.logspace(-8, 2, 41)


@dataclass(frozen=True)
class Estimator:
    """The least-squares estimator of Eq. 40: penalty and bounds on the scaled weights.

    Attributes
    ----------
    penalty : ndarray, shape (m, p)
        Second-difference rows of the RBF curves on the scaled weights
        (:func:`weight_penalty`; ``m = 0``: no penalty).
    lam : float
        Penalty weight lambda (dimensionless).
    lower, upper : ndarray, shape (p,)
        Bounds of the scaled weights (``-inf`` / ``+inf``: free).
    tie : ndarray, shape (t, p) or None
        Rows always appended with weight one, whatever lambda (:func:`tie_rows`); None: none.
    """

    penalty: np.ndarray
    lam: float
    lower: np.ndarray
    upper: np.ndarray
    tie: np.ndarray | None = None

    @property
    def plain(self) -> bool:
        """True for the paper's plain least squares (no penalty, no ties, no bounds)."""
        free = np.all(np.isneginf(self.lower)) and np.all(np.isposinf(self.upper))
        untied = self.tie is None or self.tie.shape[0] == 0
        return (self.lam == 0.0 or self.penalty.shape[0] == 0) and bool(free) and untied

    def solve(self, C: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Minimise ``||C x - d||^2 + lam ||P x||^2 + ||T x||^2`` within the bounds.

        Parameters
        ----------
        C : ndarray, shape (k, p)
            The (compressed) scaled regressor.
        d : ndarray, shape (k,)
            The (compressed) output.

        Returns
        -------
        ndarray, shape (p,)
            Scaled weights ``x`` (the parameters are ``x / s``).
        """
        if self.lam > 0.0 and self.penalty.shape[0]:
            C = np.vstack([C, np.sqrt(self.lam) * self.penalty])
            d = np.concatenate([d, np.zeros(self.penalty.shape[0])])
        if self.tie is not None and self.tie.shape[0]:
            C = np.vstack([C, self.tie])
            d = np.concatenate([d, np.zeros(self.tie.shape[0])])
        if np.all(np.isneginf(self.lower)) and np.all(np.isposinf(self.upper)):
            return np.linalg.lstsq(C, d, rcond=None)[0]
        from scipy.optimize import lsq_linear

        res = lsq_linear(C, d, bounds=(self.lower, self.upper), method="bvls", tol=1e-12)
        return np.clip(res.x, self.lower, self.upper)  # BVLS can overshoot a bound by 1e-24


def smoothness_operator(names: Sequence[str], M: int) -> np.ndarray:
    """Second differences of every RBF curve's weights, as rows over all columns.

    Parameters
    ----------
    names : sequence of str
        Regression column names (``c[i]``, ``d[i]``, ``g<j>[i]``, backbone names).
    M : int
        Number of centres.

    Returns
    -------
    ndarray, shape (m, len(names))
        ``theta[k-1] - 2 theta[k] + theta[k+1]`` for each curve and interior centre k.

    References
    ----------
    Eilers & Marx 1996 (difference penalty).
    """
    names = list(names)
    rows = []
    # the curves over the centres; the slip elements' stiffnesses and the inertia's
    # polynomial coefficients are not RBF weights of a curve
    prefixes = sorted({n.split("[")[0] for n in names if "[" in n} - {"slip", "inertia"})
    for prefix in prefixes:
        idx = [names.index(f"{prefix}[{k}]") for k in range(M)]
        for k in range(1, M - 1):
            row = np.zeros(len(names))
            row[idx[k - 1]], row[idx[k]], row[idx[k + 1]] = 1.0, -2.0, 1.0
            rows.append(row)
    return np.array(rows).reshape(-1, len(names))


def weight_penalty(penalty: np.ndarray, scale: np.ndarray, names: Sequence[str]) -> np.ndarray:
    """Carry a penalty on the weights theta over to the column-scaled weights ``x = s theta``.

    The fit solves for ``x`` on the regressor ``Psi / s`` (unit column norms). A difference
    penalty written on ``x`` itself (``||D_2 x||``) does not ask for a smooth curve: a centre
    the data hardly reach has a small column norm ``s_k``, so a wild weight ``theta_k`` there
    costs almost nothing, which is where a curve most needs the penalty. This returns the rows
    ``P diag(1 / s)`` (the penalty on theta), every row of a curve multiplied by the geometric
    mean of ``s`` over that curve's columns, so that lambda stays dimensionless and one lambda
    weighs every curve alike whatever its unit.

    Parameters
    ----------
    penalty : ndarray, shape (m, p)
        Rows on theta (:func:`smoothness_operator`).
    scale : ndarray, shape (p,)
        Column norms ``s`` of the regressor (> 0).
    names : sequence of str, length p
        Regression column names; a curve's columns are ``<curve>[k]``.

    Returns
    -------
    ndarray, shape (m, p)
        Rows on the scaled weights ``x``: ``||rows @ x||^2 = sum_curves sbar_curve^2
        ||D_2 theta_curve||^2``.

    References
    ----------
    Eilers & Marx 1996, Sec. 2 (the difference penalty acts on the basis coefficients of
    the curve).
    """
    s = np.asarray(scale, dtype=float)
    prefix = np.array([n.split("[")[0] if "[" in n else "" for n in names])
    gmean = {pre: float(np.exp(np.mean(np.log(s[prefix == pre])))) for pre in set(prefix)}
    out = np.zeros(penalty.shape)
    for i, row in enumerate(penalty):
        touched = np.flatnonzero(row)
        if touched.size:
            out[i] = row / s * gmean[prefix[touched[0]]]
    return out


def tie_rows(
    names: Sequence[str], M: int, scale: np.ndarray, undriven: Sequence[str]
) -> np.ndarray:
    """Second-difference rows that continue a curve over the centres its data do not reach.

    A weight whose column the data barely inform (a centre of ``g_i`` beyond where ``v_i``
    was applied: :func:`debist.identify.driven.undriven_centres`) is otherwise free to take
    any value at almost no cost, and through the overlap of the Gaussians it bends the curve
    inside the data too. Every second difference ``theta[k-1] - 2 theta[k] + theta[k+1]`` of
    a curve that involves such a weight is held at zero, stiffly: each row is written on the
    scaled weights ``x = s theta``, normalised to unit length and weighted by
    :data:`TIE_WEIGHT` against the unit-norm columns (a row's scale does not change what it
    holds, and unit rows keep the stacked system's singular values near the data's). The
    weights continue linearly from the driven centres, and where a curve's data reach fewer
    than three centres it is a straight line in its weights.

    Parameters
    ----------
    names : sequence of str
        Regression column names (``g<j>[k]`` style for the curves).
    M : int
        Number of centres.
    scale : ndarray, shape (p,)
        Column norms ``s`` of the regressor (> 0).
    undriven : sequence of str
        Names of the weights the data do not reach, e.g. ``"g2[9]"``.

    Returns
    -------
    ndarray, shape (t, p)
        Rows on the scaled weights ``x = s theta`` (``t = 0`` when nothing is tied).

    References
    ----------
    Eilers & Marx 1996, Sec. 2 and 8 (a difference penalty extrapolates a curve linearly
    beyond its data; a large weight makes the continuation exact).
    """
    names = list(names)
    rows = smoothness_operator(names, M)
    tied = [names.index(n) for n in undriven if n in names]
    if not tied or rows.shape[0] == 0:
        return np.zeros((0, len(names)))
    touched = np.abs(rows[:, tied]).sum(axis=1) > 0
    on_x = rows[touched] / np.asarray(scale, dtype=float)  # theta = x / s
    return TIE_WEIGHT * on_x / np.linalg.norm(on_x, axis=1, keepdims=True)


def constraint_bounds(names: Sequence[str], constraints: Sequence[str]) -> tuple:
    """Bounds of the weights from sign statements on the curves.

    Parameters
    ----------
    names : sequence of str
        Regression column names.
    constraints : sequence of str
        Statements ``"d >= 0"``, ``"g1 >= 0"``, ``"g2 <= 0"``.

    Returns
    -------
    lower, upper : ndarray, shape (len(names),)
        ``0`` or ``-inf`` / ``+inf`` per column: the curve's RBF weights and backbone gain
        (``viscous``, ``input_gain<j>``) take the stated sign; the analytical curves' scales
        (``physics_damping``, ``physics_gain<j>``, ``physics_quadratic<j>``) are non-negative
        (their curves carry the sign).

    Raises
    ------
    WorkflowError
        For a statement that is not of the accepted form, or a curve the model lacks.
    """
    names = list(names)
    lower = np.full(len(names), -np.inf)
    upper = np.full(len(names), np.inf)
    for text in constraints:
        m = CONSTRAINT.match(str(text))
        if m is None:
            raise WorkflowError(
                f"[identify] constraints: {text!r} is not of the form 'd >= 0', 'g1 >= 0' "
                "or 'g2 <= 0'"
            )
        curve, op = m.groups()
        if curve == "d":
            own, scalar, physics = "d[", "viscous", "physics_damping"
        else:
            j = curve[1:]
            own, scalar, physics = f"{curve}[", f"input_gain{j}", f"physics_gain{j}"
        cols = [i for i, n in enumerate(names) if n.startswith(own) or n == scalar]
        if not cols and physics not in names:
            raise WorkflowError(
                f"[identify] constraints: {text!r}, but the model has no curve {curve!r}"
            )
        for i in cols:
            if op == ">=":
                lower[i] = 0.0
            else:
                upper[i] = 0.0
        scales = [physics] + ([f"physics_quadratic{curve[1:]}"] if curve != "d" else [])
        for name in scales:
            if name in names:
                lower[names.index(name)] = 0.0
    return lower, upper


def gcv_lambda(
    R: np.ndarray, qty: np.ndarray, y_perp2: float, n: int, penalty: np.ndarray
) -> tuple[float, np.ndarray]:
    """Choose lambda by generalised cross-validation on a logarithmic grid.

    Parameters
    ----------
    R : ndarray, shape (p, p)
        R factor of the scaled regressor.
    qty : ndarray, shape (p,)
        ``Q^T y``.
    y_perp2 : float
        ``||y||^2 - ||Q^T y||^2``, the part of the output no parameter can fit.
    n : int
        Rows of the regression.
    penalty : ndarray, shape (m, p)
        :func:`smoothness_operator`.

    Returns
    -------
    lam : float
        The minimiser of ``GCV = n RSS / (n - tr H)^2`` over :data:`LAMBDA_GRID`.
    trace : ndarray, shape (len(LAMBDA_GRID), 3)
        ``(lambda, GCV, tr H)`` per grid point.

    References
    ----------
    Golub, Heath & Wahba 1979, Eq. 1.4.
    """
    p = R.shape[1]
    out = []
    for lam in LAMBDA_GRID:
        B = np.vstack([R, np.sqrt(lam) * penalty])
        U, S, Vt = np.linalg.svd(B, full_matrices=False)
        keep = S[0] * p * np.finfo(float).eps < S
        rhs = np.concatenate([qty, np.zeros(penalty.shape[0])])
        x = Vt[keep].T @ ((U[:, keep].T @ rhs) / S[keep])
        rss = float(np.sum((R @ x - qty) ** 2) + y_perp2)
        tr = float(np.sum((R @ Vt[keep].T / S[keep]) ** 2))
        out.append((lam, n * rss / max(n - tr, 1.0) ** 2, tr))
    trace = np.array(out)
    return float(trace[np.argmin(trace[:, 1]), 0]), trace
