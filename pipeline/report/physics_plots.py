"""Figures of the physics model (Fig. 3, 4, 5, 6a, 7 of the paper) as matplotlib Figures.

Every function takes results and returns a :class:`matplotlib.figure.Figure` built without
pyplot (no global state, any backend); saving is the caller's: ``fig.savefig(path)``.

References
----------
Masoud & Maas 2025, Fig. 3-7.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from debist.physics.analysis import Analysis
from debist.physics.dynamics import ModeAnalysis
from debist.physics.prestrain import PrestrainSweep, equilibrium_branches
from debist.physics.reduced import Comparison, ReducedCurves
from debist.physics.statics import ForceCurve
from debist.report.tables import physics_factor

__all__ = [
    "analysis_figures",
    "plot_capacitance",
    "plot_comparison",
    "plot_force_displacement",
    "plot_modes",
    "plot_prestrain_sweep",
    "plot_reduced_curves",
]

_COLOURS = {(0, 0): "black", (1, 0): "tab:red", (0, 1): "tab:green", (1, 1): "tab:blue"}


def _colour(v1: float, v2: float) -> str:
    return _COLOURS[(int(v1 > 0), int(v2 > 0))]


def _label(v1: float, v2: float) -> str:
    return f"$v_1$ = {v1 / 1e3:g} kV, $v_2$ = {v2 / 1e3:g} kV"


def _segments(x, y, stable):
    """Split a curve into runs of equal stability (sharing the boundary vertex)."""
    cuts = np.flatnonzero(stable[1:] != stable[:-1]) + 1
    start = 0
    for c in [*cuts, len(stable)]:
        sl = slice(max(start - 1, 0), c)
        yield x[sl], y[sl], bool(stable[start])
        start = c


def plot_prestrain_sweep(sweep: PrestrainSweep, report_unit: str | None = None) -> Figure:
    """Equilibria versus ``z_b`` (Fig. 3): stable solid, unstable dashed, bifurcations marked.

    Parameters
    ----------
    sweep : PrestrainSweep
        Result of :func:`debist.physics.prestrain.prestrain_sweep`.
    report_unit : str, optional
        ``[validate] report_unit`` for q (:func:`debist.report.tables.physics_factor`;
        default mm).

    Returns
    -------
    matplotlib.figure.Figure
        ``q`` [report unit] on the x axis, ``z_b = b_max - b`` [mm] on the y axis.

    References
    ----------
    Masoud & Maas 2025, Eq. 16, 17, Fig. 3.
    """
    f, unit = physics_factor(report_unit)
    fig = Figure(figsize=(6.4, 5.2), layout="constrained")
    ax = fig.add_subplot()
    handles = []
    for s, (v1, v2) in enumerate(sweep.voltages):
        col = _colour(v1, v2)
        for q, z, stable in equilibrium_branches(sweep, s):
            ax.plot(q * f, z * 1e3, color=col, ls="-" if stable else "--", lw=1.6)
        handles.append(Line2D([], [], color=col, label=_label(v1, v2)))
    zmin, zmax = float(np.min(sweep.z_b)), float(np.max(sweep.z_b))
    marks = []
    for z, name in ((sweep.z_b_min, r"$z_{b,\min}$"), (sweep.z_b_max, r"$z_{b,\max}$")):
        if np.isfinite(z):
            ax.axhline(z * 1e3, color="0.4", lw=0.8, ls=":")
            marks.append((z * 1e3, f"{name}\n{z * 1e3:.2f} mm"))
            zmin, zmax = min(zmin, z), max(zmax, z)
    pad = 0.03 * (zmax - zmin)
    ax.set_ylim((zmin - pad) * 1e3, (zmax + pad) * 1e3)
    right = ax.twinx()
    right.set_ylim(ax.get_ylim())
    right.set_yticks([m[0] for m in marks], [m[1] for m in marks], fontsize=8)
    handles += [
        Line2D([], [], color="0.3", ls="-", label="stable"),
        Line2D([], [], color="0.3", ls="--", label="unstable"),
    ]
    fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncols=3)
    ax.set_xlabel(f"tip displacement $q$ [{unit}]")
    ax.set_ylabel(r"$z_b = b_{\max} - b$ [mm]")
    ax.set_title("Equilibria versus pre-strain")
    ax.grid(alpha=0.3)
    return fig


def plot_force_displacement(
    curves: Sequence[ForceCurve], *, f_lim: float = 0.15, report_unit: str | None = None
) -> Figure:
    """Force-displacement curves ``F(q)`` (Fig. 4); stable solid, unstable dashed.

    Parameters
    ----------
    curves : sequence of ForceCurve
        One curve per voltage state (:func:`debist.physics.statics.force_displacement`).
    f_lim : float
        Half range of the force axis [N].
    report_unit : str, optional
        ``[validate] report_unit`` for q (:func:`debist.report.tables.physics_factor`;
        default mm).

    Returns
    -------
    matplotlib.figure.Figure
        ``F`` [mN] versus ``q`` [report unit].

    References
    ----------
    Masoud & Maas 2025, Eq. 15, Fig. 4.
    """
    f, unit = physics_factor(report_unit)
    fig = Figure(figsize=(6.4, 4.8), layout="constrained")
    ax = fig.add_subplot()
    for c in curves:
        col = _colour(c.v1, c.v2)
        for k, (x, y, st) in enumerate(_segments(c.q * f, c.F * 1e3, c.stable)):
            ax.plot(x, y, color=col, ls="-" if st else "--", lw=1.6,
                    label=_label(c.v1, c.v2) if k == 0 else None)  # fmt: skip
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.axvline(0.0, color="0.5", lw=0.8)
    ax.set_ylim(-f_lim * 1e3, f_lim * 1e3)
    ax.set_xlabel(f"tip displacement $q$ [{unit}]")
    ax.set_ylabel("external force $F$ [mN]")
    ax.set_title("Force-displacement characteristic (dashed: unstable)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def plot_capacitance(curve: ForceCurve, report_unit: str | None = None) -> Figure:
    """Capacitances ``C_1(q)``, ``C_2(q)`` and ``dC_i/dq`` along a static path (Fig. 5).

    Parameters
    ----------
    curve : ForceCurve
        Static path, normally at ``v = 0``.
    report_unit : str, optional
        ``[validate] report_unit`` for q (:func:`debist.report.tables.physics_factor`;
        default mm).

    Returns
    -------
    matplotlib.figure.Figure
        Two panels: ``C_i`` [nF] and ``dC_i/dq`` [nF per report unit] versus ``q``
        [report unit].

    References
    ----------
    Masoud & Maas 2025, Eq. 11, 18, Fig. 5.
    """
    fig = Figure(figsize=(6.4, 5.6), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    f, unit = physics_factor(report_unit)
    q = curve.q * f
    for i, (name, col) in enumerate((("DE 1 (left)", "tab:red"), ("DE 2 (right)", "tab:green"))):
        ax1.plot(q, curve.C[:, i] * 1e9, color=col, label=f"$C_{i + 1}$, {name}")
        ax2.plot(q, curve.dC_dq[:, i] * 1e9 / f, color=col,
                 label=rf"$\partial C_{i + 1}/\partial q$")  # fmt: skip
    ax2.axhline(0.0, color="0.5", lw=0.8)
    ax1.set_ylabel("capacitance [nF]")
    ax2.set_ylabel(rf"$\partial C/\partial q$ [nF/{unit}]")
    ax2.set_xlabel(f"tip displacement $q$ [{unit}]")
    ax1.set_title("Capacitance along the static path")
    for ax in (ax1, ax2):
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    return fig


def plot_comparison(cmp: Comparison, report_unit: str | None = None) -> Figure:
    """Full versus reduced model under the switching voltages (Fig. 7).

    Parameters
    ----------
    cmp : Comparison
        Result of :func:`debist.physics.reduced.compare_full_reduced`.
    report_unit : str, optional
        ``[validate] report_unit`` for q (:func:`debist.report.tables.physics_factor`;
        default mm).

    Returns
    -------
    matplotlib.figure.Figure
        ``q(t)`` [report unit] of both models (with NRMSE) above the voltages [kV].

    References
    ----------
    Masoud & Maas 2025, Eq. 41, Fig. 7.
    """
    fig = Figure(figsize=(7.2, 5.2), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=(2.2, 1))
    t = cmp.full.t
    f, unit = physics_factor(report_unit)
    ax1.plot(t, cmp.full.q * f, color="black", lw=1.4, label="full model (Eq. 21)")
    ax1.plot(cmp.reduced.t, cmp.reduced.q * f, color="tab:orange", ls="--", lw=1.4,
             label="reduced model (Eq. 26)")  # fmt: skip
    ax1.set_ylabel(f"tip displacement $q$ [{unit}]")
    ax1.set_title(
        f"Full vs reduced model: NRMSE(q) = {100 * cmp.nrmse_q:.1f} %, "
        f"NRMSE($\\varphi$) = {100 * cmp.nrmse_phi:.1f} %"
    )
    ax1.legend(fontsize=8, loc="lower left")
    ax2.plot(t, cmp.v1 / 1e3, color="tab:red", label="$v_1$ (left DE)")
    ax2.plot(t, cmp.v2 / 1e3, color="tab:green", ls="--", label="$v_2$ (right DE)")
    ax2.set_ylabel("voltage [kV]")
    ax2.set_xlabel("time $t$ [s]")
    ax2.set_ylim(-0.2, max(float(np.max(cmp.v1)), float(np.max(cmp.v2)), 1.0) / 1e3 * 1.15)
    ax2.legend(fontsize=8, loc="upper right")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    return fig


def plot_modes(modes: ModeAnalysis) -> Figure:
    """Mode shapes of a simulated deflection field from the SVD (Fig. 6a).

    Parameters
    ----------
    modes : ModeAnalysis
        Result of :func:`debist.physics.dynamics.mode_analysis`.

    Returns
    -------
    matplotlib.figure.Figure
        Modes scaled by their singular value (RMS deflection contribution) [mm] along the beam.

    References
    ----------
    Masoud & Maas 2025, Fig. 6a.
    """
    fig = Figure(figsize=(6.4, 4.4), layout="constrained")
    ax = fig.add_subplot()
    n_t = max(modes.coefficients.shape[0], 1)
    for k, col in zip(range(modes.modes.shape[1]), ("tab:red", "tab:blue", "tab:green"),
                      strict=False):  # fmt: skip
        amp = modes.singular_values[k] / np.sqrt(n_t)
        ax.plot(modes.modes[:, k] * amp * 1e3, modes.x * 1e3, color=col,
                label=f"mode {k + 1} ({100 * modes.energy_fraction[k]:.2f} %)")  # fmt: skip
    ax.axvline(0.0, color="0.5", lw=0.8)
    ax.set_xlabel("RMS deflection of the mode [mm]")
    ax.set_ylabel("position along the beam $x$ [mm]")
    ax.set_title("SVD mode shapes of the simulated beam deflection")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def plot_reduced_curves(curves: ReducedCurves, report_unit: str | None = None) -> Figure:
    """Characteristic curves of the reduced model (``c, d, g_1, g_2, m_q``; cf. Fig. 14).

    Parameters
    ----------
    curves : ReducedCurves
        Result of :func:`debist.physics.reduced.reduced_curves`.
    report_unit : str, optional
        ``[validate] report_unit`` for q and what is per length of q (``d`` [N s per
        unit], ``g_i`` [nF per unit]; :func:`debist.report.tables.physics_factor`;
        default mm).

    Returns
    -------
    matplotlib.figure.Figure
        Four panels versus ``q`` [report unit].

    References
    ----------
    Masoud & Maas 2025, Eq. 26, 33, Fig. 14.
    """
    fig = Figure(figsize=(8.0, 5.6), layout="constrained")
    axs = fig.subplots(2, 2, sharex=True).ravel()
    f, unit = physics_factor(report_unit)
    q = curves.q * f
    axs[0].plot(q, curves.f * 1e3, color="black")
    axs[0].set_ylabel("$f(q) = c(q)\\,q$ [mN]")
    axs[1].plot(q, curves.d / f, color="black")
    axs[1].set_ylabel(f"$d(q)$ [N s/{unit}]")
    axs[2].plot(q, curves.g1 * 1e9 / f, color="tab:red", label="$g_1$")
    axs[2].plot(q, curves.g2 * 1e9 / f, color="tab:green", label="$g_2$")
    axs[2].set_ylabel(rf"$g_i = \partial C_i / (2\,\partial q)$ [nF/{unit}]")
    axs[2].legend(fontsize=8)
    axs[3].plot(q, curves.m_q * 1e3, color="black")
    axs[3].set_ylabel("$m_q(q)$ [g]")
    for ax in axs:
        ax.grid(alpha=0.3)
    for ax in axs[2:]:
        ax.set_xlabel(f"tip displacement $q$ [{unit}]")
    fig.suptitle("Reduced-model characteristic curves")
    return fig


def analysis_figures(result: Analysis, report_unit: str | None = None) -> dict[str, Figure]:
    """Draw the figures of the analysis (matplotlib), named after the paper's.

    Parameters
    ----------
    result : Analysis
        From :func:`debist.physics.analysis.run_analysis`.
    report_unit : str, optional
        ``[validate] report_unit``: q and what is per length of q are drawn in it
        (:func:`debist.report.tables.physics_factor`; default mm); the beam's geometry
        (z_b, x and the modes' deflection) stays in mm.

    Returns
    -------
    dict of str to matplotlib.figure.Figure
        ``fig3_prestrain``, ``fig4_force_displacement``, ``fig5_capacitance``,
        ``fig6a_modes``, ``fig7_full_vs_reduced`` and ``reduced_curves``.

    References
    ----------
    Masoud & Maas 2025, Fig. 3-7.
    """
    return {
        "fig3_prestrain": plot_prestrain_sweep(result.sweep, report_unit),
        "fig4_force_displacement": plot_force_displacement(result.curves, report_unit=report_unit),
        "fig5_capacitance": plot_capacitance(result.curves[0], report_unit),
        "fig6a_modes": plot_modes(result.modes),
        "fig7_full_vs_reduced": plot_comparison(result.comparison, report_unit),
        "reduced_curves": plot_reduced_curves(result.reduced, report_unit),
    }
