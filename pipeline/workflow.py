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

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pipeline.errors import WorkflowError

ROLES = ("estimation", "validation")
SECTIONS = (
    "workflow",
    "ingest",
    "datasets",
    "differentiate",
    "identify",
    "validate",
    "compare",
    "study",
    "physics",
    "analyze",
    "rig",
)
#: Sections that make a workflow meaningful without data sets (a design analysis).
DATALESS = ("physics",)


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
    """

    path: Path
    name: str
    output_dir: Path
    datasets: tuple[DatasetSpec, ...]
    sections: dict[str, dict[str, Any]] = field(default_factory=dict)

    def section(self, name: str) -> dict[str, Any]:
        """Return a stage section (empty if absent)."""
        return dict(self.sections.get(name, {}))

    def stage_dir(self, stage: str) -> Path:
        """Directory of a stage's artifacts."""
        return self.output_dir / stage


def load_workflow(path: str | Path, output_dir: str | Path | None = None) -> Workflow:
    """Read and check a workflow file.

    Parameters
    ----------
    path : path-like
        The TOML file.
    output_dir : path-like, optional
        Overrides ``[workflow] output_dir``.

    Returns
    -------
    Workflow

    Raises
    ------
    WorkflowError
        If the file is missing or not valid TOML, a section or key is unknown, a
        data set lacks ``source`` or has a bad ``role``, a source file is missing, there
        are neither data sets nor a ``[physics]`` section, or a physics parameter is invalid.
    """
    path = Path(path).resolve()
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise WorkflowError(f"workflow file '{path}' does not exist") from None
    except tomllib.TOMLDecodeError as exc:
        raise WorkflowError(f"workflow file '{path}' is not valid TOML: {exc}") from None
    unknown = set(raw) - set(SECTIONS)
    if unknown:
        raise WorkflowError(f"'{path}': unknown section(s) {sorted(unknown)}; known: {SECTIONS}")
    if "physics" in raw:
        from pipeline.physics.params import PrototypeParams

        try:
            PrototypeParams.from_dict(raw["physics"])
        except WorkflowError as exc:
            raise WorkflowError(f"'{path}' {exc}") from None
    head = raw.get("workflow", {})
    name = head.get("name", path.stem)
    for key in set(head) - {"name", "description", "output_dir"}:
        raise WorkflowError(f"'{path}' [workflow]: unknown key {key!r}")
    base = path.parent
    out = Path(output_dir) if output_dir else base / head.get("output_dir", f"runs/{name}")
    datasets = []
    default_ingest = raw.get("ingest", {})
    experiments = raw.get("rig", {}).get("experiments", {})
    for ds_name, table in raw.get("datasets", {}).items():
        where = f"'{path}' [datasets.{ds_name}]"
        if not isinstance(table, dict) or ("source" in table) == ("rig" in table):
            raise WorkflowError(
                f"{where}: needs a `source` file or a virtual-rig experiment `rig` (one of them)"
            )
        role = table.get("role", "validation")
        if role not in ROLES:
            raise WorkflowError(f"{where}: role must be one of {ROLES}, got {role!r}")
        rig = table.get("rig")
        if rig is not None:
            if rig not in experiments:
                raise WorkflowError(
                    f"{where}: rig experiment {rig!r} is not in [rig.experiments] "
                    f"(known: {sorted(experiments)})"
                )
            source = (out / "rig" / f"{rig}.mat").resolve()
        else:
            source = (base / table["source"]).resolve()
            if not source.is_file():
                raise WorkflowError(f"{where}: source file '{source}' does not exist")
        keys = ("source", "role", "rig")
        overrides = {k: v for k, v in table.items() if k not in keys}
        datasets.append(DatasetSpec(ds_name, source, role, {**default_ingest, **overrides}, rig))
    if not datasets and not any(name in raw for name in DATALESS):
        raise WorkflowError(
            f"'{path}': no [datasets.<name>] section (and no [physics] section to analyze)"
        )
    if datasets and not any(d.role == "estimation" for d in datasets):
        raise WorkflowError(f"'{path}': no data set has role = 'estimation'")
    sections = {k: v for k, v in raw.items() if k not in ("workflow", "ingest", "datasets")}
    return Workflow(path, name, out.resolve(), tuple(datasets), sections)
