"""Identified curves against the truth of the reduced plant (workflows/paper-experiment-staircase).

On the reduced plant (``[rig.plant] model = "reduced"``) the true curves are exactly of the form
of Eq. 37, so the identified restoring force ``c(q) q + F_0`` and the input gains ``g_i(q)``
(``identify/curves.parquet``) can be checked against ``rig/identification_truth.h5``:

1. wherever debist marks a curve identified, it is within 10 % of the truth's range over the
   model's ``q_range`` (the grid of ``curves.parquet``);
2. the truth lies inside the 95 % band at >= 90 % of those points;
3. the marked region is not trivially small: the restoring force is marked over +-1.5 mm
   around each well centre (the stable zeros of the true ``f``), and each ``g_i`` over the q
   interval its sub-threshold excitation visits near each well where it was applied: the
   logged q during the profile's sub-threshold blocks (its segments other than pulses and
   rest) at the samples where ``v_i^2`` is at least 10 % of its largest value in those blocks
   and the beam dwells (quasi-static by the rig's true q_dot), split at the barrier; the
   central 98 % of those positions (1st to 99th percentile): a point the beam reached for 1 %
   of the time at an edge is seen by the data from one side only, and debist does not mark
   an extrapolation (two-sided support, :func:`debist.identify.bands.support_weights`).
"""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from debist.cli import app

ROOT = Path(__file__).resolve().parents[2]
WORKFLOW = ROOT / "workflows" / "paper-experiment-staircase.toml"
CURVES = {"restoring": "f", "g1": "g1", "g2": "g2"}  # identified curve -> truth curve
TOLERANCE = 0.10  # of the truth's range
COVERAGE = 0.90  # of the marked points inside the 95 % band
HALF_WIDTH = 1.5e-3  # [m] around each well centre, for the restoring force
ACTIVE = 0.1  # v_i^2 above this fraction of its block maximum: v_i applied
VISITED = (1.0, 99.0)  # [%] percentiles of the dwell positions: the interval visited

# every test here reads one run of the staircase workflow (its module fixtures): the slow set
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def staircase_out(tmp_path_factory):
    """The output directory of one run of the staircase workflow, and beside it its rerun
    with bootstrap-only bands; made once for both pytest-xdist workers: read only."""
    from tests.conftest import made_once

    def make(folder: Path) -> str:
        out = folder / "run"
        result = CliRunner().invoke(app, ["run", str(WORKFLOW), "--out", str(out)])
        assert result.exit_code == 0, result.output
        args = ["run", str(WORKFLOW), "--out", str(folder / "bootstrap"), "--until", "identify",
                "-S", "identify.model_error=false"]  # fmt: skip
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, result.output
        return ""

    folder, _ = made_once(tmp_path_factory, "staircase", make)
    return folder / "run"


@pytest.fixture(scope="module")
def staircase_boot_out(staircase_out):
    """The same run with bootstrap-only bands (``model_error = false``), in its own folder
    beside the shipped run's (a run with --set in the folder its --out names, never into the
    original run's)."""
    return staircase_out.parent / "bootstrap"


@pytest.fixture(scope="module")
def staircase(staircase_out):
    """The staircase run's curves, the truth on their grid, the regions (shipped bands)."""
    return _curves_and_truth(staircase_out)


@pytest.fixture(scope="module")
def staircase_boot(staircase_boot_out):
    """As :func:`staircase`, with bootstrap-only bands and their masks."""
    return _curves_and_truth(staircase_boot_out)


def _curves_and_truth(out: Path):
    """The run's curves, the truth on their grid, the regions."""
    import tomllib

    from debist.core import artifacts
    from debist.rig.experiment import RigConfig
    from debist.rig.profiles import make_profile
    from debist.rig.visited import excitation_blocks, rest_points, visited_intervals

    curves = pd.read_parquet(out / "identify/curves.parquet")
    rig_truth = artifacts.read_h5(out / "rig/identification_truth.h5")
    truth = rig_truth["curves"]
    log = pd.read_parquet(out / "ingest/identification.parquet")
    q = curves.q.to_numpy()
    true = {name: np.interp(q, truth["q"], truth[key]) for name, key in CURVES.items()}

    wells, barrier = rest_points(truth["q"], truth["f"])
    wells = wells[(wells > q[0]) & (wells < q[-1])]
    assert wells.size == 2 and wells[0] < barrier < wells[1]

    # the profile's sub-threshold blocks, on the log's time grid
    workflow = tomllib.loads(WORKFLOW.read_text())
    rig = RigConfig.from_dict(workflow["rig"], workflow.get("physics", {}))
    exp = rig.experiments["identification"]
    profile = make_profile(exp.profile, **exp.profile_kwargs())
    t, q_log = log.t.to_numpy(), log.q.to_numpy()
    block = excitation_blocks(profile.segments, t)
    q_dot = rig_truth["states"]["q_dot"]  # the true q_dot, on the log's grid
    assert q_dot.size == t.size
    required = {"restoring": [(w - HALF_WIDTH, w + HALF_WIDTH) for w in wells]}
    for i in (1, 2):
        h = log[f"v{i}"].to_numpy() ** 2
        required[f"g{i}"] = visited_intervals(
            q_log, h, block, q_dot, wells, barrier, active=ACTIVE, percentiles=VISITED
        )
    return curves, true, required


