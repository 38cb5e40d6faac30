"""Global options of the debist CLI."""

import json
import re
import shutil
from importlib.metadata import version

import pytest
from typer.testing import CliRunner

from debist.cli import app
from tests.conftest import SYNTHETIC_WORKFLOW, write_rig_csv


def test_version_prints_the_installed_version_and_exits():
    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0
    assert result.output.strip() == f"debist {version('debist')}"


def test_version_runs_before_a_command_would():
    result = CliRunner().invoke(app, ["--version", "verify", "does-not-exist.toml"])
    assert result.exit_code == 0 and "debist" in result.output


@pytest.fixture
def project(tmp_path, bistable_record):
    write_rig_csv(tmp_path, bistable_record)
    (tmp_path / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    return tmp_path


@pytest.mark.slow
def test_quiet_prints_only_the_run_digest_and_verbose_says_why(project):
    wf = str(project / "wf.toml")
    result = CliRunner().invoke(app, ["-q", "run", wf])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert len(lines) == 1 and re.fullmatch(r"run digest: [0-9a-f]{64}", lines[0]), lines
    digest = lines[0].split()[-1]
    assert CliRunner().invoke(app, ["verify", wf, "--digest", digest]).exit_code == 0

    normal = CliRunner().invoke(app, ["run", wf]).output
    assert "skipping" in normal and "manifest" not in normal
    verbose = " ".join(CliRunner().invoke(app, ["-v", "run", wf]).output.split())
    assert verbose.count("matches its manifest, outputs unchanged") == 5

    out = " ".join(CliRunner().invoke(app, ["-v", "identify", wf, "--force"]).output.split())
    assert "Running stage 'identify' ... (forced)" in out
    fit = re.search(r"timings: .*\bfit (\d+\.\d+) s", out)
    assert fit is not None and float(fit.group(1)) > 0, out
    assert "timings:" not in CliRunner().invoke(app, ["identify", wf, "--force"]).output

    # a changed setting: -v says what changed; -q still prints nothing but the digest
    (project / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=2e-6))
    out = " ".join(CliRunner().invoke(app, ["-v", "differentiate", wf]).output.split())
    assert "'differentiate' ..." in out and "changed (alpha))" in out
    result = CliRunner().invoke(app, ["--quiet", "run", wf])
    assert result.exit_code == 0 and result.output.startswith("run digest: ")
    assert len(result.output.splitlines()) == 1


def test_quiet_still_prints_errors_and_status():
    result = CliRunner().invoke(app, ["-q", "run", "does-not-exist.toml"])
    assert result.exit_code == 2 and "does-not-exist.toml" in result.output


def test_quiet_and_verbose_together_are_a_usage_error():
    result = CliRunner().invoke(app, ["-q", "-v", "run", "does-not-exist.toml"])
    assert result.exit_code == 2 and "both" in result.output


def test_the_convergence_notice_names_the_keys_to_change(project):
    wf = str(project / "wf.toml")
    text = SYNTHETIC_WORKFLOW.format(alpha=1e-6)
    # the workflow states 10 iterations (the paper's fixed count): its choice, not noticed
    out = " ".join(CliRunner().invoke(app, ["run", wf, "--until", "differentiate"]).output.split())
    assert "Stage 'differentiate' done" in out and "iteration limit" not in out
    summary = json.loads((project / "out" / "differentiate" / "summary.json").read_text())
    assert list(summary["converged"].values()) == [False, False]  # still recorded
    # the default count against a tolerance of 1e-14 stops first: said, with the keys
    (project / "wf.toml").write_text(text.replace("iterations = 10", "tol = 1e-14"))
    out = " ".join(CliRunner().invoke(app, ["run", wf, "--until", "differentiate"]).output.split())
    assert "iteration" in out and "tolerance" in out and "2 data" in out and "set(s)" in out
    assert "raise [differentiate] iterations (now " in out
    assert "loosen [differentiate] tol (now 1e-14)" in out
    # whether it matters: how far a run with 4x the iterations moved the derivatives
    summary = json.loads((project / "out" / "differentiate" / "summary.json").read_text())
    longer = summary["longer_run"].values()
    q_dot, q_ddot = (max(r[k] for r in longer) for k in ("q_dot", "q_ddot"))
    assert {r["iterations"] for r in longer} == {40}
    assert f"a run with 40 iterations moved q_dot by {100 * q_dot:.3g} % and q_ddot by " in out
    assert f"q_ddot by {100 * q_ddot:.3g} % (relative change, largest data set)" in out
    matters = max(q_dot, q_ddot) >= 0.01
    assert ("It may matter" in out) == matters and ("It does not matter" in out) != matters
    again = CliRunner().invoke(app, ["run", wf, "--until", "differentiate"]).output
    assert "iteration limit" not in again  # said once, when the stage ran
    (project / "wf.toml").write_text(
        text.replace("iterations = 10", "iterations = 400\ntol = 1e-2")
    )
    out = CliRunner().invoke(app, ["run", wf, "--until", "differentiate"]).output
    assert "Stage 'differentiate' done" in out and "iteration limit" not in out


