"""Every number a workflow holds, set to 10^5, 10^8 and 10^12: refused naming its key, or within
the memory budget, before any stage runs (the schema and the up-front estimate only)."""

from __future__ import annotations

import pytest

from debist.core.errors import ResourceError, WorkflowError
from debist.core.preflight import BUDGET_ENV, memory_budget
from debist.workflow.budget import workflow_estimates
from debist.workflow.jsonschema import workflow_schema
from debist.workflow.loader import load_workflow
from debist.workflow.schema import check_workflow

#: A workflow with every section, its data recorded by the virtual rig (so the data's length,
#: 3750 samples per experiment, is known before the ingest).
BASE = """
[workflow]
name = "budget"
output_dir = "out"

[physics]
b = 23e-3

[rig]
sample_time = 0.01

[rig.experiments.identification]
profile = "identification"
duration = 37.5

[rig.experiments.validation]
profile = "validation"
duration = 37.5
seed = 2

[ingest]
q = { regex = "Laser/q$", unit = "mm" }
v1 = { regex = "DE1/v_mon$", unit = "kV" }
v2 = { regex = "DE2/v_mon$", unit = "kV" }

[datasets.identification]
rig = "identification"
role = "estimation"

[datasets.validation]
rig = "validation"
role = "validation"

[differentiate]
method = "tvregdiff"

[identify]
M = 6

[identify.refine]

[validate]

[compare]

[compare.narx]

[study]

[study.differentiate]
method = "tvregdiff"

[analyze]

[report]
"""

#: Where the schema has a table of any name, the one of BASE the key goes into.
NAMES = {
    "ingest.<name>": "ingest.time",
    "datasets.<name>.<name>": "datasets.identification.time",
    "datasets.<name>": "datasets.identification",
    "rig.experiments.<name>": "rig.experiments.identification",
}
#: Settings a key needs beside it to be meaningful (the method it belongs to, a channel's
#: other half, the list [identify.auto] varies).
CONTEXT = {
    "differentiate.cutoff_hz": {"differentiate.method": "spectral"},
    "differentiate.taper": {"differentiate.method": "spectral"},
    "differentiate.window": {"differentiate.method": "savgol"},
    "differentiate.polyorder": {"differentiate.method": "savgol", "differentiate.window": 41},
    "identify.auto.folds": {"identify.auto.M": [4, 6]},
    "identify.auto.window": {"identify.auto.M": [4, 6]},
    "rig.experiments.identification.frequency": {"rig.experiments.identification.profile": "sine"},
}
for _channel in ("ingest.time", "datasets.identification.time"):
    for _key in ("scale", "stuck"):
        CONTEXT[f"{_channel}.{_key}"] = {f"{_channel}.name": "t"}
#: Keys that size a stage's arrays: at 10^12 each must be refused, by the schema or the
#: budget, naming the key (an estimate that ignored one of them would let it through).
SIZING = (
    "identify.M",
    "identify.bootstrap",
    "identify.refine.windows",
    "identify.refine.length",
    "identify.refine.substeps",
    "validate.substeps",
    "compare.degree",
    "study.M",
    "analyze.n_b",
    "analyze.n_q",
    "analyze.t_end",
    "analyze.degree",
    "rig.plant.oversample",
    "rig.experiments.identification.duration",
    "differentiate.window",
)


def _numeric(node: dict, defs: dict) -> set[str]:
    """The JSON types of a key that hold numbers: integer, number, array:integer, array:number."""
    out: set[str] = set()
    kind = node.get("type")
    if kind in ("integer", "number"):
        out.add(kind)
    if kind == "array":
        out |= {f"array:{t}" for t in _numeric(node.get("items", {}), defs)}
    for union in ("anyOf", "oneOf", "allOf"):
        for part in node.get(union, []):
            out |= _numeric(part, defs)
    return out


def _keys() -> list[tuple[str, frozenset[str]]]:
    """Every key of the workflow schema that holds a number, as a dotted key into BASE."""
    schema = workflow_schema()
    defs = schema["$defs"]
    found: dict[str, frozenset[str]] = {}

    def walk(node: dict, path: tuple[str, ...], seen: frozenset[str]) -> None:
        if "$ref" in node:
            name = node["$ref"].rsplit("/", 1)[-1]
            if name not in seen:
                walk(defs[name], path, seen | {name})
        for key, sub in node.get("properties", {}).items():
            kinds = _numeric(sub, defs)
            if kinds:
                found.setdefault(".".join((*path, key)), frozenset(kinds))
            walk(sub, (*path, key), seen)
        extra = node.get("additionalProperties")
        if isinstance(extra, dict):
            walk(extra, (*path, "<name>"), seen)
        for union in ("anyOf", "oneOf", "allOf"):
            for part in node.get(union, []):
                walk(part, path, seen)

    walk(schema, (), frozenset())
    out = []
    for key, kinds in found.items():
        for pattern, name in NAMES.items():
            if key.startswith(pattern + "."):
                key = name + key[len(pattern) :]
                break
        out.append((key, kinds))
    return out


