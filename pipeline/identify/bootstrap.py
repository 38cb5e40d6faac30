"""Block bootstrap of the least squares: the identified parameters re-estimated on resamples.

The regression rows of Eq. 40 are resampled in contiguous blocks (non-overlapping within each
estimation record, drawn with replacement), long enough to cover the residuals' correlation
time (:func:`block_length`), and the parameters re-estimated on each resample
(:func:`block_bootstrap`). The replicates give the bands of the identified curves
(:mod:`debist.identify.bands`) and of the stiffness at the wells.

References
----------
Carlstein 1986, Ann. Statist. 14(3), 1171-1179 (non-overlapping blocks); Kuensch 1989, Ann.
Statist. 17(3), 1217-1241 (moving blocks, the n^(1/3) rate); Politis & White 2004,
Econometric Reviews 23(1), 53-70 (block length from the correlation time).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

__all__ = ["block_bootstrap", "block_length"]


def block_length(residuals: Sequence[np.ndarray], n_rows: int) -> int:
    """Block length of the bootstrap from the residuals' correlation time.

    Twice the first lag at which the residuals' autocorrelation (averaged over the records)
    falls below ``1/e``, and at least ``n^(1/3)`` (the rate of Kuensch 1989), capped at a
    quarter of the shortest record.

    Parameters
    ----------
    residuals : sequence of ndarray, shape (n_r,)
        Equation errors per record, in row order.
    n_rows : int
        Total rows ``n``.

    Returns
    -------
    int
        Block length [samples], >= 1.

    References
    ----------
    Politis & White 2004 (block length grows with the dependence); Kuensch 1989.
    """
    shortest = min(r.size for r in residuals)
    max_lag = max(1, shortest // 4)
    acf = np.zeros(max_lag + 1)
    for r in residuals:
        x = r - r.mean()
        spec = np.fft.rfft(x, 2 * x.size)
        a = np.fft.irfft(spec * np.conj(spec))[: max_lag + 1]
        acf += a / a[0] if a[0] > 0 else 0.0
    acf /= len(residuals)
    below = np.flatnonzero(acf < np.exp(-1.0))
    tau = int(below[0]) if below.size else max_lag
    return int(min(max(2 * tau, np.ceil(n_rows ** (1.0 / 3.0)), 1), max_lag))


def block_bootstrap(
    psi: np.ndarray,
    y: np.ndarray,
    record_rows: Sequence[int],
    n_boot: int,
    seed: int,
    block: int | None = None,
    estimator=None,
) -> tuple[np.ndarray, int]:
    """Least-squares parameters re-estimated on block resamples of the regression rows.

    Parameters
    ----------
    psi : ndarray, shape (n, p)
        Regressor (rows of all records stacked, in time order within each record).
    y : ndarray, shape (n,)
        Regression output.
    record_rows : sequence of int
        Rows per record (they sum to ``n``); blocks never cross a record boundary.
    n_boot : int
        Number of replicates ``B`` (>= 1).
    seed : int
        Seed of the generator (:func:`numpy.random.default_rng`).
    block : int, optional
        Block length [rows]; default :func:`block_length` of the least-squares residuals.
    estimator : debist.identify.regularise.Estimator, optional
        The estimator of the fit (penalty, bounds) when it is not plain least squares: each
        replicate then solves its weighted problem through the Cholesky factor of its Gram.

    Returns
    -------
    theta : ndarray, shape (B, p)
        The replicates' parameters (least squares on the column-scaled rows, the block
        counts as row weights; the regressor has full column rank, as the fit checks).
    block : int
        The block length used [rows].

    Raises
    ------
    ValueError
        If ``record_rows`` does not sum to the number of rows or ``n_boot < 1``.

    References
    ----------
    Carlstein 1986 (non-overlapping blocks); Kuensch 1989.
    """
    n, p = psi.shape
    if sum(record_rows) != n:
        raise ValueError(f"record_rows sum to {sum(record_rows)}, the regressor has {n} rows")
    if n_boot < 1:
        raise ValueError(f"n_boot must be >= 1, got {n_boot}")
    scale = np.linalg.norm(psi, axis=0)
    scale = np.where(scale == 0, 1.0, scale)
    Q, R = np.linalg.qr(psi / scale)
    if block is None:
        resid = y - Q @ (Q.T @ y)  # the least-squares residual
        bounds = np.cumsum([0, *record_rows])
        block = block_length([resid[s:e] for s, e in itertools.pairwise(bounds)], n)
    starts, ends = [], []
    offset = 0
    for rows in record_rows:
        s = np.arange(offset, offset + rows, block)
        starts.extend(s.tolist())
        ends.extend(np.minimum(s + block, offset + rows).tolist())
        offset += rows
    # Each replicate is the least squares with integer row weights (the block counts). With
    # a = Q R once, it is (Q^T W Q) phi = Q^T W y, theta = R^-1 phi: the weighted Gram of the
    # orthonormal Q is well conditioned (no squared condition number of normal equations),
    # and it is a sum of per-block Grams, so all replicates cost one matrix product.
    rows = [slice(s, e) for s, e in zip(starts, ends, strict=True)]
    gram = np.stack([Q[r].T @ Q[r] for r in rows]).reshape(len(rows), p * p)
    qty = np.stack([Q[r].T @ y[r] for r in rows])
    rng = np.random.default_rng(seed)
    k = int(np.ceil(n / block))
    counts = np.stack([np.bincount(rng.integers(0, len(rows), k), minlength=len(rows))
                       for _ in range(n_boot)]).astype(float)  # fmt: skip
    H = (counts @ gram).reshape(n_boot, p, p)
    r = counts @ qty
    from scipy.linalg import solve_triangular

    floor = np.sqrt(np.finfo(float).eps)  # H ~ I for the whole data: Q is orthonormal
    eig = np.linalg.eigvalsh(H)  # ascending, per replicate
    full = eig[:, 0] > floor * eig[:, -1]
    plain = estimator is None or estimator.plain
    if plain and full.all():
        phi = np.linalg.solve(H, r[:, :, None])[:, :, 0]
        return solve_triangular(R, phi.T).T / scale, int(block)
    out = np.empty((n_boot, p))
    for b in range(n_boot):
        C, d = _replicate_system(H[b], r[b], R, floor, bool(full[b]))
        out[b] = (np.linalg.lstsq(C, d, rcond=None)[0] if plain else estimator.solve(C, d)) / scale
    return out, int(block)


def _replicate_system(H: np.ndarray, r: np.ndarray, R: np.ndarray, floor: float, full: bool):
    """Return ``C, d`` of one replicate: ``C^T C = R^T H R`` and ``C^T d = R^T r``.

    ``H = L L^T`` (Cholesky) gives ``C = L^T R`` when ``full``. A replicate whose blocks miss
    the rows of some column has a singular ``H`` (eigenvalues at most ``floor`` times the
    largest): its eigen-decomposition restricted to the larger eigenvalues gives the same
    normal equations, and the least squares then returns the minimum-norm weights (zero
    along what that replicate does not inform) instead of failing or returning noise.
    """
    from scipy.linalg import eigh, solve_triangular

    if full:
        L = np.linalg.cholesky(H)
        return L.T @ R, solve_triangular(L, r, lower=True)
    e, V = eigh(H)
    keep = e > floor * e[-1]
    root = np.sqrt(e[keep])
    return root[:, None] * (V[:, keep].T @ R), (V[:, keep].T @ r) / root
