"""Ingest: pint units and their dimension checks, time tolerance, one read per file, MF4."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import debist.ingest.load as ingest
from debist.core.errors import RigLogError, WorkflowError
from debist.core.units import UNITS, lookup_unit
from debist.ingest.checks import printed_resolution, time_rtol
from debist.ingest.load import load_rig_log
from debist.ingest.resample import resample_segment
from debist.ingest.spec import IngestSpec
from debist.stages.ingest import run_ingest
from debist.workflow.loader import DatasetSpec

G0 = 9.80665  # [m/s^2] standard gravity (CGPM 1901)


def write_csv(path: Path, header: str, rows: np.ndarray, fmt: str = "%.17g") -> Path:
    lines = [header] + [",".join(fmt % v for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


# ----------------------------------------------------------------------------- units
@pytest.mark.parametrize(
    ("unit", "factor", "si", "quantity"),
    [
        ("mm/s", 1e-3, "m/s", "velocity"),
        ("g0", G0, "m/s^2", "acceleration"),
        ("kV", 1e3, "V", "voltage"),
        ("m/s^2", 1.0, "m/s^2", "acceleration"),
        ("deg", math.pi / 180.0, "rad", "angle"),
        ("mN", 1e-3, "N", "force"),
        ("1", 1.0, "1", "dimensionless"),
        ("[\u00b5m]", 1e-6, "m", "length"),
        ("bar", 1e5, "Pa", "pressure"),
    ],
)
def test_pint_units_convert_to_si(unit, factor, si, quantity):
    entry = lookup_unit(unit)
    assert entry.factor == pytest.approx(factor, rel=1e-15)
    assert (entry.si, entry.quantity) == (si, quantity)
    assert unit in UNITS and UNITS[unit] == entry


def test_offset_and_unparsable_units_are_not_units():
    assert lookup_unit("degC") is None and lookup_unit("bananas") is None
    assert "2 mm" not in UNITS
    with pytest.raises(KeyError):
        UNITS["bananas"]


def test_mm_per_s_g0_and_kv_channels_are_converted_to_si(tmp_path):
    t = np.arange(20) * 1e-3
    rows = np.column_stack([t, np.full(20, 2.0), np.full(20, 0.5), np.full(20, 1.5), 3.0 + t])
    log = write_csv(tmp_path / "log.csv", "t,u,acc,speed,x", rows)
    spec = IngestSpec.from_dict(
        {
            "time": {"name": "t", "unit": "s"},
            "q": {"name": "x", "unit": "mm"},
            "v1": {"name": "u", "unit": "kV"},
            "v2": {"name": "acc", "unit": "g0"},
            "speed": {"name": "speed", "unit": "mm/s"},
        }
    )
    (df,) = load_rig_log(log, spec)
    np.testing.assert_allclose(df["v1"], 2000.0, rtol=1e-15)
    np.testing.assert_allclose(df["v2"], 0.5 * G0, rtol=1e-15)
    np.testing.assert_allclose(df["speed"], 1.5e-3, rtol=1e-15)
    np.testing.assert_allclose(df["q"], (3.0 + t) * 1e-3, rtol=1e-15)
    assert df.attrs["units"] == {"t": "s", "q": "m", "v1": "V", "v2": "m/s^2", "speed": "m/s"}


@pytest.mark.parametrize(
    ("key", "table", "expected", "got"),
    [
        ("time", {"name": "t", "unit": "mm"}, "time [s]", "length [m]"),
        ("q", {"name": "x", "unit": "mm/s"}, "length [m]", "velocity [m/s]"),
        ("q", {"name": "x", "unit": "g0"}, "length [m]", "acceleration [m/s^2]"),
        ("v1", {"name": "u", "unit": "mm/s"}, "voltage [V]", "velocity [m/s]"),
        ("v1", {"name": "u", "unit": "s"}, "voltage [V]", "time [s]"),
    ],
)
def test_wrong_dimension_is_a_workflow_error_naming_key_value_and_dimension(
    key, table, expected, got
):
    section = {"time": {"name": "t", "unit": "s"}, "q": {"name": "x", "unit": "mm"}}
    section["v1"] = {"name": "u", "unit": "V"}
    section[key] = table
    with pytest.raises(WorkflowError) as err:
        IngestSpec.from_dict(section)
    assert err.value.key == f"ingest.{key}.unit" and err.value.value == table["unit"]
    assert expected in str(err.value)
    assert f"got {table['unit']!r} ({got})" in str(err.value)


def test_calibration_changes_the_quantity_and_extras_take_any_unit(tmp_path):
    t = np.arange(10) * 1e-3
    rows = np.column_stack([t, np.full(10, 2.0), np.full(10, 4.0), np.full(10, 7.0)])
    log = write_csv(tmp_path / "log.csv", "t,u,x,rho", rows)
    spec = IngestSpec.from_dict(
        {
            "time": {"name": "t", "unit": "ms"},
            "q": {"name": "x", "unit": "mV", "scale": 0.5, "si_unit": "meter"},
            "v1": {"name": "u", "unit": "V"},
            "rho": {"name": "rho", "unit": "g/cm^3"},
        }
    )
    (df,) = load_rig_log(log, spec)
    np.testing.assert_allclose(df["q"], 4.0 * 1e-3 * 0.5, rtol=1e-15)
    np.testing.assert_allclose(df["rho"], 7000.0, rtol=1e-12)
    np.testing.assert_allclose(df["t"], t * 1e-3, rtol=1e-15)
    assert df.attrs["units"]["q"] == "m"


def test_declared_unit_of_a_wrong_dimension_is_refused(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    t = np.arange(10) * 1e-3
    fields = [
        pa.field("t", pa.float64(), metadata={"unit": "s"}),
        pa.field("x", pa.float64(), metadata={"unit": "N"}),
        pa.field("u", pa.float64(), metadata={"unit": "kV"}),
    ]
    table = pa.table([t, np.ones(10), np.ones(10)], schema=pa.schema(fields))
    path = tmp_path / "declared.parquet"
    pq.write_table(table, path)
    spec = IngestSpec.from_dict({"time": {"name": "t"}, "q": {"name": "x"}, "v1": {"name": "u"}})
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, spec)
    assert err.value.channel == "x"
    assert "'N'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        IngestSpec.from_dict({"q": {"name": "x", "unit": "N"}, "v1": {"name": "u"}})
    assert "unit" in str(err.value)
    assert "'N'" in str(err.value)
    # the same unit in two spellings is no conflict
    spec = IngestSpec.from_dict(
        {"time": {"name": "t", "unit": "second"}, "q": {"name": "u"}, "v1": {"name": "u"}}
    )
    (df,) = load_rig_log(path, spec)
    assert df["v1"].eq(1000.0).all() and df.attrs["units"]["q"] == "V"


# ------------------------------------------------------------------ time tolerance
def test_printed_resolution_and_tolerance_of_a_9_digit_time_column():
    t = np.arange(4096) * 0.00048828125
    written = np.array([float(f"{v:.9g}") for v in t])
    assert printed_resolution(written) == pytest.approx(1e-8)  # 1.99951172: 9 digits
    assert printed_resolution(t) < 1e-10  # the exact binary fractions, written in full
    assert time_rtol(written, 1e-8) == pytest.approx(2e-8 / 0.00048828125, rel=1e-6)
    assert time_rtol(t) == 1e-6
    assert time_rtol(np.arange(100.0), 1.0) == 1e-3  # never above 0.1 %


@pytest.mark.parametrize("fmt", ["%.9g", "%.9f"])
def test_time_column_with_9_digits_resamples_4_to_1(tmp_path, fmt):
    n, dt = 8192, 0.00048828125  # 2048 Hz for 4 s
    t = np.arange(n) * dt
    x = np.sin(2 * np.pi * 3.0 * t)
    rows = np.column_stack([t, x, np.cos(2 * np.pi * 3.0 * t)])
    log = write_csv(tmp_path / "log.csv", "time,x,u", rows, fmt=fmt)
    section = {
        "time": {"name": "time", "unit": "s"},
        "q": {"name": "x", "unit": "mm"},
        "v1": {"name": "u", "unit": "V"},
        "resample": {"sample_time": 4 * dt},
    }
    (df,) = load_rig_log(log, IngestSpec.from_dict(section))
    assert len(df) == n // 4
    np.testing.assert_allclose(np.diff(df["t"]), 4 * dt, rtol=1e-9)
    assert df["t"].iloc[0] == 0.0
    inner = slice(20, -20)
    expected = 1e-3 * np.sin(2 * np.pi * 3.0 * df["t"].to_numpy())
    np.testing.assert_allclose(df["q"].to_numpy()[inner], expected[inner], atol=2e-6)


def test_polyphase_tolerance_is_shared_by_uniformity_and_ratio():
    dt = 0.00048828125
    t = np.round(np.arange(4096) * dt, 8)  # 8 decimals: steps off by up to 1e-8 s
    x = np.ones((t.size, 1))
    with pytest.raises(RigLogError) as err:
        resample_segment(t, x, 4 * dt, "polyphase")  # as if written in full
    assert "sampling" in str(err.value)
    t2, _ = resample_segment(t, x, 4 * dt, "polyphase", resolution=1e-8)
    assert t2.size == 1024
    with pytest.raises(RigLogError) as err:
        resample_segment(t, x, 4 * dt * (1 + 1e-3), "polyphase", resolution=1e-8)
    assert "fraction" in str(err.value)
    assert "tolerance" in str(err.value)


def test_sample_time_is_checked_against_the_files_time_column(tmp_path):
    dt = 0.00048828125
    t = np.arange(200) * dt
    rows = np.column_stack([t, np.sin(t), np.cos(t)])
    log = write_csv(tmp_path / "log.csv", "time,x,u", rows, fmt="%.9g")
    section = {"q": {"name": "x", "unit": "mm"}, "v1": {"name": "u", "unit": "V"}}
    (df,) = load_rig_log(log, IngestSpec.from_dict({**section, "sample_time": dt}))
    assert df.attrs["channels"]["t"] == f"k * {dt:g} s"
    with pytest.raises(RigLogError) as err:
        load_rig_log(log, IngestSpec.from_dict({**section, "sample_time": 0.000488}))
    assert err.value.path.endswith("log.csv")
    assert err.value.channel == "time"
    assert "`sample_time`" in str(err.value)
    assert "0.000488 s" in str(err.value)
    mapped = {**section, "time": {"name": "time", "unit": "s"}, "sample_time": 0.0005}
    with pytest.raises(RigLogError) as err:
        load_rig_log(log, IngestSpec.from_dict(mapped))
    assert err.value.channel == "time"
    assert "`sample_time`" in str(err.value)
    assert "0.0005 s" in str(err.value)
    assert "0.00048828" in str(err.value)


# ----------------------------------------------------------------- one read per file
def test_two_data_sets_naming_one_file_read_it_once(tmp_path, monkeypatch):
    t = np.arange(400) * 1e-3
    log = write_csv(tmp_path / "log.csv", "t,x,u", np.column_stack([t, np.sin(t), t]))
    calls = []
    real = ingest.read_text

    def counting(*args, **kwargs):
        calls.append(args[0])
        return real(*args, **kwargs)

    monkeypatch.setattr(ingest, "read_text", counting)
    base = {"time": {"name": "t", "unit": "s"}, "q": {"name": "x", "unit": "mm"}}
    base["v1"] = {"name": "u", "unit": "V"}
    datasets = [
        DatasetSpec("a", log, "estimation", {**base, "slice": [0, 200]}),
        DatasetSpec("b", log, "validation", {**base, "slice": [200, 400]}),
        DatasetSpec("c", log, "validation", {**base, "delimiter": ","}),  # other read options
    ]
    tables = run_ingest(datasets)
    assert len(calls) == 2
    assert (len(tables["a"]), len(tables["b"]), len(tables["c"])) == (200, 200, 400)
    assert tables["b"]["t"].iloc[0] == pytest.approx(0.2)


def test_a_file_rewritten_between_reads_is_read_again(tmp_path):
    reads = []
    cache = ingest.RawLogCache(lambda path, spec: reads.append(path) or len(reads))
    spec = IngestSpec.from_dict({"sample_time": 1.0, "q": {"column": 0}, "v1": {"column": 1}})
    path = tmp_path / "f.csv"
    path.write_text("1,2\n")
    assert cache.read(path, spec) == cache.read(path, spec) == 1
    path.write_text("1,2\n3,4\n")
    assert cache.read(path, spec) == 2


# ---------------------------------------------------------------------------- MF4
def write_mf4(path: Path) -> dict[str, np.ndarray]:
    asammdf = pytest.importorskip("asammdf", reason="asammdf (the mf4 extra) not installed")
    t = np.arange(500) * 1e-3
    t2 = np.arange(250) * 2e-3
    data = {
        "q": 5.0 * np.sin(2 * np.pi * t),
        "v1": 1.0 + 0.5 * np.cos(2 * np.pi * t),
        "acc": 0.25 * np.sin(2 * np.pi * t2),
    }
    mdf = asammdf.MDF(version="4.10")
    mdf.append(
        [
            asammdf.Signal(data["q"], t, name="Model Root/Laser/q", unit="mm"),
            asammdf.Signal(data["v1"], t, name="Model Root/DE1/v_mon", unit="kV"),
        ],
        comment="fast raster",
    )
    mdf.append([asammdf.Signal(data["acc"], t2, name="Shaker/acc", unit="g0")], comment="slow")
    mdf.save(path, overwrite=True)
    mdf.close()
    return {"t": t, "t2": t2, **data}


def test_mf4_file_through_the_normal_ingest_path(tmp_path):
    path = tmp_path / "rig.mf4"
    truth = write_mf4(path)
    assert ingest.detect_format(path) == "mf4"
    section = {"q": {"regex": "Laser/q$"}, "v1": {"name": "Model Root/DE1/v_mon"}}
    spec = IngestSpec.from_dict(section)
    (df,) = load_rig_log(path, spec)
    assert df.attrs["format"] == "mf4"
    np.testing.assert_allclose(df["t"], truth["t"], rtol=0, atol=1e-15)
    np.testing.assert_allclose(df["q"], truth["q"] * 1e-3, rtol=1e-15)  # file unit mm
    np.testing.assert_allclose(df["v1"], truth["v1"] * 1e3, rtol=1e-15)  # file unit kV
    assert df.attrs["units"] == {"t": "s", "q": "m", "v1": "V"}
    raw = ingest.read_raw(path, spec)
    assert [r.name for r in raw.rasters] == ["time (group 0)", "time (group 1)"]
    assert {c.name: c.unit for c in raw.channels}["Shaker/acc"] == "g0"


def test_mf4_channels_on_two_groups_need_resample_and_convert_g0(tmp_path):
    path = tmp_path / "rig.mf4"
    truth = write_mf4(path)
    section = {"q": {"regex": "Laser/q$"}, "v1": {"regex": "acc$"}}
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(section))
    assert "different" in str(err.value)
    section["resample"] = {"sample_time": 2e-3, "method": "linear"}
    (df,) = load_rig_log(path, IngestSpec.from_dict(section))
    np.testing.assert_allclose(df["v1"], truth["acc"][: len(df)] * G0, rtol=1e-12)
    assert df.attrs["units"]["v1"] == "m/s^2"
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict({**section, "v1": {"regex": "acc$", "unit": "V"}}))
    assert "`v1`" in str(err.value)
    assert "'g0'" in str(err.value)


def test_mf4_without_asammdf_says_how_to_install(tmp_path, monkeypatch):
    import builtins

    path = tmp_path / "rig.mf4"
    write_mf4(path)
    real_import = builtins.__import__

    def no_asammdf(name, *args, **kwargs):
        if name.startswith("asammdf"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_asammdf)
    spec = IngestSpec.from_dict({"q": {"regex": "Laser/q$"}, "v1": {"regex": "v_mon$"}})
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, spec)
    assert err.value.path.endswith("rig.mf4")
    assert "debist[mf4]" in str(err.value)
