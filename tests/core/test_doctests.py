"""The docstring examples of every module of debist run, as written (doctest)."""

from __future__ import annotations

import doctest
import importlib
import importlib.util
import pkgutil
import warnings

import pytest

import debist

MODULES = sorted(
    m.name for m in pkgutil.walk_packages(debist.__path__, "debist.") if m.name != "debist.__main__"
)


def _module(name: str):
    """Import a module, or skip when it needs a tool that is no dependency (SymPy)."""
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name is None or exc.name.split(".")[0] == "debist":
            raise
        pytest.skip(f"{name} needs {exc.name}, which is not a dependency of debist")


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    module = _module(name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = doctest.testmod(
            module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False
        )
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed in {name}"


def test_every_package_has_examples():
    """Doctests are not confined to a few packages: each sub-package holds some."""
    finder = doctest.DocTestFinder()
    counts: dict[str, int] = {}
    for name in MODULES:
        package = ".".join(name.split(".")[:2])
        try:
            tests = finder.find(importlib.import_module(name))
        except ModuleNotFoundError:  # a code generator that needs SymPy
            continue
        counts[package] = counts.get(package, 0) + sum(len(t.examples) for t in tests)
    packages = {
        n
        for n in counts
        if n.count(".") == 1 and importlib.util.find_spec(n).submodule_search_locations
    }
    assert sum(counts.values()) > 100
    assert [p for p in sorted(packages) if counts[p] == 0] == []
