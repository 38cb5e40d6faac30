"""Workflow files: TOML descriptions of one experiment (or fleet) and the stages to run on it.

A workflow names its data sets (source file, role, per-set ingest overrides) and
holds one section per stage. Paths inside are relative to the workflow file, so
a workflow runs the same from any working directory.

Examples
--------
A minimal workflow::

    [workflow]
    name = "silverbox"
    output_dir = "../runs/silverbox"

    [ingest]
    sample_time = 1.6384e-3
    q = { column = 1, unit = "V" }
    v1 = { column = 0, unit = "V" }

    [datasets.estimation]
    source = "../data/silverbox/SNLS80mV.csv.gz"
    role = "estimation"
    slice = [40650, 105712]

    [differentiate]
    method = "tvregdiff"

    [identify]
    M = 10

    [validate]
    init_samples = 50
"""

from __future__ import annotations

import copy
import json
import os
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from debist.core.arguments import check_path, check_path_text, check_regular_file
from debist.core.errors import ArgumentError, WorkflowError
from debist.core.names import check_file_name
from debist.workflow import tomltext
from debist.workflow.overrides import override_folder, overrides_table
from debist.workflow.schema import DATALESS, ROLES, SECTIONS, check_workflow

__all__ = ["DATALESS", "ROLES", "SECTIONS", "DatasetSpec", "Workflow", "load_workflow"]


@dataclass(frozen=True)
class DatasetSpec:
    """One data set of a workflow.

    Parameters
    ----------
    name : str
        Data set name (used for artifact file names).
    source : pathlib.Path
        Rig-log file, resolved against the workflow file's folder.
    role : {"estimation", "validation"}
        Used for identification, or only for validation.
    ingest : dict
        The workflow's ``[ingest]`` section updated by this data set's own keys.
    rig : str or None
        Name of the virtual-rig experiment (``[rig.experiments.<name>]``) whose log this
        data set is; its ``source`` is then that log in the rig stage's folder.
    """

    name: str
    source: Path
    role: str
    ingest: dict[str, Any]
    rig: str | None = None


@dataclass(frozen=True)
class Workflow:
    """A parsed workflow file.

    Parameters
    ----------
    path : pathlib.Path
        The workflow file (absolute).
    name : str
        Workflow name.
    output_dir : pathlib.Path
        Root of the stage directories.
    datasets : tuple of DatasetSpec
        Data sets in file order; empty for a design analysis (``[physics]`` only).
    sections : dict
        The stage sections (``differentiate``, ``identify``, ``validate``, ...).
    overrides : dict
        The settings overridden for this run, as nested tables (``{"identify": {"M": 8}}``;
        empty for the file as it is). With overrides and no ``--out``, ``output_dir`` is the
        folder of :func:`debist.workflow.overrides.override_folder` beside the workflow's own;
        an ``--out`` the user names is ``output_dir`` itself.
    own_output_dir : pathlib.Path or None
        With overrides, the workflow's own output folder, whose stages the settings leave
        as they are may be copied instead of recomputed (:meth:`debist.engine.runner.
        Runner.run`); None without overrides, or when it is ``output_dir`` itself.
    """

    path: Path
    name: str
    output_dir: Path
    datasets: tuple[DatasetSpec, ...]
    sections: dict[str, dict[str, Any]] = field(default_factory=dict)
    overrides: dict[str, Any] = field(default_factory=dict)
    own_output_dir: Path | None = None

    def section(self, name: str) -> dict[str, Any]:
        """Return a stage section (empty if absent)."""
        return dict(self.sections.get(name, {}))

    def stage_dir(self, stage: str) -> Path:
        """Directory of a stage's artifacts."""
        return self.output_dir / stage


def _resolve(path: Path, what: str) -> Path:
    """Return the absolute path with symbolic links resolved, or say why it cannot be."""
    if "\x00" in str(path):
        raise WorkflowError(f"{what} {str(path)!r} holds a NUL byte: not a path")
    check_path_text(path, what)  # e.g. 'ü' under LC_ALL=C with PYTHONUTF8=0
    try:
        return path.resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop (RuntimeError before 3.13)
        raise WorkflowError(f"{what} '{path}' cannot be resolved: {exc}") from None


