"""The identify stage's sentences shown in the report unit: every position they name converted.

The stage words its excitation warnings with q in mm (q in m) or q's own unit, and its
stability verdict in SI; :func:`debist.report.tables.display_summary` rewrites their positions
into ``[validate] report_unit``. These tests run sentences the stage really writes through it
and fail when one keeps a number in the unit it was said in: a change of wording the rewrite
does not know.
"""

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from debist.identify.excitation import check_excitation
from debist.identify.stability import verdict
from debist.model.basis import RBFBasis
from debist.report.tables import display_summary
from tests.conftest import duffing_record

ROOT = Path(__file__).resolve().parents[2]
NUMBER = r"[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?"


def _numbers(text):
    return [float(x) for x in re.findall(NUMBER, text)]


def assert_converted(said, shown, old, new, factor):
    """``shown`` is ``said`` with every position in ``old`` rewritten in ``new``.

    No number is left followed by ``old`` (alone or closing a run of intervals), as many
    ``new`` as there were ``old``, and each number either kept (not a position) or times
    ``factor`` to the four digits written.
    """
    unit = re.escape(old)
    left = re.findall(rf"{NUMBER}\]? {unit}(?![\w/^])", shown) if new != old else []
    assert not left, f"positions left in {old}: {left} in {shown!r}"
    count = len(re.findall(rf" {unit}(?![\w/^])", said))
    assert len(re.findall(rf" {re.escape(new)}(?![\w/^])", shown)) == count, shown
    before, after = _numbers(said), _numbers(shown)
    assert len(before) == len(after), (said, shown)
    # every number of a q interval "[a, b]" or after "sigma = " is a position, however worded
    where = rf"\[({NUMBER}), ({NUMBER})\]|sigma = ({NUMBER})"
    spots = [[float(x) for x in m if x] for m in re.findall(where, said)]
    moved = [[float(x) for x in m if x] for m in re.findall(where, shown)]
    assert len(spots) == len(moved), (said, shown)
    for a, b in zip(spots, moved, strict=True):
        assert b == pytest.approx([factor * x for x in a], rel=1e-3, abs=1e-9), (said, shown)
    scaled = 0
    for a, b in zip(before, after, strict=True):
        if b != pytest.approx(a) or factor == 1.0:
            assert b == pytest.approx(factor * a, rel=1e-3, abs=1e-9), (said, shown)
            scaled += 1
    return scaled


def _warnings(summary, report_unit):
    return (display_summary(summary, report_unit).get("excitation") or {}).get("warnings", [])


def test_excitation_warnings_the_check_writes_are_converted():
    """A Duffing record that covers only the middle of a wide basis, and a second input that
    is never on: 'no data ... sigma = x mm ... q in [a, b] and [c, d] mm' and the others."""
    rec = duffing_record(lambda t: 15.0 * np.cos(2 * np.pi * 0.8 * t), "sine")
    wide = 3.0 * float(np.max(np.abs(rec.q)))
    basis = RBFBasis.equidistant(-wide, wide, M=12, sigma_n=0.5)
    report = check_excitation([rec], basis, "v", unit_scale=1e3, unit_name="mm")
    said = report.warnings
    assert any("sigma = " in w and "] and [" in w for w in said), said  # the case is exercised
    summary = {"units": {"q": "m", "per_unit_mass": False}, "excitation": {"warnings": said}}
    for unit, new, factor in (("um", "µm", 1e3), ("m", "m", 1e-3), ("mm", "mm", 1.0)):
        shown = _warnings(summary, unit)
        scaled = sum(
            assert_converted(a, b, "mm", new, factor) for a, b in zip(said, shown, strict=True)
        )
        if factor != 1.0:  # sigma and both ends of every interval
            assert scaled >= 3


def test_the_stability_verdicts_positions_and_damping_are_converted():
    """Both verdicts the stability check writes, with positions [m] and the damping [N s/m]
    of SI, in the report unit (the damping per it)."""
    table = pd.DataFrame({
        "q": [-0.0123457, 0.0108642], "static_stable": [True, True], "d": [-0.0042, 0.3],
        "level": [0, 0],
    })  # fmt: skip
    visited = [(-0.0213579, 0.0230864)]
    unstable = verdict(table, visited).reason
    stable = verdict(table.assign(d=[0.2, 0.3]), visited).reason
    for reason in (unstable, stable):
        summary = {"units": {"q": "m", "per_unit_mass": False}, "design": {"reason": reason}}
        shown = display_summary(summary, "um")["design"]["reason"]
        for si in ("0.0123457", "0.0213579", "0.0230864", "-0.0042"):
            assert si not in shown, shown  # no SI number left
        assert "[-21360, 23090] µm" in shown or "at q = -12350 µm" in shown, shown
    assert (
        "[-21360, 23090] µm"
        in display_summary({"units": {"q": "m"}, "design": {"reason": stable}}, "um")["design"][
            "reason"
        ]
    )
    shown = display_summary(
        {"units": {"q": "m", "per_unit_mass": False}, "design": {"reason": unstable}}, None
    )["design"]["reason"]
    assert "damping d = -4.2e-06 N s/mm" in shown and "at q = -12.35 mm" in shown, shown


@pytest.mark.slow
def test_the_paper_experiments_identify_sentences_are_all_converted(paper_experiment_run):
    """Every sentence the paper experiment's identify stage wrote, in µm and m."""
    folder, _ = paper_experiment_run
    summary = json.loads((folder / "identify" / "summary.json").read_text(encoding="utf-8"))
    said = summary["excitation"]["warnings"]
    assert said and summary["units"]["q"] == "m"
    for unit, new, factor in (("um", "µm", 1e3), ("m", "m", 1e-3)):
        for a, b in zip(said, _warnings(summary, unit), strict=True):
            assert_converted(a, b, "mm", new, factor)
        reason = display_summary(summary, unit)["design"]["reason"]
        assert f"] {new}" in reason and not re.search(r"\d\] mm", reason), reason


@pytest.mark.slow
def test_silverboxs_identify_sentences_are_all_converted(tmp_path):
    """Silverbox records q in V and reports in mV: its sentences, said in V, shown in mV."""
    from typer.testing import CliRunner

    from debist.cli import app

    workflow = ROOT / "workflows" / "silverbox.toml"
    result = CliRunner().invoke(app, ["run", str(workflow), "--out", str(tmp_path), "-q"])
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "identify" / "summary.json").read_text(encoding="utf-8"))
    said = summary["excitation"]["warnings"]
    assert summary["units"]["q"] == "V"
    for a, b in zip(said, _warnings(summary, "mV"), strict=True):
        assert_converted(a, b, "V", "mV", 1e3)
    reason = display_summary(summary, "mV")["design"]["reason"]
    assert "] mV" in reason and not re.search(rf"{NUMBER}\] V\b", reason), reason
