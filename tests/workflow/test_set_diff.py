"""`run --set KEY=VALUE` (an experiment in its own folder beside the run) and `diff`."""

import hashlib
import json
import shlex
import shutil

import pytest

import debist
from debist.core import artifacts
from debist.core.errors import OutputDirError, WorkflowError
from debist.engine import outdir
from debist.workflow.loader import load_workflow, parse_overrides
from debist.workflow.overrides import override_args, override_digest
from tests.conftest import invoke_cli


def invoke(*args):
    code, out = invoke_cli(*args)
    return code, " ".join(out.split())


@pytest.fixture
def base(synthetic_run):
    return synthetic_run[0]


def test_overrides_parse_as_toml_with_a_string_fallback_and_are_checked(tmp_path, base):
    assert parse_overrides(["identify.M=6", 'datasets."a.b".role="validation"', "x.y=[1, 2]"]) == {
        "identify": {"M": 6},
        "datasets": {"a.b": {"role": "validation"}},
        "x": {"y": [1, 2]},
    }
    assert parse_overrides(["differentiate.method=spectral"]) == {
        "differentiate": {"method": "spectral"}
    }
    with pytest.raises(WorkflowError) as err:
        parse_overrides(["identify.M"])
    assert "KEY=VALUE" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        load_workflow(base / "wf.toml", overrides=["identify.M=six"])
    assert err.value.key == "identify.M"
    assert "'six'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        load_workflow(base / "wf.toml", overrides={"identify.N": 3})
    assert err.value.key == "identify.N"
    assert "unknown" in str(err.value) and "key" in str(err.value)
    wf = load_workflow(base / "wf.toml", overrides={"identify.M": 6, "identify.sigma_n": 1.0})
    assert wf.sections["identify"]["M"] == 6 and wf.sections["identify"]["sigma_n"] == 1.0


