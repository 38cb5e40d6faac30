"""A fleet whose every member's logs pass the template's own ingest.

:func:`debist.rig.fleet.make_fleet` keeps prototypes that are bistable and switchable by
their statics; whether a prototype's *recording* is usable is a property of the rig run: a
member that overshoots past the laser's range, for instance, logs samples at the range limit,
which the template's ingest refuses as sensor faults. :func:`viable_fleet` therefore runs the
rig and ingest stages of each candidate (into a temporary folder) and keeps the first ``size``
draws that pass, in draw order; the rejected draws and their reasons are returned to be
reported. Member names keep their draw index, so a member is the same prototype whatever
the fleet size.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping
from pathlib import Path

from debist.core.errors import DebistError
from debist.engine.runner import Runner
from debist.rig.fleet import FleetError
from debist.rig.fleet_workflows import fleet_workflows
from debist.workflow.loader import load_workflow

__all__ = ["viable_fleet"]

#: Extra draws allowed per requested member before giving up.
EXTRA_DRAWS = 2


def _ingest_problem(text: str, folder: Path, label: str) -> str | None:
    """Run a candidate's rig and ingest stages in a scratch folder; the error, or None."""
    check = folder / f".{label}.check.toml"
    with tempfile.TemporaryDirectory(prefix="debist-fleet-") as tmp:
        try:
            check.write_text(text, encoding="utf-8")
            wf = load_workflow(check, Path(tmp) / "run")
            stages = [s for s in ("rig", "ingest") if s in Runner(wf).stages()]
            Runner(wf).run(stages)
        except DebistError as exc:
            return str(exc)
        finally:
            check.unlink(missing_ok=True)
    return None


def viable_fleet(
    template: Mapping,
    template_dir: Path,
    folder: Path,
    size: int,
    seed: int,
    scatter: Mapping[str, float] | None = None,
) -> tuple[dict[str, str], dict[str, str]]:
    """Render ``size`` member workflows whose rig logs pass the template's ingest.

    Parameters
    ----------
    template : mapping
        The parsed template workflow (it needs a ``[rig]`` section).
    template_dir : pathlib.Path
        Folder of the template.
    folder : pathlib.Path
        Folder the member workflows go to (created; the checks write a scratch workflow
        there and remove it).
    size : int
        Members wanted.
    seed : int
        Seed of the scatter.
    scatter : mapping, optional
        Spreads (:data:`debist.rig.fleet.DEFAULT_SCATTER`).

    Returns
    -------
    files : dict of str to str
        ``<name>-<draw>.toml`` -> TOML text of the kept members, in draw order.
    rejected : dict of str to str
        Member name -> why its log failed the template's ingest (one line).

    Raises
    ------
    FleetError
        If fewer than ``size`` of ``size * (1 + EXTRA_DRAWS)`` draws pass.
    WorkflowError
        As :func:`debist.rig.fleet_workflows.fleet_workflows`.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.1 (the experiment each member repeats).
    """
    folder.mkdir(parents=True, exist_ok=True)
    n_draws = size * (1 + EXTRA_DRAWS)
    draws = fleet_workflows(template, template_dir, folder, n_draws, seed=seed, scatter=scatter)
    kept: dict[str, str] = {}
    rejected: dict[str, str] = {}
    for name, text in draws if size > 0 else ():
        label = name.removesuffix(".toml")
        problem = _ingest_problem(text, folder, label)
        if problem is None:
            kept[name] = text
        else:
            rejected[label] = problem
        if len(kept) == size:
            break
    if len(kept) < size:
        raise FleetError(
            f"only {len(kept)} of {n_draws} drawn prototypes give logs that the template's "
            f"ingest accepts (wanted {size}); first refusal: {next(iter(rejected.values()))}"
        )
    return kept, rejected
