"""A zoo folder's index (``zoo.json``): which members it holds, of which seed.

Light on purpose (no rig or physics imports): ``debist batch`` reads it to expand a zoo
folder into its members' workflows.
"""

from __future__ import annotations

import json
import os
import shlex
from pathlib import Path
from typing import Any

from debist.core.errors import DebistError, WorkflowError
from debist.core.names import check_file_name

__all__ = ["MEMBER_WORKFLOW", "ZOO_FILE", "ZooError", "read_zoo", "zoo_workflows"]

#: The zoo's index file in its folder.
ZOO_FILE = "zoo.json"
#: A member's workflow file in its folder.
MEMBER_WORKFLOW = "workflow.toml"


class ZooError(DebistError, RuntimeError):
    """A zoo cannot be written or read: an unusable folder, or a member without a viable draw."""


def read_zoo(folder: str | os.PathLike) -> dict[str, Any] | None:
    """Return a folder's zoo index (``zoo.json``), or None if it has none.

    Parameters
    ----------
    folder : path-like
        A zoo folder.

    Returns
    -------
    dict or None
        ``version``, ``seed``, ``size``, ``members`` (plain file-name components) and
        ``complete``: false while ``debist zoo`` writes it, or when it was stopped part
        way (an index without the key is a finished zoo of an older debist).

    Raises
    ------
    ZooError
        If ``zoo.json`` is not a zoo index, or a member name is not a plain file name.
    """
    path = Path(folder) / ZOO_FILE
    if not path.is_file():
        return None
    try:
        index = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(index, dict) or not isinstance(index.get("members"), list):
            raise ValueError("not an object with a 'members' list")
        for name in index["members"]:
            check_file_name(name, f"{ZOO_FILE} members")
    except (OSError, ValueError, RecursionError, WorkflowError) as exc:
        raise ZooError(f"'{path}' is not a zoo index: {exc}") from None
    return index


def zoo_workflows(folder: str | os.PathLike) -> list[Path]:
    """Return the workflow files of a zoo's members that exist, in member order.

    Parameters
    ----------
    folder : path-like
        A zoo folder.

    Returns
    -------
    list of pathlib.Path

    Raises
    ------
    WorkflowError
        If the folder is not a zoo, is an unfinished one (naming the command that finishes
        it), or none of its members has a workflow.
    """
    try:
        index = read_zoo(folder)
    except ZooError as exc:
        raise WorkflowError(str(exc)) from None
    if index is None:
        raise WorkflowError(f"'{folder}' is not a zoo folder (no {ZOO_FILE})")
    if index.get("complete", True) is not True:
        there = sum((Path(folder) / name / "truth.json").is_file() for name in index["members"])
        words = ["--size", len(index["members"]), "--seed", index.get("seed"), "--dir", folder]
        command = shlex.join(["debist", "zoo", *map(str, words)])
        raise WorkflowError(
            f"the zoo '{folder}' is unfinished ({there} of {len(index['members'])} members; "
            f"debist zoo was stopped): finish it first with: {command}"
        )
    found = [Path(folder) / name / MEMBER_WORKFLOW for name in index["members"]]
    found = [p for p in found if p.is_file()]
    if not found:
        raise WorkflowError(f"the zoo '{folder}' holds no member workflow yet")
    return found
