"""Signs physics implies for the curves of Eq. 37, kept where a least-squares fit breaks them.

A passive mechanism dissipates (d(q) >= 0); a dielectric elastomer's gain ``g_i = (1/2)
dC_i/dq`` per unit mass keeps one sign over its range. :func:`physical_signs` finds where an
unconstrained fit breaks either on the visited range and returns the sign statements of
``[identify] constraints`` that the fit is then redone with
(:func:`debist.identify.fit.fit_rbf_model`).

References
----------
Masoud & Maas 2025, Eq. 35-37; Khalil, Nonlinear Systems, 3rd ed., Sec. 4.1.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from debist.identify.config import IdentifyConfig
    from debist.model.rbf import RBFModel

__all__ = ["GAIN_REVERSAL", "lost_dissipation", "physical_signs"]

#: A gain reversed by less than this share of its largest magnitude on the visited range is
#: taken as the fit's noise at the edge of the range, not as a broken sign.
GAIN_REVERSAL = 0.1


def _on_visited(model: RBFModel, q: np.ndarray, n_grid: int):
    """Evaluate d (n_grid,) and the gains (n_grid, n_inputs) on a grid over q's range (or None)."""
    grid = np.linspace(float(np.nanmin(q)), float(np.nanmax(q)), n_grid)
    curves = model.curves(grid)
    gains = np.asarray(curves["g"]).reshape(grid.size, -1) if "g" in curves else None
    return grid, curves.get("d"), gains


def physical_signs(
    model: RBFModel,
    q: np.ndarray,
    h: np.ndarray,
    cfg: IdentifyConfig,
    n_grid: int = 801,
    after: Sequence[str] = (),
) -> tuple[tuple[str, ...], str]:
    """Find the signs physics implies that a least-squares fit broke on the visited range.

    Damping d is not negative where the data are, and a DE's gain ``g_i = (1/2) dC_i/dq`` keeps
    the sign of the covariance of ``v_i^2`` and q. For each curve without a stated sign that the
    fit breaks (d below zero; a gain reversed by more than :data:`GAIN_REVERSAL` of its largest
    magnitude) a constraint is returned. Why: docs/explanation/implementation.md.

    Parameters
    ----------
    model : RBFModel
        The fit checked: least squares, or a refit under the signs in ``after``.
    q : ndarray, shape (n,)
        Estimation positions [unit of q].
    h : ndarray, shape (n, n_inputs)
        The inputs' h(v) at those samples [V^2 for ``"v2"``].
    cfg : IdentifyConfig
        ``rbf``, ``input_map`` and ``constraints`` (the signs the workflow states).
    n_grid : int
        Points of the visited range checked.
    after : sequence of str
        Signs the fit was already refitted under (named in ``reason``; their curves are
        skipped when ``cfg.constraints`` holds them); empty for the least-squares fit.

    Returns
    -------
    statements : tuple of str
        Constraints to add, e.g. ``("d >= 0", "g2 <= 0")``; empty if none.
    reason : str
        Each curve's value of the wrong sign farthest from zero, and where [unit of q]; or empty.

    References
    ----------
    Masoud & Maas 2025, Eq. 35-37 (g_i from dC_i/dq, d(q) z the friction force); Khalil,
    Nonlinear Systems, 3rd ed., Sec. 4.1 (a mechanical system with non-negative damping
    does not gain energy).
    """
    stated = {str(c).split()[0].split(">")[0].split("<")[0] for c in cfg.constraints}
    grid, d, gains = _on_visited(model, q, n_grid)
    statements, words = [], []
    if "d" in cfg.rbf and "d" not in stated and d is not None:
        k = int(np.argmin(d))
        if d[k] < 0:
            statements.append("d >= 0")
            words.append(f"d = {d[k]:.4g} 1/s at q = {grid[k]:.4g}")
    if "g" in cfg.rbf and gains is not None and cfg.input_map == "v2":
        h = np.asarray(h, dtype=float).reshape(q.size, -1)
        for j in range(gains.shape[1]):
            name, g = f"g{j + 1}", gains[:, j]
            sign = np.sign(np.cov(h[:, j], q)[0, 1])
            largest = float(np.max(np.abs(g)))
            if name in stated or sign == 0 or np.all(g * sign >= -GAIN_REVERSAL * largest):
                continue
            k = int(np.argmin(g * sign))
            statements.append(f"{name} {'>=' if sign > 0 else '<='} 0")
            words.append(f"{name} = {g[k]:.4g} at q = {grid[k]:.4g}")
    if not statements:
        return (), ""
    fit = f"the fit under {', '.join(after)}" if after else "the least-squares fit"
    return tuple(statements), (
        f"imposed {', '.join(statements)}: {fit} had {'; '.join(words)} on the visited range"
    )


def lost_dissipation(reference: RBFModel, model: RBFModel, q: np.ndarray, n_grid: int = 801) -> str:
    """Say where ``model`` has d < 0 on the visited range though ``reference`` keeps d >= 0.

    A later stage (the simulation-error finish) must not make a passive mechanism gain energy
    where the fit kept it dissipative. The gains' signs are not judged here: a finish may bend
    a gain at the edge of the range (a creep term removed moves both gains' ends by more than
    :data:`GAIN_REVERSAL`) without the free run gaining energy.

    Parameters
    ----------
    reference : RBFModel
        The model whose damping counts (the least-squares fit, signs imposed).
    model : RBFModel
        The model checked, on the same curves.
    q : ndarray, shape (n,)
        Estimation positions [unit of q]; their range is checked.
    n_grid : int
        Points of the visited range checked.

    Returns
    -------
    str
        Empty, or e.g. ``"d = -0.8 1/s at q = 0.0011"``.

    References
    ----------
    Masoud & Maas 2025, Eq. 37; Khalil, Nonlinear Systems, 3rd ed., Sec. 4.1.
    """
    grid, d_ref, _ = _on_visited(reference, q, n_grid)
    _, d, _ = _on_visited(model, q, n_grid)
    if d_ref is None or d is None or np.min(d_ref) < 0 or np.min(d) >= 0:
        return ""
    k = int(np.argmin(d))
    return f"d = {d[k]:.4g} 1/s at q = {grid[k]:.4g}"
