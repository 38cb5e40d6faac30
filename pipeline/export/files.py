"""A run's identified model as the files of one export format (what ``debist export`` writes).

:func:`load_identified` reads the identify stage's model (checking it is up to date),
:func:`load_scheme` the run's records and ``[validate]`` table for the scheme the code
carries, and :func:`export_files` renders the files of a format with the generators of
:mod:`.c`, :mod:`.matlab` and :mod:`.python`.

References
----------
Masoud & Maas 2025, Eq. 37-40 (the model exported).
"""

from __future__ import annotations

from pathlib import Path

from debist.core import artifacts
from debist.core.errors import OutputDirError, WorkflowError
from debist.export.c import c_sources
from debist.export.common import ExportInfo
from debist.export.matlab import matlab_source
from debist.export.python import python_source
from debist.export.scheme import Scheme, run_scheme
from debist.identify.bands import identified_intervals
from debist.model.rbf import RBFModel
from debist.validate.config import ValidateConfig
from debist.validate.datasets import validation_datasets

__all__ = ["FORMATS", "export_files", "export_folder", "load_identified", "load_scheme"]

#: Export formats of ``debist export --format``.
FORMATS = ("c", "matlab", "python")


def export_files(
    model, fmt: str, info: ExportInfo | None = None, scheme: Scheme | None = None
) -> dict[str, str]:
    """Return the files of an export format.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    fmt : {"c", "matlab", "python"}
        :func:`c_sources`, :func:`matlab_source` or :func:`python_source`.
    info : ExportInfo, optional
        Provenance for the header comments.
    scheme : Scheme, optional
        The free-run scheme and its scores on the run's records (:func:`load_scheme`);
        default :func:`debist.export.scheme.default_scheme`.

    Returns
    -------
    dict of str to str
        File name to text.

    Raises
    ------
    WorkflowError
        If ``fmt`` is unknown.
    """
    if fmt == "c":
        return c_sources(model, info, scheme)
    if fmt == "matlab":
        return matlab_source(model, info, scheme)
    if fmt == "python":
        return python_source(model, info, scheme)
    raise WorkflowError(f"--format must be one of {FORMATS}, got {fmt!r}")


def load_identified(runner):
    """Read the identified model of a run after checking that identify is up to date.

    Parameters
    ----------
    runner : debist.engine.runner.Runner
        The workflow's runner.

    Returns
    -------
    model : RBFModel
        From ``identify/model.h5``.
    info : ExportInfo
        Workflow name, run digest, sha256 of ``identify/manifest.json`` and the identified
        intervals of ``identify/curves.parquet``.

    Raises
    ------
    WorkflowError
        If the workflow has no identify stage (no data sets), or the identify stage is
        missing or stale (naming why: never run, outputs changed such as a modified
        ``model.h5``, config or upstream changed), as ``run --stages`` refuses it.
    """
    wf = runner.wf
    if "identify" not in runner.stages():
        raise WorkflowError(
            f"workflow '{wf.path}' has no identify stage (no [[datasets]]): nothing to export"
        )
    state = next(s for s in runner.status() if s.stage == "identify")
    sdir = wf.stage_dir("identify")
    if state.state != "up to date":  # a usage problem, as `run --stages` says it (exit 2)
        raise WorkflowError(
            f"stage 'identify' in '{sdir}' is {state.state} ({state.reason}): run "
            f"`debist identify {wf.path}` (or `debist run`) first"
        )
    model = RBFModel.from_tree(artifacts.read_h5(sdir / "model.h5"), str(sdir / "model.h5"))
    manifest = artifacts.read_manifest(sdir)
    identified: dict[str, list[list[float]]] = {}
    if manifest is not None and "curves.parquet" in manifest.outputs:
        frame = artifacts.read_parquet(sdir / "curves.parquet")
        for col in frame.columns:
            if col.endswith("_identified"):
                mask = frame[col].to_numpy(dtype=bool)
                identified[col[: -len("_identified")]] = identified_intervals(
                    frame["q"].to_numpy(), mask
                )
    info = ExportInfo(
        workflow=wf.name,
        run_digest=runner.digest(),
        identify_manifest=artifacts.manifest_digest(sdir),
        identified=identified,
    )
    return model, info


def load_scheme(runner, model) -> Scheme:
    """Return the scheme of the run's validate stage and what the exported code scores on it.

    Reads the ingest and differentiate tables (up to date with an up-to-date identify
    stage), the workflow's ``[validate]`` table and, when the validate stage is up to date,
    its NRMSE(q) of the identified model (``validate/nrmse.parquet``) to print beside
    the export's own.

    Parameters
    ----------
    runner : debist.engine.runner.Runner
        The workflow's runner; its identify stage is up to date (:func:`load_identified`).
    model : RBFModel
        The identified model.

    Returns
    -------
    Scheme
        :func:`debist.export.scheme.run_scheme` on the run's records.

    Raises
    ------
    WorkflowError
        If the ``[validate]`` table is invalid (naming the key).
    ArtifactError
        If the ingest or differentiate stage has no artifacts.
    """
    cfg = ValidateConfig.from_dict(runner.section("validate"))
    datasets = validation_datasets(runner.tables("ingest"), runner.tables("differentiate"))
    reported: dict[str, float] = {}
    state = {s.stage: s.state for s in runner.status()}
    if state.get("validate") == "up to date":
        table = runner.read_parquet("validate", "nrmse.parquet")
        rows = table[table["model"] == "rbf"]
        reported = dict(zip(rows["dataset"], rows["nrmse_q"].astype(float), strict=True))
    return run_scheme(model, datasets, cfg, reported)


def export_folder(output_dir: Path, dest: Path | None, names) -> Path:
    """Return the folder the export's files go to, refusing a symbolic link on the way.

    The default folder is ``export/`` in the output folder: a symbolic link there (the
    folder or one of the files) would take the write, and with ``--force`` the replacement,
    to a place outside the output folder, so it is refused; so is a file of ``dest`` that
    is a symbolic link.

    Parameters
    ----------
    output_dir : pathlib.Path
        The run's output folder.
    dest : pathlib.Path or None
        The folder the user chose (``--dest``), or None for ``<output_dir>/export``.
    names : iterable of str
        The file names about to be written.

    Returns
    -------
    pathlib.Path
        ``dest``, or ``output_dir / "export"``.

    Raises
    ------
    OutputDirError
        The default folder is a symbolic link or resolves outside ``output_dir``, or a
        file to be written is a symbolic link, naming it.
    """
    target = output_dir / "export" if dest is None else Path(dest)
    if dest is None and (
        target.is_symlink()
        or (target.exists() and not target.resolve().is_relative_to(output_dir.resolve()))
    ):
        raise OutputDirError(
            f"export folder '{target}' is a symbolic link: refused, debist writes only into "
            "the output folder itself (remove the link, or give --dest)"
        )
    for name in names:
        if (target / name).is_symlink():
            raise OutputDirError(
                f"'{target / name}' is a symbolic link: refused, debist never writes through "
                "one (remove it)"
            )
    return target
