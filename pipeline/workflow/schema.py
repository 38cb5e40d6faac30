"""The workflow schema: every section of a parsed workflow file checked before any stage runs.

:func:`check_workflow` builds each section's typed configuration, the same classes the
stages build (:mod:`debist.core.config`), from the parsed TOML, merged the way the stages
merge them (a data set's ingest is ``[ingest]`` updated by its own keys, ``[compare]``
takes ``input_map`` from ``[identify]``, ``[study.identify]`` updates ``[identify]``), so
a workflow that loads has no wrong type, unknown key or out-of-range value left for a
stage to trip over. The first problem found is raised as a one-line
:class:`~debist.core.errors.WorkflowError`::

    [identify] M: expected an integer, got 'ten'
    [datasets.estimation] source: expected a string, got 5
    [compare] unknown key 'degre'; did you mean 'degree'? (known keys: degree, ...)

References
----------
pydantic 2 documentation, "Dataclasses" and "Strict Mode" (https://docs.pydantic.dev/2.x/);
TOML v1.0.0 (https://toml.io/en/v1.0.0), tables and arrays of tables.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

import pydantic

from debist.core import preflight
from debist.core.config import CONFIG, config_from_section, dotted_key, unknown_key_message
from debist.core.errors import WorkflowError
from debist.core.names import check_file_name
from debist.core.units import UNITS
from debist.differentiate.base import CONFIGS
from debist.differentiate.tvregdiff_method import TVRegDiffConfig
from debist.identify.config import IdentifyConfig
from debist.ingest.spec import OPTION_KEYS, IngestSpec
from debist.model.narx import NarxConfig
from debist.model.sindy import SindyConfig
from debist.model.terms import PHYSICS_TERMS
from debist.physics.config import AnalyzeConfig
from debist.physics.params import PrototypeParams
from debist.rig.config import RigConfig
from debist.rig.profiles import make_profile
from debist.validate.config import ValidateConfig
from debist.workflow.budget import check_rig_budget, check_workflow_budget
from debist.workflow.sections import ReportConfig, StudyConfig

__all__ = [
    "DATALESS",
    "ROLES",
    "SECTIONS",
    "CheckedWorkflow",
    "DatasetEntry",
    "WorkflowHead",
    "check_workflow",
]

#: The sections a workflow may have, in the order they are checked.
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
    "report",
)
#: Sections that make a workflow meaningful without data sets (a design analysis).
DATALESS = ("physics",)
#: Roles of a data set.
ROLES = ("estimation", "validation")
#: Keys of a ``[datasets.<name>]`` table that are not ingest overrides.
DATASET_KEYS = ("source", "rig", "role")


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class WorkflowHead:
    """The ``[workflow]`` section.

    Parameters
    ----------
    name : str or None
        Workflow name; default the file name without ``.toml``.
    description : str
        One line on what the workflow does.
    output_dir : str or None
        Root of the stage folders, relative to the workflow file (not empty: that would be
        the workflow's own folder); default ``runs/<name>`` next to it.
    """

    name: Annotated[str, pydantic.Field(min_length=1)] | None = None
    description: str = ""
    output_dir: Annotated[str, pydantic.Field(min_length=1)] | None = None


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class DatasetEntry:
    """The keys of a ``[datasets.<name>]`` table that are not ingest overrides.

    Parameters
    ----------
    source : str or None
        Rig-log file, relative to the workflow file.
    rig : str or None
        Name of a ``[rig.experiments.<name>]`` whose recording the data set is.
    role : {"estimation", "validation"}
        Used for identification, or only for validation.

    Exactly one of ``source`` and ``rig`` is given (checked by :func:`check_workflow`).
    """

    source: str | None = None
    rig: str | None = None
    role: Literal["estimation", "validation"] = "validation"


@dataclass(frozen=True)
class CheckedWorkflow:
    """Every section of a workflow as the typed configuration its stage builds.

    Attributes
    ----------
    head : WorkflowHead
        ``[workflow]``.
    datasets : dict of str to tuple of (DatasetEntry, IngestSpec)
        Each data set with its merged ingest, in file order.
    differentiate : object
        ``[differentiate]``: the config of its ``method`` (see
        :data:`debist.differentiate.base.CONFIGS`).
    identify : IdentifyConfig
        ``[identify]`` (``m_q = "physics"`` stands in as 1 kg: the stage resolves it).
    validate : ValidateConfig
        ``[validate]``.
    compare : SindyConfig or None
        ``[compare]`` with ``input_map`` from ``[identify]``.
    study : tuple of (StudyConfig, IdentifyConfig, TVRegDiffConfig) or None
        ``[study]``, with the identification and differentiation it varies.
    physics : PrototypeParams or None
        ``[physics]``.
    analyze : AnalyzeConfig or None
        ``[analyze]``.
    rig : RigConfig or None
        ``[rig]`` with ``[physics]``.
    report : ReportConfig or None
        ``[report]`` (an empty table: the defaults).
    narx : NarxConfig or None
        ``[compare.narx]`` (None without ``[compare]``).
    """

    head: WorkflowHead
    datasets: dict[str, tuple[DatasetEntry, IngestSpec]] = field(default_factory=dict)
    differentiate: Any = None
    identify: IdentifyConfig | None = None
    validate: ValidateConfig | None = None
    compare: SindyConfig | None = None
    study: tuple[StudyConfig, IdentifyConfig, TVRegDiffConfig] | None = None
    physics: PrototypeParams | None = None
    analyze: AnalyzeConfig | None = None
    rig: RigConfig | None = None
    report: ReportConfig | None = None
    narx: NarxConfig | None = None


def _origin(own: Mapping[str, Any], here: str, base: str) -> Callable[[str], str]:
    """Label a key of a merged section by the table it came from."""
    return lambda key: here if key in own else base


def _tables(raw: Mapping[str, Any]) -> None:
    unknown = [name for name in raw if name not in SECTIONS]
    if unknown:
        close = difflib.get_close_matches(unknown[0], SECTIONS, n=1)
        hint = f"; did you mean [{close[0]}]?" if close else ""
        raise WorkflowError(
            f"[{unknown[0]}] unknown section{hint} (known sections: {', '.join(SECTIONS)})"
        )
    for name, value in raw.items():
        if not isinstance(value, Mapping):
            raise WorkflowError(f"[{name}] expected a table, got {value!r}", key=name, value=value)


def _rig(raw: Mapping[str, Any]) -> RigConfig | None:
    if "rig" not in raw:
        return None

    cfg = RigConfig.from_dict(raw["rig"], raw.get("physics", {}))
    check_rig_budget(cfg)  # before a profile of the experiments' length is built
    for name, exp in cfg.experiments.items():
        check_file_name(name, "[rig.experiments] experiment name")  # rig/<name>.mat
        try:
            make_profile(exp.profile, **exp.profile_kwargs())
        except WorkflowError as exc:
            raise WorkflowError(
                f"[rig.experiments.{name}] {exc}", key=f"rig.experiments.{name}", value=exc.value
            ) from None
    return cfg


def _datasets(
    raw: Mapping[str, Any], rig: RigConfig | None
) -> dict[str, tuple[DatasetEntry, IngestSpec]]:
    default = raw.get("ingest", {})
    experiments = sorted(rig.experiments) if rig is not None else []
    out = {}
    for name, table in raw.get("datasets", {}).items():
        check_file_name(name, "[datasets] data set name")  # it becomes ingest/<name>.parquet
        where = f"[datasets.{name}]"
        if not isinstance(table, Mapping):
            raise WorkflowError(f"[datasets] {name}: expected a table, got {table!r}")
        own = {k: table[k] for k in DATASET_KEYS if k in table}
        entry = config_from_section(DatasetEntry, own, where)
        if (entry.source is None) == (entry.rig is None):
            raise WorkflowError(
                f"{where} expected exactly one of `source` (a rig-log file) or `rig` "
                f"(a [rig.experiments.<name>]), got {'both' if entry.source else 'neither'}"
            )
        if entry.rig is not None and entry.rig not in experiments:
            raise WorkflowError(
                f"{where} rig: expected the name of a [rig.experiments.<name>] table "
                f"({', '.join(experiments) or 'there is none'}), got {entry.rig!r}",
                key=dotted_key(where, "rig"),
                value=entry.rig,
            )
        overrides = {k: v for k, v in table.items() if k not in DATASET_KEYS}
        for key, value in overrides.items():
            if key not in OPTION_KEYS and not isinstance(value, Mapping):
                known = [*DATASET_KEYS, *OPTION_KEYS]
                raise WorkflowError(
                    unknown_key_message(where, key, known)
                    + "; a channel is a table {name|regex|column = ..., unit = ...}"
                )
        spec = IngestSpec.from_dict({**default, **overrides}, _origin(overrides, where, "[ingest]"))
        out[name] = (entry, spec)
    if not out and not any(name in raw for name in DATALESS):
        raise WorkflowError(
            "[datasets] expected at least one [datasets.<name>] table (or a [physics] section "
            "to analyze)"
        )
    if out and not any(entry.role == "estimation" for entry, _ in out.values()):
        raise WorkflowError(
            "[datasets] expected at least one data set with role = 'estimation', got none"
        )
    return out


def _differentiate(section: Mapping[str, Any], where: str) -> Any:
    params = dict(section)
    method = params.pop("method", "tvregdiff")
    if not isinstance(method, str) or method not in CONFIGS:
        known = ", ".join(repr(m) for m in CONFIGS)
        raise WorkflowError(f"{where} method: expected one of {known}, got {method!r}")
    return CONFIGS[method].from_dict(params, where)


def _identify(
    section: Mapping[str, Any],
    where: str | Callable[[str], str],
    physics: bool,
    specs: list[IngestSpec],
    study: bool = False,
) -> IdentifyConfig:
    label = where if callable(where) else (lambda _key, w=where: w)
    section = dict(section)
    if section.get("m_q") == "physics":
        if study:
            raise WorkflowError(
                f"{label('m_q')} m_q: 'physics' is not resolved in the studies; give a mass "
                "[kg] or 'identify' in [study.identify]"
            )
        if not physics:
            raise WorkflowError(f"{label('m_q')} m_q: 'physics' needs a [physics] section")
        section["m_q"] = 1.0  # a stand-in: the identify stage computes the analytical m_q
    cfg = IdentifyConfig.from_dict(section, where)
    terms = sorted(set(cfg.backbone) & set(PHYSICS_TERMS))
    if terms and (study or not physics):
        need = "are not available in the studies" if study else "need a [physics] section"
        raise WorkflowError(f"{label('backbone')} backbone: {', '.join(terms)} {need}")
    for spec in specs:
        if terms and spec.n_inputs != 2:
            raise WorkflowError(
                f"{label('backbone')} backbone: {', '.join(terms)} need the two DE voltages "
                f"v1, v2 as inputs, the data have {spec.n_inputs}"
            )
        if cfg.input_gain is not None and len(cfg.input_gain) != spec.n_inputs:
            raise WorkflowError(
                f"{label('input_gain')} input_gain: expected {spec.n_inputs} gain(s), one per "
                f"input v1 ... v{spec.n_inputs}, got {list(cfg.input_gain)!r}"
            )
    for n_inputs in sorted({spec.n_inputs for spec in specs}):
        preflight.check_identify_config(cfg, n_inputs)  # data-free lower bound of its memory
    return cfg


def _q_si(spec: IngestSpec) -> str | None:
    """SI unit of q as the ingest stage will produce it (None: the file declares it)."""
    q = spec.channels[0]
    if q.si_unit is not None:
        return q.si_unit
    return UNITS[q.unit].si if q.unit is not None else None


def _validate(section: Mapping[str, Any], physics: bool, specs: list[IngestSpec]) -> ValidateConfig:
    cfg = ValidateConfig.from_dict(section)
    if cfg.analytical and not physics:
        raise WorkflowError("[validate] analytical: true needs a [physics] section")
    if cfg.report_unit is not None:
        report_si = UNITS[cfg.report_unit].si if cfg.report_unit in UNITS else None
        for si in {_q_si(spec) for spec in specs} - {None}:
            if report_si != si:
                raise WorkflowError(
                    f"[validate] report_unit: expected a unit of q (SI unit {si!r}), "
                    f"got {cfg.report_unit!r}"
                )
    return cfg


def _study(
    raw: Mapping[str, Any], specs: list[IngestSpec]
) -> tuple[StudyConfig, IdentifyConfig, TVRegDiffConfig]:
    study = dict(raw["study"])
    own_identify = study.pop("identify", {})
    if not isinstance(own_identify, Mapping):
        raise WorkflowError(f"[study] identify: expected a table, got {own_identify!r}")
    identify = {**raw.get("identify", {}), **own_identify}
    icfg = _identify(
        identify, _origin(own_identify, "[study.identify]", "[identify]"), True, specs, True
    )
    where = "[study.differentiate]" if "differentiate" in study else "[differentiate]"
    diff = study.pop("differentiate", raw.get("differentiate", {}))
    if not isinstance(diff, Mapping):
        raise WorkflowError(f"[study] differentiate: expected a table, got {diff!r}")
    if diff.get("method", "tvregdiff") != "tvregdiff":
        raise WorkflowError(
            f"{where} method: the alpha study varies TVRegDiff, expected 'tvregdiff', got "
            f"{diff['method']!r} (give a [study.differentiate] table)"
        )
    dcfg = _differentiate(diff, where)

    return StudyConfig.from_dict(study), icfg, dcfg


def check_workflow(raw: Mapping[str, Any]) -> CheckedWorkflow:
    """Check every section of a parsed workflow file with the stages' own config classes.

    Parameters
    ----------
    raw : mapping
        The workflow file as parsed by :func:`tomllib.loads`.

    Returns
    -------
    CheckedWorkflow
        The typed configuration of each section.

    Raises
    ------
    WorkflowError
        At the first problem, in one line naming the section and key and echoing the
        value: ``[section] key: expected ..., got ...``; for an unknown key or section,
        the closest known one as a suggestion. Also: a data set without exactly one of
        ``source`` and ``rig``, a ``rig`` that names no experiment, no estimation data set,
        ``m_q = "physics"``, ``physics_*`` terms or ``analytical = true`` without a
        ``[physics]`` section, ``input_gain`` of the wrong length for the data's inputs, a
        ``report_unit`` that is not a unit of q, a study whose alpha study has no TVRegDiff
        settings.
    ResourceError
        If a stage's arrays, estimated from the settings, exceed the memory budget
        (:func:`debist.workflow.budget.check_workflow_budget`), naming the key.

    References
    ----------
    pydantic 2, "Dataclasses" (https://docs.pydantic.dev/2.x/concepts/dataclasses/).

    Examples
    --------
    >>> check_workflow({"physics": {"b": 0.024}}).physics.b
    0.024
    >>> check_workflow({"physics": {}, "compare": {"degre": 2}})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    debist.core.errors.WorkflowError: [compare] unknown key 'degre'; did you mean 'degree'? ...
    """
    _tables(raw)
    head = config_from_section(WorkflowHead, raw.get("workflow", {}), "[workflow]")
    physics = PrototypeParams.from_dict(raw["physics"]) if "physics" in raw else None
    rig = _rig(raw)
    datasets = _datasets(raw, rig)
    specs = [spec for _, spec in datasets.values()]
    has_physics = physics is not None
    differentiate = _differentiate(raw.get("differentiate", {}), "[differentiate]")
    identify = _identify(raw.get("identify", {}), "[identify]", has_physics, specs)
    validate = _validate(raw.get("validate", {}), has_physics, specs)
    compare = narx = None
    if "compare" in raw:
        sindy = {"input_map": raw.get("identify", {}).get("input_map", "v2"), **raw["compare"]}

        narx = NarxConfig.from_dict(sindy.pop("narx", None), "[compare.narx]")
        compare = SindyConfig.from_dict(sindy, "[compare]")
    study = _study(raw, specs) if "study" in raw else None
    analyze = None
    if "analyze" in raw:
        analyze = AnalyzeConfig.from_dict(raw["analyze"])
    report = None
    if "report" in raw:
        report = ReportConfig.from_dict(raw["report"])
    checked = CheckedWorkflow(
        head, datasets, differentiate, identify, validate, compare, study, physics, analyze, rig,
        report, narx,
    )  # fmt: skip
    check_workflow_budget(checked)  # every stage's arrays within the memory budget
    return checked