KEYS = _keys()


def _value(kinds: frozenset[str], exponent: int) -> object:
    """10^exponent as the key's type: an integer where it takes one, a list for an array."""
    if "integer" in kinds:
        return 10**exponent
    if "number" in kinds:
        return float(10**exponent)
    item = 10**exponent if "array:integer" in kinds else float(10**exponent)
    return [item, item, item]


def _tables(key: str) -> list[str]:
    """The table headers a message may name the key by: ``[a]``, ``[a.b]``, ..."""
    parts = key.split(".")
    return [f"[{'.'.join(parts[:i])}]" for i in range(1, len(parts))]


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    path = tmp_path_factory.mktemp("budget") / "wf.toml"
    path.write_text(BASE)
    return path


@pytest.fixture(autouse=True)
def fixed_budget(monkeypatch):
    """The same budget on every machine: 4 GB."""
    monkeypatch.setenv(BUDGET_ENV, "4")


def test_the_walk_finds_the_numbers_of_every_section():
    sections = {key.split(".")[0] for key, _ in KEYS}
    assert sections >= {
        "ingest", "datasets", "differentiate", "identify", "validate", "compare", "study",
        "physics", "analyze", "rig", "report",
    }  # fmt: skip
    assert set(SIZING) <= {key for key, _ in KEYS}
    assert len(KEYS) > 150


def test_the_base_workflow_is_within_the_budget(base):
    checked = load_workflow(base)
    assert checked.datasets
    estimates = workflow_estimates(check_workflow(_raw(base)))
    assert len(estimates) >= 8  # rig x 2, identify, refine, validate x 2, SINDy, NARX, ...
    assert all(0 < e.nbytes <= memory_budget() for e in estimates)


def _raw(path):
    import tomllib

    return tomllib.loads(path.read_text())


@pytest.mark.parametrize("exponent", [5, 8, 12])
@pytest.mark.parametrize(("key", "kinds"), KEYS, ids=[k for k, _ in KEYS])
def test_a_huge_number_is_refused_naming_its_key_or_fits_the_budget(base, key, kinds, exponent):
    overrides = {**CONTEXT.get(key, {}), key: _value(kinds, exponent)}
    try:
        load_workflow(base, overrides=overrides)
    except WorkflowError as exc:  # exit code 2, before any stage runs
        message = str(exc)
        assert "\n" not in message
        assert key.rsplit(".", 1)[-1] in message, message
        assert any(table in message for table in _tables(key)), message
        return
    assert key not in SIZING or exponent < 12, f"{key} = 10^{exponent} was not refused"
    raw = _raw(base)
    for dotted, value in overrides.items():
        *tables, last = dotted.split(".")
        table = raw
        for name in tables:
            table = table.setdefault(name, {})
        table[last] = value
    estimates = workflow_estimates(check_workflow(raw))
    assert estimates and max(e.nbytes for e in estimates) <= memory_budget()


def test_a_rig_experiment_too_long_for_the_budget_is_refused_before_its_profile(base):
    # 2e5 s at 0.01 s, 50 samples of padding either end, oversample 10: 2.00001e8 internal
    # steps of 13 states
    with pytest.raises(ResourceError) as info:
        load_workflow(base, overrides={"rig.experiments.identification.duration": 2e5})
    message = str(info.value)
    assert "[rig.experiments.identification] duration = 200000 s" in message
    assert "200001000 internal steps x 13 states" in message
    # 2.00001e8 steps x (4 x 13 + 2) float64 + 2e8 DAC samples x 50 float64: 166 GB
    assert "needs about 166 GB" in message and "budget is 4 GB" in message


def test_the_rig_estimate_grows_with_the_duration_and_the_oversampling(base):
    def rig_bytes(**overrides):
        raw = _raw(base)
        raw["rig"].setdefault("plant", {})
        for key, value in overrides.items():
            table, _, name = key.rpartition(".")
            node = raw["rig"]
            for part in table.split(".") if table else ():
                node = node[part]
            node[name] = value
        (est,) = [e for e in workflow_estimates(check_workflow(raw)) if "[rig.exp" in e.setting][:1]
        return est.nbytes

    one = rig_bytes()
    # the profile's DAC samples (37500 x 50 float64) do not scale with the oversampling
    refs = 8 * 50 * 37500
    assert rig_bytes(**{"plant.oversample": 20}) - refs == pytest.approx(2 * (one - refs), rel=0.02)
    assert rig_bytes(**{"experiments.identification.duration": 75.0}) == pytest.approx(
        2 * one, rel=0.02
    )


