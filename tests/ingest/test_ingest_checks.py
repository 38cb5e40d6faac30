"""Checks, format detection, Parquet and resampling of the ingest library."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from debist.core.errors import RigLogError, UnitMismatchWarning
from debist.ingest.checks import find_gaps, split_segments
from debist.ingest.detect import detect_format, sniff_format
from debist.ingest.load import load_rig_log
from debist.ingest.resample import resample_segment
from debist.ingest.spec import IngestSpec

SECTION = {
    "time": {"name": "t", "unit": "s"},
    "q": {"name": "q", "unit": "mm"},
    "v1": {"name": "u", "unit": "V"},
}


def write_csv(path: Path, t, q, u) -> Path:
    pd.DataFrame({"t": t, "q": q, "u": u}).to_csv(path, index=False)
    return path


@pytest.fixture
def log(tmp_path) -> Path:
    t = np.arange(20) * 0.01
    return write_csv(tmp_path / "run.csv", t, np.sin(t), np.cos(t))


def load(path: Path, **changes) -> list[pd.DataFrame]:
    return load_rig_log(path, IngestSpec.from_dict({**SECTION, **changes}))


# ------------------------------------------------------------------------ value checks
def test_nan_names_file_channel_index_and_time(tmp_path):
    t = np.arange(20) * 0.01
    q = np.ones(20)
    q[7] = np.nan
    q[9] = np.nan
    path = write_csv(tmp_path / "nan.csv", t, q, q)
    with pytest.raises(RigLogError) as err:
        load(path)
    assert err.value.path.endswith("nan.csv")
    assert err.value.channel == "q"
    assert "`q`" in str(err.value)
    assert err.value.sample == 7 and np.isnan(err.value.value)
    assert "t = 0.07 s" in str(err.value)
    assert "2 non-finite" in str(err.value)
    # outside the slice it does not matter
    (df,) = load(path, slice=[10, 20])
    assert len(df) == 10 and df.attrs["first_index"] == 10


def test_inf_is_reported_like_nan(tmp_path):
    t = np.arange(20) * 0.01
    u = np.zeros(20)
    u[3] = -np.inf
    path = write_csv(tmp_path / "inf.csv", t, np.zeros(20), u)
    with pytest.raises(RigLogError) as err:
        load(path)
    assert err.value.channel == "u"
    assert "`v1`" in str(err.value)
    assert err.value.sample == 3 and err.value.value == -np.inf
    assert "t = 0.03 s" in str(err.value)


def test_repeated_time(tmp_path):
    t = np.arange(20) * 0.01
    t[5] = t[4]
    path = write_csv(tmp_path / "rep.csv", t, np.zeros(20), np.zeros(20))
    with pytest.raises(RigLogError) as err:
        load(path)
    assert err.value.path.endswith("rep.csv")
    assert err.value.channel == "t"
    assert err.value.sample == 5 and err.value.value == pytest.approx(0.04)
    assert "t[4] = 0.04 s" in str(err.value)
    assert "t[5] = 0.04 s" in str(err.value)
    assert "(repeated);" in str(err.value)


def test_time_going_back(tmp_path):
    t = np.arange(20) * 0.01
    t[10] = 0.02
    path = write_csv(tmp_path / "back.csv", t, np.zeros(20), np.zeros(20))
    with pytest.raises(RigLogError) as err:
        load(path)
    assert "t[10] = 0.02 s" in str(err.value)
    assert "0.07 s)" in str(err.value)


def test_nan_time(tmp_path):
    t = np.arange(20) * 0.01
    t[6] = np.nan
    path = write_csv(tmp_path / "tnan.csv", t, np.zeros(20), np.zeros(20))
    with pytest.raises(RigLogError) as err:
        load(path)
    assert err.value.channel == "t"
    assert err.value.sample == 6 and np.isnan(err.value.value)


def test_gap_error_and_split(tmp_path):
    t = np.r_[np.arange(10) * 0.01, 1.0 + np.arange(10) * 0.01]
    path = write_csv(tmp_path / "gap.csv", t, np.arange(20.0), np.zeros(20))
    with pytest.raises(RigLogError) as err:
        load(path)
    assert err.value.path.endswith("gap.csv")
    assert err.value.channel == "t"
    assert "1 gap(s)" in str(err.value)
    assert "t = 0.09 s" in str(err.value)
    assert err.value.sample == 9 and err.value.value == pytest.approx(0.91)
    assert "lasts 0.91 s" in str(err.value)
    assert 'gaps = "split"' in str(err.value)
    a, b = load(path, gaps="split", min_segment=5)
    assert a["q"].tolist() == [i * 1e-3 for i in range(10)]
    assert b.attrs["first_index"] == 10 and b["t"].iloc[0] == 1.0


@pytest.mark.parametrize(
    ("changes", "selection", "kept"),
    [
        ({"slice": [0, 2]}, "slice = [0, 2]", "keeps 2 of 20"),
        ({"slice": [30, 40]}, "slice = [20, 20]", "keeps 0 of 20"),
        ({"time_window": [5.0, 6.0]}, "time_window = [5.0, 6.0] s", "keeps 0"),
        ({"time_window": [0.0, 0.015]}, "time_window = [0.0, 0.015] s", "keeps 2"),
    ],
)
def test_empty_selection(log, changes, selection, kept):
    with pytest.raises(RigLogError) as err:
        load(log, **changes)
    assert err.value.path.endswith("run.csv")
    assert str(err.value).split(": ", 1)[1].startswith("empty selection")
    assert f"{selection} {kept}" in str(err.value)


def test_sample_time_missing_without_time_channel(log):
    section = {"q": {"name": "q", "unit": "mm"}, "v1": {"name": "u", "unit": "V"}}
    with pytest.raises(RigLogError) as err:
        load_rig_log(log, IngestSpec.from_dict(section))
    assert err.value.path.endswith("run.csv")
    assert "`sample_time`" in str(err.value)


def test_sample_time_must_agree_with_time_channel(log):
    (df,) = load(log, sample_time=0.01)
    assert len(df) == 20
    with pytest.raises(RigLogError) as err:
        load(log, sample_time=0.001)
    assert "`sample_time` = 0.001 s" in str(err.value)
    assert err.value.value == pytest.approx(0.01)


def test_missing_channel_lists_names_truncated(tmp_path):
    frame = pd.DataFrame({f"ch{i:02d}": np.zeros(5) for i in range(30)})
    frame.insert(0, "t", np.arange(5.0))
    path = tmp_path / "wide.csv"
    frame.to_csv(path, index=False)
    section = {**SECTION, "q": {"name": "ch00", "unit": "m"}, "v1": {"name": "volts", "unit": "V"}}
    with pytest.raises(RigLogError) as info:
        load_rig_log(path, IngestSpec.from_dict(section))
    message = str(info.value)
    assert "wide.csv', channel 'volts': `v1`: no channel named 'volts'" in message
    assert "'t', 'ch00', 'ch01'" in message and "'ch18', ... (11 more)" in message


def test_channels_of_different_length_in_a_mat_file(tmp_path):
    import scipy.io

    path = tmp_path / "ragged.mat"
    scipy.io.savemat(path, {"t": np.arange(10.0), "q": np.zeros(10), "u": np.zeros(9)})
    with pytest.raises(RigLogError) as err:
        load(path)
    assert err.value.channel == "u"
    assert "`v1`" in str(err.value)
    assert "has 9" in str(err.value)
    assert "`t`" in str(err.value)
    assert "'t'" in str(err.value)


def test_output_contract(log):
    (df,) = load(log, extra_b={"name": "q", "unit": "m"}, extra_a={"name": "u", "unit": "mV"})
    assert list(df.columns) == ["t", "q", "v1", "extra_a", "extra_b"]
    assert all(df[c].dtype == np.float64 for c in df.columns)
    assert isinstance(df.index, pd.RangeIndex)
    assert df["extra_a"].iloc[0] == pytest.approx(1e-3)  # cos(0) mV -> V
    assert set(df.attrs) >= {"units", "source", "channels", "segment", "format"}
    assert df.attrs["units"] == {"t": "s", "q": "m", "v1": "V", "extra_a": "V", "extra_b": "m"}
    assert np.all(np.diff(df["t"]) > 0)


# ------------------------------------------------------------------- format detection
def test_garbage_file(tmp_path):
    rng = np.random.default_rng(0)
    path = tmp_path / "garbage.mat"
    path.write_bytes(b"\x00\xff" + rng.integers(0, 256, 2000, dtype=np.uint8).tobytes())
    with pytest.raises(RigLogError) as err:
        load(path)
    assert err.value.path.endswith("garbage.mat")
    assert "mat-v4" in str(err.value)
    path = path.rename(tmp_path / "garbage.bin")
    with pytest.raises(RigLogError) as err:
        load(path)
    assert err.value.path.endswith("garbage.bin")
    assert "unrecognised" in str(err.value) and "binary" in str(err.value)


def test_empty_and_missing_file(tmp_path):
    (tmp_path / "empty.csv").write_bytes(b"")
    with pytest.raises(RigLogError) as err:
        load(tmp_path / "empty.csv")
    assert err.value.path.endswith("empty.csv")
    assert "empty" in str(err.value)
    with pytest.raises(RigLogError) as err:
        load(tmp_path / "nope.csv")
    assert err.value.path.endswith("nope.csv")
    assert "such" in str(err.value)
    (tmp_path / "blank.csv").write_text("\n\n  \n")
    with pytest.raises(RigLogError) as err:
        load(tmp_path / "blank.csv")
    assert err.value.path.endswith("blank.csv")
    assert "without" in str(err.value)


def test_content_wins_over_extension(tmp_path, log):
    disguised = tmp_path / "really_csv.mat"
    disguised.write_bytes(log.read_bytes())
    (df,) = load(disguised)
    assert df.attrs["format"] == "csv" and len(df) == 20
    assert detect_format(disguised) == "csv"


def test_declared_format_must_match_content(log):
    with pytest.raises(RigLogError) as err:
        load(log, format="parquet")
    assert err.value.path.endswith("run.csv")
    assert "format = 'parquet'" in str(err.value)
    assert "'csv'" in str(err.value)
    with pytest.raises(RigLogError) as err:
        load(log, format="mat")
    assert "format = 'mat'" in str(err.value)
    assert "'csv'" in str(err.value)
    assert load(log, format="csv")[0].attrs["format"] == "csv"


def test_sniff_format_magic_bytes():
    head = b"MATLAB 5.0 MAT-file, Platform: GLNXA64".ljust(116) + bytes(8)
    assert sniff_format(head + b"\x00\x01IM") == "mat-v5"
    assert sniff_format(head + b"\x01\x00MI") == "mat-v5"  # big-endian writer
    v73 = (head + b"\x00\x02IM").ljust(512, b"\x00") + b"\x89HDF\r\n\x1a\n"
    assert sniff_format(v73) == "mat-v7.3"
    with pytest.raises(RigLogError) as err:
        sniff_format(head + b"\x00\x03IM")
    assert "version 0x0300" in str(err.value)
    assert sniff_format(b"PAR1\x15\x04") == "parquet"
    assert sniff_format(b"t;q\n1,5;2\n") == "csv"
    assert sniff_format("µm\n1\n".encode()[:2]) == "csv"  # cut inside a character
    assert sniff_format(b"\x89HDF\r\n\x1a\n") is None
    assert sniff_format(b"ab\x00cd") is None


# ------------------------------------------------------------------------- Parquet
def parquet_table(n: int = 50) -> pa.Table:
    t = np.arange(n) * 0.002
    return pa.table(
        {
            "time": pa.array(t),
            "laser": pa.array(np.sin(t) * 10.0),
            "v_DE1": pa.array(np.full(n, 3.0)),
        }
    ).replace_schema_metadata(None)


def with_units(table: pa.Table, units: dict[str, str]) -> pa.Table:
    fields = [
        f.with_metadata({"unit": units[f.name]}) if f.name in units else f for f in table.schema
    ]
    return table.cast(pa.schema(fields))


PARQUET = {
    "time": {"name": "time", "unit": "s"},
    "q": {"name": "laser", "unit": "mm"},
    "v1": {"column": 2, "unit": "kV"},
}


def test_parquet_by_name_and_column(tmp_path):
    path = tmp_path / "run.parquet"
    pq.write_table(with_units(parquet_table(), {"v_DE1": "kV", "laser": "mm"}), path)
    (df,) = load_rig_log(path, IngestSpec.from_dict(PARQUET))
    assert df.attrs["format"] == "parquet"
    assert df["v1"].eq(3000.0).all()
    np.testing.assert_allclose(df["q"], np.sin(df["t"]) * 1e-2, rtol=1e-15)
    assert df.attrs["channels"] == {"t": "time", "q": "laser", "v1": "v_DE1"}


def test_a_declared_unit_of_the_same_quantity_wins_over_the_workflow_and_is_said(tmp_path):
    plain = tmp_path / "kv.parquet"
    pq.write_table(with_units(parquet_table(), {"v_DE1": "kV"}), plain)
    (in_kv,) = load_rig_log(plain, IngestSpec.from_dict(PARQUET))
    table = parquet_table()  # the same voltages recorded in V, the workflow still says kV
    volts = table.set_column(2, "v_DE1", pa.array(table.column(2).to_numpy() * 1000.0))
    path = tmp_path / "units.parquet"
    pq.write_table(with_units(volts, {"v_DE1": "V"}), path)
    with pytest.warns(UnitMismatchWarning, match=r"units.parquet: channel 'v_DE1'.*declares 'V'"):
        (in_v,) = load_rig_log(path, IngestSpec.from_dict(PARQUET))
    np.testing.assert_allclose(in_v["v1"], in_kv["v1"], rtol=1e-15)
    assert in_v.attrs["units"]["v1"] == "V"
    with pytest.raises(RigLogError) as err:
        pq.write_table(with_units(volts, {"v_DE1": "mm"}), path)
        load_rig_log(path, IngestSpec.from_dict(PARQUET))
    assert err.value.channel == "v_DE1"
    assert "wrong" in str(err.value)
    assert "quantity" in str(err.value)


def test_parquet_timestamp_time_column(tmp_path):
    table = parquet_table(10)
    stamps = pa.array(
        np.datetime64("2025-01-01T00:00:00") + np.arange(10) * np.timedelta64(2, "ms")
    )
    table = table.set_column(0, "time", stamps)
    path = tmp_path / "stamps.parquet"
    pq.write_table(table, path)
    (df,) = load_rig_log(path, IngestSpec.from_dict(PARQUET))
    # seconds since the epoch in float64: a resolution of about 0.24 us
    np.testing.assert_allclose(np.diff(df["t"]), 0.002, atol=5e-7)
    assert df["t"].iloc[0] == pytest.approx(1735689600.0)
    section = {**PARQUET, "time": {"name": "time", "unit": "ms"}}  # the stamps are the truth
    with pytest.warns(UnitMismatchWarning, match="says `time.unit` = 'ms'"):
        (again,) = load_rig_log(path, IngestSpec.from_dict(section))
    np.testing.assert_array_equal(again["t"], df["t"])


def test_truncated_parquet(tmp_path):
    path = tmp_path / "full.parquet"
    pq.write_table(parquet_table(), path)
    cut = tmp_path / "cut.parquet"
    cut.write_bytes(path.read_bytes()[:-20])
    with pytest.raises(RigLogError) as err:
        load_rig_log(cut, IngestSpec.from_dict(PARQUET))
    assert err.value.path.endswith("cut.parquet")
    assert "Parquet" in str(err.value)


# ------------------------------------------------------------------------ resampling
def test_polyphase_decimation_of_a_band_limited_signal():
    fs, f0 = 1000.0, 5.0
    t = np.arange(4000) / fs
    x = np.sin(2 * np.pi * f0 * t)
    t2, y = resample_segment(t, x[:, None], 0.01, "polyphase")
    assert t2[0] == 0.0 and t2.size == 400
    np.testing.assert_allclose(np.diff(t2), 0.01, rtol=1e-12)
    inner = slice(20, -20)
    np.testing.assert_allclose(y[inner, 0], np.sin(2 * np.pi * f0 * t2[inner]), atol=2e-3)


def test_polyphase_removes_what_the_new_rate_cannot_carry():
    t = np.arange(5000) * 1e-3
    alias = np.sin(2 * np.pi * 90.0 * t)  # above the 50 Hz Nyquist of a 10 ms grid
    _, y = resample_segment(t, alias[:, None], 0.01, "polyphase")
    assert np.max(np.abs(y[20:-20])) < 0.02  # plain decimation would keep amplitude 1


def test_polyphase_rational_ratio_and_identity():
    t = np.arange(300) * 0.003
    x = np.c_[np.full(300, 2.0), np.linspace(0.0, 1.0, 300)]
    t2, y = resample_segment(t, x, 0.002, "polyphase")  # up 3, down 2
    np.testing.assert_allclose(np.diff(t2), 0.002, rtol=1e-12)
    assert t2[-1] <= t[-1]
    # each polyphase branch has its own DC gain: a ripple of < 0.1 % on a constant
    np.testing.assert_allclose(y[:, 0], 2.0, rtol=1e-3)
    _t3, y3 = resample_segment(t, x, 0.003, "polyphase")
    np.testing.assert_array_equal(y3, x)
    with pytest.raises(RigLogError) as err:
        resample_segment(t, x, 0.003 * np.pi, "polyphase")
    assert "fraction" in str(err.value)


def test_linear_resampling_is_exact_on_lines():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.5, 1.5, 100)) * 1e-3  # jittery
    x = 4.0 - 2.5 * t
    t2, y = resample_segment(t, x[:, None], 1e-3, "linear")
    assert t2[0] == t[0] and t2[-1] <= t[-1]
    np.testing.assert_allclose(y[:, 0], 4.0 - 2.5 * t2, rtol=1e-12)


def test_resampled_frame_via_load(log):
    (df,) = load(log, resample={"sample_time": 0.02})
    assert len(df) == 10
    np.testing.assert_allclose(df["t"], np.arange(10) * 0.02, atol=1e-15)
    assert df.attrs["resample"] == {"sample_time": 0.02, "method": "polyphase"}


# ------------------------------------------------------------------ property tests
@settings(max_examples=60, derandomize=True, deadline=None)
@given(data=st.data())
def test_split_keeps_every_sample_once_and_no_gap_inside(data):
    n_steps = data.draw(st.integers(min_value=4, max_value=80))
    # fewer than half of the steps are gaps, so the median step is 1
    where = data.draw(st.sets(st.integers(0, n_steps - 1), max_size=(n_steps - 1) // 2))
    lengths = data.draw(st.lists(st.floats(2.0, 50.0), min_size=len(where), max_size=len(where)))
    min_segment = data.draw(st.integers(min_value=3, max_value=10))
    steps = np.ones(n_steps)
    steps[sorted(where)] = lengths
    t = np.r_[0.0, np.cumsum(steps)]
    gaps, median = find_gaps(t, 1.5)
    assert median == 1.0 and gaps.tolist() == sorted(where)
    kept, dropped = split_segments(t.size, gaps, min_segment)
    ranges = sorted(kept + dropped)
    assert ranges[0][0] == 0 and ranges[-1][1] == t.size
    assert all(a[1] == b[0] for a, b in itertools.pairwise(ranges))
    for start, stop in kept:
        assert stop - start >= min_segment
        assert np.all(np.diff(t[start:stop]) <= 1.5 * median)
    assert all(stop - start < min_segment for start, stop in dropped)
