"""Code fingerprints of the stages: the source a stage runs, found by its imports.

A stage's key must change when the code that computes its outputs changes, and only
then: editing the virtual rig must leave a Silverbox run up to date, editing the
identification must rerun identify and what follows. The fingerprint of a module is the
sha256 of the source of that module and of every module of this package it imports,
transitively, found by reading the import statements of the sources (:mod:`ast`;
imports inside functions count, imports under ``if TYPE_CHECKING:`` do not, since they
never run). Importing ``a.b.c`` also runs ``a/__init__`` and ``a/b/__init__``, so those
count too. Parsing every source costs about 0.2 s, so the import names found in a source are
kept in the user cache (:mod:`debist.core.cache`) under the sha256 of that source: a
source that changes is parsed again, and the fingerprint itself always hashes the sources
as they are.

References
----------
Python Language Reference, "The import system" (package ``__init__`` execution);
:mod:`ast` documentation; the ``typing.TYPE_CHECKING`` constant.
"""

from __future__ import annotations

import ast
import hashlib
import os
from functools import cache
from pathlib import Path

from debist.core import cache as user_cache

__all__ = ["code_fingerprint", "module_closure"]

#: The package whose modules are followed; imports of other packages are libraries,
#: recorded by version in the stage key instead.
PACKAGE = "debist"
#: The package's own folder (this module lives in its ``engine`` package). Its name need not be
#: ``debist``: in a checkout and in an
#: editable install the source folder is ``pipeline/``, mapped to the import name ``debist``.
_ROOT = Path(__file__).resolve().parent.parent


@cache
def _module_file(name: str, root: Path = _ROOT) -> Path | None:
    head, *rest = name.split(".")
    if head != PACKAGE:
        return None
    base = root.joinpath(*rest)
    if (base / "__init__.py").is_file():
        return base / "__init__.py"
    path = base.with_suffix(".py")
    return path if path.is_file() else None


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


#: Fields of AST nodes that hold statements (bodies, branches, handlers, match cases).
_BLOCKS = ("body", "orelse", "finalbody", "handlers", "cases")


def _imported_names(tree: ast.AST, package: str) -> set[str]:
    """Absolute names of the modules an AST imports (and the names it imports from them)."""
    names: set[str] = set()

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                parts = parts[: len(parts) - node.level + 1]
                base = ".".join(parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
        # imports are statements: follow the statement lists only, not the expressions
        for field in _BLOCKS:
            for child in getattr(node, field, ()):
                visit(child)

    visit(tree)
    return names


#: The cache file of import names: {module: [sha256 of its source, [names]]}.
_INDEX = "imports-v1.json"
#: The index as read once per process, and the modules parsed since (written back once).
_index: dict[str, list] | None = None
_parsed: dict[str, list] = {}


def _package_imports(name: str, path: Path) -> list[str]:
    """Names of this package that the source of module ``name`` imports (cached by content)."""
    global _index
    if _index is None:
        found = user_cache.read_json(_INDEX)
        _index = found if isinstance(found, dict) else {}
    source = path.read_bytes()
    digest = hashlib.sha256(source).hexdigest()
    entry = _index.get(name)
    if (
        isinstance(entry, list)
        and len(entry) == 2
        and entry[0] == digest
        and isinstance(entry[1], list)
        and all(isinstance(n, str) and n.split(".")[0] == PACKAGE for n in entry[1])
    ):
        return entry[1]
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    names = sorted(
        n
        for n in _imported_names(ast.parse(source, str(path)), package)
        if n == PACKAGE or n.startswith(PACKAGE + ".")
    )
    _index[name] = _parsed[name] = [digest, names]
    return names


def _save_index() -> None:
    """Write the modules parsed in this process into the cache (best effort, once each)."""
    if _parsed and _index is not None:
        user_cache.write_json(_INDEX, _index)
        _parsed.clear()


@cache
def _direct_imports(name: str, root: Path) -> frozenset[str]:
    path = _module_file(name, root)
    if path is None:
        return frozenset()
    found: set[str] = set()
    for imported in _package_imports(name, path):
        parts = imported.split(".")
        for i in range(1, len(parts) + 1):  # a.b.c runs a/__init__ and a/b/__init__
            prefix = ".".join(parts[:i])
            if _module_file(prefix, root) is not None:
                found.add(prefix)
    return frozenset(found)


def module_closure(module: str, root: str | os.PathLike | None = None) -> tuple[str, ...]:
    """Every module of the package that importing and running ``module`` may execute.

    Parameters
    ----------
    module : str
        Absolute module name, e.g. ``"debist.stages.identify"``.
    root : path-like, optional
        The package's own folder, whatever its name (default: the folder of this module).

    Returns
    -------
    tuple of str
        Sorted module names, ``module`` and its packages included.

    Raises
    ------
    ValueError
        If ``module`` is not a module of the package.

    Examples
    --------
    >>> "debist.rig.plant" in module_closure("debist.stages.identify")
    False
    >>> "debist.identify.fit" in module_closure("debist.stages.identify")
    True
    """
    base = _ROOT if root is None else Path(root).resolve()
    if _module_file(module, base) is None:
        raise ValueError(f"`module` {module!r} is not a module of the {PACKAGE!r} package")
    parts = module.split(".")
    todo = [".".join(parts[:i]) for i in range(1, len(parts) + 1)]
    seen: set[str] = set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        todo.extend(_direct_imports(name, base) - seen)
    _save_index()
    return tuple(sorted(seen))


def code_fingerprint(module: str, root: str | os.PathLike | None = None) -> str:
    """Return the sha256 of the source of ``module`` and every module it imports.

    Parameters
    ----------
    module : str
        Absolute module name (a stage's module).
    root : path-like, optional
        The package's own folder, whatever its name (default: the folder of this module).

    Returns
    -------
    str
        64 hexadecimal characters over the module names and source bytes of
        :func:`module_closure`, in sorted order (names, not paths, so a checkout, an
        editable install and a wheel give the same fingerprint); computed once per process.

    Raises
    ------
    ValueError
        If ``module`` is not a module of the package.
    """
    return _fingerprint(module, _ROOT if root is None else Path(root).resolve())


@cache
def _fingerprint(module: str, root: Path) -> str:
    digest = hashlib.sha256()
    for name in module_closure(module, root):
        path = _module_file(name, root)
        assert path is not None  # module_closure only returns existing modules
        digest.update(name.encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()
