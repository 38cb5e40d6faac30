"""The output folder of a workflow: who owns it, one writer at a time, leftovers, the digest.

debist writes only into a folder it owns: one it created (and marked with
``.debist-output.json``, which names the workflow file and, for a run with ``--set``, the
settings overridden), an empty one, or one that holds nothing
but debist's stage folders (an output folder of an earlier version, adopted). It refuses the
file system root, the user's home folder, the workflow's own folder and any folder that holds
the workflow's data sources. One process writes at a time: a lock file per output folder
(:mod:`filelock`, an OS advisory lock released when the process ends, however it ends) with
the holder's pid, host, command and start time beside it. Interrupted stage swaps leave
folders that :func:`recover` resolves at the start of the next command that writes.

References
----------
filelock documentation (https://py-filelock.readthedocs.io); POSIX ``flock(2)``.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path

from debist.core import artifacts
from debist.core.artifacts import SWAP_FOLDER
from debist.core.artifacts import run_digest as run_digest  # the run's digest, named here too
from debist.core.errors import OutputDirError, RunLockedError
from debist.core.fileformats import atomic_write
from debist.workflow.overrides import override_args

__all__ = [
    "HOLDER",
    "LOCK",
    "MARKER",
    "check_output_dir",
    "check_place",
    "claim_output_dir",
    "describe_leftover",
    "leftovers",
    "lock_holder",
    "output_lock",
    "recover",
    "run_digest",
    "writing",
]

#: The marker of an output folder debist owns (JSON naming the workflow).
MARKER = ".debist-output.json"
#: The lock file of an output folder.
LOCK = ".debist.lock"
#: Who holds the lock (JSON: pid, host, command, start time); removed on release.
HOLDER = ".debist.lock.json"
OWN_FILES = frozenset({MARKER, LOCK, HOLDER})


def _marker(out: Path) -> dict:
    try:
        data = json.loads((out / MARKER).read_text(encoding="utf-8"))
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def _canonical(tree: Mapping) -> str:
    return json.dumps(tree, sort_keys=True, separators=(",", ":"), default=str)


def _marker_workflow(out: Path) -> str | None:
    name = _marker(out).get("workflow")
    return None if name is None else str(name)


def _marker_file(out: Path) -> Path | None:
    """Return the workflow file the marker names (stored relative to the folder), resolved."""
    rel = _marker(out).get("workflow_file")
    return (out / rel).resolve() if isinstance(rel, str) else None


def _describe(overrides: Mapping) -> str:
    """Name a run's settings: the workflow as it is, or its ``--set`` options."""
    if not overrides:
        return "the workflow file as it is (no --set)"
    return "--set " + " --set ".join(override_args(overrides))


def _debist_layout(out: Path, stages: Sequence[str]) -> bool:
    """Tell whether every entry of ``out`` is debist's (an unmarked older output folder).

    Stage folders with manifests, swap leftovers and lock files are debist's.
    """
    for entry in out.iterdir():
        if entry.name in OWN_FILES or (entry.is_dir() and SWAP_FOLDER.match(entry.name)):
            continue
        if not (entry.is_dir() and entry.name in stages and (entry / artifacts.MANIFEST).is_file()):
            return False
    return True


