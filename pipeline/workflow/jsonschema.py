"""The JSON Schema of a workflow file, built from the config classes that check it.

:func:`workflow_schema` returns one JSON Schema (draft 2020-12) of a whole workflow TOML
file: every section, sub-table and key that :func:`debist.workflow.schema.check_workflow`
accepts, with its type, range, default and description. The per-key parts come from
pydantic (``TypeAdapter``-style generation over the stages' own config dataclasses), the
descriptions from each class's numpydoc ``Parameters`` section or, for a class with many
fields, from the docstring under each field's declaration, so the schema cannot drift
from the checks. What the classes leave to code (the channel tables of ``[ingest]``, the
``method`` of ``[differentiate]``, the candidate lists of ``[identify.auto]``, the sub-tables
of ``[rig]``) is added here by hand, following :mod:`debist.workflow.schema`.

The schema describes the file's shape. Rules that span several keys or sections (exactly
one of ``source`` and ``rig`` per data set, ``physics_*`` terms only with ``[physics]``,
the memory budget) stay with :func:`~debist.workflow.schema.check_workflow`, which gives
the one-line messages.

References
----------
JSON Schema 2020-12 (https://json-schema.org/draft/2020-12/json-schema-core);
pydantic 2 documentation, "JSON Schema" (https://docs.pydantic.dev/2.x/concepts/json_schema/);
numpydoc docstring guide (https://numpydoc.readthedocs.io/en/latest/format.html).
"""

from __future__ import annotations

import ast
import copy
import inspect
import itertools
import re
import textwrap
from typing import Any

import docstring_parser
from pydantic.json_schema import GenerateJsonSchema, models_json_schema

from debist.differentiate.base import CONFIGS
from debist.identify.config import DEFAULT_WINDOW, IdentifyConfig, RefineConfig
from debist.ingest.spec import ChannelSpec, IngestSpec
from debist.model.narx import NarxConfig
from debist.model.sindy import SindyConfig
from debist.physics.config import AnalyzeConfig
from debist.physics.params import PrototypeParams
from debist.rig.config import ExperimentConfig
from debist.rig.params import RigParams
from debist.validate.config import ValidateConfig
from debist.workflow.schema import SECTIONS, DatasetEntry, WorkflowHead
from debist.workflow.sections import ReportConfig, StudyConfig

__all__ = ["SCHEMA_ID", "workflow_schema"]

#: The ``$schema`` of the returned document.
SCHEMA_ID = "https://json-schema.org/draft/2020-12/schema"
#: Fields of the config classes that no workflow key sets (the stages fill them in), besides
#: those a class lists in its ``INTERNAL``.
_INTERNAL = {"ChannelSpec": ("role",), "IngestSpec": ("channels",), "RigParams": ("prototype",)}
#: [identify] keys that [identify.auto] does not vary (see debist.identify.config.check_grid).
_NOT_AUTO = ("prior", "bootstrap", "auto", "refine")
#: A reST role such as :class:`~debist.identify.refine.RefineConfig`.
_ROLE = re.compile(r":[a-z]+:`(~?)([^`]+)`")


def _role(match: re.Match[str]) -> str:
    """Write a reST cross-reference as code: ``~a.b.C`` as ``C``, ``a.b.C`` as it is."""
    name = match.group(2)
    return f"`{name.rsplit('.', 1)[-1] if match.group(1) else name}`"


def _plain(text: str | None) -> str:
    """Join a docstring's lines and write its reST literals and roles as Markdown code."""
    return _ROLE.sub(_role, " ".join((text or "").split())).replace("``", "`")


def _field_docs(cls: type) -> dict[str, str]:
    """Return the docstrings written under a class's field declarations (``x: int = 1``)."""
    out: dict[str, str] = {}
    for klass in reversed(cls.__mro__[:-1]):
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError, SyntaxError):  # no source: a builtin or a generated class
            continue
        body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
        for field, doc in itertools.pairwise(body):
            if (
                isinstance(field, ast.AnnAssign)
                and isinstance(field.target, ast.Name)
                and isinstance(doc, ast.Expr)
                and isinstance(doc.value, ast.Constant)
                and isinstance(doc.value.value, str)
            ):
                out[field.target.id] = inspect.cleandoc(doc.value.value)
    return out


def _descriptions(cls: type) -> tuple[str, dict[str, str]]:
    """Return a class's summary and its field descriptions (numpydoc or under each field)."""
    doc = docstring_parser.parse(cls.__doc__ or "", docstring_parser.DocstringStyle.NUMPYDOC)
    summary = " ".join(x for x in (doc.short_description, doc.long_description) if x)
    params = {name: _plain(text) for name, text in _field_docs(cls).items()}
    for param in doc.params:
        for name in param.arg_name.split(","):  # "lo, hi : float" documents two fields
            params[name.strip()] = _plain(param.description)
    return _plain(summary), params


