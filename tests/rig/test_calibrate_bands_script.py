"""The band calibration script's member settings (benchmarks/calibrate_bands.py).

The calibration's model errors are only as good as the settings every fleet member was run
with: these tests check that the script writes them into each member's workflow, and leaves a
member file untouched (so its cached stages stay valid) when nothing changes.
"""

import importlib.util
import tomllib
from pathlib import Path

import tomli_w

ROOT = Path(__file__).resolve().parents[2]


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
    script._set_members([(wf, tmp_path)], False, ("physics_creep",), {"weights_window": 0.5})
    identify = tomllib.loads(wf.read_text())["identify"]
    assert identify["backbone"] == ["linear_spring", "viscous", "physics_creep"]
    assert identify["model_error"] is False
    assert identify["weights_window"] == 0.5
    assert (identify["M"], identify["slip"]) == (6, 4)  # the member's own settings stay


def test_a_dotted_setting_reaches_its_own_table(tmp_path):
    script, wf = _script(), _member(tmp_path)
    ramps = "rig.experiments.identification.ramps"
    script._set_members([(wf, tmp_path)], True, (), {ramps: [0.0, 1.0], "M": 8})
    raw = tomllib.loads(wf.read_text())
    assert raw["rig"]["experiments"]["identification"]["ramps"] == [0.0, 1.0]
    assert raw["identify"]["M"] == 8 and "rig.experiments" not in str(raw["identify"])
    stamp = wf.stat().st_mtime_ns
    script._set_members([(wf, tmp_path)], True, (), {ramps: [0.0, 1.0], "M": 8})
    assert wf.stat().st_mtime_ns == stamp  # already set: not rewritten


def test_a_member_already_set_is_not_rewritten(tmp_path):
    script, wf = _script(), _member(tmp_path)
    script._set_members([(wf, tmp_path)], True, ("physics_creep",), {"weights_window": 0.5})
    before = wf.read_bytes()
    wf.write_bytes(before)
    stamp = wf.stat().st_mtime_ns
    script._set_members([(wf, tmp_path)], True, ("physics_creep",), {"weights_window": 0.5})
    assert wf.stat().st_mtime_ns == stamp and wf.read_bytes() == before
    script._set_members([(wf, tmp_path)], True, (), {"weights_window": 1.0})
    assert tomllib.loads(wf.read_text())["identify"]["weights_window"] == 1.0


def test_a_gain_error_is_pooled_per_prototype_and_relative_to_the_local_gain():
    """A gain's lacking half-width is a fraction of its local magnitude, and each prototype's
    curve adds its largest one to the pool: a gain 30 % off at every marked point of one
    prototype is one value 0.3 (pointwise, its many points would outweigh the others); the
    restoring force adds every point, a fraction of its scale."""
    import numpy as np

    script = _script()
    q = np.linspace(-1.0, 1.0, 11)
    true = 2.0 + q  # one-signed gain, 1..3
    est = 1.3 * true  # a gain error of 30 %: the truth lies 0.3 / 1.3 of |est| below
    marked = np.ones(q.size, dtype=bool)
    lacking = script._lacking("g1", true, est, est, est, marked)  # band of zero width
    np.testing.assert_allclose(lacking, 0.3 / 1.3, rtol=1e-12)
    assert script._pooled_values("g1", lacking) == [max(lacking)]
    # the restoring force: |err| / scale (largest magnitude of the estimate, 3.9) per point
    err = script._lacking("restoring", true, est, est, est, marked)
    np.testing.assert_allclose(err, 0.3 * true / 3.9, rtol=1e-12)
    assert len(script._pooled_values("restoring", err)) == q.size
    # the band's reach toward the truth is taken off in quadrature
    half = script._lacking("g1", true, est, est - 0.1 * est, est, marked)
    np.testing.assert_allclose(half, np.sqrt((0.3 / 1.3) ** 2 - 0.1**2), rtol=1e-12)


def test_the_visited_table_counts_wells_marked_points_and_errors():
    """Two members' g_1 wells: one fully marked, one half; within 10 %; the errors' max, median."""
    rows = [
        {"curve": "g1", "points": 4, "marked": 4, "max_error": 0.02, "median_error": 0.01},
        {"curve": "g1", "points": 6, "marked": 3, "max_error": 0.15, "median_error": 0.05},
        {"curve": "g2", "points": 5, "marked": 0, "max_error": 0.03, "median_error": 0.02},
    ]
    lines = _script()._visited_markdown(rows)
    assert "| g1 | 2 | 1 | 7 of 10 | 1 | 15.0 / 3.0 % |" in lines
    assert "| g2 | 1 | 0 | 0 of 5 | 1 | 3.0 / 2.0 % |" in lines
    assert _script()._visited_markdown([]) == []


