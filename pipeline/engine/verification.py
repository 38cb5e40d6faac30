"""Verify a run: every artifact, every manifest, the chain of manifests and a quoted digest.

:meth:`debist.engine.runner.Runner.verify` and ``version_notes`` call these. A verification
only reads the output folder, except that it re-reads the data sources (ingest is a pure
function of them) and, to explain a digest that differs, reruns the workflow into a
temporary folder.

The run digest is :func:`debist.core.artifacts.run_digest` over the stage manifests in order.
"""

from __future__ import annotations

import importlib
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

from debist.core import artifacts
from debist.core.errors import ArtifactError, RunLockedError
from debist.core.fileformats import write_output
from debist.engine import outdir
from debist.engine.rundiff import set_run_beside
from debist.stages import registry
from debist.workflow.overrides import override_folder

__all__ = ["missing_output", "verify_run", "version_notes"]


def missing_output(
    output_dir: str | Path, overrides: dict[str, Any], stages: list[str] | tuple[str, ...]
) -> str | None:
    """Say that a workflow's output folder does not exist, naming the run it may mean.

    With ``--set`` overrides, the folder a run with exactly those settings and no ``--out``
    wrote beside it (:func:`debist.workflow.overrides.override_folder`); without them, the
    newest ``<folder>.set-<8 hex>`` run beside it (:func:`debist.engine.rundiff.set_run_beside`),
    as ``diff`` suggests.

    Parameters
    ----------
    output_dir : path-like
        The run's output folder (``--out`` or ``[workflow] output_dir``).
    overrides : dict
        The run's ``--set`` overrides (nested tables; empty for none).
    stages : sequence of str
        The workflow's stages: a folder counts as its run when one of them has a manifest.

    Returns
    -------
    str or None
        One line (``output folder '...' does not exist (the workflow was never run
        there)`` and the hint, if any), or None when the folder exists.

    Examples
    --------
    >>> missing_output("/nonexistent/runs/rig", {}, ["rig"])
    "output folder '/nonexistent/runs/rig' does not exist (the workflow was never run there)"
    """
    out = Path(output_dir)
    if out.is_dir():
        return None
    exact = override_folder(out, overrides)
    if exact != out:
        ran = any((exact / s / artifacts.MANIFEST).is_file() for s in stages)
        hint = f"; the run with these --set settings beside it is '{exact}' (pass that --out)"
        hint = hint if ran else ""
    else:
        near = set_run_beside(out)
        hint = f"; did you mean '{near}' (a run with --set overrides)?" if near else ""
    return f"output folder '{out}' does not exist (the workflow was never run there){hint}"


def _changed_keys(config: dict[str, Any], recorded: dict[str, Any]) -> list[str]:
    """Keys whose values differ between a stage config and a manifest's, with the values."""
    canon = artifacts.canonical_json
    out = []
    for k in sorted(set(config) | set(recorded)):
        if canon(config.get(k)) != canon(recorded.get(k)):
            out.append(f"{k} ({canon(recorded.get(k))} -> {canon(config.get(k))})")
    return out


def verify_run(runner: Any, digest: str | None = None) -> list[str]:
    """Check every artifact, every manifest and the chain (and a quoted digest).

    Parameters
    ----------
    runner : debist.engine.runner.Runner
        The workflow's runner (its output folder, stages and keys; not imported here:
        the runner imports this module).
    digest : str, optional
        A run digest (as ``run`` prints it) the manifests must match.

    Returns
    -------
    list of str
        Problems, each naming the file: a missing output folder (and the run with the
        same overrides in its ``.set-`` folder beside it, if there is one), missing or extra
        stage folders and manifests, modified, missing or unlisted outputs, manifests
        whose key does not match their own fields, a broken chain (recorded inputs or
        upstream manifests that differ from the current ones, changed source files),
        leftovers of an interrupted run, and a digest that differs. Empty when all is
        intact.

    Raises
    ------
    RunLockedError
        While another process writes to the output folder.
    """
    out = runner.wf.output_dir
    mine = runner.stages()
    missing = missing_output(out, runner.wf.overrides, mine)
    if missing is not None:
        return [missing]
    if outdir.is_locked(out):
        raise RunLockedError(
            f"output folder '{out}' is being written by {outdir.lock_holder(out)}: "
            "verify when it is done"
        )
    problems = [outdir.describe_leftover(p) for p in outdir.leftovers(out)]
    for entry in sorted(out.iterdir()):
        if (
            entry.is_dir()
            and entry.name not in mine
            and not artifacts.SET_ASIDE.fullmatch(entry.name)
            and (entry.name in registry.names() or (entry / artifacts.MANIFEST).exists())
        ):
            problems.append(f"'{entry}': extra stage folder (not a stage of this workflow)")
    for stage in mine:
        problems += _verify_stage(runner, stage)
    if not problems:
        problems += _verify_ingest(runner)
    if digest is not None and not problems:
        quoted = digest.strip().lower()
        actual = runner.digest()
        if actual != quoted:
            problems.append(_explain_digest(runner, quoted, actual))
    return problems


