"""Run a workflow's stages with content-hash caching; report status; verify a run.

A stage is up to date when its manifest's key equals the key computed from the current
configuration, the fingerprint of the stage's code, its libraries' versions, its input
hashes and its upstream manifests, and its outputs still hash to the manifest. ``run``
skips such stages; anything else is rerun, and so is everything downstream whose inputs
change as a result.

Before a run writes anything it checks the output folder (:mod:`debist.engine.outdir`: its
owner, forbidden places, foreign files in stage folders), takes the folder's lock and
resolves the leftovers of an interrupted run. ``status`` and ``verify`` only read.
"""

from __future__ import annotations

import importlib
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any

from threadpoolctl import threadpool_limits

from debist.core import artifacts
from debist.core.allocator import collector_frozen, release_freed_memory
from debist.core.beside import BesideRun
from debist.core.errors import (
    ArtifactError,
    DebistError,
    OutputDirError,
    RigLogError,
    WorkflowError,
)
from debist.core.faults import fault_point
from debist.core.fileformats import FileIdentity, file_identity, sha256_identified
from debist.core.forking import fork_workers, one_core
from debist.engine import outdir, verification
from debist.engine.fingerprint import code_fingerprint
from debist.physics.params import PrototypeParams
from debist.stages import registry
from debist.workflow.loader import Workflow

#: Stage names in execution order.
STAGES = registry.names()
#: Stages that read measured data sets.
DATA_STAGES = ("ingest", "differentiate", "identify", "validate", "compare", "study")


@dataclass(frozen=True)
class Reason:
    """One reason why a stage is stale or missing.

    Attributes
    ----------
    kind : str
        One of ``never_run``, ``foreign_files``, ``upstream_stale`` (an upstream stage will
        rerun), ``upstream_missing``, ``upstream_changed`` (recorded upstream manifests
        differ), ``artifact_missing``, ``artifact_modified``, ``artifact_unlisted``,
        ``config_changed``, ``input_changed``, ``code_changed``, ``library_changed``,
        ``layout_changed`` (made by an older debist), ``damaged_manifest`` (unreadable) and
        ``interrupted_run`` (leftovers).
    detail : str
        The same in words, naming the keys, files or stages.
    """

    kind: str
    detail: str


@dataclass(frozen=True)
class StageStatus:
    """State of one stage folder.

    Attributes
    ----------
    stage : str
        Stage name.
    state : {"up to date", "stale", "missing"}
        What a run would do: skip, rerun, run.
    reason : str
        Why it is stale or missing (empty when up to date); mentions the leftovers of an
        interrupted run and what the next run does with them.
    reasons : tuple of Reason
        The same, one entry per reason.
    """

    stage: str
    state: str
    reason: str = ""
    reasons: tuple[Reason, ...] = ()

    def to_json(self) -> dict[str, Any]:
        """Return ``{"state": "up_to_date" | "stale" | "missing", "reasons": [...]}``.

        Returns
        -------
        dict
            ``reasons``: one ``{"kind": ..., "detail": ...}`` per :class:`Reason`.
        """
        return {
            "state": self.state.replace(" ", "_"),
            "reasons": [{"kind": r.kind, "detail": r.detail} for r in self.reasons],
        }


Event = Callable[[str, str, str], None]


def physics_params(wf: Workflow):
    """Return the prototype of the workflow's ``[physics]`` section (Table 1 where absent).

    Parameters
    ----------
    wf : Workflow
        The workflow.

    Returns
    -------
    debist.physics.params.PrototypeParams
        Table 1 updated by the section's keys [SI].

    Raises
    ------
    WorkflowError
        On an unknown key or an invalid value.
    """
    return PrototypeParams.from_dict(wf.section("physics"))


