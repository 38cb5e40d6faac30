"""The README and the documentation site: short README, complete references, a nav that builds."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import click
import pytest
import typer
import yaml

from debist.cli import app
from debist.workflow.jsonschema import workflow_schema

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
MAIN = (
    'python3 -m venv .venv && . .venv/bin/activate && pip install ".[narx]" && '
    "debist run workflows/silverbox.toml"
)
TESTS = 'python3 -m venv .venv && . .venv/bin/activate && pip install ".[test]" && pytest'


def commands() -> list[str]:
    """The subcommands registered on the Typer app, as the shell spells them."""
    group = typer.main.get_command(app)
    return group.list_commands(click.Context(group))


def config() -> dict:
    return yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))


def nav_pages(nav) -> list[str]:
    """Every page of a mkdocs nav (nested lists of {title: page or list})."""
    out = []
    for item in nav:
        for value in item.values() if isinstance(item, dict) else [item]:
            out += nav_pages(value) if isinstance(value, list) else [value]
    return out


def hook(name: str):
    spec = importlib.util.spec_from_file_location(name, DOCS / "hooks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ------------------------------------------------------------------ README


def test_the_readme_is_short_and_starts_with_the_two_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    shown = re.sub(r"<!--.*?-->", "", text, flags=re.S)  # the docs-test marks are not shown
    assert len(shown.split()) <= 800  # as `wc -w README.md` counts what a reader sees
    head = "\n".join(text.splitlines()[:40])
    assert MAIN in head and TESTS in head
    assert "debist init" in text and "debist run" in text


def test_the_readme_test_command_is_the_one_ci_runs():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert 'pip install --quiet ".[test]"' in ci and "\npytest -q " in ci
    assert "\nmkdocs build --strict" in ci and 'pip install --quiet ".[docs]"' in ci


def test_every_relative_link_of_the_readme_exists():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    links = [t for t in re.findall(r"\]\(([^)#\s]+)", text) if "://" not in t]
    assert any(t.startswith("docs/") for t in links), links
    missing = [t for t in links if not (ROOT / t).exists()]
    assert missing == []


# ------------------------------------------------------------------ site


def test_every_nav_page_exists_and_every_page_is_in_the_nav():
    cfg = config()
    pages = nav_pages(cfg["nav"])
    assert len(pages) == len(set(pages))
    assert [p for p in pages if not (DOCS / p).is_file()] == []
    written = {p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md")}
    assert written - set(pages) == set()  # no page that the nav does not reach
    assert all((ROOT / h).is_file() for h in cfg["hooks"])


def test_the_cli_reference_documents_every_subcommand():
    page = (DOCS / "reference" / "cli.md").read_text(encoding="utf-8")
    assert re.search(r"::: mkdocs-typer2\s+:module: debist\.cli\s+:name: debist", page)
    assert "mkdocs-typer2" in config()["plugins"]
    # what the plugin renders: Typer's own Markdown of the app
    out = subprocess.run(
        [sys.executable, "-m", "typer", "debist.cli", "utils", "docs", "--name", "debist"],
        capture_output=True, text=True, check=True, timeout=120,
    ).stdout  # fmt: skip
    names = commands()
    assert {"run", "init", "fleet", "zoo", "batch", "export", "diff", "schema"} <= set(names)
    assert [n for n in names if f"## `debist {n}`" not in out] == []
    assert "<output_dir>" not in out  # raw angle brackets break the plugin's XML step


def test_the_api_reference_lists_every_exported_name():
    import debist

    page = (DOCS / "reference" / "api.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"^\s+- (\w+)$", page, re.M))
    listed |= set(re.findall(r"^::: debist\.[\w.]+\.(\w+)$", page, re.M))
    assert set(debist.__all__) - {"__version__"} == listed


def test_the_workflow_key_page_lists_every_key_of_the_schema():
    schema = workflow_schema()
    keys = set(schema["properties"])
    for table in schema["$defs"].values():
        keys |= set(table.get("properties", {}))
        for prop in table.get("properties", {}).values():
            keys |= set(prop.get("properties", {}))  # inline tables: [identify.auto]
    page = hook("workflow_keys").render(schema)
    assert [k for k in sorted(keys) if f"`{k}`" not in page and f"[{k}]" not in page] == []
    for section in schema["properties"]:
        assert f"## [{section}]" in page
    assert "### [identify.refine]" in page and "#### [rig.experiments.<experiment>]" in page
    assert "| `M` | integer (>= 2) | `10` | Number of RBF centres per curve" in page
    marker = (DOCS / "reference" / "workflow-keys.md").read_text(encoding="utf-8")
    assert hook("workflow_keys").MARKER in marker


@pytest.mark.slow
def test_the_site_builds_strictly(tmp_path):
    pytest.importorskip("mkdocs", reason="the docs extra is not installed: pip install '.[docs]'")
    pytest.importorskip("mkdocstrings_handlers.python", reason="the docs extra is not installed")
    pytest.importorskip("mkdocs_typer2", reason="the docs extra is not installed")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"  # `typer`
    site = tmp_path / "site"
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    cli = (site / "reference" / "cli" / "index.html").read_text(encoding="utf-8")
    assert [n for n in commands() if f"debist {n}" not in cli] == []
    keys = (site / "reference" / "workflow-keys" / "index.html").read_text(encoding="utf-8")
    assert "<!-- workflow-keys -->" not in keys and "sigma_n" in keys
    api = (site / "reference" / "api" / "index.html").read_text(encoding="utf-8")
    assert 'id="debist.api.run"' in api and 'id="debist.api.workflow_schema"' in api
    assert not list(ROOT.glob("site")), "the build wrote into the repository"