def test_a_rig_sample_time_longer_than_an_experiment_is_refused(base):
    with pytest.raises(WorkflowError, match=r"\[rig\] sample_time: expected at most"):
        load_workflow(base, overrides={"rig.sample_time": 100.0})


def test_a_bootstrap_too_large_is_named_as_the_setting_to_change(base):
    with pytest.raises(ResourceError, match=r"\[identify\] bootstrap = 100000000:"):
        load_workflow(base, overrides={"identify.bootstrap": 10**8})


def test_the_sindy_library_is_counted_as_monomials(base):
    raw = _raw(base)
    raw["compare"] = {"degree": 3}
    (est,) = [e for e in workflow_estimates(check_workflow(raw)) if "[compare] degree" in e.setting]
    # (3 + 1)(3 + 2) / 2 = 10 monomials in q, q_dot, each alone and times h1, h2: 30 terms;
    # 3750 estimation samples; pysindy's 18 blocks
    assert est.nbytes == 8 * 18 * 3750 * 30


def test_resampling_a_rig_log_onto_a_fine_grid_is_refused_naming_the_key(base):
    # 37.5 s at 1e-9 s: 3.75e10 samples of q, v1, v2 and time, 4 copies: 4.8 TB
    with pytest.raises(ResourceError) as info:
        load_workflow(
            base, overrides={"ingest.resample": {"sample_time": 1e-9, "method": "linear"}}
        )
    message = str(info.value)
    assert "[ingest] resample.sample_time = 1e-09 s (as [datasets.identification] reads it)" in (
        message
    )
    assert "onto 37500000000 samples needs about 4.8 TB" in message


def test_a_coarser_resampling_shrinks_the_least_squares_estimate(base):
    def identify_bytes(overrides):
        raw = _raw(base)
        raw["ingest"].update(overrides)
        (est,) = [e for e in workflow_estimates(check_workflow(raw)) if "regressor" in e.need][:1]
        return est

    plain = identify_bytes({})
    coarse = identify_bytes({"resample": {"sample_time": 0.02}})
    assert "3750 samples" in plain.need and "1875 samples" in coarse.need
    assert coarse.nbytes < plain.nbytes


def test_a_pre_strain_sweep_of_a_hundred_thousand_screw_positions_is_refused(base):
    # each screw position holds a continuation of the static path per voltage state
    with pytest.raises(ResourceError) as info:
        load_workflow(base, overrides={"analyze.n_b": 100_000})
    message = str(info.value)
    assert message.split(": ", 1)[1].startswith("[analyze] n_b = 100000, n_q = 121")
    # 1e5 x 110000 + 121 x 240 + 5001 x 200 float64: 88 GB
    assert "needs about 88 GB" in message


def test_a_design_analysis_without_an_analyze_table_is_estimated_with_its_defaults():
    (est,) = workflow_estimates(check_workflow({"physics": {"b": 0.023}}))
    assert est.setting == "[analyze] n_b = 101, n_q = 121, t_end = 5 s"
    assert est.nbytes == 8 * (101 * 110_000 + 121 * 240 + 5001 * 200)


def test_the_largest_m_of_identify_auto_is_estimated(base):
    with pytest.raises(ResourceError) as info:
        load_workflow(base, overrides={"identify.auto.M": [6, 100_000]})
    message = str(info.value).split(": ", 1)[1]
    assert message.startswith("[identify.auto] M = 100000: the regressor of 3750 samples")
    load_workflow(base, overrides={"identify.auto.M": [4, 6, 8]})


def test_the_rig_experiments_that_run_at_once_must_fit_together(base, monkeypatch):
    import debist.workflow.budget as budget

    monkeypatch.setattr(budget, "fork_workers", lambda n: min(n, 2))  # two cores
    # 3000 s each: 300100 x 10 steps x 54 + 3e6 DAC samples x 50 float64 = 2.5 GB, 5 GB both
    longer = {f"rig.experiments.{name}.duration": 3000.0 for name in ("identification",
                                                                       "validation")}  # fmt: skip
    with pytest.raises(ResourceError) as info:
        load_workflow(base, overrides=longer)
    assert (
        str(info.value)
        .split(": ", 1)[1]
        .startswith(
            "[rig.experiments.identification] duration = 3000 s and [rig.experiments.validation] "
            "duration = 3000 s (run in parallel, one per core): the integration of 2 experiments "
            "at once needs about 4.99 GB"
        )
    )
    load_workflow(base, overrides={"rig.experiments.identification.duration": 3000.0})
    monkeypatch.setattr(budget, "fork_workers", lambda n: 1)  # serially: one at a time
    load_workflow(base, overrides=longer)
