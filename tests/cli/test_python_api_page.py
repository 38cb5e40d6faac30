"""The Python API page's script (docs/how-to/python-api.md), run as it is, from an empty folder."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from debist.workflow.overrides import override_folder

ROOT = Path(__file__).resolve().parents[2]


PAGE = ROOT / "docs" / "how-to" / "python-api.md"


def page_script() -> str:
    """The first Python block of the Python API page, under its "Python API" heading."""
    text = PAGE.read_text(encoding="utf-8")
    section = text.split("# Python API", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_page_names_only_what_the_api_exports():
    import debist

    script = page_script()
    called = set(re.findall(r"debist\.([a-z_]+)\(", script))
    assert called and called <= set(debist.__all__)
    assert 'if __name__ == "__main__":' in script  # Dask's workers re-import it


@pytest.mark.slow
def test_the_page_script_runs(tmp_path):
    """Nothing of the checkout is copied: the script gets its workflow from the package."""
    (tmp_path / "example.py").write_text(page_script(), encoding="utf-8")
    run = subprocess.run(
        [sys.executable, "example.py"], cwd=tmp_path, capture_output=True, text=True, timeout=1200
    )
    assert run.returncode == 0, run.stdout + run.stderr
    out = run.stdout
    assert re.search(r"run digest: [0-9a-f]{64}", out)
    gap = float(re.search(r"free run: (\S+) m", out).group(1))
    assert gap <= 1e-12
    members = re.findall(r"^(\S+) unseen NRMSE\(q\) \[%\]: \[([0-9.]+)\]$", out, re.M)
    assert len(members) == 2, out
    assert all(float(value) < 5.0 for _, value in members), members
    assert len(list((tmp_path / "fleet-api").glob("*.toml"))) == 2
    shipped = tmp_path / "debist-example" / "workflows" / "paper-experiment.toml"
    assert shipped.read_bytes() == (ROOT / "workflows" / "paper-experiment.toml").read_bytes()
    # the script's run has overrides: its own folder beside the workflow's output folder
    runs = tmp_path / "debist-example" / "runs"
    own = override_folder(runs / "paper-experiment", {"validate": {"predict_steps": 20}})
    assert (own / "validate").is_dir()
    assert not (runs / "paper-experiment").exists()  # the workflow's own run was never made
