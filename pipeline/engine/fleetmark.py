"""A fleet folder's record (``.debist-fleet.json``): finished, or stopped part way.

``debist fleet`` screens its candidates in the fleet folder itself: each candidate's workflow
is written there for its rig and ingest check, and a passing one's output folder is kept. A
fleet killed part way (SIGKILL, a power cut: nothing in the process can clean up) would leave
unscreened workflows that ``debist batch`` would run and that the next ``debist fleet``
refuses as existing ones. So the fleet writes this record first, marked unfinished, names
each candidate in it (with the sha256 of its text) before the candidate's file is written,
and marks it finished after the member workflows are written:

- :func:`unfinished_fleet` tells ``debist batch`` to refuse such a folder;
- :func:`clear_unfinished` lets the next ``debist fleet`` remove exactly what the stopped one
  wrote (a candidate file only while it holds the text recorded, an output folder only while
  its marker names that candidate) and start over.

Light on purpose (no rig or physics imports): ``debist batch`` reads it.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shlex
import shutil
import tomllib
from pathlib import Path
from typing import Any

from debist.core.fileformats import atomic_write
from debist.engine.outdir import MARKER as _OUTPUT_MARKER

__all__ = [
    "FLEET_MARKER",
    "clear_unfinished",
    "finish_fleet",
    "note_candidate",
    "start_fleet",
    "unfinished_fleet",
    "unfinished_message",
]

#: The record of a fleet in its folder.
FLEET_MARKER = ".debist-fleet.json"


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _read(folder: Path) -> dict[str, Any] | None:
    try:
        record = json.loads((folder / FLEET_MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) and record.get("debist") == "fleet" else None


def _write(folder: Path, record: dict[str, Any]) -> None:
    atomic_write(folder / FLEET_MARKER, json.dumps(record, indent=1) + "\n")


def start_fleet(folder: str | os.PathLike, template: str | os.PathLike, size: int, seed: int):
    """Record a fleet as unfinished in its folder (created), before any candidate is written.

    Parameters
    ----------
    folder : path-like
        The fleet folder.
    template : path-like
        The template workflow (recorded absolute, for the command that replaces the fleet).
    size, seed : int
        The fleet's size and seed, as asked for.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    record = {"debist": "fleet", "complete": False, "template": str(Path(template).resolve()),
              "size": int(size), "seed": int(seed), "candidates": {}}  # fmt: skip
    _write(folder, record)


def note_candidate(folder: str | os.PathLike, name: str, text: str) -> None:
    """Name a candidate's workflow file in the unfinished fleet's record, before it is written.

    Parameters
    ----------
    folder : path-like
        The fleet folder (nothing is recorded unless :func:`start_fleet` was called).
    name : str
        The candidate's workflow file name (``<name>-<draw>.toml``).
    text : str
        Its text (its sha256 is recorded).
    """
    folder = Path(folder)
    record = _read(folder)
    if record is None:  # no fleet was started here (a direct call of the checks)
        return
    record.setdefault("candidates", {})[name] = _sha256(text)
    _write(folder, record)


def finish_fleet(folder: str | os.PathLike, names: list[str]) -> None:
    """Mark a fleet finished: its member workflows are all written.

    Parameters
    ----------
    folder : path-like
        The fleet folder.
    names : list of str
        The member workflow files, in draw order.
    """
    folder = Path(folder)
    record = _read(folder) or {"debist": "fleet"}
    record.pop("candidates", None)
    _write(folder, {**record, "complete": True, "workflows": list(names)})


def unfinished_fleet(folder: str | os.PathLike) -> dict[str, Any] | None:
    """Return the record of a fleet stopped part way in this folder, or None.

    Parameters
    ----------
    folder : path-like
        A folder (of workflows).

    Returns
    -------
    dict or None
        The record (``template``, ``size``, ``seed``, ``candidates``) when the folder holds
        a fleet whose ``debist fleet`` did not end; None otherwise (no record, or finished).
    """
    record = _read(Path(folder))
    return record if record is not None and record.get("complete") is not True else None


def unfinished_message(folder: str | os.PathLike, record: dict[str, Any]) -> str:
    """One line: the folder holds an unfinished fleet, and the command that replaces it.

    Parameters
    ----------
    folder : path-like
        The fleet folder.
    record : dict
        Its :func:`unfinished_fleet` record.

    Returns
    -------
    str
    """
    words = ["debist", "fleet", str(record.get("template", "TEMPLATE")), "--size",
             str(record.get("size", 1)), "--seed", str(record.get("seed", 0)), "--dir",
             os.fspath(folder)]  # fmt: skip
    return (
        f"'{folder}' holds a fleet whose debist fleet was stopped before it ended (its "
        f"workflows are unscreened): replace it with: {shlex.join(words)}"
    )


def clear_unfinished(folder: str | os.PathLike) -> list[Path]:
    """Remove what a stopped fleet wrote in its folder, and its record.

    A candidate's workflow file is removed only while it holds the text recorded for it,
    and its output folder only while that folder's marker names the candidate's file as its
    owner (a file or folder the user put there since is kept); an empty ``runs`` folder left
    behind goes too.

    Parameters
    ----------
    folder : path-like
        The fleet folder.

    Returns
    -------
    list of pathlib.Path
        The workflow files and output folders removed (none when the fleet is finished or
        there is no record).
    """
    folder = Path(folder)
    record = unfinished_fleet(folder)
    if record is None:
        return []
    removed: list[Path] = []
    for name, digest in dict(record.get("candidates") or {}).items():
        path = folder / Path(str(name)).name
        for out in _output_folders(path, folder):
            removed.append(out)
            shutil.rmtree(out, ignore_errors=True)
        try:
            if _sha256(path.read_text(encoding="utf-8")) == digest:
                path.unlink()
                removed.append(path)
        except (OSError, UnicodeDecodeError):
            pass
    runs = folder / "runs"
    if runs.is_dir() and not any(runs.iterdir()):
        runs.rmdir()
    (folder / FLEET_MARKER).unlink(missing_ok=True)
    return removed


def _output_folders(path: Path, folder: Path) -> list[Path]:
    """Return the output folder of a candidate's workflow if its marker names it the owner."""
    out = folder / "runs" / path.stem  # the fleet's own place, where the file is gone or unread
    unread = (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, KeyError, TypeError)
    with contextlib.suppress(*unread):
        text = path.read_text(encoding="utf-8")
        out = (folder / tomllib.loads(text)["workflow"]["output_dir"]).resolve()
    try:
        marker = json.loads((out / _OUTPUT_MARKER).read_text(encoding="utf-8"))
        owner = (out / marker["workflow_file"]).resolve()
    except (OSError, ValueError, KeyError, TypeError):
        return []
    return [out] if owner == path.resolve() else []
