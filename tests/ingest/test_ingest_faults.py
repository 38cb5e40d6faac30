"""Sensor validity checks at ingest: range limits, stuck values, faults = error | split."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from debist.core.errors import RigLogError, WorkflowError, exit_code
from debist.ingest.load import load_rig_log
from debist.ingest.spec import IngestSpec

N = 400
DT = 0.01
SECTION = {
    "time": {"name": "t", "unit": "s"},
    "q": {"name": "q", "unit": "mm", "range": [-25, 25]},
    "v1": {"name": "u", "unit": "V"},
}


def laser(seed: int = 0) -> np.ndarray:
    """A noisy laser reading [mm] well inside its range."""
    rng = np.random.default_rng(seed)
    k = np.arange(N)
    return 5.0 * np.sin(2 * np.pi * k / 97) + rng.normal(0.0, 0.01, N)


def write_mat(path: Path, q: np.ndarray, u: np.ndarray | None = None) -> Path:
    u = np.cos(np.arange(N) * DT) if u is None else u
    variables = {"t": np.arange(N) * DT, "q": q, "u": u}
    scipy.io.savemat(path, {k: np.asarray(v, float)[:, None] for k, v in variables.items()})
    return path


def load(path: Path, **changes):
    return load_rig_log(path, IngestSpec.from_dict({**SECTION, **changes}))


# -------------------------------------------------------------------------- range limits
def test_laser_at_range_limit_is_an_error_naming_file_channel_samples_time(tmp_path):
    q = laser()
    q[200:220] = 25.0
    path = write_mat(tmp_path / "x.mat", q)
    with pytest.raises(RigLogError) as info:
        load(path)
    msg = str(info.value)
    assert msg.startswith(f"file '{path}', channel 'q': `q`: 20 samples at the range limit 25 mm")
    assert "(samples 200-219, t = 2-2.19 s, value 25 mm)" in msg
    assert "1 fault" in msg and "20 sample(s)" in msg and 'faults = "split"' in msg
    assert exit_code(info.value) == 1


def test_beyond_the_lower_limit_is_a_fault(tmp_path):
    q = laser()
    q[10:13] = [-25.0, -25.5, -26.0]
    path = write_mat(tmp_path / "low.mat", q)
    with pytest.raises(RigLogError) as err:  # fmt: skip
        load(path)
    assert "3 samples" in str(err.value)
    assert "limit -25 mm" in str(err.value)
    assert "samples 10-12" in str(err.value)
    assert "t = 0.1-0.12 s" in str(err.value)
    assert "values -26" in str(err.value)
    assert "to -25 mm" in str(err.value)


def test_split_cuts_the_fault_and_keeps_the_segments_around_it(tmp_path):
    q = laser()
    q[200:220] = 25.0
    path = write_mat(tmp_path / "x.mat", q)
    frames = load(path, faults="split")
    assert [len(f) for f in frames] == [200, 180]
    assert [f.attrs["first_index"] for f in frames] == [0, 220]
    assert [f.attrs["n_segments"] for f in frames] == [2, 2]
    np.testing.assert_array_equal(frames[1]["q"].to_numpy(), q[220:] * 1e-3)
    assert frames[0]["t"].iloc[-1] == pytest.approx(1.99) and frames[1]["t"].iloc[0] == 2.2
    assert all(f.attrs["dropped_segments"] == [] for f in frames)


def test_split_drops_pieces_shorter_than_min_segment(tmp_path):
    q = laser()
    q[50:70] = 25.0  # leaves 50 samples before (< min_segment = 100) and 330 after
    path = write_mat(tmp_path / "x.mat", q)
    (frame,) = load(path, faults="split")
    assert len(frame) == 330 and frame.attrs["first_index"] == 70
    assert frame.attrs["dropped_segments"] == [{"first_index": 0, "n_samples": 50, "t_start": 0.0}]
    # with a smaller min_segment both pieces are kept
    assert [len(f) for f in load(path, faults="split", min_segment=50)] == [50, 330]


def test_split_combines_with_gap_splitting(tmp_path):
    t = np.arange(N) * DT
    t[300:] += 1.0  # a gap between samples 299 and 300
    q = laser()
    q[100:110] = 25.0
    variables = {"t": t, "q": q, "u": np.cos(t)}
    path = tmp_path / "gap.mat"
    scipy.io.savemat(path, {k: v[:, None] for k, v in variables.items()})
    frames = load(path, faults="split", gaps="split")
    assert [(f.attrs["first_index"], len(f)) for f in frames] == [(0, 100), (110, 190), (300, 100)]


def test_values_inside_the_limits_pass(tmp_path):
    q = laser()
    q[100], q[101] = 25.0 - 1e-12, -25.0 + 1e-12  # hundreds of ulps inside
    path = write_mat(tmp_path / "in.mat", q)
    (frame,) = load(path)
    assert len(frame) == N and frame["q"].max() == pytest.approx(25e-3)
    # within a few ulps of the limit counts as at the limit (rounding of conversions)
    q[100] = 25.0 - 2 * np.spacing(25.0)
    with pytest.raises(RigLogError) as err:
        load(write_mat(tmp_path / "ulp.mat", q))
    assert "`q`" in str(err.value)
    assert "1 sample" in str(err.value)
    assert "limit 25 mm" in str(err.value)
    assert "samples 100-100" in str(err.value)
    assert "t = 1-1 s" in str(err.value)


def test_range_is_in_the_recorded_unit_also_with_a_negative_scale(tmp_path):
    q = laser()
    q[5] = 25.0
    path = write_mat(tmp_path / "neg.mat", q)
    q_spec = {"name": "q", "unit": "mm", "scale": -1.0, "range": [-25, 25]}
    with pytest.raises(RigLogError) as err:
        load(path, q=q_spec)
    assert "limit 25 mm" in str(err.value)
    assert "samples 5-5" in str(err.value)
    assert "t = 0.05-0.05 s" in str(err.value)


# ------------------------------------------------------------------------ stuck values
def test_stuck_q_is_an_error(tmp_path):
    q = laser()
    q[100:130] = q[100]
    path = write_mat(tmp_path / "stuck.mat", q)
    with pytest.raises(RigLogError) as info:
        load(path)
    msg = str(info.value)
    assert info.value.channel == "q" and "`q`: 30 identical" in msg and "stuck" in msg
    assert "(samples 100-129, t = 1-1.29 s, value " in msg and "; stuck = 10)" in msg


def test_stuck_threshold_is_k_samples(tmp_path):
    q = laser()
    q[100:109] = q[100]  # 9 < 10: noise can do that
    (frame,) = load(write_mat(tmp_path / "nine.mat", q))
    assert len(frame) == N
    q[100:110] = q[100]
    with pytest.raises(RigLogError) as err:
        load(write_mat(tmp_path / "ten.mat", q))
    assert "10 identical" in str(err.value)
    # an explicit stuck = 0 turns the check off; stuck = 12 tolerates the run of 10
    q_spec = {**SECTION["q"]}
    assert len(load(tmp_path / "ten.mat", q={**q_spec, "stuck": 0})[0]) == N
    assert len(load(tmp_path / "ten.mat", q={**q_spec, "stuck": 12})[0]) == N


def test_stuck_split_removes_the_run(tmp_path):
    q = laser()
    q[150:170] = q[150]
    frames = load(write_mat(tmp_path / "stuck.mat", q), faults="split")
    assert [(f.attrs["first_index"], len(f)) for f in frames] == [(0, 150), (170, 230)]


def test_held_input_voltage_is_not_flagged_by_default(tmp_path):
    n = 800
    t = np.arange(n) * DT
    rng = np.random.default_rng(1)
    q = np.sin(t) + rng.normal(0.0, 0.01, n)
    u = np.where(np.arange(n) < 500, 2.0, np.cos(t))  # held at 2 V for 500 samples
    path = tmp_path / "held.mat"
    scipy.io.savemat(path, {"t": t[:, None], "q": q[:, None], "u": u[:, None]})
    (frame,) = load(path)
    assert len(frame) == n and (frame["v1"].to_numpy()[:500] == 2.0).all()
    # only an explicit `stuck` checks an input
    with pytest.raises(RigLogError) as err:
        load(path, v1={"name": "u", "unit": "V", "stuck": 50})
    assert err.value.channel == "u"
    assert "`v1`" in str(err.value)
    assert "500 identical" in str(err.value)
    assert "samples 0-499" in str(err.value)


def test_constant_q_is_not_checked_by_default(tmp_path):
    # a quantised reading at rest (median step 0) is no stuck sensor by the default rule
    q = np.zeros(N)
    q[::50] = 0.1
    (frame,) = load(write_mat(tmp_path / "rest.mat", q))
    assert len(frame) == N


def test_range_fault_wins_over_stuck(tmp_path):
    q = laser()
    q[200:260] = 25.0  # identical too, but reported as the range limit
    with pytest.raises(RigLogError) as info:
        load(write_mat(tmp_path / "x.mat", q))
    assert "60 samples" in str(info.value)
    assert "identical" not in str(info.value)


# ---------------------------------------------------------------------------- the spec
def test_spec_keys_parse_and_round_trip():
    spec = IngestSpec.from_dict(
        {**SECTION, "v1": {"name": "u", "unit": "V", "stuck": 25}, "faults": "split"}
    )
    assert spec.channels[0].range == (-25.0, 25.0) and spec.channels[0].stuck is None
    assert spec.channels[1].stuck == 25 and spec.faults == "split"
    assert IngestSpec.from_dict(spec.to_dict()) == spec
    assert IngestSpec.from_dict(SECTION).faults == "error"


@pytest.mark.parametrize(
    ("changes", "key", "value", "fact"),
    [
        ({"q": {"name": "q", "range": [25, 0]}}, "ingest.q.range", [25, 0], "[start, end]"),
        ({"q": {"name": "q", "range": [0, 1, 2]}}, "ingest.q.range", [0, 1, 2], "at most 2"),
        ({"q": {"name": "q", "stuck": 1}}, "ingest.q.stuck", 1, "expected 0 (no check)"),
        ({"q": {"name": "q", "stuck": -3}}, "ingest.q.stuck", -3, ">= 0"),
        ({"faults": "ignore"}, "ingest.faults", "ignore", "'error' or 'split'"),
        ({"time": {"name": "t", "range": [0, 1]}}, "ingest.time.range", [0, 1], "time channel"),
    ],
)
def test_bad_keys_are_workflow_errors(changes, key, value, fact):
    with pytest.raises(WorkflowError) as err:
        IngestSpec.from_dict({**SECTION, **changes})
    assert err.value.key == key and err.value.value == value
    assert fact in str(err.value)