def stage_config(wf: Workflow, stage: str) -> dict[str, Any]:
    """Return the resolved configuration of a stage: what of the workflow its key hashes.

    Parameters
    ----------
    wf : Workflow
        The workflow.
    stage : str
        Stage name.

    Returns
    -------
    dict
        JSON-compatible; source paths relative to the workflow file, so the same workflow
        gives the same keys in any clone.

    Raises
    ------
    WorkflowError
        On an invalid ``[physics]`` section.
    """
    if stage == "ingest":
        return {
            "datasets": {
                d.name: {
                    "source": f"rig:{d.rig}"
                    if d.rig
                    else Path(os.path.relpath(d.source, wf.path.parent)).as_posix(),
                    "role": d.role,
                    "ingest": d.ingest,
                }
                for d in wf.datasets
            }
        }
    if stage == "rig":
        return {"rig": wf.section("rig"), "physics": physics_params(wf).to_dict()}
    if stage == "study":
        names = ("study", "identify", "validate", "differentiate")
        return {name: wf.section(name) for name in names}
    # the unit the identify and analyze stages draw q in (their figures), when one is stated
    shown = wf.section("validate").get("report_unit")
    shown = {"report_unit": shown} if shown is not None else {}
    if stage == "analyze":
        return {"physics": physics_params(wf).to_dict(), "analyze": wf.section("analyze"), **shown}
    physics = {"physics": physics_params(wf).to_dict()} if "physics" in wf.sections else {}
    if stage == "compare":
        sindy = wf.section("compare")
        sindy.setdefault("input_map", wf.section("identify").get("input_map", "v2"))
        return {"sindy": sindy, "validate": wf.section("validate"), **physics}
    if stage == "identify":
        return {**wf.section(stage), **physics, **shown}
    if stage == "validate" and physics:
        return {**wf.section(stage), **physics}
    return wf.section(stage)


#: Stages that free-run models with the compiled kernels (:mod:`debist.simulate.warmup`).
FREE_RUN_STAGES = ("identify", "validate", "compare")
#: Nice value added to a stage run beside the others (only the report reads it): on a
#: machine with fewer free cores than work, the stages the run waits for come first.
BESIDE_NICENESS = 10


