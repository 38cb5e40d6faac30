"""The design analysis of Section 3 in one call: pre-strain sweep, F(q), C(q), full vs reduced.

This is what ``debist analyze`` runs for a prototype's ``[physics]`` parameters: the
equilibria versus pre-strain with both bifurcation points (Fig. 3), the force-displacement
curves of the four voltage states (Fig. 4), the capacitances along the static path (Fig. 5),
the SVD modes of a switching simulation (Fig. 6a) and the full versus reduced model under
the switching steps of Fig. 7, with the reduced model's characteristic curves.

References
----------
Masoud & Maas 2025, Section 3, Fig. 3-7.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from debist.physics.config import AnalyzeConfig
from debist.physics.dynamics import ModeAnalysis, mode_analysis
from debist.physics.params import PrototypeParams
from debist.physics.prestrain import PrestrainSweep, prestrain_sweep
from debist.physics.reduced import (
    Comparison,
    ReducedCurves,
    compare_full_reduced,
    fit_reduced,
    switching_profile,
)
from debist.physics.statics import FORCE_STATES, ForceCurve, equilibria, force_displacements

__all__ = ["Analysis", "AnalyzeConfig", "analysis_tree", "run_analysis"]


@dataclass(frozen=True)
class Analysis:
    """Results of :func:`run_analysis`.

    Attributes
    ----------
    params : PrototypeParams
        The prototype analysed.
    sweep : PrestrainSweep
        Equilibria versus pre-strain and the bifurcation points (Fig. 3).
    curves : tuple of ForceCurve
        ``F(q)`` with ``C_i(q)`` for the four voltage states of Fig. 4 at ``params.b``.
    comparison : Comparison
        Full versus reduced model under the switching steps (Fig. 7).
    modes : ModeAnalysis
        SVD of the full model's deflection field in that simulation (Fig. 6a).
    reduced : ReducedCurves
        The reduced model's characteristic curves on the grid of ``curves``.
    operating_points : dict
        Equilibria at ``params.b`` per voltage state: ``q`` [m] and ``stable`` flags.
    """

    params: PrototypeParams
    sweep: PrestrainSweep
    curves: tuple[ForceCurve, ...]
    comparison: Comparison
    modes: ModeAnalysis
    reduced: ReducedCurves
    operating_points: dict[str, dict[str, np.ndarray]]


def _state_name(v1: float, v2: float) -> str:
    return f"v1_{v1 / 1e3:g}kV_v2_{v2 / 1e3:g}kV"


def run_analysis(params: PrototypeParams, config: AnalyzeConfig | None = None) -> Analysis:
    """Run the design analysis of Section 3 for one prototype.

    Parameters
    ----------
    params : PrototypeParams
        Prototype parameters (SI units); ``params.b`` is the operating point.
    config : AnalyzeConfig, optional
        Ranges and resolutions; defaults as documented there.

    Returns
    -------
    Analysis
        Sweep, curves, comparison, modes, reduced curves and operating points.

    Raises
    ------
    StaticsError
        If the static path cannot be continued (e.g. a prototype without equilibria).
    ValueError
        If the prototype has no stable state to start the switching simulation from.

    References
    ----------
    Masoud & Maas 2025, Eq. 15-17, 24-26, 41, Fig. 3-7.
    """
    cfg = config or AnalyzeConfig()
    b = None if cfg.b_range is None else np.linspace(*cfg.b_range, cfg.n_b)
    if b is None:
        b = np.linspace(params.b_max - 12.5e-3, params.b_max, cfg.n_b)
    sweep = prestrain_sweep(params, b=b)
    q = np.linspace(-cfg.q_max, cfg.q_max, cfg.n_q)
    curves = force_displacements(params, q, FORCE_STATES)
    model = fit_reduced(params, degree=cfg.degree)
    comparison = compare_full_reduced(
        params,
        t_end=cfg.t_end,
        profile=switching_profile(left=cfg.left, right=cfg.right),
        model=model,
    )
    points = {}
    for v1, v2 in FORCE_STATES:
        eqs = equilibria(params, v1=v1, v2=v2)
        points[_state_name(v1, v2)] = {
            "q": np.array([e.q for e in eqs]),
            "stable": np.array([e.stable for e in eqs]),
        }
    return Analysis(
        params=params,
        sweep=sweep,
        curves=curves,
        comparison=comparison,
        modes=mode_analysis(comparison.full.qm, params),
        reduced=model.curves(q),
        operating_points=points,
    )


def analysis_tree(result: Analysis) -> dict[str, Any]:
    """Return the analysis as a nested mapping for ``statics.h5`` (SI units).

    Parameters
    ----------
    result : Analysis
        From :func:`run_analysis`.

    Returns
    -------
    dict
        Groups ``params``, ``prestrain``, ``force_displacement/<state>``,
        ``operating_points/<state>``, ``reduced`` and ``comparison``.
    """
    s = result.sweep
    cmp = result.comparison
    tree: dict[str, Any] = {
        "attrs": {"source": "Masoud & Maas 2025, Section 3", "units": "SI"},
        "params": {k: np.float64(v) for k, v in result.params.to_dict().items()},
        "prestrain": {
            "attrs": {"z_b_min": s.z_b_min, "z_b_max": s.z_b_max},
            "b": s.b,
            "z_b": s.z_b,
            "voltages": s.voltages,
            "q": s.q,
            "F": s.F,
            "eq_state": s.eq_state,
            "eq_b_index": s.eq_b_index,
            "eq_q": s.eq_q,
            "eq_stable": s.eq_stable,
        },
        "force_displacement": {},
        "operating_points": result.operating_points,
        "reduced": {
            name: getattr(result.reduced, name)
            for name in ("q", "m_q", "d", "f", "c", "g1", "g2", "C1", "C2", "k1", "k2", "phi")
        },
        "comparison": {
            "attrs": {"nrmse_q": cmp.nrmse_q, "nrmse_phi": cmp.nrmse_phi},
            "t": cmp.full.t,
            "v1": cmp.v1,
            "v2": cmp.v2,
            "q_full": cmp.full.q,
            "phi_full": cmp.full.phi,
            "q_reduced": cmp.reduced.q,
            "phi_reduced": cmp.reduced.phi,
        },
        "modes": {"singular_values": result.modes.singular_values},
    }
    for c in result.curves:
        tree["force_displacement"][_state_name(c.v1, c.v2)] = {
            "attrs": {"v1": c.v1, "v2": c.v2, "b": c.b},
            "q": c.q,
            "F": c.F,
            "dF_dq": c.dF_dq,
            "stable": c.stable,
            "C": c.C,
            "dC_dq": c.dC_dq,
        }
    return tree