@pytest.mark.parametrize("bands", ["shipped", "bootstrap"])
@pytest.mark.parametrize("name", list(CURVES))
def test_identified_curves_match_the_truth_where_marked(staircase, staircase_boot, name, bands):
    """Within 10 % of the truth's range wherever marked, with either band (the model-error
    term only takes marks away: this workflow's band_tolerance = 0.1 is below twice every
    curve's model error (the as-fitted table: T_z = 0, no effective-mass scale), so its shipped
    bands mark nothing, which the test checks)."""
    from debist.identify.bands import MODEL_ERROR_AS_FITTED as MODEL_ERROR

    curves, true, _ = staircase if bands == "shipped" else staircase_boot
    marked = curves[f"{name}_identified"].to_numpy()
    if bands == "bootstrap":
        assert marked.any()
    else:
        assert not marked.any() and 2 * MODEL_ERROR[name.rstrip("12")] > 0.1
        return
    error = np.abs(curves[name].to_numpy() - true[name])[marked]
    worst = float(error.max() / np.ptp(true[name]))
    q_worst = curves.q.to_numpy()[marked][np.argmax(error)]
    assert worst <= TOLERANCE, f"{name}: {worst:.1%} of its range at q = {q_worst * 1e3:.2f} mm"


@pytest.mark.parametrize("name", list(CURVES))
def test_marked_region_covers_the_wells_and_the_excited_intervals(staircase_boot, name):
    """Where the data inform a curve (bootstrap bands: the masks' support logic)."""
    curves, _, required = staircase_boot
    q = curves.q.to_numpy()
    marked = curves[f"{name}_identified"].to_numpy()
    # restoring: both wells; g_i: applied in both wells by this profile
    assert len(required[name]) == 2
    for lo, hi in required[name]:
        if name != "restoring":  # the staircase moves the beam by mm, not by noise
            assert hi - lo >= 2e-3, f"{name}: excited only over [{lo}, {hi}] m"
        inside = (q >= lo) & (q <= hi)
        assert inside.sum() >= 10
        missing = q[inside & ~marked]
        assert missing.size == 0, (
            f"{name}: not marked at q = {np.round(missing * 1e3, 2).tolist()} mm "
            f"of [{lo * 1e3:.2f}, {hi * 1e3:.2f}] mm"
        )


def test_the_gains_are_not_marked_with_their_model_error(staircase):
    """The gains' calibrated model error (the as-fitted table's "g", of their local magnitude:
    this workflow has T_z = 0 and no effective-mass scale) exceeds half the band tolerance
    wherever a gain is above 0.17 of its scale, and this profile's gains are marked nowhere;
    the band says how far off they may be."""
    from debist.identify.bands import MODEL_ERROR_AS_FITTED as MODEL_ERROR
    from debist.identify.config import IdentifyConfig

    tolerance = IdentifyConfig().band_tolerance
    assert MODEL_ERROR["g"] > tolerance / 2
    curves, _, _ = staircase
    for name in ("g1", "g2"):
        assert not curves[f"{name}_identified"].any()
        value = curves[name].to_numpy()
        half = (curves[f"{name}_hi"] - curves[f"{name}_lo"]).to_numpy() / 2
        assert np.all(half >= MODEL_ERROR["g"] * 0.5 * np.abs(value))  # the term, roughly


@pytest.mark.parametrize("name", ["restoring", "g1", "g2"])
def test_truth_inside_the_95_percent_band_where_marked(staircase, staircase_boot, name):
    """The shipped band (bootstrap and the model error calibrated on the fleets of
    benchmarks/calibrate_bands.py, not on this workflow) holds the truth at >= 90 % of the
    points the data inform: the bootstrap masks (the shipped masks mark no g_i)."""
    curves, true, _ = staircase
    marked = staircase_boot[0][f"{name}_identified"].to_numpy()
    if name == "restoring":
        marked = marked | curves["restoring_identified"].to_numpy()
    assert marked.sum() >= 10
    lo, hi = curves[f"{name}_lo"].to_numpy(), curves[f"{name}_hi"].to_numpy()
    inside = ((lo <= true[name]) & (true[name] <= hi))[marked]
    assert inside.mean() >= COVERAGE, f"{name}: truth inside the band at {inside.mean():.0%}"