def _read(path: Path) -> dict[str, Any]:
    """Read and parse the workflow file, one line per way it can fail."""
    where = f"workflow file '{path}'"
    check_regular_file(path, "workflow file")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise WorkflowError(f"{where} does not exist") from None
    except IsADirectoryError:
        raise WorkflowError(f"{where} is a directory, not a TOML file") from None
    except UnicodeDecodeError as exc:
        raise WorkflowError(
            f"{where} is not UTF-8 text (byte {exc.start}: {exc.reason}); TOML files are UTF-8"
        ) from None
    except OSError as exc:
        raise WorkflowError(f"{where} cannot be read: {exc.strerror or exc}") from None
    try:
        return tomltext.loads(text, where)
    except tomllib.TOMLDecodeError as exc:
        raise WorkflowError(f"{where} is not valid TOML: {exc}") from None


def _items(overrides: object) -> list[str]:
    """Return the ``KEY=VALUE`` strings of a sequence of overrides, each checked."""
    if isinstance(overrides, str | bytes) or not isinstance(overrides, Sequence):
        raise ArgumentError(
            f"overrides: expected a mapping {{'identify.M': 8}} or a list of 'KEY=VALUE' "
            f"strings, got {type(overrides).__name__} {overrides!r}"
        )
    for item in overrides:
        if not isinstance(item, str):
            raise ArgumentError(
                f"overrides: expected 'KEY=VALUE' strings such as 'identify.M=8', got "
                f"{type(item).__name__} {item!r}"
            )
    return list(overrides)


def _output_dir(path: Path, what: str) -> Path:
    """Resolve an output folder and refuse one that is (or lies inside) a file."""
    out = _resolve(path, what)
    if not out.name:  # the stage folders would land in the file system's root
        raise ArgumentError(
            f"{what} '{out}' is the root of the file system; choose a folder of its own"
        )
    for parent in (out, *out.parents):
        if os.path.lexists(parent):
            if not parent.is_dir():
                raise ArgumentError(
                    f"{what} '{out}' cannot be a folder: '{parent}' is a file, not a directory"
                )
            break
    return out


def _own_output_dir(
    path: Path, name: str, stated: str | None, *, strict: bool = False
) -> Path | None:
    """Return the workflow's own output folder (``[workflow] output_dir`` or ``runs/<name>``).

    ``strict``: raise when it cannot be a folder; else None (a run with ``--out`` only reads
    it, to copy the stages its overrides leave as they are).
    """
    try:
        if stated:
            return _output_dir(path.parent / Path(stated).expanduser(), "[workflow] output_dir")
        check_file_name(name, f"{path}: [workflow] name (no output_dir given)")
        return _output_dir(path.parent / "runs" / name, "[workflow] output_dir")
    except (ArgumentError, WorkflowError):
        if strict:
            raise
        return None


def parse_overrides(items: Sequence[str]) -> dict[str, Any]:
    """Parse ``KEY=VALUE`` settings (``debist run --set``) into a nested table.

    ``KEY`` is a TOML dotted key (``identify.M``, ``datasets."run.2".role``) and ``VALUE`` a
    TOML value (``8``, ``[4, 6]``, ``"auto"``); a value that is not valid TOML is taken as
    a string (``differentiate.method=spectral``).

    Parameters
    ----------
    items : sequence of str
        The settings, in order (a later one wins).

    Returns
    -------
    dict
        Nested tables, e.g. ``{"identify": {"M": 8}}``.

    Raises
    ------
    WorkflowError
        If an item has no ``=``, holds a line break (a value is one TOML value, so no
        ``[table]`` header can follow it), its key is not a TOML key or its value nests
        arrays or inline tables deeper than :data:`debist.workflow.tomltext.MAX_NESTING`.

    Examples
    --------
    >>> parse_overrides(["identify.M=8", "differentiate.method=spectral"])
    {'identify': {'M': 8}, 'differentiate': {'method': 'spectral'}}
    """
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise WorkflowError(f"--set {item!r}: expected KEY=VALUE, e.g. identify.M=8")
        if item.splitlines() != [item]:  # a line break of str.splitlines, anywhere
            raise WorkflowError(
                f"--set {item!r}: expected one KEY=VALUE on one line; a value is one TOML "
                "value, with no line break or [table] header"
            )
        try:
            table = tomltext.loads(f"{key.strip()} = {value.strip()}", "--set")
        except tomllib.TOMLDecodeError:
            try:
                table = tomllib.loads(f"{key.strip()} = {json.dumps(value.strip())}")
            except tomllib.TOMLDecodeError as exc:
                raise WorkflowError(
                    f"--set {item!r}: {key.strip()!r} is not a key: {exc}"
                ) from None
        _merge(out, table)
    return out


