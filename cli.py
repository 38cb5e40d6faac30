"""Run debist from a checkout: ``python cli.py run workflows/silverbox.toml``.

The command line itself is :mod:`debist.cli` (the package's source folder is ``pipeline/``,
installed under the import name ``debist``). When debist is not installed, this script makes
``pipeline/`` importable as ``debist`` for this process only.
"""

import importlib.util
import sys
from pathlib import Path

if importlib.util.find_spec("debist") is None:  # a bare checkout: map debist -> ./pipeline
    _src = Path(__file__).resolve().parent / "pipeline"
    _spec = importlib.util.spec_from_file_location(
        "debist", _src / "__init__.py", submodule_search_locations=[str(_src)]
    )
    sys.modules["debist"] = _module = importlib.util.module_from_spec(_spec)
    _spec.loader.exec_module(_module)

from debist.cli import main

if __name__ == "__main__":
    main()
