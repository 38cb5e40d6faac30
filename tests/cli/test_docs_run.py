"""Every shell block of the README, the tutorials and the how-to pages runs as written.

Each ```` ```bash ```` block of a page runs with ``bash -e -o pipefail`` in the page's own copy of
what the commands need (``workflows/``, ``data/``), in page order, with the installed ``debist``
on ``PATH``; afterwards every output the block names exists (a run's folder holds its manifests,
an ``init --out`` file, a ``fleet``/``zoo --dir`` folder, an ``export --dest`` folder, both
folders of a ``diff``). An HTML comment on the line before a block changes that, and says why:

- ``<!-- docs-test: skip: REASON -->``: not run (it installs, serves, or needs what one machine
  lacks, such as a Dask cluster);
- ``<!-- docs-test: fails: REASON -->``: must exit non-zero (a command shown failing);
- ``<!-- docs-test: given: NAME=PATH ... -->``: the page's example files, copied from what earlier
  blocks made before the block runs (the README's ``est.mat``, ``val.mat``).

The shipped workflows' own runs (paper experiment, Silverbox) are made once and copied into each
page's folder, as a reader who followed the README has them; a page's ``debist run`` of them then
finds every stage up to date, and everything else a page runs is computed in its folder.

References
----------
CommonMark 0.31 (fenced code blocks, HTML blocks), parsed by markdown-it-py; POSIX shell
command language (``shlex``).
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from markdown_it import MarkdownIt

ROOT = Path(__file__).resolve().parents[2]
PAGES = [
    "README.md",
    *(p.relative_to(ROOT).as_posix() for p in sorted((ROOT / "docs" / "tutorials").glob("*.md"))),
    *(p.relative_to(ROOT).as_posix() for p in sorted((ROOT / "docs" / "how-to").glob("*.md"))),
]
MARKS = ("skip", "fails", "given")
#: Bound on one block [s] (a guard against a hung command, not a timing test).
BLOCK_TIMEOUT = 1800
#: What each page's folder holds, copied from the repository.
NEEDS = ("workflows", "data")
#: The runs a page finds made (the README's commands), made once.
MADE = ("workflows/paper-experiment.toml", "workflows/silverbox.toml")


@dataclass(frozen=True)
class Block:
    """One ```` ```bash ```` block of a page and the mark on the line before it."""

    page: str
    line: int  # 1-based line of the opening fence
    text: str
    mark: str | None = None  # "skip", "fails", "given" or None
    note: str = ""  # the mark's reason, or the given files

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def blocks(page: str) -> list[Block]:
    """The bash blocks of a page in order, each with the docs-test mark before it."""
    tokens = MarkdownIt("commonmark").parse((ROOT / page).read_text(encoding="utf-8"))
    out, before = [], None
    for token in tokens:
        if token.type == "fence" and token.info.strip() == "bash":
            mark, note = None, ""
            if before is not None and before.map[1] == token.map[0]:  # the line just before
                head, _, rest = before.content.strip().removeprefix("<!--").partition(":")
                assert head.strip() == "docs-test", f"{page}:{before.map[0] + 1}: {before.content}"
                mark, _, note = rest.partition(":")
                mark, note = mark.strip(), note.removesuffix("-->").strip()
            out.append(Block(page, token.map[0] + 1, token.content, mark, note))
        before = token if token.type == "html_block" and "docs-test" in token.content else None
    return out


def commands(text: str) -> list[list[str]]:
    """The ``debist`` commands of a block, as argument lists (``debist`` first).

    Continuation lines are joined and comments dropped; a command ends at ``|``, ``&&``, ``;``
    or ``)`` (``digest=$(debist -q run WF | cut ...)`` holds ``debist -q run WF``).
    """
    out = []
    for line in text.replace("\\\n", " ").splitlines():
        lexer = shlex.shlex(line, posix=True, punctuation_chars=True)
        lexer.whitespace_split, lexer.commenters = True, "#"
        current = None
        for word in lexer:
            if current is None:
                if word == "debist":
                    current = [word]
            elif word and set(word) <= set("|&;()"):
                out.append(current)
                current = None
            else:
                current.append(word)
        if current is not None:
            out.append(current)
    return out


def _options(args: list[str]) -> tuple[list[str], dict[str, list[str]]]:
    """Split a subcommand's arguments into positionals and options (each option's values)."""
    flags = {"--list", "--force", "--json", "--wait", "-q", "-v", "--quiet", "--verbose"}
    positional, options, i = [], {}, 0
    while i < len(args):
        word = args[i]
        if word.startswith("-") and word not in flags:
            name, eq, value = word.partition("=")
            if not eq:
                value, i = args[i + 1], i + 1
            options.setdefault({"-S": "--set"}.get(name, name), []).append(value)
        elif not word.startswith("-"):
            positional.append(word)
        i += 1
    return positional, options


def outputs(command: list[str], folder: Path) -> list[tuple[str, Path]]:
    """What a ``debist`` command leaves in ``folder``: ``(kind, path)``, kind "run", "file",
    "folder"; a run's folder is ``--out``, else the workflow's (``.set-`` with ``--set``)."""
    from debist.workflow.loader import load_workflow

    words = command[1:]
    while words and words[0].startswith("-"):  # debist's own options: -q, -v
        words = words[1:]
    if not words:
        return []
    name, (positional, options) = words[0], _options(words[1:])
    out = options.get("--out", [None])[-1]
    if name in ("run", "ingest", "differentiate", "identify", "validate", "compare", "study"):
        if out is not None:
            return [("run", folder / out)]
        wf = load_workflow(folder / positional[0], overrides=options.get("--set"))
        return [("run", wf.output_dir)]
    if name == "init" and out is not None:
        return [("file", folder / out)]
    if name in ("fleet", "zoo"):
        return [("folder", folder / options["--dir"][-1])]
    if name == "export" and "--dest" in options:
        return [("folder", folder / options["--dest"][-1])]
    if name == "diff" and len(positional) == 2:
        return [("run", folder / p) for p in positional]
    return []


def present(kind: str, path: Path) -> bool:
    from debist.engine.rundiff import is_run

    if kind == "run":
        return is_run(path)
    if kind == "file":
        return path.is_file()
    return path.is_dir() and any(path.iterdir())


# ------------------------------------------------------------------ quick: the pages' marks


def test_every_mark_is_known_and_says_why():
    found = [b for page in PAGES for b in blocks(page)]
    assert len(found) >= 20 and {b.page for b in found} >= {"README.md", "docs/how-to/diff.md"}
    for block in found:
        assert block.mark in (None, *MARKS), block.where
        if block.mark in ("skip", "fails"):
            assert len(block.note.split()) >= 3, f"{block.where}: say why ({block.note!r})"
        if block.mark == "given":
            pairs = [item.partition("=") for item in block.note.split()]
            assert pairs and all(n and eq and p for n, eq, p in pairs), block.where
    # what can not run here is marked, and only that: the installs, the server, the cluster
    skipped = {b.where for b in found if b.mark == "skip"}
    installs = {b.where for b in found if "pip install" in b.text or "mkdocs serve" in b.text}
    assert installs <= skipped
    assert all("--address" in b.text for b in found if b.where in skipped - installs)


def test_the_commands_and_their_outputs_are_read_as_the_shell_reads_them(tmp_path):
    text = (
        "debist run wf.toml --out runs/a-tuned -S identify.M=6 \\\n"
        "    -S 'identify.q_range=[-1e-3, 1e-3]'   # a comment: debist run x\n"
        "debist diff runs/a runs/a-tuned\n"
        "digest=$(debist -q run wf.toml --set identify.M=8 | cut -d' ' -f3)\n"
        "mkdir -p logs && debist init a.mat b.mat --out p.toml --force\n"
    )
    found = commands(text)
    assert found == [
        ["debist", "run", "wf.toml", "--out", "runs/a-tuned", "-S", "identify.M=6", "-S",
         "identify.q_range=[-1e-3, 1e-3]"],
        ["debist", "diff", "runs/a", "runs/a-tuned"],
        ["debist", "-q", "run", "wf.toml", "--set", "identify.M=8"],
        ["debist", "init", "a.mat", "b.mat", "--out", "p.toml", "--force"],
    ]  # fmt: skip
    assert outputs(found[0], tmp_path) == [("run", tmp_path / "runs/a-tuned")]
    assert outputs(found[1], tmp_path) == [("run", tmp_path / "runs/a"),
                                           ("run", tmp_path / "runs/a-tuned")]  # fmt: skip
    assert outputs(found[3], tmp_path) == [("file", tmp_path / "p.toml")]
    # the own-rig tutorial compares the folder its tuned run names
    (tuned, diff), *_ = [commands(b.text) for b in blocks("docs/tutorials/own-rig.md")
                         if "diff" in b.text]  # fmt: skip
    assert outputs(tuned, tmp_path)[0] in outputs(diff, tmp_path)


# ------------------------------------------------------------------ slow: the pages run


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    """A folder with what the pages' commands need and the shipped workflows' own runs."""
    from tests.conftest import made_once

    def make(folder: Path) -> str:
        for name in NEEDS:
            shutil.copytree(ROOT / name, folder / name)
        for workflow in MADE:
            done = run_bash(f"debist run {workflow}", folder)
            assert done.returncode == 0, done.stdout + done.stderr
        return ""

    folder, _ = made_once(tmp_path_factory, "docs-project", make)
    return folder


def debist_bin() -> Path:
    """The folder of the installed ``debist`` script (beside this Python)."""
    return Path(sys.executable).parent


def run_bash(text: str, folder: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PATH": f"{debist_bin()}{os.pathsep}{os.environ.get('PATH', '')}"}
    return subprocess.run(
        ["bash", "-e", "-o", "pipefail", "-c", text], cwd=folder, env=env, capture_output=True,
        text=True, timeout=BLOCK_TIMEOUT, check=False,
    )  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_every_shell_block_of_the_page_runs_as_written(page, project, tmp_path):
    if shutil.which("debist", path=str(debist_bin())) is None:
        pytest.skip(f"no installed debist beside {sys.executable} (pip install .)")
    found = blocks(page)
    if all(b.mark == "skip" for b in found):
        pytest.skip(f"{page}: no block runs here ({'; '.join(b.note for b in found) or 'none'})")
    folder = tmp_path / "page"
    shutil.copytree(project, folder, symlinks=True)
    for block in found:
        if block.mark == "skip":
            continue
        if block.mark == "given":
            for item in block.note.split():
                name, _, source = item.partition("=")
                assert (folder / source).is_file(), f"{block.where}: given {source} is missing"
                shutil.copyfile(folder / source, folder / name)
        done = run_bash(block.text, folder)
        said = f"{block.where}: exit {done.returncode}\n{block.text}{done.stdout}{done.stderr}"
        if block.mark == "fails":
            assert done.returncode != 0, said
            continue
        assert done.returncode == 0, said
        for command in commands(block.text):
            for kind, path in outputs(command, folder):
                assert present(kind, path), (
                    f"{block.where}: {shlex.join(command)}: no {kind} {path}"
                )