def file_hashes(folder):
    """sha256 of every file under ``folder`` (hidden ones too), by relative path."""
    return {
        p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def test_overrides_name_their_own_folder_beside_the_output_folder(base, tmp_path):
    own = load_workflow(base / "wf.toml")
    assert own.output_dir == base / "out" and own.overrides == {}
    digest = override_digest({"identify": {"M": 6}})
    assert len(digest) == 8 and int(digest, 16) >= 0
    # the same settings, however written, find the same folder
    for given in (["identify.M=6"], ["identify.M = 6"], {"identify.M": 6}, ["identify={M=6}"]):
        wf = load_workflow(base / "wf.toml", overrides=given)
        assert wf.output_dir == base / f"out.set-{digest}", given
        assert wf.overrides == {"identify": {"M": 6}}
    other = load_workflow(base / "wf.toml", overrides={"identify.M": 7}).output_dir
    assert (
        other.parent == base
        and other.name.startswith("out.set-")
        and other.name != (f"out.set-{digest}")
    )
    # an --out the user names is the run's folder itself, overrides or not; the stages the
    # settings leave alone may still be copied from the workflow's own folder
    moved = load_workflow(base / "wf.toml", tmp_path / "b", overrides=["identify.M=6"])
    assert moved.output_dir == tmp_path / "b" and moved.own_output_dir == base / "out"
    assert load_workflow(base / "wf.toml", tmp_path / "b").own_output_dir is None
    same = load_workflow(base / "wf.toml", base / "out", overrides=["identify.M=6"])
    assert same.output_dir == base / "out" and same.own_output_dir is None
    # written back as --set options, they read as the same tables
    tree = {"identify": {"M": 6, "refine": {"prior": [0, 30]}}, "datasets": {"a.b": {"role": "x"}}}
    args = override_args(tree)
    assert args == ['datasets."a.b".role="x"', "identify.M=6", "identify.refine.prior=[0, 30]"]
    assert parse_overrides(args) == tree


def test_a_folder_marked_for_other_overrides_is_refused(base, tmp_path):
    places = {"workflow_dir": base, "workflow_file": base / "wf.toml", "stages": ()}
    mine = {"identify": {"M": 6}}
    outdir.claim_output_dir(tmp_path / "x", workflow="synthetic", overrides=mine, **places)
    marker = json.loads((tmp_path / "x" / outdir.MARKER).read_text())
    assert marker["workflow"] == "synthetic" and marker["overrides"] == mine
    outdir.check_output_dir(tmp_path / "x", workflow="synthetic", overrides=mine, **places)
    with pytest.raises(OutputDirError) as err:  # fmt: skip
        outdir.check_output_dir(tmp_path / "x", workflow="synthetic", **places)
    assert "--set" in str(err.value) and "identify.M=6" in str(err.value)
    assert "holds" in str(err.value) and "file" in str(err.value)
    with pytest.raises(OutputDirError) as err:
        outdir.check_output_dir(
            tmp_path / "x", workflow="synthetic", overrides={"identify": {"M": 7}}, **places
        )
    assert "--set" in str(err.value) and "identify.M=7" in str(err.value)
    # the workflow's own folder keeps its marker without overrides, byte for byte
    outdir.claim_output_dir(tmp_path / "own", workflow="synthetic", **places)
    assert "overrides" not in json.loads((tmp_path / "own" / outdir.MARKER).read_text())
    with pytest.raises(OutputDirError) as err:
        outdir.check_output_dir(tmp_path / "own", workflow="synthetic", overrides=mine, **places)
    assert "workflow" in str(err.value)


def fake_run(folder, configs):
    """An output folder with one manifest per stage, recording ``configs[stage]``."""
    for stage, config in configs.items():
        artifacts.write_stage(
            folder / stage, stage=stage, key="k", code="c", versions={}, config=config,
            inputs={}, upstream={}, outputs={}, summary={},
        )  # fmt: skip
    return folder


def test_diff_shows_only_settings_that_differ_once_defaults_are_filled_in(tmp_path):
    a = fake_run(tmp_path / "a", {
        "differentiate": {"method": "tvregdiff", "alpha": 1},
        "validate": {"substeps": 2},
        "compare": {"sindy": {"degree": 3, "narx": {}}, "validate": {"substeps": 2}},
    })  # fmt: skip
    b = fake_run(tmp_path / "b", {
        "differentiate": {"alpha": 1.0},  # method left to its default, 1 written as 1.0
        "validate": {},
        "compare": {"sindy": {"degree": 3}, "validate": {}},  # [compare.narx] absent
    })  # fmt: skip
    found = debist.diff(a, b)
    assert found["config"] == [] and found["runs"] == [str(a), str(b)]
    c = fake_run(tmp_path / "c", {
        "differentiate": {"method": "tvregdiff", "alpha": 1},
        "validate": {"substeps": 4, "engine": "compiled"},
        "compare": {"sindy": {"degree": 3, "narx": {"enabled": False}}, "validate": {}},
    })  # fmt: skip
    rows = debist.diff(b, c)["config"]
    assert rows == [
        {"stage": "validate", "key": "substeps", "a": 2, "b": 4},
        {"stage": "compare", "key": "sindy.narx.enabled", "a": True, "b": False},
    ]
    code, out = invoke("diff", b, c)
    assert code == 0 and "substeps" in out and "None" not in out and "engine" not in out


def test_diff_of_a_workflow_needs_its_overrides(base):
    with pytest.raises(WorkflowError) as err:
        debist.diff(base / "wf.toml")
    assert "give" in str(err.value) and "file" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        debist.diff(base / "out", base / "out", overrides={"identify.M": 6})
    assert "workflow" in str(err.value) and "two" in str(err.value)
    code, out = invoke("diff", base / "wf.toml")
    assert code == 2 and "--set KEY=VALUE" in out


def test_diff_of_a_missing_folder_names_the_set_run_beside_it(tmp_path, monkeypatch):
    configs = {"identify": {"M": 6}}
    fake_run(tmp_path / "runs" / "rig", configs)
    fake_run(tmp_path / "runs" / "rig-tuned.set-1a2b3c4d", configs)
    (tmp_path / "runs" / "rig-tuned.set-0000000a").mkdir()  # no manifests: not a run
    fake_run(tmp_path / "runs" / "rig-tuned.set-XYZ", configs)  # not 8 hex digits
    fake_run(tmp_path / "runs" / "rig-tunedx.set-2a2b3c4d", configs)  # another name
    with pytest.raises(WorkflowError) as err:
        debist.diff(tmp_path / "runs" / "rig", tmp_path / "runs" / "rig-tuned")
    beside = tmp_path / "runs" / "rig-tuned.set-1a2b3c4d"
    assert f"did you mean '{beside}' (a run with --set overrides)?" in str(err.value)
    assert str(err.value).startswith(f"'{tmp_path / 'runs' / 'rig-tuned'}' is not an output")
    # the name spelt as the user spelt it, relative to the current folder
    monkeypatch.chdir(tmp_path)
    code, out = invoke_cli("diff", "runs/rig", "runs/rig-tuned")
    assert code == 2 and "did you mean 'runs/rig-tuned.set-1a2b3c4d'" in out, out
    # without such a run beside it: no suggestion
    with pytest.raises(WorkflowError) as err:
        debist.diff(tmp_path / "runs" / "rig", tmp_path / "runs" / "other")
    assert "did you mean" not in str(err.value) and "no manifests" in str(err.value)


def test_verify_of_a_missing_out_names_the_set_run_an_older_debist_made_beside_it(base, tmp_path):
    settings = {"identify.M": 6}
    missing = debist.verify(base / "wf.toml", overrides=settings, output_dir=tmp_path / "x")
    assert not missing.ok and "does not exist" in missing.problems[0]
    assert "--set" not in missing.problems[0]  # nothing beside it
    beside = tmp_path / f"x.set-{override_digest({'identify': {'M': 6}})}"
    fake_run(beside, {"identify": {"M": 6}})
    found = debist.verify(base / "wf.toml", overrides=settings, output_dir=tmp_path / "x")
    assert f"the run with these --set settings beside it is '{beside}'" in found.problems[0]
    other = debist.verify(base / "wf.toml", overrides={"identify.M": 7}, output_dir=tmp_path / "x")
    assert str(beside) not in other.problems[0]  # another setting's folder is not named


def test_status_of_a_missing_out_names_the_set_run_beside_it(base, tmp_path):
    x = tmp_path / "x"
    settings = {"identify.M": 6}
    code, out = invoke("status", base / "wf.toml", "--out", x, "--set", "identify.M=6")
    assert code == 0 and f"output folder '{x}' does not exist" in out and "--set" not in out
    assert debist.missing_output(base / "wf.toml", output_dir=base / "out") is None  # it exists
    beside = fake_run(tmp_path / f"x.set-{override_digest({'identify': {'M': 6}})}",
                      {"identify": {"M": 6}})  # fmt: skip
    # with --set: the folder of exactly these settings, as verify names it
    said = debist.missing_output(base / "wf.toml", overrides=settings, output_dir=x)
    code, out = invoke("status", base / "wf.toml", "--out", x, "--set", "identify.M=6")
    assert code == 0 and f"the run with these --set settings beside it is '{beside}'" in out
    assert said == debist.verify(base / "wf.toml", overrides=settings, output_dir=x).problems[0]
    code, out = invoke("status", base / "wf.toml", "--out", x, "--set", "identify.M=7")
    assert code == 0 and str(beside) not in out and "does not exist" in out
    # without --set: the newest .set- run beside it, as diff names it
    code, out = invoke("status", base / "wf.toml", "--out", x)
    assert code == 0 and f"did you mean '{beside}' (a run with --set overrides)?" in out, out
    code, out = invoke_cli("status", base / "wf.toml", "--out", x, "--json")
    assert code == 0 and json.loads(out)["identify"]["state"] == "missing"  # JSON only


def test_run_says_where_no_report_is_and_how_to_get_one(base, tmp_path):
    shutil.copytree(base, tmp_path / "p")
    code, out = invoke("run", tmp_path / "p" / "wf.toml")
    assert code == 0, out
    assert "written" in out and "[report]" in out
    assert "add" in out and out.count("[report]") >= 2


@pytest.mark.slow
def test_run_set_writes_beside_the_run_and_leaves_it_byte_identical(base, tmp_path):
    shutil.copytree(base, tmp_path / "my project")
    root = tmp_path / "my project"  # a space: the printed command must quote it
    wf = root / "wf.toml"
    before = file_hashes(root / "out")
    sets = ["identify.M=6", "validate.substeps = 3"]
    code, text = invoke_cli("run", wf, "--set", sets[0], "-S", sets[1])
    assert code == 0, text
    folder = root / f"out.set-{override_digest(parse_overrides(sets))}"
    assert folder.is_dir() and "writes" in text and str(folder) in " ".join(text.split())
    assert file_hashes(root / "out") == before  # the original run, byte for byte
    assert artifacts.read_manifest(folder / "identify").config["M"] == 6
    marker = json.loads((folder / outdir.MARKER).read_text())
    assert marker["overrides"] == {"identify": {"M": 6}, "validate": {"substeps": 3}}

    # the printed verify command, pasted as it is
    line = next(x for x in text.splitlines() if "check it later with: " in x)
    words = shlex.split(line.split("check it later with: ", 1)[1])
    assert words[:3] == ["debist", "verify", str(wf)] and words.count("--set") == 2
    code, out = invoke_cli(*words[1:])
    assert code == 0, out

    # status, verify, export, open_run and diff with the same --set find that folder
    code, out = invoke("status", wf, "--set", "identify.M=6", "-S", "validate.substeps=3")
    assert code == 0 and out.count("up to date") == 5, out
    assert invoke("verify", wf)[0] == 0  # the workflow's own run is still intact
    code, out = invoke("verify", wf, "-S", "identify.M=6")
    assert code != 0 and "exist" in out  # another experiment: not run yet
    code, out = invoke("export", wf, "--format", "python", "-S", sets[0], "-S", sets[1])
    assert code == 0 and (folder / "export" / "debist_model.py").is_file(), out
    settings = {"identify.M": 6, "validate.substeps": 3}
    result = debist.open_run(wf, overrides=settings)
    assert result.output_dir == folder and result.digest in text
    assert debist.verify(wf, result.digest, overrides=settings).ok
    code, out = invoke("diff", wf, "--set", sets[0], "--set", sets[1], "--json")
    assert code == 0, out
    found = json.loads(out)
    assert found["runs"] == [str(root / "out"), str(folder)]
    assert {"stage": "identify", "key": "M", "a": 8, "b": 6} in found["config"]
    assert {"stage": "validate", "key": "substeps", "a": 2, "b": 3} in found["config"]
    assert all(r["stage"] not in ("ingest", "differentiate") for r in found["config"])
    rbf = [r for r in found["nrmse"] if r["model"] == "rbf" and r["metric"] == "nrmse_q [%]"]
    assert rbf and all(r["a"] != r["b"] for r in rbf)
    table = artifacts.read_parquet(folder / "compare" / "nrmse.parquet")
    row = table[(table.model == "rbf") & (table.dataset == "check")].iloc[0]
    (check,) = [r for r in rbf if r["dataset"] == "check"]
    assert check["b"] == pytest.approx(100 * row.nrmse_q)
    # the same comparison by the two folders
    assert json.loads(invoke_cli("diff", root / "out", folder, "--json")[1]) == found
    code, out = invoke("diff", root / "out", folder)
    assert code == 0 and "settings" in out and "NRMSE" in out and "differs" in out
    code, out = invoke("diff", root / "out", root / "out")
    assert code == 0 and "same" in out and "NRMSE" in out
    code, out = invoke("diff", root / "out", tmp_path / "nowhere")
    assert code == 2 and "output" in out and "folder" in out
    assert file_hashes(root / "out") == before


@pytest.mark.slow
def test_run_set_with_out_writes_exactly_there_and_the_other_commands_find_it(base, tmp_path):
    shutil.copytree(base, tmp_path / "p")
    root, wf = tmp_path / "p", tmp_path / "p" / "wf.toml"
    before = file_hashes(root / "out")
    code, text = invoke("run", wf, "--out", root / "m6", "-S", "identify.M=6", "-v")
    assert code == 0, text
    assert "the folder --out names" in text and "own run: copied" in text
    assert artifacts.read_manifest(root / "m6" / "identify").config["M"] == 6
    assert not list(root.glob("*.set-*")) and file_hashes(root / "out") == before
    code, out = invoke("status", wf, "--out", root / "m6", "-S", "identify.M=6")
    assert code == 0 and "up to date" in out and "stale" not in out and "missing" not in out
    code, out = invoke("status", wf, "--out", root / "m6")  # without the --set: M differs
    assert code == 0 and "stale" in out and "M" in out, out
    found = json.loads(invoke_cli("diff", root / "out", root / "m6", "--json")[1])
    assert {"stage": "identify", "key": "M", "a": 8, "b": 6} in found["config"]
    same = invoke_cli("diff", wf, "-S", "identify.M=6", "--out", root / "m6", "--json")[1]
    assert json.loads(same) == found
    assert invoke("verify", wf, "--out", root / "m6", "-S", "identify.M=6")[0] == 0
    # the folder holds the run of identify.M=6: another setting is refused there
    code, out = invoke("run", wf, "--out", root / "m6", "-S", "identify.M=7")
    assert code == 2 and "identify.M=6" in out and "identify.M=7" in out, out
    assert artifacts.read_manifest(root / "m6" / "identify").config["M"] == 6


@pytest.mark.slow
def test_run_set_copies_the_stages_the_settings_leave_as_they_are(base, tmp_path):
    """`--set validate.substeps=3` leaves ingest, differentiate and identify the computation
    the workflow's own run made (the same key): their folders are copied byte for byte and
    the experiment verifies; a stage whose artifact was changed in the own run is computed
    again, and the own run is left as it is."""
    shutil.copytree(base, tmp_path / "p")
    root, wf = tmp_path / "p", tmp_path / "p" / "wf.toml"
    code, text = invoke_cli("run", wf, "-S", "validate.substeps=3", "-v")
    assert code == 0, text
    text = " ".join(text.split())
    folder = root / f"out.set-{override_digest({'validate': {'substeps': 3}})}"
    for stage in ("ingest", "differentiate", "identify"):
        assert f"Stage '{stage}' is up to date" in text and "own run: copied" in text
        assert file_hashes(folder / stage) == file_hashes(root / "out" / stage), stage
    assert "Running stage 'validate'" in text
    assert invoke("verify", wf, "-S", "validate.substeps=3")[0] == 0
    # the own run's identify changed after it ran: not copied, computed again
    summary = root / "out" / "identify" / "summary.json"
    summary.write_text(summary.read_text() + " ", encoding="utf-8")
    changed = file_hashes(root / "out")
    code, text = invoke_cli("run", wf, "-S", "validate.substeps=4", "-v")
    assert code == 0, text
    text = " ".join(text.split())
    assert "Stage 'differentiate' is up to date" in text and "Running stage 'identify'" in text
    assert file_hashes(root / "out") == changed
