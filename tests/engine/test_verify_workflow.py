"""`debist verify` checks a run against the workflow as it is now, and places a wrong digest."""

import dataclasses
import json
import shutil

import pandas as pd
import pytest

from debist.core import artifacts
from tests.conftest import invoke_cli

STAGES = ["ingest", "differentiate", "identify", "validate", "compare"]


def invoke(*args):
    code, out = invoke_cli(*args)
    return code, " ".join(out.split())


def resign(out, stage):
    """Re-sign a stage's manifest after its outputs were edited, and the chain after it."""
    later = STAGES[STAGES.index(stage) :]
    for name in later:
        sdir = out / name
        m = artifacts.read_manifest(sdir)
        outputs = {rel: artifacts.sha256_file(sdir / rel) for rel in m.outputs}
        ups = {u: artifacts.manifest_digest(out / u) for u in m.upstream}
        inputs = dict(m.inputs)
        for key in inputs:
            up, _, rel = key.partition("/")
            if up in STAGES and rel:
                inputs[key] = artifacts.sha256_file(out / up / rel)
        m = dataclasses.replace(m, outputs=outputs, upstream=ups, inputs=inputs)
        m = dataclasses.replace(m, key=m.expected_key())
        (sdir / artifacts.MANIFEST).write_text(m.to_json())


def test_a_changed_workflow_fails_verify_and_names_the_key(synthetic_copy):
    root, _ = synthetic_copy
    wf = root / "wf.toml"
    wf.write_text(wf.read_text().replace("M = 8", "M = 6"))
    code, out = invoke("verify", wf)
    assert code == 3
    assert "changed" in out and "[identify] M (8 -> 6)" in out


@pytest.mark.slow
def test_stage_folders_copied_from_a_run_with_another_setting_fail_without_a_digest(
    synthetic_copy, tmp_path
):
    root, _ = synthetic_copy
    wf = root / "wf.toml"
    wf.write_text(wf.read_text() + "\n[report]\n")  # the report stage is copied too
    code, out = invoke("run", wf)
    assert code == 0 and "Running stage 'identify'" not in out, out
    other = tmp_path / "other"
    other.mkdir()
    shutil.copy(root / "rig.csv", other / "rig.csv")
    (other / "wf.toml").write_text(wf.read_text().replace("M = 8", "M = 6"))
    code, out = invoke("run", other / "wf.toml")
    assert code == 0, out
    for stage in ("identify", "validate", "compare", "report"):
        shutil.rmtree(root / "out" / stage)
        shutil.copytree(other / "out" / stage, root / "out" / stage)
    code, out = invoke("verify", root / "wf.toml")
    assert code == 3 and "[identify] M (6 -> 8)" in out, out


def test_edited_and_resigned_ingest_tables_fail_without_a_digest(synthetic_copy):
    root, _ = synthetic_copy
    path = root / "out" / "ingest" / "estimation.parquet"
    table = pd.read_parquet(path)
    table["q"] *= 1.01
    table.to_parquet(path)
    resign(root / "out", "ingest")
    code, out = invoke("verify", root / "wf.toml")
    assert code == 3
    assert "estimation.parquet': differs" in out and "sources" in out
    assert "check.parquet" not in out  # the untouched table is not blamed


@pytest.mark.slow
def test_a_digest_names_the_first_stage_that_departs_from_it(synthetic_copy):
    root, digest = synthetic_copy
    path = root / "out" / "validate" / "nrmse.parquet"
    table = pd.read_parquet(path)
    table["nrmse_q"] *= 0.5  # a better-looking result, re-signed with a consistent chain
    table.to_parquet(path)
    resign(root / "out", "validate")
    code, out = invoke("verify", root / "wf.toml")
    assert code == 0, out  # the chain holds: only the digest can tell
    code, out = invoke("verify", root / "wf.toml", "--digest", digest)
    assert code == 3
    assert "'validate' differs" in out and "digest" in out
    assert "report" not in out and "'compare'" not in out


@pytest.mark.slow
def test_a_wrong_digest_on_an_intact_run_is_not_called_a_changed_manifest(synthetic_copy):
    root, digest = synthetic_copy
    wrong = "0" * 64
    code, out = invoke("verify", root / "wf.toml", "--digest", wrong)
    assert code == 3
    assert "intact" in out and digest in out
    code, out = invoke("verify", root / "wf.toml", "--digest", digest)
    assert code == 0, out


def test_verify_works_on_a_run_whose_lock_file_cannot_be_opened(synthetic_copy, monkeypatch):
    import filelock

    root, _ = synthetic_copy

    def refuse(self, *a, **k):
        raise PermissionError(30, "Read-only file system")

    monkeypatch.setattr(filelock.BaseFileLock, "acquire", refuse)
    (root / "out" / ".debist.lock").touch()
    code, out = invoke("verify", root / "wf.toml")
    assert code == 0, out
    assert json.loads((root / "out" / ".debist-output.json").read_text())["workflow_file"]


def test_verify_notes_library_versions_that_differ_from_the_run(synthetic_copy):
    root, _ = synthetic_copy
    path = root / "out" / "identify" / artifacts.MANIFEST
    m = artifacts.read_manifest(root / "out" / "identify")
    m = dataclasses.replace(m, versions={**m.versions, "numpy": "0.0.1"})
    m = dataclasses.replace(m, key=m.expected_key())
    path.write_text(m.to_json())
    resign(root / "out", "validate")  # the chain after identify follows its new manifest
    code, out = invoke("verify", root / "wf.toml")
    assert code == 0, out  # a note, not a failure
    assert "identify: numpy 0.0.1" in out and "installed" in out
