"""The installed package: one top-level name, ``debist``, whose source folder is ``pipeline/``."""

from __future__ import annotations

import importlib.metadata
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import debist
from debist.engine.fingerprint import code_fingerprint

ROOT = Path(__file__).resolve().parents[2]


def _python(code: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=120
    )


#: The packages of the example workflows and their data (package data only, no modules).
EXAMPLES = {"debist.examples.workflows": "workflows", "debist.examples.data": "data"}


def test_every_source_folder_is_a_listed_package():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert config["package-dir"] == {"debist": "pipeline", **EXAMPLES}
    folders = sorted(
        ".".join(("debist", *p.parent.relative_to(ROOT / "pipeline").parts))
        for p in (ROOT / "pipeline").rglob("__init__.py")
    )
    assert sorted(config["packages"]) == sorted([*folders, *EXAMPLES])
    assert not (ROOT / "pipeline" / "examples").exists()  # the wheel's name for them only


def test_the_export_templates_are_package_data():
    """The wheel carries pipeline/export/templates/*.j2, and the package finds every one."""
    import importlib.resources

    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert data["package-data"]["debist.export"] == ["templates/*.j2"]
    assert set(data["package-data"]) == {"debist.export", *EXAMPLES}
    on_disk = sorted(p.name for p in (ROOT / "pipeline/export/templates").glob("*.j2"))
    found = importlib.resources.files("debist.export") / "templates"
    assert on_disk and sorted(p.name for p in found.iterdir()) == on_disk


def test_only_debist_is_importable_outside_the_checkout(tmp_path):
    found = _python("import debist; print(debist.__name__)", tmp_path)
    assert found.returncode == 0, found.stderr
    assert found.stdout.strip() == "debist"
    for name in ("pipeline", "cli"):
        missing = _python(f"import {name}", tmp_path)
        assert missing.returncode != 0
        assert f"No module named '{name}'" in missing.stderr
    top_level = importlib.metadata.distribution("debist").read_text("top_level.txt")
    if top_level is not None:  # written by setuptools for both install modes
        assert top_level.split() == ["debist"]


def test_the_checkout_script_runs_without_an_installed_debist(tmp_path):
    # sys.modules["debist"] = None makes importlib.util.find_spec("debist") answer None, as in
    # a bare checkout; cli.py must then load ./pipeline under the name debist itself
    code = (
        "import sys, runpy; sys.modules['debist'] = None; sys.argv = ['cli.py', '--version'];"
        f"runpy.run_path({str(ROOT / 'cli.py')!r}, run_name='__main__')"
    )
    run = _python(code, tmp_path)
    assert run.returncode == 0, run.stderr
    assert debist.__version__ in run.stdout


def test_python_dash_m_debist_is_the_command_line(tmp_path):
    run = subprocess.run(
        [sys.executable, "-m", "debist", "--version"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0, run.stderr
    assert debist.__version__ in run.stdout


@pytest.mark.parametrize("folder", ["pipeline", "debist"])
def test_fingerprints_do_not_depend_on_the_source_folders_name(tmp_path, folder):
    copy = tmp_path / folder
    shutil.copytree(ROOT / "pipeline", copy, ignore=shutil.ignore_patterns("__pycache__"))
    module = "debist.stages.identify"
    assert code_fingerprint(module, copy) == code_fingerprint(module, ROOT / "pipeline")


def test_the_modules_import_each_other_without_cycles():
    """No import cycle among debist's modules, imports inside functions included."""
    from debist.engine import fingerprint

    root = fingerprint._ROOT
    names = []
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        names.append(".".join(["debist", *(parts[:-1] if parts[-1] == "__init__" else parts)]))
    # importing a.b.c runs a and a.b first: that edge from a module to its own packages is not
    # a cycle (and the packages' __init__ files import none of their modules)
    graph = {
        m: {n for n in fingerprint._direct_imports(m, root) if n != m and not m.startswith(n + ".")}
        for m in names
    }
    done: set[str] = set()

    def visit(node: str, path: list[str]) -> None:
        if node in path:
            raise AssertionError("import cycle: " + " -> ".join([*path[path.index(node) :], node]))
        if node in done:
            return
        for nxt in sorted(graph.get(node, ())):
            visit(nxt, [*path, node])
        done.add(node)

    for name in names:
        visit(name, [])
    assert len(names) > 100 and sum(map(len, graph.values())) > 500  # the graph was read


def test_package_inits_import_none_of_their_modules():
    """A package's __init__ runs no debist import (typing-only imports aside)."""
    import ast

    from debist.engine import fingerprint

    for init in sorted((ROOT / "pipeline").rglob("__init__.py")):
        found = fingerprint._imported_names(ast.parse(init.read_text()), "debist")
        assert not [n for n in found if n.startswith("debist")], f"{init} imports {found}"
