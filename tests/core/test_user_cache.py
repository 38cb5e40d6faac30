"""The user cache saves start-up time and never changes an answer.

Two things are cached: the import names of debist's modules (stage fingerprints) and pint's
answers (unit lookups and the reports' unit formatting). Each test compares the cached path
with an independent computation: the AST of the sources, or pint itself.
"""

from __future__ import annotations

import ast
import json
import os

import pint
import pytest

from debist.core import cache as user_cache
from debist.core import units
from debist.engine import fingerprint
from debist.stages.registry import STAGES


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty user cache, and every in-process memo cleared (a fresh process)."""
    folder = tmp_path / "cache"
    monkeypatch.setenv(user_cache.ENV, str(folder))
    monkeypatch.setattr(fingerprint, "_index", None)
    monkeypatch.setattr(fingerprint, "_parsed", {})
    for memo in (fingerprint._direct_imports, fingerprint._fingerprint, fingerprint._module_file):
        memo.cache_clear()
    for memo in (units._all_answers, units.lookup_unit, units._stamp):
        memo.cache_clear()
    yield folder
    for memo in (fingerprint._direct_imports, fingerprint._fingerprint, fingerprint._module_file):
        memo.cache_clear()
    for memo in (units._all_answers, units.lookup_unit):
        memo.cache_clear()


def _fresh_process():
    """Forget the in-process memos, keep the cache folder (the next command)."""
    fingerprint._index = None
    fingerprint._parsed.clear()
    for memo in (fingerprint._direct_imports, fingerprint._fingerprint, fingerprint._module_file):
        memo.cache_clear()
    for memo in (units._all_answers, units.lookup_unit):
        memo.cache_clear()


def _ast_imports(name: str) -> list[str]:
    """The package names a module imports, from its AST (the uncached computation)."""
    path = fingerprint._module_file(name)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = fingerprint._imported_names(ast.parse(path.read_bytes()), package)
    return sorted(n for n in found if n == "debist" or n.startswith("debist."))


def test_stage_fingerprints_are_the_same_with_a_cold_and_a_warm_cache(cache):
    modules = [entry.module for entry in STAGES]
    cold = {m: fingerprint.code_fingerprint(m) for m in modules}
    closures = {m: fingerprint.module_closure(m) for m in modules}
    index = json.loads((cache / "imports-v1.json").read_text())
    assert "debist.stages.identify" in index and "debist.identify.fit" in index
    for name, (_digest, names) in index.items():
        assert names == _ast_imports(name), name
    _fresh_process()
    assert {m: fingerprint.code_fingerprint(m) for m in modules} == cold
    assert {m: fingerprint.module_closure(m) for m in modules} == closures


def test_a_stale_or_forged_entry_is_parsed_again(cache):
    fingerprint.module_closure("debist.stages.ingest")
    path = cache / "imports-v1.json"
    index = json.loads(path.read_text())
    true_names = index["debist.stages.ingest"][1]
    # a source that changed since: the digest no longer matches, so the names are not used
    index["debist.stages.ingest"] = ["0" * 64, ["debist.rig.plant"]]
    # a malformed entry of the right digest (a name outside the package) is not used either
    digest = index["debist.ingest.load"][0]
    index["debist.ingest.load"] = [digest, ["os.path"]]
    path.write_text(json.dumps(index))
    _fresh_process()
    closure = fingerprint.module_closure("debist.stages.ingest")
    assert "debist.rig.plant" not in closure and "debist.ingest.mat" in closure
    repaired = json.loads(path.read_text())
    assert repaired["debist.stages.ingest"][1] == true_names
    assert repaired["debist.ingest.load"][1] == _ast_imports("debist.ingest.load")


def test_a_corrupt_or_unwritable_cache_costs_only_time(cache):
    expected = fingerprint.module_closure("debist.stages.validate")
    _fresh_process()
    (cache / "imports-v1.json").write_text('{"debist.validate.freerun": [')  # truncated
    assert fingerprint.module_closure("debist.stages.validate") == expected
    _fresh_process()
    blocked = cache.parent / "a-file"
    blocked.write_text("not a folder")
    os.environ[user_cache.ENV] = str(blocked / "cache")  # mkdir fails, for root too
    assert fingerprint.module_closure("debist.stages.validate") == expected
    assert units.lookup_unit("kV").factor == 1000.0
    assert units.pretty_unit("N*s/m") == "N s/m"
    assert not (blocked / "cache").exists()


@pytest.mark.parametrize(
    "symbol", ["mm", "kV", "m/s^2", "g0", "[µm]", "deg", "-", "degC", "2 mm", "bananas", "N*m"]
)
def test_unit_lookups_are_pints_answers_cold_and_warm(cache, symbol):
    registry = pint.UnitRegistry()
    cold = units.lookup_unit(symbol)
    _fresh_process()
    warm = units.lookup_unit(symbol)
    assert warm == cold
    stored = json.loads((cache / "units-v1.json").read_text())
    assert units.canonical_unit(symbol) in stored["lookup"]
    text = units.canonical_unit(symbol).replace("^", "**")
    if cold is None:
        return
    one = registry.Quantity(1.0, registry.parse_units(text)).to_base_units()
    assert cold.factor == pytest.approx(one.magnitude, rel=1e-15)


def test_pretty_units_are_pints_answers_cold_and_warm(cache):
    expressions = ["(m/s**2)/m", "N*s/m", "m/m", "(N)/(V)**2", "kg*m/s**2"]
    cold = [units.pretty_unit(e) for e in expressions]
    _fresh_process()
    assert [units.pretty_unit(e) for e in expressions] == cold
    assert cold[:3] == ["1/s^2", "N s/m", "1"]


def test_answers_of_another_pint_or_another_units_module_are_not_used(cache):
    units.lookup_unit("mm")
    path = cache / "units-v1.json"
    stored = json.loads(path.read_text())
    stored["lookup"]["mm"] = [1.0, "m", "length"]  # a forged answer
    stored["stamp"] = stored["stamp"].replace("pint ", "pint 0.0.1+", 1)
    path.write_text(json.dumps(stored))
    _fresh_process()
    assert units.lookup_unit("mm").factor == 0.001
    stored = json.loads(path.read_text())
    stored["lookup"]["mm"] = [1.0, "m"]  # the right stamp, a malformed answer
    path.write_text(json.dumps(stored))
    _fresh_process()
    assert units.lookup_unit("mm").factor == 0.001