def test_the_run_tables_show_q_and_stiffness_in_one_unit_system(synthetic_copy):
    """No report_unit, q in m: q*, the identified ranges and RMS(q) in mm; the curves are per
    unit mass (m_q = 1), so k* is 1/s^2 with the stage's numbers and the forces mm/s^2."""
    root, _ = synthetic_copy
    result = CliRunner().invoke(app, ["run", str(root / "wf.toml")])
    assert result.exit_code == 0, result.output
    out = result.output
    summary = json.loads((root / "out" / "identify" / "summary.json").read_text())
    assert summary["units"]["q"] == "m" and summary["units"]["per_unit_mass"] is True
    assert "q* [mm]" in out and "q* [m]" not in out and "k* [1/s^2]" in out
    assert "m/s^2/m" not in out and "forces in mm/s^2" in out
    wells = [r for r in summary["design"]["equilibria"] if r["static_stable"]]
    for r in wells:
        assert f"{1e3 * r['q']:.4g}" in out and f"{r['k']:.4g}" in out
    lo, hi = summary["q_data_range"]
    assert f"in [{1e3 * lo:.4g}, {1e3 * hi:.4g}] mm)" in " ".join(out.split())
    assert "identified on q [mm] in" in out
    nrmse = json.loads((root / "out" / "compare" / "summary.json").read_text())["table"]
    rbf = next(r for r in nrmse if r["model"] == "rbf" and r["dataset"] == "check")
    assert rbf["rms_unit"] == "mm" and f"{rbf['rms_q']:.4g} mm" in out
    assert "(coefficients as fitted, in SI: q [m], q_dot [m/s], q_ddot [m/s^2])" in out


def test_verbose_timings_account_for_the_stage_wall_time(synthetic_run, tmp_path):
    """The parts ``-v`` shows (the stage's own, ``import``, ``other``, ``write``) add up to the
    wall time the stage line reports, within the rounding of the display."""
    shutil.copytree(synthetic_run[0], tmp_path / "p")
    wf = str(tmp_path / "p" / "wf.toml")
    result = CliRunner().invoke(app, ["-v", "validate", wf, "--force"])
    assert result.exit_code == 0, result.output
    out = " ".join(result.output.split())
    total = float(re.search(r"Stage 'validate' done \((\d+\.\d+) s\)", out).group(1))
    line = re.search(r"timings: (.*?) \(stage (\d+\.\d+) s\)", out)
    parts = dict(re.findall(r"([a-z][a-z -]*?) (\d+\.\d+) s(?:, |$)", line.group(1)))
    for name in ("read inputs", "simulate", "replicates", "import", "other", "write"):
        assert name in parts, parts
    shown = sum(float(v) for v in parts.values())
    slack = 0.005 * len(parts) + 0.01  # each part and the total rounded to 0.01 s
    assert 0.9 * total - slack <= shown <= total + slack, (shown, total, parts)
    assert abs(float(line.group(2)) - total) <= 0.05 * total + slack
