"""Run a workflow's stages with content-hash caching; report status; verify artifacts.

A stage is up to date when its manifest's key equals the key computed from the
current configuration, code and input hashes, and its outputs still hash to the
manifest. ``run`` skips such stages; anything else is rerun, and so is
everything downstream whose inputs change as a result.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline import artifacts
from pipeline.errors import ArtifactError, WorkflowError
from pipeline.workflow import Workflow

#: Stages in execution order and the stages each reads from.
STAGES = ("rig", "ingest", "differentiate", "identify", "validate", "compare", "study", "analyze")
#: Stages that run only when the workflow has their section.
OPTIONAL = ("rig", "study", "analyze")
#: Stages that read measured data sets.
DATA_STAGES = ("ingest", "differentiate", "identify", "validate", "compare", "study")
UPSTREAM = {
    "rig": (),
    "ingest": (),  # plus "rig" when a data set is a virtual-rig log (Runner._upstream)
    "differentiate": ("ingest",),
    "identify": ("ingest", "differentiate"),
    "validate": ("ingest", "differentiate", "identify"),
    "compare": ("ingest", "differentiate", "validate"),
    "study": ("ingest", "differentiate"),
    "analyze": (),
}


@dataclass(frozen=True)
class StageStatus:
    """State of one stage directory.

    Attributes
    ----------
    stage : str
        Stage name.
    state : {"up to date", "stale", "missing"}
        What a run would do: skip, rerun, run.
    reason : str
        Why it is stale or missing (empty when up to date).
    """

    stage: str
    state: str
    reason: str = ""


Event = Callable[[str, str, str], None]


def physics_params(wf: Workflow):
    """Return the prototype of the workflow's ``[physics]`` section (Table 1 where absent).

    Parameters
    ----------
    wf : Workflow
        The workflow.

    Returns
    -------
    pipeline.physics.params.PrototypeParams
        Table 1 updated by the section's keys [SI].

    Raises
    ------
    WorkflowError
        On an unknown key or an invalid value.
    """
    from pipeline.physics.params import PrototypeParams

    return PrototypeParams.from_dict(wf.section("physics"))


def _stage_config(wf: Workflow, stage: str) -> dict[str, Any]:
    if stage == "ingest":
        return {
            "datasets": {
                d.name: {
                    "source": f"rig:{d.rig}"
                    if d.rig
                    else os.path.relpath(d.source, wf.path.parent),
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
    if stage == "analyze":
        return {"physics": physics_params(wf).to_dict(), "analyze": wf.section("analyze")}
    physics = {"physics": physics_params(wf).to_dict()} if "physics" in wf.sections else {}
    if stage == "compare":
        sindy = wf.section("compare")
        sindy.setdefault("input_map", wf.section("identify").get("input_map", "v2"))
        return {"sindy": sindy, "validate": wf.section("validate"), **physics}
    if stage in ("identify", "validate") and physics:
        return {**wf.section(stage), **physics}
    return wf.section(stage)


class Runner:
    """Executes, inspects and verifies the stages of one workflow.

    Parameters
    ----------
    workflow : Workflow
        The parsed workflow.
    """

    def __init__(self, workflow: Workflow):
        self.wf = workflow
        self._source_hashes: dict[Path, str] = {}

    def stages(self) -> list[str]:
        """List the stages of this workflow.

        The data stages when it has data sets, ``study`` with a ``[study]`` section, and
        ``analyze`` with an ``[analyze]`` section or when ``[physics]`` is all there is.
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
            elif s not in OPTIONAL or s in self.wf.sections:
                out.append(s)
        return out

    # ------------------------------------------------------------------ keys
    def _upstream(self, stage: str) -> tuple[str, ...]:
        """Stages whose artifacts ``stage`` reads."""
        if stage == "ingest" and any(d.rig for d in self.wf.datasets):
            return ("rig",)
        return UPSTREAM[stage]

    def _inputs(self, stage: str) -> dict[str, str] | None:
        """Input hashes of a stage, or None when an upstream stage has no manifest."""
        if stage == "ingest":
            out = {}
            rig = artifacts.read_manifest(self.wf.stage_dir("rig"))
            for d in self.wf.datasets:
                if d.rig:
                    if rig is None or f"{d.rig}.mat" not in rig.outputs:
                        return None
                    out[f"{d.name}:source"] = rig.outputs[f"{d.rig}.mat"]
                    continue
                if d.source not in self._source_hashes:
                    self._source_hashes[d.source] = artifacts.sha256_file(d.source)
                out[f"{d.name}:source"] = self._source_hashes[d.source]
            return out
        inputs = {}
        for up in self._upstream(stage):
            manifest = artifacts.read_manifest(self.wf.stage_dir(up))
            if manifest is None:
                return None
            inputs.update({f"{up}/{rel}": h for rel, h in manifest.outputs.items()})
        return inputs

    def _key(self, stage: str) -> tuple[str | None, dict[str, str] | None]:
        inputs = self._inputs(stage)
        if inputs is None:
            return None, None
        return artifacts.stage_key(stage, _stage_config(self.wf, stage), inputs), inputs

    # ---------------------------------------------------------------- status
    def status(self) -> list[StageStatus]:
        """State of every stage: up to date, stale (with the reason) or missing.

        Returns
        -------
        list of StageStatus
            In stage order.
        """
        result: list[StageStatus] = []
        rerun: set[str] = set()
        for stage in self.stages():
            manifest = artifacts.read_manifest(self.wf.stage_dir(stage))
            if manifest is None:
                result.append(StageStatus(stage, "missing", "never run"))
                rerun.add(stage)
                continue
            ups = [u for u in self._upstream(stage) if u in rerun]
            if ups:
                result.append(StageStatus(stage, "stale", f"upstream '{ups[-1]}' will rerun"))
                rerun.add(stage)
                continue
            reason = self._stale_reason(stage, manifest)
            if reason:
                result.append(StageStatus(stage, "stale", reason))
                rerun.add(stage)
            else:
                result.append(StageStatus(stage, "up to date"))
        return result

    def _stale_reason(self, stage: str, manifest: artifacts.Manifest) -> str:
        key, inputs = self._key(stage)
        changed = artifacts.changed_outputs(self.wf.stage_dir(stage), manifest)
        if changed:
            return "outputs changed: " + ", ".join(changed[:3])
        if key == manifest.key:
            return ""
        config = _stage_config(self.wf, stage)
        if artifacts.canonical_json(config) != artifacts.canonical_json(manifest.config):
            keys = sorted(
                k
                for k in set(config) | set(manifest.config)
                if artifacts.canonical_json(config.get(k))
                != artifacts.canonical_json(manifest.config.get(k))
            )
            return f"config changed ({', '.join(keys)})"
        diff = sorted(
            k for k in set(inputs) | set(manifest.inputs) if inputs.get(k) != manifest.inputs.get(k)
        )
        if diff:
            return "inputs changed: " + ", ".join(diff[:3])
        if manifest.code != artifacts.code_version():
            return f"code changed ({manifest.code} -> {artifacts.code_version()})"
        return "key changed"

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
            Stages to consider (default all, in order). Upstream stages outside
            the selection must have artifacts.
        force : bool, optional
            Rerun even up-to-date stages.
        on_event : callable, optional
            Called as ``on_event(stage, what, detail)`` with ``what`` in
            ``{"skip", "start", "done"}``.

        Returns
        -------
        dict of str to Manifest
            The manifest of every stage considered.

        Raises
        ------
        ArtifactError
            If an upstream stage has no artifacts.
        DebistError
            Whatever a stage raises; that stage's previous artifacts stay.
        """
        on_event = on_event or (lambda *a: None)
        selected = list(stages or self.stages())
        for s in selected:
            if s not in STAGES:
                raise WorkflowError(f"unknown stage {s!r}; stages: {STAGES}")
        manifests = {}
        for stage in STAGES:
            if stage not in selected:
                continue
            key, inputs = self._key(stage)
            if key is None:
                missing = [
                    u
                    for u in self._upstream(stage)
                    if artifacts.read_manifest(self.wf.stage_dir(u)) is None
                ]
                raise ArtifactError(
                    f"stage '{stage}' needs the artifacts of {missing}: run those first"
                )
            sdir = self.wf.stage_dir(stage)
            manifest = artifacts.read_manifest(sdir)
            if (
                not force
                and manifest is not None
                and manifest.key == key
                and not artifacts.changed_outputs(sdir, manifest)
            ):
                on_event(stage, "skip", "up to date")
                manifests[stage] = manifest
                continue
            on_event(stage, "start", "")
            t0 = time.perf_counter()
            outputs, summary = self._execute(stage)
            manifests[stage] = artifacts.write_stage(
                sdir,
                stage=stage,
                key=key,
                inputs=inputs,
                config=_stage_config(self.wf, stage),
                outputs=outputs,
                summary=summary,
            )
            on_event(stage, "done", f"{time.perf_counter() - t0:.2f} s")
        return manifests

    # -------------------------------------------------------------- loading
    def tables(self, stage: str) -> dict[str, Any]:
        """Load the per-data-set Parquet tables of a stage (ingest or differentiate)."""
        manifest = artifacts.read_manifest(self.wf.stage_dir(stage))
        if manifest is None:
            raise ArtifactError(f"stage '{stage}' has no artifacts in '{self.wf.stage_dir(stage)}'")
        return {
            Path(rel).stem: artifacts.read_parquet(self.wf.stage_dir(stage) / rel)
            for rel in sorted(manifest.outputs)
            if rel.endswith(".parquet") and "/" not in rel
        }

    def _physics(self):
        return physics_params(self.wf) if "physics" in self.wf.sections else None

    def _execute(self, stage: str) -> tuple[dict[str, Any], dict[str, Any]]:
        from pipeline import physics_stages as ps
        from pipeline import stages as st

        if stage == "rig":
            res = ps.run_rig(self.wf.section("physics"), self.wf.section("rig"))
            return res.outputs, res.summary
        if stage == "analyze":
            res = ps.run_analyze(physics_params(self.wf), self.wf.section("analyze"))
            outputs: dict[str, Any] = {"statics.h5": artifacts.H5Tree(res.tree)}
            outputs.update({f"{n}.png": artifacts.Figure(f) for n, f in res.figures.items()})
            return outputs, res.summary
        if stage == "ingest":
            tables = st.run_ingest(self.wf.datasets)
            return {f"{n}.parquet": f for n, f in tables.items()}, {
                "datasets": {n: len(f) for n, f in tables.items()}
            }
        tables = self.tables("ingest")
        if stage == "differentiate":
            derivs = st.run_differentiate(tables, self.wf.section("differentiate"))
            converged = {n: d.attrs["converged"] for n, d in derivs.items()}
            return {f"{n}.parquet": d for n, d in derivs.items()}, {"converged": converged}
        derivs = self.tables("differentiate")
        if stage == "identify":
            res = st.run_identify(tables, derivs, self.wf.section("identify"), self._physics())
            tree = {**res.model.to_tree(), "diagnostics": st.diagnostics_tree(res.diagnostics)}
            if res.equation_error_model is not None and res.equation_error_model is not res.model:
                tree["equation_error"] = res.equation_error_model.to_tree()["model"]
            return {"model.h5": artifacts.H5Tree(tree), "curves.parquet": res.curves}, res.summary
        if stage == "study":
            results = st.run_study(tables, derivs, _stage_config(self.wf, "study"))
            outputs = {}
            for name, (table, figure) in results.items():
                outputs[f"{name}.parquet"] = table
                outputs[f"{name}.png"] = artifacts.Figure(figure)
            return outputs, {
                name: table.to_dict(orient="records") for name, (table, _) in results.items()
            }
        if stage == "compare":
            rbf = artifacts.read_parquet(self.wf.stage_dir("validate") / "nrmse.parquet")
            res = st.run_compare(
                tables, derivs, rbf, _stage_config(self.wf, "compare"), self._physics()
            )
            outputs = {
                "sindy.h5": artifacts.H5Tree(res.model.to_tree()),
                "nrmse.parquet": res.table,
            }
            outputs.update({f"simulated/{n}.parquet": s for n, s in res.simulated.items()})
            summary = {
                **res.summary,
                "table": res.table.to_dict(orient="records"),
                "published": list(self.wf.section("validate").get("published", [])),
                "order": [d.name for d in self.wf.datasets],
            }
            return outputs, summary
        from pipeline.identify import RBFModel

        tree = artifacts.read_h5(self.wf.stage_dir("identify") / "model.h5")
        model = RBFModel.from_tree(tree)
        ls = tree.get("equation_error")
        baseline = RBFModel.from_tree({"model": ls}) if ls is not None else None
        res = st.run_validate(
            model, tables, derivs, self.wf.section("validate"), baseline, self._physics()
        )
        outputs: dict[str, Any] = {"nrmse.parquet": res.table}
        outputs.update({f"simulated/{n}.parquet": s for n, s in res.simulated.items()})
        outputs.update({f"plots/{n}.png": artifacts.Figure(f) for n, f in res.figures.items()})
        summary = {
            "table": res.table.to_dict(orient="records"),
            "published": list(self.wf.section("validate").get("published", [])),
            "order": [d.name for d in self.wf.datasets],
            "sim_time": res.sim_time,
        }
        return outputs, summary

    # ---------------------------------------------------------------- verify
    def verify(self) -> list[str]:
        """Re-hash every artifact and check the chain of manifests.

        Returns
        -------
        list of str
            Problems, each naming the file: modified or missing outputs, files
            not in a manifest, and stages whose recorded inputs differ from
            their upstream stage's current outputs. Empty when all is intact.
        """
        problems = []
        for stage in STAGES:
            sdir = self.wf.stage_dir(stage)
            manifest = artifacts.read_manifest(sdir)
            if manifest is None:
                continue
            problems += [f"{sdir / c}" for c in artifacts.changed_outputs(sdir, manifest)]
            if stage not in ("ingest", "rig") or self._upstream(stage):
                inputs = self._inputs(stage)
                if inputs is not None and inputs != manifest.inputs:
                    problems.append(
                        f"{sdir / artifacts.MANIFEST} (built from other upstream artifacts)"
                    )
        return problems