def version_notes(runner: Any) -> list[str]:
    """Libraries installed now in other versions than those that made the run's stages.

    Not a failure (the artifacts verify by their hashes), but a rerun may give other
    bytes, so ``verify`` says it.

    Parameters
    ----------
    runner : debist.engine.runner.Runner
        The workflow's runner.

    Returns
    -------
    list of str
        One line per stage and library, e.g. ``"identify: numpy 2.3.5 made it, 2.4.6
        installed"``.
    """
    notes = []
    for stage in runner.stages():
        try:
            manifest = artifacts.read_manifest(runner.wf.stage_dir(stage))
        except ArtifactError:
            continue
        if manifest is None:
            continue
        _, now = runner._code(stage)
        for lib, made in sorted(manifest.versions.items()):
            if now.get(lib, made) != made:
                notes.append(f"{stage}: {lib} {made} made it, {now[lib]} installed now")
    return notes


def _explain_digest(runner: Any, quoted: str, actual: str | None) -> str:
    """Say where a run departs from a quoted digest, by rerunning its workflow elsewhere.

    The digest hashes the stage manifests in order, so it implies every manifest only
    through a run that produces it: the workflow is rerun from its sources into a
    temporary folder (stages are deterministic), and when that rerun gives the quoted
    digest, the first stage whose manifest differs from the rerun's is the one changed.
    """
    with tempfile.TemporaryDirectory(prefix="debist-verify-") as tmp:
        fresh = type(runner)(replace(runner.wf, output_dir=Path(tmp) / "run"))
        fresh.run()
        again = fresh.digest()
        first = next(
            (
                s
                for s in runner.stages()
                if artifacts.manifest_digest(runner.wf.stage_dir(s))
                != artifacts.manifest_digest(fresh.wf.stage_dir(s))
            ),
            None,
        )
    out = runner.wf.output_dir
    if again == quoted and first is not None:
        return (
            f"'{runner.wf.stage_dir(first) / artifacts.MANIFEST}': stage '{first}' differs from "
            f"the run the quoted digest {quoted} names (a rerun of this workflow from its "
            f"sources gives that digest; this run's is {actual})"
        )
    if again == actual:
        return (
            f"'{out}': the quoted digest {quoted} is not this run's: the run is intact and "
            f"a rerun from its sources gives its digest {actual}; the quoted one names "
            "another run (other sources, workflow or library versions)"
        )
    return (
        f"'{out}': the quoted digest {quoted} matches neither this run ({actual}) nor a "
        f"rerun of this workflow from its sources ({again}); the first stage that differs "
        f"from the rerun is '{first}'"
    )


def _verify_ingest(runner: Any) -> list[str]:
    """Re-read the sources and compare with the ingest artifacts (they must be identical).

    Ingest is where measured data enter; its outputs are a pure function of the
    sources and the workflow, cheap to recompute. A table edited and re-signed with
    consistent hashes and keys is found here, without a digest.
    """
    sdir = runner.wf.stage_dir("ingest")
    manifest = artifacts.read_manifest(sdir)
    if manifest is None or "ingest" not in runner.stages():
        return []
    module = importlib.import_module(registry.stage("ingest").module)
    result = module.execute(runner)
    with tempfile.TemporaryDirectory(prefix="debist-verify-") as tmp:
        fresh = {}
        for rel, value in result.outputs.items():
            target = Path(tmp) / rel
            write_output(value, target)
            fresh[rel] = artifacts.sha256_file(target)
    differ = sorted(
        rel for rel in set(fresh) | set(manifest.outputs) - {artifacts.SUMMARY}
        if fresh.get(rel) != manifest.outputs.get(rel)
    )  # fmt: skip
    return [
        f"'{sdir / rel}': differs from what the sources give now (re-read from the data "
        "sources of the workflow)"
        for rel in differ
    ]


def _verify_stage(runner: Any, stage: str) -> list[str]:
    sdir = runner.wf.stage_dir(stage)
    try:
        manifest = artifacts.read_manifest(sdir)
    except ArtifactError as exc:
        return [str(exc)]
    if manifest is None:
        return [f"'{sdir / artifacts.MANIFEST}': missing (stage '{stage}' never ran)"]
    path = sdir / artifacts.MANIFEST
    problems = [f"'{sdir / c}'" for c in artifacts.changed_outputs(sdir, manifest)]
    if manifest.stage != stage or manifest.expected_key() != manifest.key:
        problems.append(f"'{path}': edited (its key does not match its own fields)")
    changed = _changed_keys(runner.stage_config(stage), manifest.config)
    if changed:
        problems.append(
            f"'{path}': the workflow changed since this run: [{stage}] {', '.join(changed)}"
        )
    for up in runner._upstream(stage):
        recorded = manifest.upstream.get(up)
        actual = artifacts.manifest_digest(runner.wf.stage_dir(up))
        if recorded != actual:
            problems.append(
                f"'{path}': broken chain, upstream manifest '{up}/{artifacts.MANIFEST}' "
                "is not the one this stage was made from"
            )
    found = runner._inputs(stage)
    if found is not None and found[0] != manifest.inputs:
        names = sorted(
            k
            for k in set(found[0]) | set(manifest.inputs)
            if found[0].get(k) != manifest.inputs.get(k)
        )
        problems.append(
            f"'{path}': made from other inputs than the current ones ({', '.join(names[:3])})"
        )
    return problems
