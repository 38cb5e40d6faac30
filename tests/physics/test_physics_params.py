"""Parameters of the physics model: Table 1 in SI, TOML loading, validation, docs."""

import dataclasses
import importlib
import inspect
import tomllib
from pathlib import Path

import pytest

from debist.core.errors import WorkflowError
from debist.physics.params import V_MAX, PrototypeParams

ROOT = Path(__file__).resolve().parents[2]
MODULES = ["params", "kinematics", "energy", "statics", "prestrain", "dynamics", "reduced"]


def test_paper_values_in_si():
    p = PrototypeParams.paper()
    assert pytest.approx(530.4e-9, rel=1e-12) == p.V_DE  # n d_0 A_0 (docs/interpretation.md item 4)
    assert pytest.approx(8 * 8.854e-12 * 2.8 * 1326e-6 / 50e-6, rel=1e-12) == p.C_0
    assert pytest.approx(5.2597e-9, rel=1e-4) == p.C_0
    assert p.E == 2.1e9  # GPa, with the 1/2 (docs/interpretation.md items 2, 3)
    assert p.z_b == pytest.approx(7e-3)
    assert V_MAX == 3e3


def test_workflow_physics_section_loads_to_the_paper_prototype():
    raw = tomllib.loads((ROOT / "workflows" / "paper-analysis.toml").read_text())
    p = PrototypeParams.from_dict(raw["physics"])
    ref = PrototypeParams.paper()
    for f in dataclasses.fields(p):
        assert getattr(p, f.name) == pytest.approx(getattr(ref, f.name), rel=1e-12), f.name
    assert set(raw["physics"]) == {f.name for f in dataclasses.fields(p)}  # every key listed


def test_unknown_key_is_named():
    with pytest.raises(WorkflowError) as err:
        PrototypeParams.from_dict({"E": 2e9, "Young": 1.0})
    assert err.value.key == "physics.Young"
    assert "unknown" in str(err.value)
    assert "epsilon_0" in str(err.value)


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("E", "2.1 GPa", r"^\[physics\] E: expected a number, got '2.1 GPa'$"),
        ("l", -0.09, r"^\[physics\] l: expected a number > 0, got -0.09$"),
        ("b", float("nan"), r"^\[physics\] b: expected a finite number, got nan$"),
        ("eta", -1.0, r"^\[physics\] eta: expected a number >= 0, got -1.0$"),
        ("beta", True, r"^\[physics\] beta: expected a number, got True$"),
    ],
)
def test_invalid_values_raise(key, value, match):
    with pytest.raises(WorkflowError, match=match):
        PrototypeParams.from_dict({key: value})


def test_zero_damping_is_allowed_and_replace_rederives_volume():
    p = PrototypeParams.paper().replace(eta=0.0, A_0=1000e-6)
    assert p.eta == 0.0
    assert pytest.approx(8 * 50e-6 * 1000e-6) == p.V_DE
    q = PrototypeParams(V_DE=1e-6).replace(A_0=1000e-6)
    assert q.V_DE == 1e-6  # an explicit volume is kept
    assert PrototypeParams.from_dict(p.to_dict()) == p


def test_not_a_table():
    with pytest.raises(WorkflowError) as err:
        PrototypeParams.from_dict([("E", 1.0)])
    assert "'E'" in str(err.value)
    assert "1.0" in str(err.value)


@pytest.mark.parametrize("name", MODULES)
def test_public_api_has_numpydoc_sections(name):
    mod = importlib.import_module(f"debist.physics.{name}")
    for item in mod.__all__:
        obj = getattr(mod, item)
        doc = inspect.getdoc(obj) or ""
        assert doc, f"{name}.{item} has no docstring"
        if inspect.isfunction(obj):
            assert "Parameters\n----------" in doc, f"{name}.{item}"
            assert "Returns\n-------" in doc, f"{name}.{item}"
            assert "References\n----------" in doc or "Masoud" in doc, item
        elif inspect.isclass(obj) and dataclasses.is_dataclass(obj):
            assert "Attributes\n----------" in doc or "Parameters\n----------" in doc, item