def check_place(
    out: str | os.PathLike,
    *,
    workflow_dir: str | os.PathLike,
    sources: Sequence[str | os.PathLike] = (),
    what: str = "output folder",
    advice: str = "debist writes its stage folders only into a folder of their own; set "
    "[workflow] output_dir or --out to one",
) -> None:
    """Refuse a folder no debist command writes into: a user's folder or the data's.

    Parameters
    ----------
    out : path-like
        The folder (absolute, resolved).
    workflow_dir : path-like
        The folder of the workflow file.
    sources : sequence of path-like
        The workflow's data source files.
    what : str, optional
        What the folder is for, for the message (``"export folder (dest)"``).
    advice : str, optional
        What to do instead, for the message.

    Raises
    ------
    OutputDirError
        If ``out`` is the file system root, the home folder (:meth:`pathlib.Path.home`),
        the workflow file's folder, or holds one of ``sources``.

    Examples
    --------
    >>> try:
    ...     check_place("/", workflow_dir="/tmp/wf", what="export folder", advice="use another")
    ... except OutputDirError as exc:
    ...     print(exc)
    export folder '/' is the file system root: use another
    """
    out = Path(out)
    places = {Path(out.anchor): "the file system root", Path.home().resolve(): "your home folder"}
    places[Path(workflow_dir).resolve()] = "the workflow file's own folder"
    if out in places:
        raise OutputDirError(f"{what} '{out}' is {places[out]}: {advice}")
    for source in sources:
        if Path(source).resolve().is_relative_to(out):
            raise OutputDirError(
                f"{what} '{out}' holds the data source '{source}': choose a folder apart from "
                "the data"
            )


def check_output_dir(
    out: str | os.PathLike,
    *,
    workflow: str,
    workflow_dir: str | os.PathLike,
    sources: Sequence[str | os.PathLike] = (),
    stages: Sequence[str] = (),
    workflow_file: str | os.PathLike | None = None,
    overrides: Mapping | None = None,
) -> None:
    """Refuse an output folder debist must not write into (nothing is created).

    An output folder belongs to the workflow *file* that made it (its marker records the
    file's path relative to the folder, so a project moved as a whole keeps its runs), not
    to a ``[workflow] name``, which two different workflows may share; and to the settings
    overridden for its run (none for the workflow's own folder), so a run with other
    ``--set`` options never writes into it.

    Parameters
    ----------
    out : path-like
        The output folder (absolute).
    workflow : str
        The workflow's name (what the marker records).
    workflow_dir : path-like
        The folder of the workflow file.
    sources : sequence of path-like
        The workflow's data source files.
    stages : sequence of str
        The stage names of debist (to recognise an unmarked output folder of an earlier
        version).
    workflow_file : path-like, optional
        The workflow file (absolute): the folder's owner.
    overrides : mapping, optional
        The settings overridden for this run, as nested tables (none: the file as it is).

    Raises
    ------
    OutputDirError
        If ``out`` is the file system root, the home folder, the workflow's folder, holds
        a data source (:func:`check_place`), is a file, is marked for another workflow
        file (or, for a marker of an older debist that names no file, another workflow
        name) or for other overridden settings, or exists, is not empty and is not debist's.
    """
    out = Path(out)
    check_place(out, workflow_dir=workflow_dir, sources=sources)
    if out.exists() and not out.is_dir():
        raise OutputDirError(f"output folder '{out}' is a file, not a folder")
    if not out.is_dir():
        return
    owner = _marker_workflow(out)
    owner_file = _marker_file(out)
    if (out / MARKER).exists():
        mine = Path(workflow_file).resolve() if workflow_file is not None else None
        if owner_file is not None and mine is not None and owner_file != mine:
            raise OutputDirError(
                f"output folder '{out}' belongs to the workflow file '{owner_file}' (see its "
                f"{MARKER}), not '{mine}': give this workflow its own output_dir"
            )
        if owner_file is None and owner != workflow:
            raise OutputDirError(
                f"output folder '{out}' belongs to workflow {owner!r} (see its {MARKER}), not "
                f"{workflow!r}: give this workflow its own output_dir"
            )
        theirs = _marker(out).get("overrides") or {}
        if _canonical(theirs) != _canonical(overrides or {}):
            raise OutputDirError(
                f"output folder '{out}' holds the run of {_describe(theirs)} (see its {MARKER}),"
                f" not of {_describe(overrides or {})}: give this run its own output folder"
            )
        return
    entries = sorted(p.name for p in out.iterdir())
    if entries and not _debist_layout(out, stages):
        shown = ", ".join(f"'{e}'" for e in entries[:5])
        more = f" and {len(entries) - 5} more" if len(entries) > 5 else ""
        raise OutputDirError(
            f"output folder '{out}' exists and holds files that are not debist's ({shown}{more}):"
            " debist writes only into a new or empty folder, or one it made; choose another"
            " output_dir or --out"
        )


