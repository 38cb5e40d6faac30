"""OS errors (full or read-only disk, permissions, links) are one line, exit 2, and harmless."""

import errno
import os
import shutil
from pathlib import Path

import pytest

from debist.core import artifacts
from debist.engine import outdir
from tests.conftest import invoke_cli

invoke = invoke_cli


def error_lines(out):
    return [line for line in out.splitlines() if line.startswith("error:")]


@pytest.fixture
def project(synthetic_copy):
    return synthetic_copy[0]


def manifests(out):
    return {s: artifacts.manifest_digest(out / s) for s in ("ingest", "differentiate", "identify")}


@pytest.mark.parametrize(
    ("code", "text"),
    [(errno.ENOSPC, "No space left on device"), (errno.EACCES, "Permission denied")],
)
def test_a_failing_write_is_one_line_and_keeps_the_earlier_stages(project, monkeypatch, code, text):
    out = project / "out"
    before = manifests(out)
    real = artifacts.write_output

    def failing(value, path):
        if "validate" in str(path):
            raise OSError(code, text, str(path))
        return real(value, path)

    monkeypatch.setattr(artifacts, "write_output", failing)
    rc, printed = invoke("run", project / "wf.toml", "--force")
    assert rc == 2, printed
    assert "Traceback" not in printed
    (line,) = error_lines(printed)
    assert f"{text} [{errno.errorcode[code]}]" in line and "validate" in line
    assert manifests(out) == before
    assert not outdir.leftovers(out)  # the unfinished stage's temporary folder is gone
    monkeypatch.setattr(artifacts, "write_output", real)
    rc, printed = invoke("run", project / "wf.toml")
    assert rc == 0, printed


def test_a_read_only_output_location_is_one_line(project, monkeypatch, tmp_path):
    real = Path.mkdir

    def read_only(self, *a, **k):
        if "ro-media" in str(self):
            raise OSError(errno.EROFS, "Read-only file system", str(self))
        return real(self, *a, **k)

    monkeypatch.setattr(Path, "mkdir", read_only)
    rc, printed = invoke("run", project / "wf.toml", "--out", tmp_path / "ro-media" / "run")
    assert rc == 2 and "Traceback" not in printed
    (line,) = error_lines(printed)
    assert "Read-only" in line and "[EROFS]" in line and "ro-media" in line


def test_a_stage_folder_replaced_by_a_link_is_refused_and_left_alone(project, tmp_path):
    out = project / "out"
    elsewhere = tmp_path / "elsewhere"
    shutil.copytree(out / "validate", elsewhere)
    shutil.rmtree(out / "validate")
    os.symlink(elsewhere, out / "validate")
    before = sorted(p.name for p in elsewhere.iterdir())
    rc, printed = invoke("run", project / "wf.toml", "--force")
    assert rc == 2 and "Traceback" not in printed
    (line,) = error_lines(printed)
    assert "symbolic" in line and "link" in line and "validate" in line
    assert sorted(p.name for p in elsewhere.iterdir()) == before  # the target is untouched
    (out / "validate").unlink()
    rc, printed = invoke("run", project / "wf.toml")
    assert rc == 0, printed
    assert (out / "validate").is_dir() and not (out / "validate").is_symlink()


def test_swap_leftovers_that_are_links_never_block_later_runs(project, tmp_path):
    out = project / "out"
    target = tmp_path / "target"
    target.mkdir()
    (target / "keep.txt").write_text("mine")
    os.symlink(target, out / ".compare.old-0123456789ab")  # a leftover link (a crashed swap)
    os.symlink(tmp_path / "gone", out / ".compare.tmp-ba9876543210")  # dangling
    rc, printed = invoke("run", project / "wf.toml")
    assert rc == 0, printed
    assert not os.path.lexists(out / ".compare.old-0123456789ab")
    assert not os.path.lexists(out / ".compare.tmp-ba9876543210")
    assert (target / "keep.txt").read_text() == "mine"
    rc, printed = invoke("run", project / "wf.toml")
    assert rc == 0, printed


def test_a_device_as_a_source_is_named_as_such(project):
    wf = project / "wf.toml"
    wf.write_text(wf.read_text().replace('source = "rig.csv"', 'source = "/dev/zero"', 1))
    rc, printed = invoke("run", wf)
    assert rc == 2
    assert "'/dev/zero'" in printed and "regular" in printed and "exist" not in printed


def test_a_nul_byte_in_the_output_folder_is_refused(project):
    rc, printed = invoke("run", project / "wf.toml", "--out", "a\x00b")
    assert rc == 2 and "null" in printed.lower() and "Traceback" not in printed
