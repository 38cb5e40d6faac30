"""A stage's recorded settings with every default filled in, as the stage ran with them.

A manifest records the settings of a stage as the workflow states them (a key left out is
not recorded), so two runs of which one states ``substeps = 2`` and the other leaves the
key to its default of 2 ran alike. :func:`with_defaults` fills in the defaults of each
table's configuration class (:mod:`debist.core.config`), so comparing two runs
(:func:`debist.engine.rundiff.diff_runs`) shows only the settings that made a difference.

References
----------
pydantic 2 documentation, "Fields" (``FieldInfo.get_default``,
https://docs.pydantic.dev/2.x/concepts/fields/).
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Callable, Mapping
from typing import Any

from debist.differentiate.base import CONFIGS
from debist.identify.config import IdentifyConfig, RefineConfig
from debist.model.narx import NarxConfig
from debist.model.sindy import SindyConfig
from debist.physics.config import AnalyzeConfig
from debist.rig.config import RigConfig
from debist.validate.config import ValidateConfig
from debist.workflow.sections import ReportConfig, StudyConfig

__all__ = ["class_defaults", "with_defaults"]


def _plain(value: Any) -> Any:
    """Return a default as the JSON a manifest holds: arrays as lists, enums by value."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return _plain(dataclasses.asdict(value))
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    if isinstance(value, enum.Enum):
        return value.value
    return value


def class_defaults(cls: type) -> dict[str, Any]:
    """Return the default of every key of a configuration class that has one.

    Parameters
    ----------
    cls : type
        A pydantic dataclass of :mod:`debist.core.config` (e.g.
        :class:`debist.validate.config.ValidateConfig`).

    Returns
    -------
    dict
        Key to default, JSON-like (tuples as lists); required keys are left out.

    Examples
    --------
    >>> from debist.validate.config import ValidateConfig
    >>> class_defaults(ValidateConfig)["substeps"]
    2
    """
    fields = getattr(cls, "__pydantic_fields__", {})
    return {
        name: _plain(info.get_default(call_default_factory=True))
        for name, info in fields.items()
        if not info.is_required()
    }


def _differentiate(table: Mapping[str, Any]) -> dict[str, Any]:
    method = table.get("method", "tvregdiff")
    cls = CONFIGS.get(method) if isinstance(method, str) else None
    return {"method": "tvregdiff", **(class_defaults(cls) if cls is not None else {})}


def _fixed(cls: type) -> Callable[[Mapping[str, Any]], dict[str, Any]]:
    return lambda _table: class_defaults(cls)


_VALIDATE = _fixed(ValidateConfig)
_IDENTIFY = _fixed(IdentifyConfig)

#: Per stage: the tables of its recorded configuration (a path of keys; () the whole
#: configuration) and the defaults of each.
TABLES: dict[str, dict[tuple[str, ...], Callable[[Mapping[str, Any]], dict[str, Any]]]] = {
    "differentiate": {(): _differentiate},
    "identify": {(): _IDENTIFY, ("refine",): _fixed(RefineConfig)},
    "validate": {(): _VALIDATE},
    "compare": {
        ("sindy",): _fixed(SindyConfig),
        ("sindy", "narx"): _fixed(NarxConfig),
        ("validate",): _VALIDATE,
    },
    "study": {
        ("study",): _fixed(StudyConfig),
        ("identify",): _IDENTIFY,
        ("identify", "refine"): _fixed(RefineConfig),
        ("validate",): _VALIDATE,
        ("differentiate",): _differentiate,
    },
    "analyze": {("analyze",): _fixed(AnalyzeConfig)},
    "rig": {("rig",): _fixed(RigConfig)},
    "report": {(): _fixed(ReportConfig)},
}
#: Tables whose absence means their defaults (an absent ``[compare.narx]`` runs NARX with
#: its defaults), unlike ``[identify.refine]``, whose absence means no refinement.
IMPLIED = frozenset({("compare", ("sindy", "narx"))})


def with_defaults(stage: str, config: Mapping[str, Any]) -> dict[str, Any]:
    """Return a stage's recorded configuration with the defaults of its tables filled in.

    Keys the configuration states keep their values; a table it does not have is added
    only when its absence means its defaults (:data:`IMPLIED`). Tables without a configuration class
    (the ingest stage's data sets) are returned as they are.

    Parameters
    ----------
    stage : str
        Stage name.
    config : mapping
        The ``config`` of the stage's manifest.

    Returns
    -------
    dict
        A new nested dict; ``config`` is not changed.

    Examples
    --------
    >>> with_defaults("validate", {})["substeps"]
    2
    >>> with_defaults("validate", {"substeps": 4})["substeps"]
    4
    """
    out = _plain(config)
    for path, defaults in TABLES.get(stage, {}).items():
        parent, table = None, out
        for key in path:
            parent, table = table, table.get(key) if isinstance(table, dict) else None
        if table is None and isinstance(parent, dict) and (stage, path) in IMPLIED:
            table = {}
        if not isinstance(table, dict):
            continue
        filled = {**defaults(table), **table}
        if parent is None:
            out = filled
        else:
            parent[path[-1]] = filled
    return out
