"""`debist schema`: the JSON Schema of a workflow file agrees with the workflow checks."""

from __future__ import annotations

import dataclasses
import json
import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from debist.cli import app
from debist.core.errors import WorkflowError
from debist.identify.config import IdentifyConfig
from debist.ingest.spec import OPTION_KEYS
from debist.rig.params import RigParams
from debist.workflow.jsonschema import workflow_schema
from debist.workflow.schema import SECTIONS, check_workflow

jsonschema = pytest.importorskip("jsonschema")

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted((ROOT / "workflows").glob("*.toml"))


@pytest.fixture(scope="module")
def validator():
    schema = workflow_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_every_shipped_workflow_is_valid_under_the_schema(path, validator):
    raw = tomllib.loads(path.read_text(encoding="utf-8"))
    check_workflow(raw)  # the workflow checks accept it ...
    assert [e.message for e in validator.iter_errors(raw)] == []  # ... and so does the schema


@pytest.mark.parametrize(
    ("raw", "where", "named"),
    [
        ({"physics": {}, "identify": {"degre": 2}}, ["identify"], "degre"),
        ({"physics": {}, "identify": {"M": "ten"}}, ["identify", "M"], "M"),
        ({"physics": {}, "differentiate": {"method": "spectral", "alpha": 1e-3}},
         ["differentiate"], "alpha"),
        ({"physics": {}, "rig": {"plant": {"friction_kk": [1.0]}, "experiments": {"a": {}}}},
         ["rig", "plant"], "friction_kk"),
        ({"physics": {}, "compare": {"narx": {"degree": "3"}}}, ["compare", "narx", "degree"],
         "degree"),
        ({"physics": {}, "datasets": {"a": {"source": "x.csv", "sample_time": 0.1,
                                           "v1": {"column": 0}, "q": {"unti": "mm"}}}},
         ["datasets", "a", "q"], "unti"),
        ({"physics": {}, "identify": {"auto": {"bootstrap": [10]}}}, ["identify", "auto"],
         "bootstrap"),
        ({"physics": {}, "identify": {"prior": 1.0}}, ["identify"], "prior"),
        ({"physiks": {}}, [], "physiks"),
    ],
)  # fmt: skip
def test_what_the_checks_refuse_the_schema_refuses_at_the_same_key(raw, where, named, validator):
    with pytest.raises(WorkflowError, match=named):
        check_workflow(raw)
    errors = list(validator.iter_errors(raw))
    assert errors, raw
    assert any(list(e.absolute_path)[: len(where)] == where for e in errors), [
        (list(e.absolute_path), e.message) for e in errors
    ]


def test_every_key_of_the_config_classes_is_in_the_schema_with_a_description():
    schema = workflow_schema()
    defs = schema["$defs"]
    assert list(schema["properties"]) == list(SECTIONS)
    identify = defs["IdentifyConfig"]["properties"]
    keys = {f.name for f in dataclasses.fields(IdentifyConfig)} - set(IdentifyConfig.INTERNAL)
    assert set(identify) == keys and "prior" not in identify  # set by the stage, not a key
    assert set(OPTION_KEYS) <= set(defs["IngestSpec"]["properties"])  # "slice" by its key
    assert "sample_slice" not in defs["IngestSpec"]["properties"]
    assert set(defs["RigParams"]["properties"]) == {
        f.name for f in dataclasses.fields(RigParams)
    } - {"prototype"}
    for name, table in defs.items():
        for key, prop in table.get("properties", {}).items():
            assert prop.get("description"), f"{name}.{key} has no description"
            assert ":class:" not in prop["description"] and "``" not in prop["description"]
    assert identify["M"]["default"] == 10
    assert identify["m_q"]["anyOf"][-1] == {"const": "physics", "type": "string"}
    assert "Number of RBF centres per curve" in identify["M"]["description"]


def test_the_command_prints_the_schema_as_json():
    result = CliRunner().invoke(app, ["schema"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output) == workflow_schema()
