"""numba's cache folder: a read-only installation without a writable home still runs.

numba caches ``cache=True`` kernels in ``__pycache__`` beside the module, else in its user-wide
folder, and fails the import when neither is writable. The tests run a copy of the package in
a subprocess whose every ``__pycache__`` is a regular file (so no folder can be made there,
even as root) and whose HOME and XDG_CACHE_HOME lie under a regular file.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import debist
from debist.core import jitcache

PACKAGE = Path(debist.__file__).parent

#: Compiles and calls one cached kernel (the NARX free run), then reports the cache folder.
_CALL = """
import os, sys
import numpy as np
import debist
from debist.core import jitcache
from debist.model.narx_kernel import narx_free_run
assert debist.__file__.startswith(sys.argv[1]), debist.__file__
# y[k] = 0.5 y[k-1] + x[k-1] with x = 1: tends to 2
y, _ = narx_free_run(np.zeros(1), np.ones((40, 1)), np.array([[0], [1]]),
                     np.array([[1], [1]]), np.array([0.5, 1.0]), 1e6)
assert abs(y[-1] - 2.0) < 1e-9, y[-1]
print(jitcache.note())
print(os.environ.get("NUMBA_CACHE_DIR", ""))
"""


def _unwritable_copy(tmp_path: Path) -> tuple[Path, dict[str, str]]:
    """A copy of the package that cannot hold a __pycache__, and an environment without a
    writable home or cache folder."""
    root = tmp_path / "site"
    shutil.copytree(PACKAGE, root / "debist", ignore=shutil.ignore_patterns("__pycache__"))
    for folder in [root / "debist", *(p for p in (root / "debist").rglob("*") if p.is_dir())]:
        (folder / "__pycache__").write_text("not a folder")
    blocker = tmp_path / "blocker"
    blocker.write_text("a file, so nothing can be created below it")
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("NUMBA_", "DEBIST_", "XDG_")) and k != "PYTHONPATH"
    }
    env.update(
        PYTHONPATH=str(root),
        PYTHONDONTWRITEBYTECODE="1",
        HOME=str(blocker / "home"),
        XDG_CACHE_HOME=str(blocker / "cache"),
    )
    return root, env


def _run(root: Path, env: dict[str, str], tmp_path: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", _CALL, str(root)],
        env=env, cwd=tmp_path, capture_output=True, text=True, timeout=600,
    )  # fmt: skip


@pytest.mark.slow
def test_no_writable_cache_folder_compiles_for_the_process_only(tmp_path):
    root, env = _unwritable_copy(tmp_path)
    env["TMPDIR"] = str(tmp_path / "tmp")
    (tmp_path / "tmp").mkdir()
    done = _run(root, env, tmp_path)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    note, folder = done.stdout.splitlines()
    assert note.startswith("numba cache: none") and "\n" not in note
    assert Path(folder).parent == tmp_path / "tmp" and Path(folder).name.startswith("debist-")
    assert not Path(folder).exists()  # removed at exit
    assert list((tmp_path / "tmp").iterdir()) == []


@pytest.mark.slow
def test_a_writable_user_cache_folder_keeps_the_kernels(tmp_path):
    root, env = _unwritable_copy(tmp_path)
    env["DEBIST_CACHE_DIR"] = str(tmp_path / "user-cache")
    done = _run(root, env, tmp_path)
    assert done.returncode == 0, done.stderr
    note, folder = done.stdout.splitlines()
    assert Path(folder) == tmp_path / "user-cache" / "numba"
    assert str(Path(folder)) in note
    assert any(Path(folder).rglob("narx_kernel.narx_free_run-*.nbi"))  # the index numba wrote


def test_a_writable_pycache_or_a_users_numba_cache_dir_is_left_to_numba(tmp_path, monkeypatch):
    """numba's own order stands when its first folder is writable: nothing is changed."""
    monkeypatch.setattr(jitcache, "_DONE", False)
    monkeypatch.setattr(jitcache, "_NOTE", "")
    monkeypatch.delenv(jitcache.ENV, raising=False)
    module = tmp_path / "pkg" / "kernels.py"
    module.parent.mkdir()
    assert jitcache.prepare_cache(module) == ""
    assert (tmp_path / "pkg" / "__pycache__").is_dir()
    assert jitcache.ENV not in os.environ
    monkeypatch.setattr(jitcache, "_DONE", False)
    monkeypatch.setenv(jitcache.ENV, str(tmp_path / "given"))
    (tmp_path / "pkg" / "__pycache__").rmdir()
    (tmp_path / "pkg" / "__pycache__").write_text("")
    assert jitcache.prepare_cache(module) == ""
    assert os.environ[jitcache.ENV] == str(tmp_path / "given")


def test_an_unwritable_pycache_moves_the_cache_to_the_user_cache_folder(tmp_path, monkeypatch):
    monkeypatch.setattr(jitcache, "_DONE", False)
    monkeypatch.setattr(jitcache, "_NOTE", "")
    monkeypatch.delenv(jitcache.ENV, raising=False)
    monkeypatch.setenv("DEBIST_CACHE_DIR", str(tmp_path / "cache"))
    module = tmp_path / "pkg" / "kernels.py"
    module.parent.mkdir()
    (module.parent / "__pycache__").write_text("")  # no folder can be made there
    note = jitcache.prepare_cache(module)
    assert os.environ[jitcache.ENV] == str(tmp_path / "cache" / "numba")
    assert note == jitcache.note() and str(tmp_path / "cache" / "numba") in note
    assert jitcache.prepare_cache(tmp_path / "elsewhere.py") == note  # decided once


_CLI = """
import sys
import debist.model.narx_kernel  # a command that compiles kernels imports it so
from debist.cli import main
sys.argv = ["debist", *sys.argv[1:]]
main()
"""


@pytest.mark.slow
@pytest.mark.parametrize("verbose", [True, False])
def test_the_command_line_says_where_the_kernels_went_in_one_line_under_v(tmp_path, verbose):
    _, env = _unwritable_copy(tmp_path)
    (tmp_path / "log.csv").write_text("time_s,x [mm]\n0,1\n0.1,2\n0.2,3\n")
    args = ["-v"] * verbose + ["init", "--list", "log.csv"]
    done = subprocess.run(
        [sys.executable, "-c", _CLI, *args],
        env=env, cwd=tmp_path, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    lines = [line for line in done.stdout.splitlines() if "numba cache" in line]
    assert lines == (["numba cache: none (no writable cache folder); the kernels are "
                      "compiled for this process only"] if verbose else [])  # fmt: skip
