"""The band calibration script's member settings (benchmarks/calibrate_bands.py).

The calibration's model errors are only as good as the settings every fleet member was run
with: these tests check that the script writes them into each member's workflow, and leaves a
member file untouched (so its cached stages stay valid) when nothing changes.
"""

import importlib.util
import tomllib
from pathlib import Path

import tomli_w

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location(
        "calibrate_bands", ROOT / "benchmarks" / "calibrate_bands.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _member(tmp_path: Path) -> Path:
    wf = tmp_path / "member-000.toml"
    identify = {"M": 6, "backbone": ["linear_spring", "viscous"], "slip": 4}
    wf.write_text(tomli_w.dumps({"workflow": {"name": "m"}, "identify": identify}))
    return wf


def test_settings_backbone_and_model_error_reach_every_member(tmp_path):
    script, wf = _script(), _member(tmp_path)
    script._set_identify([(wf, tmp_path)], False, ("physics_creep",), {"weights_window": 0.5})
    identify = tomllib.loads(wf.read_text())["identify"]
    assert identify["backbone"] == ["linear_spring", "viscous", "physics_creep"]
    assert identify["model_error"] is False
    assert identify["weights_window"] == 0.5
    assert (identify["M"], identify["slip"]) == (6, 4)  # the member's own settings stay


def test_a_member_already_set_is_not_rewritten(tmp_path):
    script, wf = _script(), _member(tmp_path)
    script._set_identify([(wf, tmp_path)], True, ("physics_creep",), {"weights_window": 0.5})
    before = wf.read_bytes()
    wf.write_bytes(before)
    stamp = wf.stat().st_mtime_ns
    script._set_identify([(wf, tmp_path)], True, ("physics_creep",), {"weights_window": 0.5})
    assert wf.stat().st_mtime_ns == stamp and wf.read_bytes() == before
    script._set_identify([(wf, tmp_path)], True, (), {"weights_window": 1.0})
    assert tomllib.loads(wf.read_text())["identify"]["weights_window"] == 1.0