def claim_output_dir(
    out: str | os.PathLike,
    *,
    workflow: str,
    workflow_file: str | os.PathLike | None = None,
    overrides: Mapping | None = None,
    **places,
) -> None:
    """Check an output folder (:func:`check_output_dir`), create it and mark it as debist's.

    Parameters
    ----------
    out : path-like
        The output folder (absolute).
    workflow : str
        The workflow's name, recorded in the marker.
    workflow_file : path-like, optional
        The workflow file (absolute), recorded relative to ``out`` as the owner.
    overrides : mapping, optional
        The settings overridden for this run (nested tables), recorded when there are any.
    **places
        ``workflow_dir``, ``sources`` and ``stages`` of :func:`check_output_dir`.

    Raises
    ------
    OutputDirError
        As :func:`check_output_dir`.
    """
    out = Path(out)
    check_output_dir(
        out, workflow=workflow, workflow_file=workflow_file, overrides=overrides, **places
    )
    out.mkdir(parents=True, exist_ok=True)
    record = {"debist": "output folder", "workflow": workflow}
    if workflow_file is not None:
        record["workflow_file"] = os.path.relpath(Path(workflow_file).resolve(), out.resolve())
    if overrides:
        record["overrides"] = json.loads(_canonical(overrides))
    if _marker(out) != record:
        atomic_write(out / MARKER, json.dumps(record, indent=2) + "\n")


@contextmanager
def writing(
    out: str | os.PathLike, *, workflow: str, wait: bool = False, **places
) -> Iterator[None]:
    """Claim an output folder and hold its lock while writing; undo a claim that wrote nothing.

    Parameters
    ----------
    out : path-like
        The output folder (absolute).
    workflow : str
        The workflow's name.
    wait : bool, optional
        Wait for another writer instead of failing.
    **places
        ``workflow_dir``, ``sources``, ``stages``, ``workflow_file`` and ``overrides`` of
        :func:`claim_output_dir`.

    Yields
    ------
    None
        While the folder is claimed and locked.

    Raises
    ------
    OutputDirError, RunLockedError
        As :func:`claim_output_dir` and :func:`output_lock`.
    """
    out = Path(out)
    new = not out.exists()
    claim_output_dir(out, workflow=workflow, **places)
    try:
        with output_lock(out, wait=wait):
            yield
    finally:
        if new and out.is_dir() and {p.name for p in out.iterdir()} <= OWN_FILES:
            shutil.rmtree(out, ignore_errors=True)  # created here and nothing was written


def lock_holder(out: str | os.PathLike) -> str:
    """Describe who holds an output folder's lock, from its holder file.

    Parameters
    ----------
    out : path-like
        The output folder.

    Returns
    -------
    str
        E.g. ``"pid 4711 on lab-pc, `debist run wf.toml`, since 2026-11-22 10:01:02"``, or
        ``"another debist process"`` when the holder file is missing or unreadable.
    """
    try:
        data = json.loads((Path(out) / HOLDER).read_text(encoding="utf-8"))
        return f"pid {data['pid']} on {data['host']}, `{data['command']}`, since {data['since']}"
    except (OSError, ValueError, KeyError, TypeError):
        return "another debist process"


@contextmanager
def output_lock(out: str | os.PathLike, *, wait: bool = False) -> Iterator[None]:
    """Hold the output folder's lock: one writer at a time.

    Parameters
    ----------
    out : path-like
        The output folder (must exist).
    wait : bool, optional
        Wait for the holder to finish instead of failing at once.

    Yields
    ------
    None
        While the lock is held; the holder file names this process.

    Raises
    ------
    RunLockedError
        If another process holds the lock and ``wait`` is false (naming the holder).
    """
    from filelock import FileLock, Timeout

    out = Path(out)
    lock = FileLock(out / LOCK, timeout=-1 if wait else 0)
    try:
        lock.acquire()
    except Timeout:
        raise RunLockedError(
            f"output folder '{out}' is being written by {lock_holder(out)}; run again when it "
            "is done"
        ) from None
    try:
        holder = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
            "since": time.strftime("%Y-%m-%d %H:%M:%S"),
        }
        (out / HOLDER).write_text(json.dumps(holder) + "\n", encoding="utf-8")
        yield
    finally:
        (out / HOLDER).unlink(missing_ok=True)
        lock.release()


