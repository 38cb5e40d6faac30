"""Figures of the physics model: they build from results, carry units, and save."""

import numpy as np
import pytest
from matplotlib.figure import Figure

from debist.physics.dynamics import mode_analysis
from debist.physics.params import PrototypeParams
from debist.physics.prestrain import prestrain_sweep
from debist.physics.reduced import compare_full_reduced, fit_reduced, switching_profile
from debist.physics.statics import FORCE_STATES, force_displacement
from debist.report import physics_plots as plots

P = PrototypeParams.paper()


@pytest.fixture(scope="module")
def comparison():
    profile = switching_profile(left=(0.05, 0.2), right=(0.3, 0.4))
    return compare_full_reduced(P, t_end=0.5, profile=profile, model=fit_reduced(P, degree=20))


def styles(ax):
    return {line.get_linestyle() for line in ax.get_lines()}


def test_fig3(tmp_path):
    sweep = prestrain_sweep(P, b=np.linspace(18e-3, 30e-3, 13), n_q=80)
    fig = plots.plot_prestrain_sweep(sweep)
    ax = fig.axes[0]
    assert {"-", "--"} <= styles(ax)  # stable solid, unstable dashed
    assert "[mm]" in ax.get_xlabel() and "[mm]" in ax.get_ylabel()
    labels = [t.get_text() for t in fig.axes[1].get_yticklabels()]
    assert any("4.84" in s for s in labels) and any("11.65" in s for s in labels)
    fig.savefig(tmp_path / "fig3.png")
    assert (tmp_path / "fig3.png").stat().st_size > 10_000


def test_fig4_fig5(tmp_path):
    q = np.linspace(-15e-3, 15e-3, 61)
    curves = [force_displacement(P, q, v1=a, v2=b) for a, b in FORCE_STATES]
    fig4 = plots.plot_force_displacement(curves)
    ax = fig4.axes[0]
    assert len(ax.get_legend().get_texts()) == 4 and "[mN]" in ax.get_ylabel()
    assert {"-", "--"} <= styles(ax)
    fig5 = plots.plot_capacitance(curves[0])
    assert len(fig5.axes) == 2 and "[nF]" in fig5.axes[0].get_ylabel()
    for name, fig in (("fig4", fig4), ("fig5", fig5)):
        fig.savefig(tmp_path / f"{name}.png")
        assert (tmp_path / f"{name}.png").stat().st_size > 10_000


def test_fig6_fig7_and_curves(tmp_path, comparison):
    fig7 = plots.plot_comparison(comparison)
    assert "NRMSE" in fig7.axes[0].get_title() and "[kV]" in fig7.axes[1].get_ylabel()
    fig6 = plots.plot_modes(mode_analysis(comparison.full.qm, P))
    fig14 = plots.plot_reduced_curves(comparison.model.curves(np.linspace(-15e-3, 15e-3, 31)))
    for name, fig in (("fig6", fig6), ("fig7", fig7), ("curves", fig14)):
        assert isinstance(fig, Figure)
        fig.savefig(tmp_path / f"{name}.png")
        assert (tmp_path / f"{name}.png").stat().st_size > 10_000