def _compile_ahead() -> list[BesideRun]:
    """Start compiling the free-run kernels in a forked process, unless they are cached.

    Returns
    -------
    list of BesideRun
        The process (to be stopped at the end of the run: it only fills numba's cache), or
        nothing when the kernels are cached or a child could not run them
        (:func:`debist.core.forking.fork_workers`).
    """
    from debist.simulate import warmup  # the compiled kernels load only when a stage needs them

    if fork_workers(2) < 2 or warmup.kernels_cached():
        return []
    return [BesideRun(warmup.compile_kernels, "compiling the free-run kernels ahead")]


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block with one BLAS thread in every BLAS library a stage may call.

    As in a batch's worker processes: a multi-threaded BLAS sums in another order, and a
    run's bytes must not depend on where it ran. threadpoolctl limits the libraries loaded
    when the block starts, and SciPy brings its own OpenBLAS, loaded with ``scipy.linalg``
    (which the command line imports on first use), so that is loaded first.

    Yields
    ------
    None

    References
    ----------
    threadpoolctl, ``threadpool_limits`` (https://github.com/joblib/threadpoolctl).
    """
    import scipy.linalg  # noqa: F401  here, not at the top: SciPy's BLAS, only when a stage runs

    with threadpool_limits(limits=1, user_api="blas"):
        yield


class Runner:
    """Executes, inspects and verifies the stages of one workflow.

    Implements :class:`debist.stages.StageInputs` for the stages it runs.

    Parameters
    ----------
    workflow : Workflow
        The parsed workflow.
    wait : bool, optional
        When another process writes to the same output folder, wait for it instead of
        refusing.
    """

    def __init__(self, workflow: Workflow, *, wait: bool = False):
        self.wf = workflow
        self.wait = wait
        self._source_hashes: dict[Path, tuple[str, FileIdentity | None]] = {}
        self._ahead: tuple[str, ...] = ()  # the stages still to run after the running one

    def stages(self) -> list[str]:
        """List the stages of this workflow, in execution order.

        The data stages when it has data sets, the optional stages with their section, and
        ``analyze`` also when ``[physics]`` is all there is.
        """
        out = []
        for s in STAGES:
            if s in DATA_STAGES and not self.wf.datasets:
                continue
            if s == "analyze":
                if "analyze" in self.wf.sections or (
                    "physics" in self.wf.sections and not self.wf.datasets
                ):
                    out.append(s)
            elif s not in registry.OPTIONAL or s in self.wf.sections:
                out.append(s)
        return out

    # ------------------------------------------------------- stage inputs
    def section(self, name: str) -> dict[str, Any]:
        """Return a section of the workflow (empty when absent)."""
        return self.wf.section(name)

    def physics(self):
        """Return the ``[physics]`` prototype, or None without that section."""
        return physics_params(self.wf) if "physics" in self.wf.sections else None

    def stage_config(self, stage: str) -> dict[str, Any]:
        """Return the resolved configuration of a stage (:func:`stage_config`)."""
        return stage_config(self.wf, stage)

    def load_ahead(self) -> None:
        """Import the stages still to run in this run and run their ``preload`` here.

        What :meth:`_load` does just before it forks a stage, for every stage after the
        running one; a stage that waits on its worker processes calls it, so that the
        loading takes the core they leave free. Runs nothing of the stages and decides
        nothing: a stage found up to date later has been loaded in vain.
        """
        for stage in self._ahead:
            self._load(stage)

    def _manifest(self, stage: str) -> artifacts.Manifest:
        manifest = artifacts.read_manifest(self.wf.stage_dir(stage))
        if manifest is None:
            raise ArtifactError(f"stage '{stage}' has no artifacts in '{self.wf.stage_dir(stage)}'")
        return manifest

    def tables(self, stage: str) -> dict[str, Any]:
        """Load the per-data-set Parquet tables of a stage (ingest or differentiate).

        Parameters
        ----------
        stage : str
            Stage name.

        Returns
        -------
        dict of str to pandas.DataFrame
            Table name to table, in name order.

        Raises
        ------
        ArtifactError
            If the stage has no artifacts.
        """
        manifest = self._manifest(stage)
        return {
            Path(rel).stem: artifacts.read_parquet(self.wf.stage_dir(stage) / rel)
            for rel in sorted(manifest.outputs)
            if rel.endswith(".parquet") and "/" not in rel
        }

    def read_h5(self, stage: str, rel: str) -> dict[str, Any]:
        """Read an HDF5 artifact of an upstream stage (see :mod:`debist.core.artifacts`)."""
        self._manifest(stage)
        return artifacts.read_h5(self.wf.stage_dir(stage) / rel)

    def summary(self, stage: str) -> dict[str, Any]:
        """Read an upstream stage's ``summary.json`` (checked against its manifest)."""
        return artifacts.read_summary(self.wf.stage_dir(stage), self._manifest(stage))

    def read_parquet(self, stage: str, rel: str) -> Any:
        """Read a Parquet artifact of an upstream stage (see :mod:`debist.core.artifacts`)."""
        self._manifest(stage)
        return artifacts.read_parquet(self.wf.stage_dir(stage) / rel)

    # ------------------------------------------------------------------ keys
    def _upstream(self, stage: str) -> tuple[str, ...]:
        """Stages whose artifacts ``stage`` reads: those of its upstream the workflow has."""
        if stage == "ingest" and any(d.rig for d in self.wf.datasets):
            return ("rig",)
        mine = self.stages()
        return tuple(u for u in registry.stage(stage).upstream if u in mine)

    def _inputs(self, stage: str) -> tuple[dict[str, str], dict[str, str]] | None:
        """Input hashes and upstream manifest hashes, or None when an upstream stage has none."""
        inputs: dict[str, str] = {}
        upstream: dict[str, str] = {}
        for up in self._upstream(stage):
            try:
                manifest = artifacts.read_manifest(self.wf.stage_dir(up))
            except ArtifactError:  # damaged: as good as missing
                return None
            if manifest is None:
                return None
            upstream[up] = artifacts.manifest_digest(self.wf.stage_dir(up))
            if stage != "ingest":
                inputs.update({f"{up}/{rel}": h for rel, h in manifest.outputs.items()})
        if stage == "ingest":
            rig = artifacts.read_manifest(self.wf.stage_dir("rig")) if "rig" in upstream else None
            for d in self.wf.datasets:
                if d.rig:
                    if rig is None or f"{d.rig}.mat" not in rig.outputs:
                        return None
                    inputs[f"{d.name}:source"] = rig.outputs[f"{d.rig}.mat"]
                    continue
                inputs[f"{d.name}:source"] = self._source_hash(d.source)
        return inputs, upstream

    def _source_hash(self, source: Path) -> str:
        """Return a source file's sha256, hashed again when the path names another file."""
        known = self._source_hashes.get(source)
        if known is None or known[1] is None or file_identity(source) != known[1]:
            known = self._source_hashes[source] = sha256_identified(source)
        return known[0]

    def _check_sources_read(self) -> None:
        """Refuse ingest tables read from other bytes than the source hashes in their key.

        Each source was hashed (:meth:`_source_hash`) before the stage read it; the path
        still names the file hashed, unwritten, only if its identity is unchanged. Else
        another program replaced or wrote it in between, and the tables may hold bytes that
        no hash in the manifest describes: the stage fails and writes nothing.
        """
        for d in self.wf.datasets:
            known = self._source_hashes.get(d.source)
            if not d.rig and (known is None or file_identity(d.source) != known[1]):
                raise RigLogError(
                    f"source '{d.source}' of data set '{d.name}' was replaced or written while "
                    "ingest read it: nothing was written; run again once the file is complete"
                )

    def _code(self, stage: str) -> tuple[str, dict[str, str]]:
        entry = registry.stage(stage)
        return code_fingerprint(entry.module), artifacts.library_versions(entry.libraries)

    def _key(self, stage: str) -> tuple[str, dict, dict] | None:
        found = self._inputs(stage)
        if found is None:
            return None
        inputs, upstream = found
        code, versions = self._code(stage)
        key = artifacts.stage_key(
            stage,
            code=code,
            versions=versions,
            config=stage_config(self.wf, stage),
            inputs=inputs,
            upstream=upstream,
        )
        return key, inputs, upstream

    def _places(self) -> dict[str, Any]:
        return {
            "workflow_dir": self.wf.path.parent,
            "workflow_file": self.wf.path,
            "sources": [d.source for d in self.wf.datasets if not d.rig],
            "stages": STAGES,
            "overrides": self.wf.overrides,
        }

    def blocker(self) -> str | None:
        """Say why a run would stop at the output folder, without touching it.

        Returns
        -------
        str or None
            The refusal :func:`debist.engine.outdir.check_output_dir` gives for this
            workflow's folder (another workflow's, not debist's, ...), or None.
        """
        try:
            outdir.check_output_dir(self.wf.output_dir, workflow=self.wf.name, **self._places())
        except DebistError as exc:
            return str(exc)
        return None

    def missing(self) -> str | None:
        """Say that the output folder does not exist and which run beside it was meant.

        Returns
        -------
        str or None
            See :func:`debist.engine.verification.missing_output`; None when it exists.
        """
        return verification.missing_output(self.wf.output_dir, self.wf.overrides, self.stages())

    # ---------------------------------------------------------------- status
    def status(self) -> list[StageStatus]:
        """State of every stage: up to date, stale (with the reason) or missing.

        Reads only: leftovers of an interrupted run are reported in the reasons of their
        stages, not resolved.

        Returns
        -------
        list of StageStatus
            In stage order.
        """
        notes: dict[str, list[Reason]] = {}
        for path in outdir.leftovers(self.wf.output_dir):
            stage = artifacts.SWAP_FOLDER.match(path.name)["stage"]
            notes.setdefault(stage, []).append(
                Reason("interrupted_run", outdir.describe_leftover(path))
            )
        result: list[StageStatus] = []
        rerun: set[str] = set()
        for stage in self.stages():
            state, reasons = self._state(stage, rerun)
            if state != "up to date":
                rerun.add(stage)
            reasons = [*reasons, *notes.get(stage, [])]
            reason = "; ".join(r.detail for r in reasons)
            result.append(StageStatus(stage, state, reason, tuple(reasons)))
        return result

    def _state(self, stage: str, rerun: set[str]) -> tuple[str, list[Reason]]:
        sdir = self.wf.stage_dir(stage)
        foreign = artifacts.foreign_files(sdir) if sdir.exists() else []
        try:
            manifest = artifacts.read_manifest(sdir)
        except ArtifactError as exc:
            return "stale", [Reason("damaged_manifest", f"{exc}; run sets the folder aside "
                                    "and recomputes the stage")]  # fmt: skip
        if manifest is None:
            if foreign:
                return "missing", [
                    Reason("foreign_files", artifacts.foreign_message(sdir, foreign))
                ]
            return "missing", [Reason("never_run", "never run")]
        ups = [u for u in self._upstream(stage) if u in rerun]
        reasons = self._stale_reasons(stage, manifest)
        if ups:  # its own reasons too: "config changed (M)" is not hidden by the upstream's
            own = [r for r in reasons if r.kind not in ("upstream_changed", "input_changed")]
            return "stale", [Reason("upstream_stale", f"upstream '{ups[-1]}' will rerun"), *own]
        return ("stale", reasons) if reasons else ("up to date", [])

    def _stale_reasons(self, stage: str, manifest: artifacts.Manifest) -> list[Reason]:
        """Every reason why a stage with a manifest is stale (empty when it is up to date)."""
        reasons = []
        changed = artifacts.changed_outputs(self.wf.stage_dir(stage), manifest)
        for kind, tag in (("missing", "(missing)"), ("modified", "(modified)")):
            names = [c for c in changed if c.endswith(tag)]
            if names:
                reasons.append(
                    Reason(f"artifact_{kind}", f"outputs {kind}: " + ", ".join(names[:3]))
                )
        unlisted = [c for c in changed if c.endswith("(not in manifest)")]
        if unlisted:
            reasons.append(
                Reason("artifact_unlisted", "outputs changed: " + ", ".join(unlisted[:3]))
            )
        found = self._key(stage)
        if found is None:
            return [*reasons, Reason("upstream_missing", "an upstream stage has no artifacts")]
        key, inputs, upstream = found
        if key == manifest.key:
            return reasons
        config = stage_config(self.wf, stage)
        canon = artifacts.canonical_json
        if canon(config) != canon(manifest.config):
            keys = sorted(
                k
                for k in set(config) | set(manifest.config)
                if canon(config.get(k)) != canon(manifest.config.get(k))
            )
            reasons.append(Reason("config_changed", f"config changed ({', '.join(keys)})"))
        diff = sorted(
            k for k in set(inputs) | set(manifest.inputs) if inputs.get(k) != manifest.inputs.get(k)
        )
        if diff:
            reasons.append(Reason("input_changed", "inputs changed: " + ", ".join(diff[:3])))
        if upstream != manifest.upstream:
            ups = sorted(
                u
                for u in set(upstream) | set(manifest.upstream)
                if upstream.get(u) != manifest.upstream.get(u)
            )
            reasons.append(
                Reason("upstream_changed", "upstream manifests changed: " + ", ".join(ups))
            )
        code, versions = self._code(stage)
        if manifest.code != code:
            reasons.append(
                Reason("code_changed", f"code changed ({manifest.code[:12]} -> {code[:12]})")
            )
        if manifest.versions != versions:
            diff = sorted(k for k in versions if versions[k] != manifest.versions.get(k))
            reasons.append(
                Reason("library_changed", "library versions changed: " + ", ".join(diff))
            )
        if not reasons:
            reasons.append(
                Reason("layout_changed", "made by an older debist (artifact layout changed)")
            )
        return reasons

    # ------------------------------------------------------------------- run
    def run(
        self,
        stages: Sequence[str] | None = None,
        *,
        force: bool = False,
        on_event: Event | None = None,
    ) -> dict[str, artifacts.Manifest]:
        """Run stages, skipping those that are up to date.

        Parameters
        ----------
        stages : sequence of str, optional
            Stages to consider (default all, in order; see :meth:`select`). Upstream
            stages outside the selection must be up to date.
        force : bool, optional
            Rerun even up-to-date stages.
        on_event : callable, optional
            Called as ``on_event(stage, what, detail)`` with ``what`` in
            ``{"recovered", "skip", "start", "done"}``; the detail of ``"start"`` says why
            the stage runs, that of ``"done"`` its wall time.

        Returns
        -------
        dict of str to Manifest
            The manifest of every stage considered, with its checked ``summary``.

        Raises
        ------
        OutputDirError
            Before anything is written: the output folder is not debist's, is a forbidden
            place, or a stage folder holds files debist did not write (named).
        RunLockedError
            Another process writes to the output folder (unless ``wait``).
        WorkflowError
            Before anything is written: an unknown stage name (the message lists the
            stages), or a selected stage whose upstream stage outside the selection is
            missing or stale (named, with the reason).
        DebistError
            Whatever a stage raises; that stage's previous artifacts stay.
        """
        on_event = on_event or (lambda *a: None)
        selected = list(stages or self.stages())
        for s in selected:
            if s not in STAGES:
                raise WorkflowError(f"unknown stage '{s}'; the stages are: {', '.join(STAGES)}")
        out = self.wf.output_dir
        with outdir.writing(out, workflow=self.wf.name, wait=self.wait, **self._places()):
            for line in outdir.recover(out):
                on_event("", "recovered", line)
            damaged = {}
            for s in selected:  # a damaged manifest: stale, its folder kept aside, recomputed
                try:
                    artifacts.read_manifest(self.wf.stage_dir(s))
                except ArtifactError as exc:
                    aside = artifacts.set_aside(self.wf.stage_dir(s))
                    damaged[s] = f"{exc}; the folder was set aside as '{aside.name}'"
            foreign = {
                s: found
                for s in selected
                if (found := artifacts.foreign_files(self.wf.stage_dir(s)))
            }
            if foreign:
                raise OutputDirError(
                    "; ".join(
                        artifacts.foreign_message(self.wf.stage_dir(s), f)
                        for s, f in foreign.items()
                    )
                )
            if stages is not None:
                self._check_upstream(selected)
            return self._run_locked(selected, force, on_event, damaged)

    def select(
        self,
        stages: Sequence[str] | None = None,
        *,
        start: str | None = None,
        until: str | None = None,
    ) -> list[str] | None:
        """Resolve a stage selection: a list of names, or a range of this workflow's stages.

        Parameters
        ----------
        stages : sequence of str, optional
            Stage names, in any order.
        start, until : str, optional
            First and last stage of a range of :meth:`stages` (inclusive).

        Returns
        -------
        list of str or None
            The selected stages in execution order; None when nothing was given (all).

        Raises
        ------
        WorkflowError
            A string instead of a list, a list together with a range, an empty list, an
            unknown stage, a range end
            that is not a stage of this workflow, or ``start`` after ``until``; the message
            names the value and lists the valid stages.
        """
        if isinstance(stages, (str, bytes)):
            raise WorkflowError(
                f"stages: expected a list of stage names, got the string {stages!r}; "
                f"pass [{stages!r}]"
            )
        if stages is None and start is None and until is None:
            return None
        if stages is not None and (start is not None or until is not None):
            raise WorkflowError("give either a list of stages or a range (from, until), not both")
        mine = self.stages()
        given = stages if stages is not None else (start, until)
        names = list(dict.fromkeys(n for n in given if n is not None))
        if not names:
            raise WorkflowError(f"no stage selected; the stages are: {', '.join(mine)}")
        for name in names:
            if name not in mine:
                what = "unknown stage" if name not in STAGES else "not a stage of this workflow:"
                raise WorkflowError(
                    f"{what} '{name}'; the stages of workflow '{self.wf.name}' are: "
                    + ", ".join(mine)
                )
        if stages is not None:
            return sorted(names, key=mine.index)
        first = mine.index(start) if start is not None else 0
        last = mine.index(until) if until is not None else len(mine) - 1
        if first > last:
            raise WorkflowError(
                f"stage '{start}' runs after '{until}': nothing between them "
                f"(order: {', '.join(mine)})"
            )
        return mine[first : last + 1]

    def _check_upstream(self, selected: list[str]) -> None:
        """Refuse a selection whose stages read a missing or stale stage outside it."""
        states = {s.stage: s for s in self.status()}
        for stage in selected:
            for up in self._upstream(stage):
                state = states.get(up)
                if up in selected or state is None or state.state == "up to date":
                    continue
                raise WorkflowError(
                    f"stage '{stage}' reads stage '{up}', which is {state.state} "
                    f"({state.reason}): run '{up}' first or include it in the selection"
                )

    def _run_locked(
        self,
        selected: list[str],
        force: bool,
        on_event: Event,
        damaged: Mapping[str, str] | None = None,
    ) -> dict[str, artifacts.Manifest]:
        damaged = damaged or {}
        manifests: dict[str, artifacts.Manifest] = {}
        pending = [s for s in STAGES if s in selected]
        beside: dict[str, BesideRun] = {}
        early: dict[str, BesideRun] = {}  # first parts started ahead (registry ``early``)
        ahead: list[BesideRun] | None = None  # tried once, at the first free-running stage
        try:
            while pending:
                ready = [s for s in pending if self._may_run_beside(s, pending)]
                stage = ready[0] if ready else pending[0]
                pending.remove(stage)
                for up in self._upstream(stage):
                    if up in beside:
                        manifests[up] = self._join(up, beside.pop(up), on_event)
                first = early.pop(stage, None)
                found = self._start(stage, force, on_event, damaged, manifests)
                if found is None:
                    if first is not None:  # its inputs came out as they were: not needed
                        first.stop()
                    continue
                if ahead is None and stage in FREE_RUN_STAGES:
                    ahead = _compile_ahead()
                if stage in ready:
                    self._load(stage)  # the child inherits it, the stages here reuse it
                    beside[stage] = BesideRun(
                        partial(self._execute, stage, *found), f"stage '{stage}'",
                        niceness=BESIDE_NICENESS,
                    )  # fmt: skip
                    continue
                early.update(self._start_early(stage, pending, early, len(beside)))
                prepared = None if first is None else first.result()
                self._ahead = tuple(pending)
                manifests[stage], seconds = self._execute(stage, *found, prepared=prepared)
                release_freed_memory()  # its temporaries: not kept for the stages after it
                on_event(stage, "done", f"{seconds:.2f} s")
            for stage in list(beside):
                manifests[stage] = self._join(stage, beside.pop(stage), on_event)
        finally:
            for run in (*beside.values(), *early.values(), *(ahead or ())):
                run.stop()
        return {s: manifests[s] for s in STAGES if s in manifests}

    def _start_early(
        self, running: str, pending: Sequence[str], started: Mapping[str, BesideRun], busy: int
    ) -> dict[str, BesideRun]:
        """Start the first parts of the pending stages that ``running`` leads to, if they can.

        A stage's first part (its module's ``prepare``, registry ``early``) starts in a
        forked process when the stages it reads are done, a stage it depends on is about to
        run here (so it will most likely run too) and a core is free beside this process and
        the ``busy`` stages already running beside it
        (:func:`debist.core.forking.fork_workers`). The module's ``preload(ctx)``, if it has
        one, runs here first: what it loads the child inherits. If the stage turns out up to
        date, the part is stopped unused.
        """
        out: dict[str, BesideRun] = {}
        for stage in pending:
            reads = registry.stage(stage).early
            if (
                not reads
                or stage in started
                or any(u in pending or u == running for u in reads)
                or running not in self._depends_on(stage)
                or fork_workers(busy + 2) < busy + 2
            ):
                continue
            module = self._load(stage)
            out[stage] = BesideRun(
                partial(self._first_part, module.prepare), f"stage '{stage}' (first part)"
            )
        return out

    def _load(self, stage: str) -> Any:
        """Import a stage's module here, and run its ``preload(ctx)`` if it has one.

        Called just before the stage (or its first part) is forked: what both processes
        would load is loaded once, here, and the child inherits it; and by
        :meth:`load_ahead`.
        """
        module = importlib.import_module(registry.stage(stage).module)
        if hasattr(module, "preload"):
            module.preload(self)
        return module

    def _depends_on(self, stage: str) -> set[str]:
        """Every stage whose artifacts ``stage`` reads, directly or through others."""
        seen: set[str] = set()
        todo = list(self._upstream(stage))
        while todo:
            up = todo.pop()
            if up not in seen:
                seen.add(up)
                todo.extend(self._upstream(up))
        return seen

    def _first_part(self, prepare: Callable[[Any], Any]) -> Any:
        """Call a stage's ``prepare(self)`` as its ``execute``, on this process's core alone."""
        with one_blas_thread(), one_core():
            return prepare(self)

    def _may_run_beside(self, stage: str, pending: Sequence[str]) -> bool:
        """Whether ``stage`` can start now in a forked process beside the pending stages.

        It is marked ``beside`` in the registry, its upstream stages are not pending, some
        pending stage does not read it (there is work to overlap with), and a second process
        may run (:func:`debist.core.forking.fork_workers`; the compiled kernels run on Python
        threads, never on numba's threading layer, so a forked child may call them).
        """
        if not registry.stage(stage).beside or fork_workers(2) < 2:
            return False
        if any(up in pending for up in self._upstream(stage)):
            return False
        return any(s != stage and stage not in self._upstream(s) for s in pending)

    def _start(
        self,
        stage: str,
        force: bool,
        on_event: Event,
        damaged: Mapping[str, str],
        manifests: dict[str, artifacts.Manifest],
    ) -> tuple[str, dict, dict] | None:
        """Skip an up-to-date stage (its manifest into ``manifests``: None), or announce it.

        Returns
        -------
        tuple or None
            The stage's key, input hashes and upstream manifest hashes when it is to run.

        Raises
        ------
        ArtifactError
            If an upstream stage has no artifacts.
        """
        found = self._key(stage)
        if found is None:
            missing = [
                u
                for u in self._upstream(stage)
                if artifacts.read_manifest(self.wf.stage_dir(u)) is None
            ]
            raise ArtifactError(
                f"stage '{stage}' needs the artifacts of {missing}: run those first"
            )
        key = found[0]
        sdir = self.wf.stage_dir(stage)
        manifest = artifacts.read_manifest(sdir)
        if (
            not force
            and manifest is not None
            and manifest.key == key
            and not artifacts.changed_outputs(sdir, manifest)
        ):
            on_event(stage, "skip", f"key {key[:12]} matches its manifest, outputs unchanged")
            summary = artifacts.read_summary(sdir, manifest)
            manifests[stage] = replace(manifest, summary=summary)
            return None
        own = self.wf.own_output_dir
        if manifest is None and not force and stage not in damaged and own is not None:
            adopted = artifacts.adopt_stage(own / stage, sdir, stage=stage, key=key)
            if adopted is not None:  # the settings leave it as the workflow's own run has it
                on_event(stage, "skip", f"key {key[:12]} matches the workflow's own run: copied")
                manifests[stage] = adopted
                return None
        if stage in damaged:
            why = damaged[stage]
        elif manifest is None:
            why = "never run"
        elif force:
            why = "forced"
        else:
            why = "; ".join(r.detail for r in self._stale_reasons(stage, manifest))
        on_event(stage, "start", why)
        fault_point(f"stage:{stage}:start", self.wf.name)
        return found

    def _execute(
        self,
        stage: str,
        key: str,
        inputs: dict[str, str],
        upstream: dict[str, str],
        prepared: Any = None,
    ) -> tuple[artifacts.Manifest, float]:
        """Run one stage's ``execute`` and write its folder; return its manifest and time [s].

        ``prepared``: the result of the stage's first part, when it ran ahead
        (:meth:`_start_early`).
        """
        t0 = time.perf_counter()
        module = importlib.import_module(registry.stage(stage).module)
        with one_blas_thread(), collector_frozen():  # its code and inputs: not traversed
            t_run = time.perf_counter()
            result = module.execute(self) if prepared is None else module.execute(self, prepared)
            ran = time.perf_counter() - t_run
        if stage == "ingest":
            self._check_sources_read()
        seconds = time.perf_counter() - t0
        # the stage's own parts, what they leave out, and the import of its code (its
        # libraries on first use); write_stage adds the writing as "write"
        parts = {"import": t_run - t0, **result.timings}
        parts["other"] = max(0.0, ran - sum(result.timings.values()))
        code, versions = self._code(stage)
        manifest = artifacts.write_stage(
            self.wf.stage_dir(stage),
            stage=stage,
            key=key,
            code=code,
            versions=versions,
            config=stage_config(self.wf, stage),
            inputs=inputs,
            upstream=upstream,
            outputs=result.outputs,
            summary=result.summary,
            timings={"stage": seconds, **parts},
        )
        return manifest, time.perf_counter() - t0

    @staticmethod
    def _join(stage: str, run: BesideRun, on_event: Event) -> artifacts.Manifest:
        """Wait for a stage that ran beside the others; announce it done."""
        manifest, seconds = run.result()
        on_event(stage, "done", f"{seconds:.2f} s, in its own process beside the others")
        return manifest

    # ---------------------------------------------------------------- verify
    def digest(self) -> str | None:
        """Return the run digest over this workflow's stages (None when one is missing)."""
        return artifacts.run_digest(self.wf.output_dir, self.stages())

    def verify(self, digest: str | None = None) -> list[str]:
        """Check every artifact, every manifest and the chain (and a quoted digest).

        See :func:`debist.engine.verification.verify_run`.

        Parameters
        ----------
        digest : str, optional
            A run digest (as ``run`` prints it) the manifests must match.

        Returns
        -------
        list of str
            Problems, each naming the file; empty when all is intact.

        Raises
        ------
        RunLockedError
            While another process writes to the output folder.
        """
        return verification.verify_run(self, digest)

    def version_notes(self) -> list[str]:
        """Libraries installed now in other versions than those that made the run's stages.

        See :func:`debist.engine.verification.version_notes`.

        Returns
        -------
        list of str
            One line per stage and library.
        """
        return verification.version_notes(self)
