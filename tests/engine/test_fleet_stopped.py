"""A fleet stopped part way: batch refuses it, the next ``debist fleet`` replaces it."""

import json
import os
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import psutil
import pytest
import tomli_w

from debist.core.errors import WorkflowError
from debist.engine.batch import expand_workflows
from debist.engine.fleetmark import (
    FLEET_MARKER,
    clear_unfinished,
    finish_fleet,
    note_candidate,
    start_fleet,
    unfinished_fleet,
)
from debist.engine.outdir import MARKER
from tests.conftest import invoke_cli

ROOT = Path(__file__).resolve().parents[2]
TEMPLATE = ROOT / "workflows" / "paper-experiment.toml"


def candidate(folder: Path, name: str, text: str, *, run: bool = True) -> Path:
    """What a check leaves: the candidate's workflow file and its own output folder."""
    path = folder / name
    path.write_text(text, encoding="utf-8")
    if run:
        out = folder / "runs" / path.stem
        out.mkdir(parents=True)
        owner = {"debist": "output folder", "workflow": path.stem,
                 "workflow_file": f"../../{name}"}  # fmt: skip
        (out / MARKER).write_text(json.dumps(owner))
        (out / "rig").mkdir()
    return path


def test_a_killed_fleet_is_refused_by_batch_and_cleared_to_the_users_files(tmp_path):
    folder = tmp_path / "fleet"
    start_fleet(folder, TEMPLATE, 3, 5)
    texts = {f"p-00{k}.toml": f'[workflow]\nname = "p-00{k}"\noutput_dir = "runs/p-00{k}"\n'
             for k in range(3)}  # fmt: skip
    for name, text in texts.items():
        note_candidate(folder, name, text)
    candidate(folder, "p-000.toml", texts["p-000.toml"])  # checked, kept
    candidate(folder, "p-001.toml", texts["p-001.toml"], run=False)  # being checked
    (folder / "runs" / "p-002").mkdir()  # the file went, its output folder stayed:
    owner = {"debist": "output folder", "workflow": "p-002", "workflow_file": "../../p-002.toml"}
    (folder / "runs" / "p-002" / MARKER).write_text(json.dumps(owner))
    mine = folder / "runs" / "mine"  # not the fleet's
    mine.mkdir()

    expected = (
        f"'{folder}' holds a fleet whose debist fleet was stopped before it ended (its workflows "
        f"are unscreened): replace it with: debist fleet {TEMPLATE} --size 3 --seed 5 --dir "
        f"{folder}"
    )
    for entry in (folder, folder / "p-000.toml", folder / "*.toml"):
        with pytest.raises(WorkflowError) as err:
            expand_workflows([entry])
        assert str(err.value) == expected
    code, out = invoke_cli("batch", folder)
    assert code == 2 and out.strip() == f"error: {expected}", out
    assert not (folder / "index.html").exists() and (folder / "p-000.toml").is_file()

    # the next fleet removes exactly what the stopped one wrote, and its record
    removed = clear_unfinished(folder)
    assert sorted(p.relative_to(folder).as_posix() for p in removed) == [
        "p-000.toml", "p-001.toml", "runs/p-000", "runs/p-002"
    ]  # fmt: skip
    assert sorted(p.name for p in folder.iterdir()) == ["runs"]
    assert [p.name for p in (folder / "runs").iterdir()] == [mine.name]
    assert unfinished_fleet(folder) is None and clear_unfinished(folder) == []


def test_a_candidate_file_changed_since_is_kept_and_a_finished_fleet_is_not_touched(tmp_path):
    folder = tmp_path / "fleet"
    start_fleet(folder, TEMPLATE, 1, 0)
    note_candidate(folder, "p-000.toml", "[workflow]\n")
    edited = candidate(folder, "p-000.toml", "[workflow]\n# my notes\n", run=False)
    assert clear_unfinished(folder) == [] and edited.read_text().endswith("# my notes\n")
    start_fleet(folder, TEMPLATE, 1, 0)
    finish_fleet(folder, ["p-000.toml"])
    assert unfinished_fleet(folder) is None
    assert expand_workflows([folder]) == [edited.resolve()]
    assert clear_unfinished(folder) == [] and (folder / FLEET_MARKER).is_file()


def _short_template(tmp_path: Path) -> Path:
    raw = tomllib.loads(TEMPLATE.read_text())
    for exp in raw["rig"]["experiments"].values():
        exp["duration"] = 8.0
    template = tmp_path / "short.toml"
    template.write_text(tomli_w.dumps(raw))
    return template


def _stop_at_first_candidate(cmd: list[str], sig: int, cwd: Path) -> tuple[int, str, list[int]]:
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while not list((cwd / "fleet").glob("*.toml")) and time.monotonic() < deadline:
            time.sleep(0.02)
        children = [p.pid for p in psutil.Process(proc.pid).children(recursive=True)]
        os.kill(proc.pid, sig)
        _out, errs = proc.communicate(timeout=120)
    finally:
        proc.kill()
    return proc.returncode, errs, children


@pytest.mark.slow
def test_a_fleet_killed_while_checking_is_replaced_by_the_same_command(tmp_path):
    template = _short_template(tmp_path)
    cmd = [sys.executable, "-m", "debist", "fleet", str(template), "--size", "2", "--seed", "1",
           "--dir", "fleet"]  # fmt: skip
    code, _errs, children = _stop_at_first_candidate(cmd, signal.SIGKILL, tmp_path)
    assert code == -signal.SIGKILL
    # its checking workers die with it: nothing writes into the folder after the kill
    _gone, alive = psutil.wait_procs([p for p in map(_process, children) if p], timeout=30)
    assert not alive
    assert unfinished_fleet(tmp_path / "fleet") is not None
    batch = subprocess.run([sys.executable, "-m", "debist", "batch", "fleet"], cwd=tmp_path,
                           capture_output=True, text=True, timeout=120)  # fmt: skip
    assert batch.returncode == 2 and batch.stderr.count("\n") == 1, batch.stderr
    assert "--size 2 --seed 1 --dir fleet" in batch.stderr and not batch.stdout
    rerun = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    assert "unscreened files and folders of the fleet stopped earlier" in rerun.stdout
    members = sorted(p.name for p in (tmp_path / "fleet").glob("*.toml"))
    assert len(members) == 2 and unfinished_fleet(tmp_path / "fleet") is None
    assert sorted(p.name for p in (tmp_path / "fleet" / "runs").iterdir()) == [
        m.removesuffix(".toml") for m in members
    ]  # fmt: skip
    assert [p.name for p in expand_workflows([tmp_path / "fleet"])] == members


@pytest.mark.slow
def test_a_fleet_stopped_by_sigterm_leaves_nothing(tmp_path):
    template = _short_template(tmp_path)
    (tmp_path / "fleet").mkdir()
    (tmp_path / "fleet" / "notes.txt").write_text("mine")
    cmd = [sys.executable, "-m", "debist", "fleet", str(template), "--size", "2", "--dir", "fleet"]
    code, errs, _children = _stop_at_first_candidate(cmd, signal.SIGTERM, tmp_path)
    assert code == 143
    assert errs.strip() == (
        "interrupted by SIGTERM: stopped; nothing of the fleet is kept; the same command "
        "writes it anew"
    )
    assert sorted(p.name for p in (tmp_path / "fleet").iterdir()) == ["notes.txt"]
    assert (tmp_path / "fleet" / "notes.txt").read_text() == "mine"


def _process(pid: int) -> psutil.Process | None:
    try:
        return psutil.Process(pid)
    except psutil.NoSuchProcess:
        return None
