"""mkdocs hook: let mkdocstrings read the package ``debist`` from its source folder, ``pipeline/``.

The package's import name (``debist``) is not its folder's name (``pipeline``, mapped by
``[tool.setuptools.package-dir]``), and griffe, which mkdocstrings uses to read the code
without importing it, finds a package by its folder. :func:`on_config` links a temporary
folder's ``debist`` to ``pipeline/`` and gives it to the Python handler as its search path,
so the API reference is read from this checkout, whether debist is installed editable, as a
wheel or not at all. :func:`on_post_build` removes the link.

References
----------
mkdocs, "Hooks" (https://www.mkdocs.org/user-guide/configuration/#hooks); mkdocstrings-python,
"paths" (https://mkdocstrings.github.io/python/usage/#paths).
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any

from mkdocs.plugins import event_priority

ROOT = Path(__file__).resolve().parents[2]
_made: list[Path] = []


@event_priority(100)  # before mkdocstrings' own on_config, which may start the handler
def on_config(config: Any) -> Any:
    """Point the Python handler at a folder whose ``debist`` is ``pipeline/`` (mkdocs event)."""
    folder = Path(tempfile.mkdtemp(prefix="debist-docs-"))
    (folder / "debist").symlink_to(ROOT / "pipeline", target_is_directory=True)
    _made.append(folder)
    handlers = config.plugins["mkdocstrings"].config.handlers
    handlers.setdefault("python", {})["paths"] = [str(folder)]
    return config


def on_post_build(config: Any) -> None:
    """Remove the temporary folders and their links (not what they point to) (mkdocs event)."""
    while _made:
        shutil.rmtree(_made.pop(), ignore_errors=True)