def test_the_replicate_line_gives_the_expected_losses_and_the_chance_of_none():
    """With shares p = 0.5, 0.2, 0 of the replicates losing the motion, 0.7 members are
    expected to lose it and none does with probability 0.5 x 0.8 x 1 = 0.40; only the member
    whose replicates all lie above 1 % is named; rows of other models are not counted."""
    import pandas as pd

    cols = ["member", "model", "nrmse_q", "poor", "lo", "hi"]
    nr = pd.DataFrame(
        [
            ["m-000", "rbf", 0.025, 0.5, 0.014, 0.25],
            ["m-001", "rbf", 0.004, 0.2, 0.003, 0.2],
            ["m-002", "rbf", 0.002, 0.0, 0.002, 0.003],
            ["m-000", "narx", 0.2, None, None, None],
        ],
        columns=cols,
    )
    (line,) = [x for x in _script()._replicates_markdown(nr) if x]
    assert "0.70 members" in line
    assert "P(none" in line and "= 0.40" in line
    assert "1 %: 2" in line
    assert line.endswith("lies above 1 %: 000")
    assert _script()._replicates_markdown(nr[nr.model == "narx"]) == []


def test_the_held_gain_rows_compare_with_the_small_signal_gain_and_the_secant(tmp_path):
    """An identified g_i made 0.9 of the full model's 3 kV secant, against a small-signal
    truth made 1.25 times the secant: the rows give 0.9, 0.72 and 0.8 at both wells, DE 1
    (g_1 > 0, pushing +q) holds the beam at the right well and DE 2 at the left."""
    import numpy as np
    import pandas as pd

    from debist.physics.statics import force_displacement
    from debist.rig.experiment import RigConfig

    script = _script()
    wf = ROOT / "workflows" / "paper-experiment.toml"
    raw = tomllib.loads(wf.read_text())
    prototype = RigConfig.from_dict(raw["rig"], raw.get("physics", {})).rig.prototype
    (tmp_path / "identify").mkdir()
    V = 3000.0
    static = pd.DataFrame({"level": [0, 1], "v1": [V, 0.0], "v2": [0.0, V]})
    static.to_parquet(tmp_path / "identify" / "static.parquet")
    q = np.linspace(-14e-3, 14e-3, 57)
    F0 = force_displacement(prototype, q, v1=0.0, v2=0.0).F
    secant = {i: (F0 - force_displacement(prototype, q, **{f"v{i}": V}).F) / V**2 for i in (1, 2)}
    assert np.all(secant[1] > 0) and np.all(secant[2] < 0)
    truth = {"q": q, "f": 100.0 * (q + 9.5e-3) * q * (q - 11e-3)}
    truth |= {f"g{i}": 1.25 * secant[i] for i in (1, 2)}
    curves = pd.DataFrame({"q": q, "g1": 0.9 * secant[1], "g2": 0.9 * secant[2]})
    rows = script._held_gain_rows(script._rig_config(wf), tmp_path, curves, {"curves": truth})
    assert [(r["curve"], round(r["well"] * 1e3, 1), r["holds"]) for r in rows] == [
        ("g1", -9.5, False), ("g2", -9.5, True), ("g1", 11.0, True), ("g2", 11.0, False)
    ]  # fmt: skip
    for r in rows:
        assert r["level"] == V
        # interpolation on the 0.5 mm grid: the curves are smooth there
        np.testing.assert_allclose(r["to_secant"], 0.9, rtol=2e-3)
        np.testing.assert_allclose(r["to_small_signal"], 0.72, rtol=2e-3)
        np.testing.assert_allclose(r["secant_to_small_signal"], 0.8, rtol=2e-3)
    lines = script._held_markdown(rows)
    row = "| g1 where it holds the beam (1 wells) | 0.72-0.72 (median 0.72) | 0.90-0.90"
    assert sum(line.startswith(row) for line in lines) == 1
    assert script._held_markdown([]) == []
