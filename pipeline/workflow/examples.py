"""The shipped example workflows and the data they read, copied to where a script runs.

The repository's ``workflows/`` and ``data/`` folders are the one copy of the examples. A
wheel carries them as package data under ``debist/examples/workflows`` and
``debist/examples/data`` (``pyproject.toml`` maps the two packages to those folders), so
an installed debist reaches them with :mod:`importlib.resources`; an editable install or a
checkout reads the folders themselves.

:func:`copy_example` writes ``<folder>/workflows/<name>.toml`` and the data files its data
sets name (with their folders' ``README.md``, which say where the data come from) under
``<folder>/data/``: the layout of the repository, so that the workflow's relative paths
(``../data/...``, ``output_dir = "../runs/<name>"``) hold unchanged and the run's
artifacts go to ``<folder>/runs/<name>``.

References
----------
Python documentation, :mod:`importlib.resources` (``files``, ``Traversable``); setuptools
documentation, "Data Files Support" (``package-data``, ``package-dir``).
"""

from __future__ import annotations

import os
import posixpath
import tomllib
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path

from debist.core.errors import OutputDirError, WorkflowError
from debist.core.fileformats import atomic_write

__all__ = ["copy_example", "example_names"]


def _shipped() -> tuple[Traversable, Traversable]:
    """Return the folders of the example workflows and data (package data, else checkout)."""
    packaged = resources.files("debist") / "examples"
    if (packaged / "workflows").is_dir():
        return packaged / "workflows", packaged / "data"
    checkout = Path(__file__).resolve().parents[2]  # pipeline/workflow/ -> the repository
    if (checkout / "workflows").is_dir():
        return checkout / "workflows", checkout / "data"
    raise WorkflowError(  # pragma: no cover - an installation without its package data
        "the example workflows are not installed with debist (no debist/examples/workflows)"
    )


def example_names() -> tuple[str, ...]:
    """Name the shipped example workflows.

    Returns
    -------
    tuple of str
        Sorted, e.g. ``("emps", "paper-analysis", "paper-experiment", ..., "silverbox")``.

    Raises
    ------
    WorkflowError
        The installation lacks its package data.

    Examples
    --------
    >>> {"paper-experiment", "silverbox"} <= set(example_names())
    True
    """
    folder, _ = _shipped()
    return tuple(sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml")))


def _data_files(text: str, name: str) -> list[tuple[str, bool]]:
    """List the files under ``data/`` a workflow reads, each with whether it must exist.

    The data sets' sources (required), then the ``README.md`` of their folders (copied
    when present); paths inside ``data/``, ``/``-separated.
    """
    sources: list[str] = []
    for table in tomllib.loads(text).get("datasets", {}).values():
        source = table.get("source")
        if source is None:
            continue
        inside = posixpath.normpath(posixpath.join("workflows", source))
        if not inside.startswith("data/"):  # pragma: no cover - a shipped workflow's own data
            raise WorkflowError(f"example '{name}': source {source!r} is not under data/")
        if inside[5:] not in sources:
            sources.append(inside[5:])
    readmes = {posixpath.join(posixpath.dirname(s), "README.md") for s in sources}
    return [(s, True) for s in sources] + [(r, False) for r in sorted(readmes)]


def _copy(source: Traversable, target: Path) -> None:
    """Copy one file; an identical one is kept, another one is refused (never overwritten)."""
    data = source.read_bytes()
    if os.path.lexists(target):
        if target.is_file() and target.read_bytes() == data:
            return
        raise OutputDirError(
            f"'{target}' exists and is not the shipped file: debist never overwrites a file "
            "(remove it or choose another folder)"
        )
    target.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(target, data)


def copy_example(name: str, folder: str | os.PathLike[str]) -> Path:
    """Copy a shipped example workflow, and the data it reads, into a folder.

    Parameters
    ----------
    name : str
        One of :func:`example_names`, e.g. ``"paper-experiment"`` (the paper's experiment
        on the virtual rig: no data) or ``"silverbox"`` (with its data file).
    folder : path-like
        Where to put them (created if missing): ``<folder>/workflows/<name>.toml`` and
        ``<folder>/data/...``; the runs then go to ``<folder>/runs/<name>``.

    Returns
    -------
    pathlib.Path
        The copied workflow file.

    Raises
    ------
    WorkflowError
        An unknown name (the names listed).
    OutputDirError
        A file of the same name exists in ``folder`` with other content (an identical one
        is kept, so a script may call this on every run).
    OSError
        The folder cannot be written.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = copy_example("emps", tmp)
    ...     print(path.relative_to(tmp).as_posix(), sorted(
    ...         p.name for p in (Path(tmp) / "data" / "emps").iterdir()))
    workflows/emps.toml ['DATA_EMPS.mat', 'DATA_EMPS_PULSES.mat', 'README.md']
    """
    names = example_names()
    if name not in names:
        raise WorkflowError(f"no example workflow {name!r}; the examples: {', '.join(names)}")
    workflows, data = _shipped()
    source = workflows / f"{name}.toml"
    folder = Path(folder)
    for inside, required in _data_files(source.read_text(encoding="utf-8"), name):
        part = data.joinpath(*inside.split("/"))
        if required or part.is_file():
            _copy(part, folder.joinpath("data", *inside.split("/")))
    target = folder / "workflows" / f"{name}.toml"
    _copy(source, target)
    return target