class _DocumentedSchema(GenerateJsonSchema):
    """pydantic's generator, describing each dataclass field by its class's docstring."""

    def dataclass_schema(self, schema: Any) -> dict[str, Any]:
        """Return pydantic's schema of a dataclass with numpydoc descriptions filled in."""
        return _document(super().dataclass_schema(schema), schema["cls"])

    def typed_dict_schema(self, schema: Any) -> dict[str, Any]:
        """Return pydantic's schema of a TypedDict with numpydoc descriptions filled in."""
        return _document(super().typed_dict_schema(schema), schema["cls"])


def _document(out: dict[str, Any], cls: type) -> dict[str, Any]:
    """Fill in the descriptions of a class's schema and drop the fields no key sets."""
    summary, params = _descriptions(cls)
    out["description"] = summary
    fields = getattr(cls, "__pydantic_fields__", {})
    aliases = {(info.alias or name): name for name, info in fields.items()}
    for key, prop in out.get("properties", {}).items():
        text = params.get(aliases.get(key, key), "")
        rule = prop.get("description")  # the type in words, as the error messages say it
        prop["description"] = f"{text} Expected: {rule}." if text and rule else text or rule
    for name in (*getattr(cls, "INTERNAL", ()), *_INTERNAL.get(cls.__name__, ())):
        out.get("properties", {}).pop(name, None)
        if name in out.get("required", ()):
            out["required"].remove(name)
        if not out.get("required"):
            out.pop("required", None)
    return out


def _ref(name: str) -> dict[str, str]:
    return {"$ref": f"#/$defs/{name}"}


def _table(description: str, **schema: Any) -> dict[str, Any]:
    return {"type": "object", "description": description, **schema}


def _ingest(defs: dict[str, Any]) -> None:
    """Add the channel tables to ``[ingest]`` and define a data set's table, ``Dataset``."""
    defs["ChannelSpec"]["description"] = (
        "A channel table: `q`, `v1` ... `vN` (contiguous) and extra columns by any other "
        "identifier; `time` (an [ingest] option) maps the time channel. "
        + defs["ChannelSpec"]["description"]
    )
    defs["IngestSpec"]["additionalProperties"] = _ref("ChannelSpec")
    defs["IngestSpec"]["description"] = (
        "How every data set's rig log is read (a data set's own keys replace these): the "
        "format and its options, and one channel table per column (`q`, `v1` ... `vN`)."
    )
    dataset = copy.deepcopy(defs["IngestSpec"])
    dataset["properties"] = {**defs["DatasetEntry"]["properties"], **dataset["properties"]}
    dataset["title"] = "Dataset"
    dataset["description"] = (
        "One data set: `source` (a rig log) or `rig` (a virtual-rig experiment), its `role`, "
        "and any [ingest] key or channel table, which replaces the [ingest] one."
    )
    defs["Dataset"] = dataset


def _differentiate(defs: dict[str, Any]) -> None:
    """Give each method's table its ``method`` key (``tvregdiff`` is the default)."""
    for method, cls in CONFIGS.items():
        key = {"const": method, "type": "string", "description": "The method."}
        if method == "tvregdiff":
            key["default"] = method
        defs[cls.__name__]["properties"] = {"method": key, **defs[cls.__name__]["properties"]}


def _identify(defs: dict[str, Any]) -> None:
    """Describe ``[identify.refine]``, ``[identify.auto]`` and ``m_q = "physics"``."""
    identify = defs["IdentifyConfig"]["properties"]
    identify["refine"] = {
        "anyOf": [_ref("RefineConfig"), {"type": "boolean"}],
        "default": False,
        "description": identify["refine"]["description"],
    }
    # "physics" stands for the analytical model's mass, resolved by the identify stage
    identify["m_q"]["anyOf"].append({"const": "physics", "type": "string"})
    candidates = sorted(k for k in identify if k not in _NOT_AUTO)
    identify["auto"] = _table(
        identify["auto"]["description"],
        properties={
            "folds": {
                "type": "integer",
                "minimum": 2,
                "default": 4,
                "description": "Blocks per estimation record of the cross-validation.",
            },
            "window": {
                "type": "integer",
                "minimum": 10,
                "default": DEFAULT_WINDOW,
                "description": "[samples] per restarted window of the held-out score.",
            },
        },
        propertyNames={"enum": ["folds", "window", *candidates]},
        additionalProperties={
            "type": "array",
            "description": "Candidate values of this [identify] key (a single value counts "
            "as a list of one).",
        },
    )


