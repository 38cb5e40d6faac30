"""One workflow per prototype of a fleet, from a template workflow (for ``debist batch``).

A lab's batch run is N prototypes through the same pipeline. :func:`fleet_workflows` takes a
workflow with a ``[rig]`` section as the template, draws N prototypes around its rig with
:func:`debist.rig.fleet.fleet_members` and returns one workflow per prototype: the template
with the member's prototype in ``[rig.prototype]``, its friction in ``[rig.plant]``, its own
name and output folder. ``[physics]`` stays the nominal design, so each member's analytical
row shows what the nominal model misses on that copy. ``debist batch`` then runs them on Dask.

Every profile's sub-threshold blocks are meant to stay below the prototype's switching
threshold (:mod:`debist.rig.profiles`). A lab sets their level for each copy it tests after a
slow ramp has shown where that copy switches; a member whose static threshold (Eq. 15,
:func:`debist.physics.statics.switching_voltage`, the lower of its two DEs) is below the
template prototype's gets every experiment's ``v_sub`` scaled down by the ratio of the two
thresholds, so it keeps the template's margin. Without it a member switching at 682 V had
"sub-threshold" validation blocks at 1 kV that snapped it over, a quasi-static switch its
identification record never contained.

References
----------
Masoud & Maas 2025, Table 1 (nominal prototype).
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import tomli_w

from debist.core.errors import WorkflowError
from debist.core.names import check_file_name
from debist.physics.params import V_MAX, PrototypeParams
from debist.physics.statics import switching_voltage
from debist.rig.fleet import fleet_members
from debist.rig.params import RigParams
from debist.rig.profiles import V_SUB

__all__ = ["fleet_workflows", "lower_threshold", "sub_threshold_scale"]


def lower_threshold(prototype: PrototypeParams, v_max: float = V_MAX) -> float:
    """Return the lower of a prototype's two static switching thresholds [V].

    Parameters
    ----------
    prototype : PrototypeParams
        The prototype.
    v_max : float
        Upper end of the search [V]; default the converters' 3 kV.

    Returns
    -------
    float
        ``min`` over DE 1 and DE 2 of :func:`debist.physics.statics.switching_voltage`
        (to 1 V); ``math.inf`` if neither switches at ``v_max``.

    References
    ----------
    Masoud & Maas 2025, Eq. 15, Section 3.3.4.
    """
    return min(switching_voltage(prototype, de, v_max=v_max) for de in (1, 2))


def sub_threshold_scale(member: PrototypeParams, v_template: float) -> tuple[float, float]:
    """Factor on a fleet member's sub-threshold level that keeps the template's margin.

    Parameters
    ----------
    member : PrototypeParams
        The member's prototype.
    v_template : float
        The template prototype's :func:`lower_threshold` [V].

    Returns
    -------
    scale : float
        ``min(1, V_member / v_template)``; 1 when the member switches no lower than the
        template (or the template does not switch at 3 kV, ``v_template`` infinite).
    v_member : float
        The member's :func:`lower_threshold` [V]; ``math.inf`` if not below ``v_template``.

    References
    ----------
    Masoud & Maas 2025, Eq. 15, Section 3.3.4; Sec. 5.1 (the sub-threshold excitation).
    """
    if not math.isfinite(v_template):
        return 1.0, math.inf
    v_member = lower_threshold(member, v_template)  # inf when not below the template's
    return min(1.0, v_member / v_template), v_member


def fleet_workflows(
    template: Mapping[str, Any],
    template_dir: Path,
    out_dir: Path,
    n: int,
    *,
    seed: int,
    scatter: Mapping[str, float] | None = None,
) -> Iterator[tuple[str, str]]:
    """Render one workflow per fleet member from a template workflow, member by member.

    The template and the scatter are checked at the call; each member is drawn, screened
    (:func:`debist.rig.fleet.fleet_members`) and rendered only when the iterator reaches it,
    so a caller that stops early pays for what it took (``dict(fleet_workflows(...))``
    renders them all).

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
    iterator of tuple of str
        File name (``<name>-<k>.toml``) and TOML text, in fleet order.

    Raises
    ------
    WorkflowError
        If the template has no ``[rig]`` section or an invalid one, ``n``/``scatter``
        are invalid, or its name is not a plain file name
        (:func:`debist.core.names.check_file_name`).
    FleetError
        When the iterator reaches a member the scatter does not give (too few working
        prototypes).

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
    members = fleet_members(n, seed=seed, nominal=nominal, scatter=scatter)
    name = template.get("workflow", {}).get("name", "fleet")
    check_file_name(name, "[workflow] name of the fleet template")  # <name>-<k>.toml
    v_template = lower_threshold(prototype)
    return _render(template, template_dir, out_dir, members, n, v_template, name, seed)


def _render(template, template_dir, out_dir, members, n, v_template, name, seed):
    """Yield each member's file name and TOML text (:func:`fleet_workflows`)."""
    width = max(3, len(str(n - 1)))
    for k, member in enumerate(members):
        scale, v_member = sub_threshold_scale(member.prototype, v_template)
        wf = copy.deepcopy(dict(template))
        label = f"{name}-{k:0{width}d}"
        head = dict(wf.get("workflow", {}))
        head.update(
            name=label,
            description=f"member {k} of the seed-{seed} fleet from {name}",
            output_dir=f"runs/{label}",
        )
        if scale < 1.0:
            head["description"] += (
                f"; sub-threshold levels x {scale:.3f} (static switching threshold "
                f"{v_member:.0f} V, below the template's)"
            )
            _scale_sub_threshold(wf, scale)
        wf["workflow"] = head
        plant = member.to_dict()
        wf["rig"] = dict(wf["rig"])
        wf["rig"]["prototype"] = plant.pop("prototype")
        wf["rig"]["plant"] = plant
        for table in wf.get("datasets", {}).values():
            if "source" in table:
                source = (template_dir / table["source"]).resolve()
                table["source"] = os.path.relpath(source, out_dir.resolve())
        yield f"{label}.toml", tomli_w.dumps(wf)


def _scale_sub_threshold(wf: dict[str, Any], scale: float) -> None:
    """Set ``v_sub`` of every rig experiment to ``scale`` times the template's (in place)."""
    rig = wf["rig"]
    rig["experiments"] = {name: dict(exp) for name, exp in rig.get("experiments", {}).items()}
    for exp in rig["experiments"].values():
        exp["v_sub"] = round(scale * float(exp.get("v_sub", V_SUB)), 1)