def is_locked(out: str | os.PathLike) -> bool:
    """Tell whether another process holds the output folder's lock now.

    Parameters
    ----------
    out : path-like
        The output folder.

    Returns
    -------
    bool
        True while a writer holds it (false for a missing folder, and for a lock file this
        process cannot open for writing: a run archived on read-only media).
    """
    from filelock import FileLock, Timeout

    path = Path(out) / LOCK
    if not path.is_file():
        return False
    lock = FileLock(path, timeout=0)
    try:
        lock.acquire()
    except Timeout:
        return True
    except OSError:  # read-only media or no write permission: nobody writes there through us
        return False
    lock.release()
    return False


def leftovers(output_dir: str | os.PathLike) -> list[Path]:
    """List the leftovers of interrupted stage swaps in an output folder.

    Parameters
    ----------
    output_dir : path-like
        The workflow's output folder.

    Returns
    -------
    list of pathlib.Path
        The ``.<stage>.tmp-*`` and ``.<stage>.old-*`` folders (or links in their place,
        dangling ones too), sorted by name.
    """
    root = Path(output_dir)
    if not root.is_dir():
        return []
    return sorted(
        p for p in root.iterdir() if (p.is_dir() or p.is_symlink()) and SWAP_FOLDER.match(p.name)
    )


def describe_leftover(path: str | os.PathLike) -> str:
    """Say what a leftover is and what :func:`recover` will do with it.

    Parameters
    ----------
    path : path-like
        A folder listed by :func:`leftovers`.

    Returns
    -------
    str
        One line naming the folder.
    """
    path = Path(path)
    match = SWAP_FOLDER.match(path.name)
    if match is None:
        return f"'{path}' is not a leftover of a stage swap"
    stage, kind = match["stage"], match["kind"]
    if kind == "tmp":
        return f"'{path}': unfinished outputs of stage '{stage}' (removed by the next run)"
    if (path.parent / stage).exists():
        return f"'{path}': the replaced outputs of stage '{stage}' (removed by the next run)"
    return (
        f"'{path}': the outputs of stage '{stage}', moved aside by an interrupted swap "
        "(restored by the next run)"
    )


def recover(output_dir: str | os.PathLike) -> list[str]:
    """Resolve the leftovers of interrupted stage swaps.

    A moved-aside folder whose stage folder is missing is restored (the newest one, if
    several); other moved-aside folders and all temporary folders are removed. Call it
    only while holding the output folder's lock.

    Parameters
    ----------
    output_dir : path-like
        The workflow's output folder.

    Returns
    -------
    list of str
        One line per leftover, saying what was done.
    """
    done = []
    found = leftovers(output_dir)
    olds = sorted(
        (p for p in found if SWAP_FOLDER.match(p.name)["kind"] == "old"),
        key=lambda p: p.lstat().st_mtime,
        reverse=True,
    )
    for path in olds:
        final = path.parent / SWAP_FOLDER.match(path.name)["stage"]
        if not os.path.lexists(final) and not path.is_symlink():
            os.replace(path, final)
            done.append(f"restored '{final.name}' from '{path.name}' (an interrupted swap)")
        else:
            artifacts.remove_tree(path)
            done.append(f"removed '{path.name}' (replaced outputs of an interrupted swap)")
    for path in found:
        if SWAP_FOLDER.match(path.name)["kind"] == "tmp":
            artifacts.remove_tree(path)
            done.append(f"removed '{path.name}' (unfinished outputs of an interrupted run)")
    return done
