"""Global options of the debist CLI."""

from importlib.metadata import version

from typer.testing import CliRunner

from cli import app


def test_version_prints_the_installed_version_and_exits():
    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0
    assert result.output.strip() == f"debist {version('debist')}"


def test_version_runs_before_a_command_would():
    result = CliRunner().invoke(app, ["--version", "verify", "does-not-exist.toml"])
    assert result.exit_code == 0 and "debist" in result.output