def _rig() -> dict[str, Any]:
    """Return the ``[rig]`` table: its own key and its three sub-tables."""
    return _table(
        "The virtual rig: the built prototype, the plant and the experiments it records "
        "(Masoud & Maas 2025, Sec. 5.1).",
        title="Rig",
        additionalProperties=False,
        properties={
            "sample_time": {
                "type": "number",
                "exclusiveMinimum": 0,
                "default": 0.01,
                "description": "Log interval [s].",
            },
            "prototype": {
                **_ref("PrototypeParams"),
                "description": "How the built prototype deviates from [physics] (same keys).",
            },
            "plant": {
                **_ref("RigParams"),
                "description": "The rig around the prototype: "
                "friction, drivers, sensor (the keys of RigParams).",
            },
            "experiments": _table(
                'The experiments by name; a data set names one with `rig = "<name>"`.',
                additionalProperties=_ref("ExperimentConfig"),
            ),
        },
    )


def workflow_schema() -> dict[str, Any]:
    """Return the JSON Schema of a workflow file (every section, sub-table and key).

    Returns
    -------
    dict
        A JSON Schema (draft 2020-12) document: ``properties`` holds one entry per section
        of :data:`debist.workflow.schema.SECTIONS` (a ``$ref`` into ``$defs``, or for
        ``[differentiate]`` an ``anyOf`` of its methods); every key has a ``description``
        from its config class's docstring, and a ``default`` where it has one. Tables whose
        keys are names (data sets, channels, rig experiments) have ``additionalProperties``.
        Serialisable with :func:`json.dumps`.

    References
    ----------
    JSON Schema 2020-12; pydantic 2, ``pydantic.json_schema.models_json_schema``
    (https://docs.pydantic.dev/2.x/api/json_schema/).

    Examples
    --------
    >>> schema = workflow_schema()
    >>> schema["$defs"]["IdentifyConfig"]["properties"]["M"]["default"]
    10
    >>> sorted(schema["properties"]) == sorted(SECTIONS)
    True
    """
    models = [
        WorkflowHead, DatasetEntry, IngestSpec, ChannelSpec, IdentifyConfig, RefineConfig,
        ValidateConfig, SindyConfig, NarxConfig, StudyConfig, PrototypeParams, AnalyzeConfig,
        RigParams, ExperimentConfig, ReportConfig, *CONFIGS.values(),
    ]  # fmt: skip
    _, top = models_json_schema(
        [(m, "validation") for m in models],
        schema_generator=_DocumentedSchema,
        ref_template="#/$defs/{model}",
    )
    defs: dict[str, Any] = top["$defs"]
    _ingest(defs)
    _differentiate(defs)
    _identify(defs)
    defs["SindyConfig"]["properties"]["narx"] = {
        **_ref("NarxConfig"),
        "description": "The polynomial NARX peer of the compare stage (the `narx` extra).",
    }
    study = defs["StudyConfig"]["properties"]
    study["identify"] = _table(
        "[identify] keys that replace the [identify] ones for the studies "
        "(the same keys as [identify]).",
        additionalProperties=True,
    )
    study["differentiate"] = {
        **_ref(CONFIGS["tvregdiff"].__name__),
        "description": "TVRegDiff settings of the alpha study (default: [differentiate]).",
    }
    defs["Rig"] = _rig()
    sections = {
        "workflow": _ref("WorkflowHead"),
        "ingest": _ref("IngestSpec"),
        "datasets": _table(
            "The data sets by name (plain file names: each becomes ingest/<name>.parquet).",
            additionalProperties=_ref("Dataset"),
        ),
        "differentiate": {
            "anyOf": [_ref(cls.__name__) for cls in CONFIGS.values()],
            "description": "Derivatives q_dot, q_ddot by the `method` named.",
        },
        "identify": _ref("IdentifyConfig"),
        "validate": _ref("ValidateConfig"),
        "compare": _ref("SindyConfig"),
        "study": _ref("StudyConfig"),
        "physics": _ref("PrototypeParams"),
        "analyze": _ref("AnalyzeConfig"),
        "rig": _ref("Rig"),
        "report": _ref("ReportConfig"),
    }
    return {
        "$schema": SCHEMA_ID,
        "title": "debist workflow file",
        "description": "A debist workflow (TOML): its data sets and one table per stage.",
        "type": "object",
        "additionalProperties": False,
        "properties": {name: sections[name] for name in SECTIONS},
        "$defs": dict(sorted(defs.items())),
    }
