"""One workflow per prototype of a fleet, from a template workflow (for ``debist batch``).

A lab's batch run is N prototypes through the same pipeline. :func:`fleet_workflows` takes a
workflow with a ``[rig]`` section as the template, draws N prototypes around its rig with
:func:`debist.rig.fleet.make_fleet` and returns one workflow per prototype: the template
with the member's prototype in ``[rig.prototype]``, its friction in ``[rig.plant]``, its own
name and output folder. ``[physics]`` stays the nominal design, so each member's analytical
row shows what the nominal model misses on that copy. ``debist batch`` then runs them on Dask.

References
----------
Masoud & Maas 2025, Table 1 (nominal prototype).
"""

from __future__ import annotations

import copy
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import tomli_w

from debist.errors import WorkflowError
from debist.names import check_file_name
from debist.physics.params import PrototypeParams
from debist.rig.fleet import make_fleet
from debist.rig.params import RigParams

__all__ = ["fleet_workflows"]


def fleet_workflows(
    template: Mapping[str, Any],
    template_dir: Path,
    out_dir: Path,
    n: int,
    *,
    seed: int,
    scatter: Mapping[str, float] | None = None,
) -> dict[str, str]:
    """Render one workflow per fleet member from a template workflow.

    Parameters
    ----------
    template : mapping
        The parsed template workflow (``tomllib``); it needs a ``[rig]`` section.
    template_dir : pathlib.Path
        Folder of the template (its relative paths are resolved against it).
    out_dir : pathlib.Path
        Folder the member workflows will be written to (their relative paths point from
        there); each member's artifacts go to ``runs/<name>-<k>`` inside it.
    n : int
        Fleet size.
    seed : int
        Seed of the scatter (same seed, same fleet).
    scatter : mapping, optional
        Spreads by name (:data:`debist.rig.fleet.DEFAULT_SCATTER`).

    Returns
    -------
    dict of str to str
        File name (``<name>-<k>.toml``) -> TOML text, in fleet order.

    Raises
    ------
    WorkflowError
        If the template has no ``[rig]`` section or an invalid one, ``n``/``scatter``
        are invalid, or its name is not a plain file name
        (:func:`debist.names.check_file_name`).
    FleetError
        If the scatter leaves too few working prototypes.

    References
    ----------
    Masoud & Maas 2025, Table 1.
    """
    if "rig" not in template:
        raise WorkflowError("the fleet template needs a [rig] section (the prototype to scatter)")
    rig = template["rig"]
    physics = template.get("physics", {})
    prototype = PrototypeParams.from_dict({**physics, **rig.get("prototype", {})})
    nominal = RigParams.from_dict({**rig.get("plant", {}), "prototype": prototype})
    members = make_fleet(n, seed=seed, nominal=nominal, scatter=scatter)
    name = template.get("workflow", {}).get("name", "fleet")
    check_file_name(name, "[workflow] name of the fleet template")  # <name>-<k>.toml
    width = max(3, len(str(n - 1)))
    out: dict[str, str] = {}
    for k, member in enumerate(members):
        wf = copy.deepcopy(dict(template))
        label = f"{name}-{k:0{width}d}"
        head = dict(wf.get("workflow", {}))
        head.update(
            name=label,
            description=f"member {k} of a fleet of {n} (seed {seed}) from {name}",
            output_dir=f"runs/{label}",
        )
        wf["workflow"] = head
        plant = member.to_dict()
        wf["rig"] = dict(wf["rig"])
        wf["rig"]["prototype"] = plant.pop("prototype")
        wf["rig"]["plant"] = plant
        for table in wf.get("datasets", {}).values():
            if "source" in table:
                source = (template_dir / table["source"]).resolve()
                table["source"] = os.path.relpath(source, out_dir.resolve())
        out[f"{label}.toml"] = tomli_w.dumps(wf)
    return out
