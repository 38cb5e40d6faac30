"""The Python API (debist.api): the same run, numbers and free runs as the command line."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

import debist
from debist.core import artifacts
from debist.core.errors import ArtifactError, OutputDirError, WorkflowError


def test_import_debist_is_light_and_lists_its_api():
    code = "import sys, debist; print(sorted(m for m in ('numpy', 'pandas') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "[]", out.stderr
    for name in ("run", "load_workflow", "load_model", "run_batch", "verify", "Result", "Model"):
        assert name in debist.__all__ and callable(getattr(debist, name))
    with pytest.raises(AttributeError) as err:
        debist.nonsense  # noqa: B018
    assert "'nonsense'" in str(err.value)


def test_run_skips_what_is_up_to_date_prints_nothing_and_reports_progress(synthetic_copy, capfd):
    root, digest = synthetic_copy
    events = []
    result = debist.run(root / "wf.toml", on_progress=events.append)
    captured = capfd.readouterr()
    assert captured.out == "" and captured.err == ""
    assert result.digest == digest
    assert {e.what for e in events} == {"skip"}
    assert [e.stage for e in events] == list(result.manifests)
    assert debist.verify(root / "wf.toml", digest).ok


def test_nrmse_is_the_table_the_cli_prints_in_percent(synthetic_run):
    root, _ = synthetic_run
    result = debist.open_run(root / "wf.toml")
    raw = artifacts.read_parquet(root / "out/compare/nrmse.parquet")  # rbf, sindy, narx
    frame = result.nrmse
    assert list(frame["model"]) == list(raw["model"])
    np.testing.assert_allclose(frame["NRMSE(q) [%]"], 100.0 * raw["nrmse_q"], rtol=1e-15)
    np.testing.assert_allclose(frame["NRMSE(q_dot) [%]"], 100.0 * raw["nrmse_q_dot"])
    assert set(frame["verdict"]) <= {"ok"} | {v for v in frame["verdict"] if v}
    # a script reads the verdicts a person reads: the Parquet column is the display's word
    assert frame["verdict"].tolist() == raw["verdict"].tolist()
    assert all(isinstance(v, str) and v for v in raw["verdict"])
    rbf = artifacts.read_parquet(root / "out/validate/nrmse.parquet")
    assert rbf["verdict"].str.len().gt(0).all()
    # the CLI's own output of that run shows the same percentages, to its two decimals
    from tests.conftest import invoke_cli

    code, out = invoke_cli("run", root / "wf.toml")
    assert code == 0
    for value in frame["NRMSE(q) [%]"]:
        assert f"{value:.2f} %" in out


@pytest.mark.slow
def test_overrides_change_the_run_and_are_recorded(synthetic_copy):
    root, digest = synthetic_copy
    events = []
    result = debist.run(root / "wf.toml", overrides={"identify.M": 6}, on_progress=events.append)
    assert result.digest != digest
    assert result.manifests["identify"].config["M"] == 6
    assert "identify" in {e.stage for e in events if e.what == "done"}
    assert result.model.rbf.basis.xi.size == 6
    # the run has its own folder beside the workflow's, whose run stays as it was
    assert result.output_dir.parent == root and result.output_dir.name.startswith("out.set-")
    assert debist.verify(root / "wf.toml", result.digest, overrides={"identify.M": 6}).ok
    assert debist.verify(root / "wf.toml", digest).ok
    assert debist.open_run(root / "wf.toml").model.rbf.basis.xi.size == 8
    assert debist.open_run(root / "wf.toml", overrides=["identify.M=6"]).digest == result.digest
    with pytest.raises(WorkflowError) as err:
        debist.load_workflow(root / "wf.toml", {"identify.M": "many"})
    assert "identify" in str(err.value)


def test_model_simulate_reproduces_the_validate_stage_free_run(synthetic_run):
    root, _ = synthetic_run
    result = debist.open_run(root / "wf.toml")
    model = debist.load_model(root / "out")
    measured = result.table("ingest", "check.parquet")
    derivs = result.table("differentiate", "check.parquet")
    v = measured[["v1", "v2"]].to_numpy()
    sim = model.simulate(measured["t"].to_numpy(), v, measured["q"][0], derivs["q_dot"][0])
    validated = result.free_run("check")
    # validate runs both records as one batch (inputs interpolated together): equal to 1e-12
    assert np.max(np.abs(sim["q"] - validated["q_sim"])) <= 1e-12  # [m]
    assert np.max(np.abs(sim["q_dot"] - validated["q_dot_sim"])) <= 1e-9  # [m/s]
    scale = np.ptp(validated["q"])
    # the NumPy reference engine: the same scheme, equal to rounding
    ref = model.simulate(
        measured["t"].to_numpy(), v, measured["q"][0], derivs["q_dot"][0], engine="numpy"
    )
    np.testing.assert_allclose(ref["q"], sim["q"], rtol=0, atol=1e-9 * scale)


def test_model_curves_and_equilibria_are_the_identify_stages(synthetic_run):
    root, _ = synthetic_run
    result = debist.open_run(root / "wf.toml")
    curves = result.curves
    evaluated = result.model.curves(curves["q"].to_numpy())
    np.testing.assert_allclose(evaluated["g1"], curves["g1"], rtol=1e-12, atol=0)
    np.testing.assert_allclose(evaluated["d"], curves["d"], rtol=1e-12, atol=1e-300)
    assert "holds" in curves.attrs["band"] or "band" in curves.attrs["band"]
    rest = result.model.equilibria()
    stored = result.equilibria
    stored = stored[(stored["model"] == "rbf") & (stored["level"] == 0)]
    np.testing.assert_allclose(np.sort(rest["q"]), np.sort(stored["q"]), rtol=1e-9)
    # wells are statically stable (k > 0), the saddle between them is not
    assert list(rest.sort_values("q")["static_stable"]) == [True, False, True]


def test_a_changed_artifact_is_never_read(synthetic_copy):
    root, _ = synthetic_copy
    model_file = root / "out/identify/model.h5"
    model_file.write_bytes(model_file.read_bytes() + b"\0")
    with pytest.raises(ArtifactError) as err:
        debist.load_model(root / "out")
    assert "changed" in str(err.value) and "wrote" in str(err.value)
    with pytest.raises(ArtifactError) as err:
        debist.open_run(root / "wf.toml").model  # noqa: B018
    assert "changed" in str(err.value) and "wrote" in str(err.value)
    found = debist.verify(root / "wf.toml")
    assert not found.ok and any("model.h5" in p for p in found.problems)


def test_simulate_refuses_bad_inputs_by_name(synthetic_run):
    root, _ = synthetic_run
    model = debist.load_model(root / "out/identify")
    t = np.arange(0.0, 0.1, 1e-3)
    with pytest.raises(ValueError) as err:
        model.simulate(t, np.zeros(t.size), 0.0, 0.0)
    assert "100" in str(err.value)
    with pytest.raises(ValueError) as err:
        model.simulate(t**2, np.zeros((t.size, 2)), 0.0, 0.0)
    assert "uniform" in str(err.value)
    with pytest.raises(ArtifactError) as err:
        debist.load_model(root)
    assert "run" in str(err.value) and "folder" in str(err.value)


def test_printing_the_nrmse_table_shows_every_row_and_column(synthetic_run):
    root, _ = synthetic_run
    table = debist.open_run(root / "wf.toml").nrmse
    text = repr(table)
    lines = text.splitlines()
    assert len(lines) == len(table) + 1 and "..." not in text
    assert lines[0].split()[:3] == ["data", "set", "role"] and "verdict" in lines[0]
    for row, line in zip(table.itertuples(index=False), lines[1:], strict=True):
        assert f"{row[3]:.2f}" in line  # NRMSE(q) [%] to two decimals, as the CLI prints it
    narx = [line for line, model in zip(lines[1:], table["model"], strict=True) if model == "narx"]
    assert narx and all("n/a" in line for line in narx)  # NARX predicts q only
    assert type(table[["model"]]) is pd.DataFrame  # a selection is a plain DataFrame


def test_the_cli_commands_are_the_apis_calls(synthetic_copy, tmp_path):
    root, digest = synthetic_copy
    wf = root / "wf.toml"
    stages = debist.workflow_stages(wf)
    assert stages[0] == "ingest" and "identify" in stages and "report" not in stages
    assert debist.run_blocker(wf) is None
    # another workflow's folder: the blocker is the refusal a run gives, and nothing is written
    other = root / "other.toml"
    other.write_text(wf.read_text().replace('name = "', 'name = "other-', 1))
    before = sorted(p.name for p in (root / "out").iterdir())
    found = debist.run_blocker(other, output_dir=root / "out")
    assert found is not None and "belongs" in found
    with pytest.raises(OutputDirError) as err:
        debist.run(other, output_dir=root / "out")
    assert "belongs" in str(err.value)
    assert sorted(p.name for p in (root / "out").iterdir()) == before
    # export: the files of the format, refused over existing ones without force
    done = debist.export_model(wf, "python", dest=tmp_path / "exp")
    assert [p.name for p in done.files] == ["debist_model.py"] and done.run_digest == digest
    assert "def rk4_step(x, v0, v1, dt):" in done.files[0].read_text()
    with pytest.raises(OutputDirError):
        debist.export_model(wf, "python", dest=tmp_path / "exp")
    assert debist.export_model(wf, "python", dest=tmp_path / "exp", force=True).files == done.files
    # diff of a run with itself: nothing differs
    found = debist.diff(root / "out", root / "out")
    assert found == {"runs": [str(root / "out")] * 2, "config": [], "nrmse": []}


def test_batch_helpers_find_tabulate_and_index(synthetic_copy):
    root, _ = synthetic_copy
    assert debist.find_workflows([root / "wf.toml"]) == [root / "wf.toml"]
    with pytest.raises(WorkflowError):
        debist.find_workflows([root / "nothing-*.toml"])
    results = debist.run_batch([root / "wf.toml"], scheduler="synchronous")
    table = debist.batch_table(results)
    assert list(table["status"]) == ["done"] and table["ran"].tolist() == [0]
    index = debist.batch_index(results)
    assert index is not None and index.name == "index.html"
    assert "wf" in index.read_text() or results[0].name in index.read_text()


# compare once: recomputed in turn, to the bytes of the original run's compare, whose first
# part ran ahead beside identify (tests/engine/test_early.py); differentiate, the cheapest
# stage to recompute, for the other damages
@pytest.mark.parametrize(
    ("damage", "stage"),
    [(b"", "compare"), (b"[1, 2]", "differentiate"), (b"[" * 100_000, "differentiate")],
)
def test_a_damaged_manifest_is_a_stale_stage_that_run_recomputes(synthetic_copy, damage, stage):
    """An empty, non-object or 100,000-deep manifest: status says stale and why, verify
    fails on it (exit 3 in the CLI), and run sets the folder aside untouched, recomputes the
    stage (the stages after it stay up to date, its bytes being the same), and leaves a run
    that verifies to the original digest."""
    from tests.conftest import invoke_cli

    root, digest = synthetic_copy
    manifest = root / "out" / stage / "manifest.json"
    manifest.write_bytes(damage)
    later = ("identify", "validate", "compare") if stage == "differentiate" else ()
    kept = {s: (root / "out" / s / "manifest.json").stat().st_mtime_ns for s in later}
    from debist.engine.runner import Runner
    from debist.workflow.loader import load_workflow

    runner = Runner(load_workflow(root / "wf.toml"))
    state = {s.stage: s for s in runner.status()}[stage]
    assert state.state == "stale" and state.reasons[0].kind == "damaged_manifest"
    assert "unreadable" in state.reasons[0].detail
    assert any(f"{stage}/manifest.json" in p for p in runner.verify())
    code, out = invoke_cli("verify", root / "wf.toml")
    assert code == 3 and "Traceback" not in out
    code, out = invoke_cli("run", root / "wf.toml")
    assert code == 0, out
    (aside,) = (root / "out").glob(f"{stage}.damaged-*")
    assert (aside / "manifest.json").read_bytes() == damage
    assert {s: (root / "out" / s / "manifest.json").stat().st_mtime_ns for s in later} == kept
    assert runner.verify() == [] and runner.digest() == digest


def test_a_string_for_overrides_or_stages_is_refused_not_split_into_characters(synthetic_copy):
    """``overrides="identify.M=8"`` and ``stages="identify"`` were read character by
    character; each is refused in one line that says what to pass instead."""
    root, _ = synthetic_copy
    with pytest.raises(WorkflowError) as err:
        debist.run(root / "wf.toml", overrides="identify.M=8")
    assert "overrides" in str(err.value) and "identify" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        debist.run(root / "wf.toml", stages="identify")
    assert "expected" in str(err.value)
    assert "'identify'" in str(err.value)