def test_the_bootstrap_band_alone_misses_the_g_truth(staircase_boot):
    """Without the model-error term the g_i band holds the truth at far below 95 %: the
    measured reason the term exists (a resampling band covers the model class's best
    approximation, not a truth outside it; Wasserman 2006, Sec. 5.7)."""
    curves, true, _ = staircase_boot
    for name in ("g1", "g2"):
        marked = curves[f"{name}_identified"].to_numpy()
        lo, hi = curves[f"{name}_lo"].to_numpy(), curves[f"{name}_hi"].to_numpy()
        inside = ((lo <= true[name]) & (true[name] <= hi))[marked]
        assert inside.mean() < 0.8, f"{name}: {inside.mean():.0%}"


def _unmodelled_force(out: Path, n: int, m_q: float) -> np.ndarray:
    """The reduced plant's forces that Eq. 37 with a constant ``m_q`` lacks, along the log [N].

    From the rig's true states (``rig/identification_truth.h5``) and the plant itself
    (:class:`debist.rig.reduced.ReducedPlant` of the workflow's ``[rig]``):
    ``(m_q(q) - m_q) q_ddot + 1/2 m_q'(q) q_dot^2`` (the position-dependent inertia) plus
    ``k_bar (k_1(q) q_eps,1 + k_2(q) q_eps,2)`` (the DE creep), with ``q_ddot`` the plant's
    right-hand side at the true states and drive voltages.
    """
    import tomllib

    from debist.core import artifacts
    from debist.rig.experiment import RigConfig
    from debist.rig.reduced import ReducedPlant

    states = artifacts.read_h5(out / "rig/identification_truth.h5")["states"]
    t, x = states["t"], states["x"]
    assert x.shape[0] == n  # the log is on the plant's sample grid
    workflow = tomllib.loads(WORKFLOW.read_text())
    rig = RigConfig.from_dict(workflow["rig"], workflow["physics"]).rig
    plant = ReducedPlant(rig, lambda s: np.interp(s, t, states["v1"]),
                         lambda s: np.interp(s, t, states["v2"]))  # fmt: skip
    k_bar = rig.prototype.V_DE * rig.prototype.Y_MW  # Eq. 26
    out_force = np.empty(n)
    for k in range(n):
        m, dm, _, _, _, _, k1, k2 = plant.curves(x[k, 0]).tolist()
        q_ddot = plant.rhs(t[k], x[k])[1]
        creep = k_bar * (k1 * x[k, 2] + k2 * x[k, 3])
        out_force[k] = (m - m_q) * q_ddot + 0.5 * dm * x[k, 1] ** 2 + creep
    return out_force


def test_the_g_error_is_bias_from_the_dynamics_eq37_lacks(staircase_boot, staircase_out):
    """Why the g_i bands miss the truth: bias from the plant's dynamics, which no band sees.

    The band is a resampling band: it covers the best approximation of the model class, not
    a truth outside it (Wasserman 2006, All of Nonparametric Statistics, Sec. 5.7). Adding
    the plant's own inertia and creep forces (which Eq. 37 lacks) to the regression output,
    an independent re-identification with the same settings, cuts the g_i error where marked
    by a factor of about 10 (measured: 3.1 -> 0.34 % and 3.5 -> 0.34 % of the range, medians),
    while the median error of the workflow's g_i exceeds the median band half-width.
    """
    import tomllib

    from debist.identify.physics_prior import physics_mass
    from debist.physics.params import PrototypeParams
    from debist.stages.identify import run_identify

    curves, true, _ = staircase_boot
    out = staircase_out
    workflow = tomllib.loads(WORKFLOW.read_text())
    tables = {"identification": pd.read_parquet(out / "ingest/identification.parquet")}
    deriv = pd.read_parquet(out / "differentiate/identification.parquet")
    physics = PrototypeParams(**workflow["physics"])
    m_q = physics_mass(physics)  # the workflow's m_q = "physics"
    corrected = deriv.copy()  # m_q q_ddot plus the missing forces: the output of Eq. 40
    corrected["q_ddot"] = deriv["q_ddot"] + _unmodelled_force(out, len(deriv), m_q) / m_q
    corrected.attrs = dict(deriv.attrs)
    res = run_identify(tables, {"identification": corrected}, workflow["identify"], physics)
    for name in ("g1", "g2"):
        marked = curves[f"{name}_identified"].to_numpy()
        span = np.ptp(true[name])
        before = np.median(np.abs(curves[name].to_numpy() - true[name])[marked]) / span
        after = np.median(np.abs(res.curves[name].to_numpy() - true[name])[marked]) / span
        half = np.median((curves[f"{name}_hi"] - curves[f"{name}_lo"]).to_numpy()[marked]) / 2
        assert before > half / span, f"{name}: median error {before:.1%} within the band"
        assert after <= before / 3, f"{name}: {before:.1%} -> {after:.1%} of its range"
