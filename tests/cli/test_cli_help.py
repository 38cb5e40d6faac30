"""Help texts keep their bracketed words: sections ([rig]) and units ([s]) print literally."""

import re

import click
import pytest
import typer
from typer.testing import CliRunner

from debist.cli import app

#: A bracketed word as the help texts write them: a section, a key path or a unit.
BRACKETED = re.compile(r"\[[A-Za-z0-9_.*/^]+\]")

GROUP = typer.main.get_command(app)
COMMANDS = sorted(GROUP.commands)


def bracketed(*texts: str | None) -> set[str]:
    """The bracketed words of help texts."""
    return {word for text in texts if text for word in BRACKETED.findall(text)}


def param_help(command: click.Command) -> list[str]:
    return [getattr(p, "help", None) or "" for p in command.params]


def render(*args: str) -> str:
    result = CliRunner().invoke(app, [*args, "--help"], terminal_width=80)
    assert result.exit_code == 0, result.output
    return result.output


def test_the_help_texts_name_the_sections_and_units_the_issue_lists():
    everything = bracketed(
        GROUP.help,
        *param_help(GROUP),
        *(t for c in GROUP.commands.values() for t in (c.help, *param_help(c))),
    )
    assert {"[rig]", "[physics]", "[s]", "[V]", "[ingest]", "[workflow]"} <= everything


def test_top_level_help_lists_every_bracketed_word_of_the_options_and_command_lines():
    out = render()
    expected = bracketed(GROUP.help, *param_help(GROUP))
    for name, command in GROUP.commands.items():
        assert name in out
        expected |= bracketed((command.help or "").split("\n\n")[0])
    assert {"[rig]", "[physics]", "[s]"} <= expected
    missing = sorted(w for w in expected if w not in out)
    assert not missing, f"lost from `debist --help`: {missing}\n{out}"


@pytest.mark.parametrize("name", COMMANDS)
def test_every_subcommand_help_keeps_its_bracketed_words(name):
    command = GROUP.commands[name]
    out = render(name)
    expected = bracketed(command.help, *param_help(command))
    missing = sorted(w for w in expected if w not in out)
    assert not missing, f"lost from `debist {name} --help`: {missing}\n{out}"


def test_the_rig_analyze_and_ingest_help_say_their_sections_and_units():
    assert "Run the virtual rig of [rig]:" in " ".join(render("simulate-rig").split())
    assert "Design analysis of [physics] (Section 3)" in " ".join(render("analyze").split())
    ingest = " ".join(render("ingest").split())
    assert "(t [s], q [m], v1..vN [V])" in ingest and "(replaces [workflow] output_dir)" in ingest