def _merge(base: dict[str, Any], extra: Mapping[str, Any]) -> dict[str, Any]:
    """Merge nested tables into ``base`` in place (values of ``extra`` win)."""
    for key, value in extra.items():
        if isinstance(value, Mapping) and isinstance(base.get(key), dict):
            _merge(base[key], value)
        else:
            base[key] = dict(value) if isinstance(value, Mapping) else value
    return base


def load_workflow(
    path: str | Path,
    output_dir: str | Path | None = None,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
) -> Workflow:
    """Read a workflow file and check every section before any stage runs.

    Parameters
    ----------
    path : path-like
        The TOML file.
    output_dir : path-like, optional
        Overrides ``[workflow] output_dir``: the run's folder, exactly, with or without
        ``overrides``.
    overrides : mapping or sequence of str, optional
        Settings that replace the file's, checked by the same schema: ``{"identify.M": 8}``
        (dotted keys), nested mappings meaning the same (``{"identify": {"M": 8}}``,
        :func:`debist.workflow.overrides.overrides_table`), or ``["identify.M=8"]``
        (:func:`parse_overrides`). The stages see the merged workflow, so their manifests
        record the values used. Without ``output_dir`` the run goes to its own folder beside
        the workflow's (:func:`debist.workflow.overrides.override_folder`).

    Returns
    -------
    Workflow

    Raises
    ------
    WorkflowError
        In one line: the file is missing, a directory, a FIFO, socket or device (refused
        before it is opened), not UTF-8, not valid TOML, nested
        deeper than :data:`debist.workflow.tomltext.MAX_NESTING` or a symlink loop; a
        section or key is unknown or a value invalid
        (:func:`debist.workflow.schema.check_workflow`: ``[section] key: expected ..., got ...``);
        a source file is missing, a directory or a symlink loop; the output folder is a
        file (or lies inside one) or a symlink loop; a path this locale's file-name
        encoding cannot hold (:func:`debist.core.arguments.check_path_text`); ``path`` or
        ``output_dir`` not a path;
        an override that is not a TOML key and value (``None``: TOML has no null).
    """
    check_path(path, "workflow")
    check_path(output_dir, "output_dir", optional=True)
    path = _resolve(Path(path), "workflow file")
    raw = _read(path)
    changed: dict[str, Any] = {}
    if isinstance(overrides, Mapping):
        changed = overrides_table(overrides)
    elif overrides:
        changed = parse_overrides(_items(overrides))
    if changed:
        _merge(raw, copy.deepcopy(changed))
    try:
        checked = check_workflow(raw)
    except WorkflowError as exc:  # keep the class (a ResourceError stays one)
        raise type(exc)(f"{path}: {exc}", key=exc.key, value=exc.value) from None
    head = checked.head
    name = head.name if head.name is not None else path.stem
    base = path.parent
    if output_dir:  # named by the user: the run goes exactly there, overrides or not
        out = _output_dir(Path(output_dir).expanduser(), "output folder (--out)")
        own = _own_output_dir(path, name, head.output_dir) if changed else None
    else:
        own = _own_output_dir(path, name, head.output_dir, strict=True)
        out = override_folder(own, changed)
    datasets = []
    for ds_name, (entry, _) in checked.datasets.items():
        table = raw["datasets"][ds_name]
        where = f"{path}: [datasets.{ds_name}] source:"
        if entry.rig is not None:
            source = out / "rig" / f"{entry.rig}.mat"
        else:
            source = _resolve(base / entry.source, f"{where} file")
            if source.is_dir():
                raise WorkflowError(f"{where} '{source}' is a directory, not a rig-log file")
            if source.exists() and not source.is_file():
                raise WorkflowError(
                    f"{where} '{source}' is not a regular file (a device, pipe or socket), "
                    "not a rig-log file"
                )
            if not source.is_file():
                raise WorkflowError(f"{where} file '{source}' does not exist")
        overrides = {k: v for k, v in table.items() if k not in ("source", "role", "rig")}
        ingest = {**raw.get("ingest", {}), **overrides}
        datasets.append(DatasetSpec(ds_name, source, entry.role, ingest, entry.rig))
    sections = {k: v for k, v in raw.items() if k not in ("workflow", "ingest", "datasets")}
    copy_from = own if changed and own != out else None
    return Workflow(path, name, out, tuple(datasets), sections, changed, copy_from)
