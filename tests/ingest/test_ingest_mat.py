"""MAT rig logs: EMPS plain variables, dSPACE ControlDesk recordings in MAT v5 and v7.3."""

from __future__ import annotations

import copy
import importlib.util
import re
import struct
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.io

from debist.core.errors import ResourceError, RigLogError, UnitMismatchWarning
from debist.ingest.channels import map_channels
from debist.ingest.load import load_rig_log, read_raw
from debist.ingest.mat import interpret_mat, read_mat
from debist.ingest.mat73 import load_mat73
from debist.ingest.spec import IngestSpec

REPO_DATA = Path(__file__).resolve().parents[2] / "data"
DATA = Path(__file__).resolve().parents[1] / "data"

_gen_spec = importlib.util.spec_from_file_location("make_dspace", DATA / "make_dspace_fixtures.py")
gen = importlib.util.module_from_spec(_gen_spec)
_gen_spec.loader.exec_module(gen)
_cols_spec = importlib.util.spec_from_file_location(
    "matcolumns", Path(__file__).resolve().parent / "test_ingest_matcolumns.py"
)
matcolumns = importlib.util.module_from_spec(_cols_spec)
_cols_spec.loader.exec_module(matcolumns)

LASER = "Model Root/Sensors/Laser/q"
DE1 = "Model Root/Amplifier/DE1/v_DE1"
DE2 = "Model Root/Amplifier/DE2/v_DE2"
FORCE = "Model Root/Sensors/Force/F"

DSPACE = {
    "q": {"regex": "Laser/q$", "unit": "mm"},
    "v1": {"regex": "Model Root/.*/v_DE1$", "unit": "kV"},
    "v2": {"regex": "Model Root/.*/v_DE2$", "unit": "kV"},
    "v1_ref": {"name": "Model Root/Amplifier/DE1/v_DE1_ref", "unit": "kV"},
}
EMPS = {
    "time": {"name": "t", "unit": "s"},
    "q": {"name": "qm", "unit": "m"},
    "v1": {"name": "vir", "unit": "V"},
}


def repo_data(*parts: str) -> Path:
    """A data set the repository ships under ``data/``."""
    path = REPO_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"data set {path} not present (the repository ships it under data/)")
    return path


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("dspace")
    gen.main(out)
    return {"v5": out / "dspace_v5.mat", "v73": out / "dspace_v73.mat"}


def load(path: Path, **section) -> list[pd.DataFrame]:
    return load_rig_log(path, IngestSpec.from_dict(section))


# ---------------------------------------------------------------------------- EMPS
def test_emps_plain_variables():
    path = repo_data("emps", "DATA_EMPS.mat")
    (df,) = load(path, **EMPS, qg={"name": "qg", "unit": "m"})
    ref = scipy.io.loadmat(path)
    assert df.shape == (24841, 4)
    assert list(df.columns) == ["t", "q", "v1", "qg"]
    assert df["t"].iloc[1] == pytest.approx(0.001, rel=1e-4)
    np.testing.assert_array_equal(df["q"], ref["qm"].ravel())
    np.testing.assert_array_equal(df["v1"], ref["vir"].ravel())
    assert df.attrs["format"] == "mat-v5"
    assert df.attrs["channels"] == {"t": "t", "q": "qm", "v1": "vir", "qg": "qg"}
    assert df.attrs["units"] == {"t": "s", "q": "m", "v1": "V", "qg": "m"}


def test_emps_scalar_variable_is_not_a_time_series():
    path = repo_data("emps", "DATA_EMPS.mat")
    with pytest.raises(RigLogError) as err:
        load(path, **EMPS, gtau={"name": "gtau", "unit": "1"})
    assert err.value.path.endswith("DATA_EMPS.mat")
    assert err.value.channel == "gtau"
    assert "1 samples" in str(err.value)
    assert "24841" in str(err.value)


def test_emps_missing_variable_lists_available():
    path = repo_data("emps", "DATA_EMPS.mat")
    section = {**EMPS, "q": {"name": "q_motor", "unit": "m"}}
    with pytest.raises(RigLogError) as err:
        load(path, **section)
    assert err.value.channel == "q_motor"
    assert "'q_motor'" in str(err.value)
    assert "'qm'" in str(err.value)
    assert "'vir'" in str(err.value)


@pytest.mark.parametrize("keep", [0.5, 0.01])
def test_emps_truncated_copy_is_a_rig_log_error(tmp_path, keep):
    src = repo_data("emps", "DATA_EMPS.mat").read_bytes()
    cut = tmp_path / "DATA_EMPS_cut.mat"
    cut.write_bytes(src[: int(len(src) * keep)])
    with pytest.raises(RigLogError) as err:
        load(cut, **EMPS)
    assert err.value.path.endswith("DATA_EMPS_cut.mat")
    assert "mat-v5" in str(err.value)


# --------------------------------------------------------------------------- dSPACE
@pytest.mark.parametrize("version", ["v5", "v73"])
def test_dspace_regex_mapping_and_kv_to_v(fixtures, version):
    (df,) = load(fixtures[version], **DSPACE)
    assert list(df.columns) == ["t", "q", "v1", "v2", "v1_ref"]
    assert len(df) == gen.N_FAST
    np.testing.assert_allclose(df["t"], np.arange(gen.N_FAST) * gen.DT_FAST, rtol=0, atol=0)
    after = df["t"] >= 0.05
    assert df["v1"][after].eq(3000.0).all()  # 3 kV -> 3000.0 V
    assert df["v1"][~after].eq(0.0).all()
    assert df["v2"].max() == 2500.0
    rec = gen.recording()
    np.testing.assert_array_equal(df["q"], rec["Y"][0]["Data"][0] * 1e-3)  # mm -> m
    assert df.attrs["units"] == {"t": "s", "q": "m", "v1": "V", "v2": "V", "v1_ref": "V"}
    assert df.attrs["channels"] == {
        "t": "Periodic Task 1",
        "q": LASER,
        "v1": DE1,
        "v2": DE2,
        "v1_ref": DE1 + "_ref",
    }
    assert df.attrs["format"] == {"v5": "mat-v5", "v73": "mat-v7.3"}[version]


def test_dspace_v5_and_v73_give_identical_tables(fixtures):
    section = {**DSPACE, "resample": {"sample_time": 0.005}, "force": {"regex": "/F$"}}
    for extra in ({}, section):
        (a,) = load(fixtures["v5"], **{**DSPACE, **extra})
        (b,) = load(fixtures["v73"], **{**DSPACE, **extra})
        pd.testing.assert_frame_equal(a, b, check_exact=True)
        for key in ("units", "channels", "segment", "n_segments", "first_index", "resample"):
            assert a.attrs[key] == b.attrs[key]


def test_mat73_decoder_matches_scipy_simplify_cells(fixtures):
    v5 = scipy.io.loadmat(fixtures["v5"], simplify_cells=True)["Recording1"]
    v73 = load_mat73(fixtures["v73"])["Recording1"]
    assert v73["Description"] == v5["Description"]
    assert [y["Name"] for y in v73["Y"]] == [y["Name"] for y in v5["Y"]]
    assert [y["Unit"] for y in v73["Y"]] == [y["Unit"] for y in v5["Y"]]
    for a, b in zip(v73["Y"] + v73["X"], v5["Y"] + v5["X"], strict=True):
        np.testing.assert_array_equal(a["Data"], b["Data"])


def _as_records(value):
    """pymatreader's struct array (dict of lists) as a list of dicts, as load_mat73 gives."""
    if isinstance(value, dict) and value and all(isinstance(v, list) for v in value.values()):
        n = {len(v) for v in value.values()}
        assert len(n) == 1
        return [{k: v[i] for k, v in value.items()} for i in range(n.pop())]
    return value


def test_mat73_decoder_matches_pymatreader_on_a_dspace_recording(fixtures):
    pymatreader = pytest.importorskip("pymatreader", reason="the independent v7.3 oracle")
    ours = load_mat73(fixtures["v73"])
    oracle = pymatreader.read_mat(str(fixtures["v73"]))
    assert set(ours) == set(oracle) == {"Recording1"}
    a, b = ours["Recording1"], oracle["Recording1"]
    assert set(a) == set(b)
    assert a["Description"] == b["Description"]
    for field in ("X", "Y"):
        mine, theirs = a[field], _as_records(b[field])
        assert len(mine) == len(theirs) > 0
        for x, y in zip(mine, theirs, strict=True):
            assert set(x) == set(y)
            for key, value in x.items():
                if isinstance(value, np.ndarray):
                    np.testing.assert_array_equal(value, np.asarray(y[key]).reshape(value.shape))
                else:
                    assert value == y[key], (field, key)


def test_mat73_decoder_matches_pymatreader_on_n_by_2_variables(tmp_path):
    pymatreader = pytest.importorskip("pymatreader", reason="the independent v7.3 oracle")
    variables = matcolumns.channels()
    path = matcolumns.write_v73(tmp_path / "columns.mat", variables)
    ours = load_mat73(path)
    oracle = pymatreader.read_mat(str(path))
    assert set(ours) == set(oracle) == set(variables)
    for name, value in variables.items():
        mine, theirs = np.asarray(ours[name]), np.asarray(oracle[name])
        assert mine.dtype == theirs.dtype == np.float64
        np.testing.assert_array_equal(mine, theirs.reshape(mine.shape))
        np.testing.assert_array_equal(mine.reshape(value.shape), value)
    assert np.asarray(ours["X3"]).shape == (variables["X3"].shape[0], 2)


@pytest.mark.parametrize("version", ["v5", "v73"])
def test_dspace_declared_unit_wins_over_the_workflow(fixtures, version):
    section = {**DSPACE, "v1": {"regex": "v_DE1$", "unit": "V"}}
    with pytest.warns(UnitMismatchWarning) as info:
        (df,) = load(fixtures[version], **section)
    message = str(info[0].message)
    assert fixtures[version].name in message and f"channel '{DE1}'" in message
    assert "declares 'kV'" in message and "`v1.unit` = 'V'" in message
    assert df["v1"].max() == 3000.0  # [V], from the declared kV
    section["v1"] = {"regex": "v_DE1$", "unit": "mm"}
    with pytest.raises(RigLogError) as err:
        load(fixtures[version], **section)
    assert "wrong" in str(err.value)
    assert "quantity" in str(err.value)


@pytest.mark.parametrize("version", ["v5", "v73"])
def test_dspace_unit_defaults_to_the_declared_one(fixtures, version):
    section = {**DSPACE, "v1": {"regex": "v_DE1$"}, "q": {"regex": "Laser/q$"}}
    (df,) = load(fixtures[version], **section)
    assert df["v1"].max() == 3000.0
    assert df.attrs["units"]["q"] == "m"


def test_dspace_unknown_declared_unit(fixtures):
    section = {**DSPACE, "temp": {"regex": "Temperature/T$"}}
    with pytest.raises(RigLogError) as err:
        load(fixtures["v5"], **section)
    assert err.value.channel == "Model Root/Sensors/Temperature/T"
    assert "'degC'" in str(err.value)


def test_dspace_unknown_declared_unit_needs_scale_and_si_unit(fixtures):
    section = {**DSPACE, "resample": {"sample_time": 0.005, "method": "linear"}}
    section["temp"] = {"regex": "Temperature/T$", "unit": "1"}
    with pytest.raises(RigLogError) as err:
        load(fixtures["v5"], **section)
    assert "wrong" in str(err.value)
    assert "'degC'" in str(err.value)
    assert "'1'" in str(err.value)
    section["temp"] = {"regex": "Temperature/T$", "scale": 2.0}
    with pytest.raises(RigLogError) as err:
        load(fixtures["v5"], **section)
    assert "'degC'" in str(err.value)
    assert "`temp.si_unit`" in str(err.value)
    section["temp"] = {"regex": "Temperature/T$", "scale": 2.0, "si_unit": "1"}
    (df,) = load(fixtures["v5"], **section)
    temp = gen.recording()["Y"][5]["Data"][0]
    np.testing.assert_allclose(df["temp"], 2.0 * temp, rtol=1e-14)
    assert df.attrs["units"]["temp"] == "1"
    assert list(df.columns) == ["t", "q", "v1", "v2", "temp", "v1_ref"]


def test_scale_with_si_unit_is_a_calibration():
    rec = gen.recording()
    rec["Y"][4]["Unit"] = "V"  # a force sensor read as a voltage, 50 N/V
    raw = interpret_mat(Path("rec.mat"), "mat-v5", {"Recording1": rec})
    spec = {**DSPACE, "force": {"regex": "/F$", "unit": "V", "scale": 50.0, "si_unit": "N"}}
    spec["resample"] = {"sample_time": 0.005}
    mapped = map_channels(raw, IngestSpec.from_dict(spec))
    force = next(c for c in mapped.columns if c.role == "force")
    assert force.unit == "N"
    np.testing.assert_array_equal(force.values, 50.0 * rec["Y"][4]["Data"][0])


def test_dspace_regex_matching_several_channels_names_them(fixtures):
    section = {**DSPACE, "v1": {"regex": "v_DE1", "unit": "kV"}}
    with pytest.raises(RigLogError) as err:
        load(fixtures["v73"], **section)
    assert "matches 2" in str(err.value)
    assert "v_DE1" in str(err.value)
    assert "', '" in str(err.value)
    assert "v_DE1_ref" in str(err.value)


def test_dspace_regex_matching_nothing_lists_channels(fixtures):
    section = {**DSPACE, "v2": {"regex": "v_DE3$", "unit": "kV"}}
    with pytest.raises(RigLogError) as err:
        load(fixtures["v73"], **section)
    assert err.value.path.endswith("dspace_v73.mat")
    assert err.value.channel == "v_DE3$"
    assert "matches" in str(err.value)


def test_dspace_column_selection_is_refused(fixtures):
    section = {**DSPACE, "q": {"column": 0, "unit": "mm"}}
    with pytest.raises(RigLogError) as err:
        load(fixtures["v5"], **section)
    assert "mat-v5" in str(err.value)
    assert "`name`" in str(err.value)
    assert "`regex`" in str(err.value)


@pytest.mark.parametrize("version", ["v5", "v73"])
def test_dspace_mixed_rasters_without_resample_name_both_channels(fixtures, version):
    section = {**DSPACE, "force": {"regex": "Force/F$", "unit": "N"}}
    with pytest.raises(RigLogError) as info:
        load(fixtures[version], **section)
    assert "different" in str(info.value)
    message = str(info.value)
    assert LASER in message and FORCE in message
    assert "200 samples" in message and "40 samples" in message


@pytest.mark.parametrize("method", ["polyphase", "linear"])
def test_dspace_mixed_rasters_with_resample(fixtures, method):
    section = {**DSPACE, "force": {"regex": "Force/F$", "unit": "N"}}
    section["resample"] = {"sample_time": 0.005, "method": method}
    (df,) = load(fixtures["v73"], **section)
    rec = gen.recording()
    grid = np.arange(gen.N_SLOW) * gen.DT_SLOW
    np.testing.assert_allclose(df["t"], grid, rtol=0, atol=1e-15)
    # the slow raster already is on the grid: unchanged
    np.testing.assert_allclose(df["force"], rec["Y"][4]["Data"][0], rtol=1e-14)
    q = rec["Y"][0]["Data"][0] * 1e-3
    if method == "linear":  # the 5 ms grid points are samples of the 1 ms raster
        np.testing.assert_allclose(df["q"], q[::5], rtol=1e-14)
    else:  # anti-aliased decimation: the noise-free step response to within the noise
        t = grid
        clean = 1.2e-3 * (1.0 - np.exp(-np.maximum(t - 0.05, 0.0) / 0.01))
        inner = (t > 0.07) & (t < 0.18)  # away from the ends and the step's corner
        assert np.max(np.abs(df["q"][inner] - clean[inner])) < 2e-5
    assert df.attrs["channels"]["t"] == "Periodic Task 1 + Periodic Task 2"


def test_dspace_mixed_rasters_refuse_slice(fixtures):
    section = {**DSPACE, "force": {"regex": "Force/F$", "unit": "N"}, "slice": [0, 10]}
    section["resample"] = {"sample_time": 0.005}
    with pytest.raises(RigLogError) as err:
        load(fixtures["v5"], **section)
    assert "10" in str(err.value)
    assert "time_window" in str(err.value)


def test_dspace_mixed_rasters_with_a_gap_are_refused(tmp_path):
    rec = gen.recording()
    rec["X"][1]["Data"] = rec["X"][1]["Data"] + (rec["X"][1]["Data"] >= 0.1) * 0.5
    path = tmp_path / "gap.mat"
    gen.write_v5(path, rec)
    section = {**DSPACE, "force": {"regex": "Force/F$", "unit": "N"}, "gaps": "split"}
    section["resample"] = {"sample_time": 0.005}
    with pytest.raises(RigLogError) as err:
        load(path, **section)
    assert err.value.path.endswith("gap.mat")
    assert err.value.channel == "Periodic Task 2"
    assert "1 gap(s)" in str(err.value)
    assert "t = 0.095 s" in str(err.value)
    assert "sample 19" in str(err.value)
    assert "lasts 0.505 s" in str(err.value)
    assert 'gaps = "split"' in str(err.value)
    (df,) = load(path, **{k: v for k, v in section.items() if k not in ("force", "resample")})
    assert len(df) == gen.N_FAST  # the fast raster alone has no gap


def test_dspace_time_spec_selects_and_checks_the_raster(fixtures):
    section = {**DSPACE, "time": {"name": "Periodic Task 1", "unit": "s"}}
    (df,) = load(fixtures["v5"], **section)
    assert len(df) == gen.N_FAST
    section["time"] = {"regex": "Task 1", "unit": "ms"}
    with pytest.warns(UnitMismatchWarning, match=r"channel 'Periodic Task 1'.*`time.unit`"):
        (again,) = load(fixtures["v5"], **section)
    np.testing.assert_array_equal(again["t"], df["t"])
    section["time"] = {"name": "Periodic Task 2"}
    with pytest.raises(RigLogError) as err:
        load(fixtures["v5"], **section)
    assert "`q`" in str(err.value)
    assert "'Periodic Task 1'" in str(err.value)


def test_dspace_slice_time_window_on_single_raster(fixtures):
    (df,) = load(fixtures["v5"], **DSPACE, slice=[40, 160], time_window=[0.05, 0.1])
    assert df["t"].iloc[0] == 0.05 and len(df) == 50
    assert df.attrs["first_index"] == 50


def test_dspace_xindex_instead_of_raster():
    rec = gen.recording()
    for y in rec["Y"]:
        y["XIndex"] = 1 if y.pop("Raster") == "Periodic Task 1" else 2
    raw = interpret_mat(Path("rec.mat"), "mat-v5", {"Recording1": rec})
    assert [c.raster for c in raw.channels] == [0, 0, 0, 0, 1, 1]
    rec["Y"][0]["XIndex"] = 3
    with pytest.raises(RigLogError) as err:
        interpret_mat(Path("rec.mat"), "mat-v5", {"Recording1": rec})
    assert err.value.channel == LASER
    assert "XIndex = 3" in str(err.value)


def test_dspace_channel_without_raster_among_several():
    rec = gen.recording()
    del rec["Y"][0]["Raster"]
    raw = interpret_mat(Path("rec.mat"), "mat-v5", {"Recording1": rec})
    with pytest.raises(RigLogError) as err:
        map_channels(raw, IngestSpec.from_dict(DSPACE))
    assert "2 time" in str(err.value)


def test_dspace_single_raster_needs_no_raster_field():
    rec = gen.recording()
    rec["X"] = rec["X"][0]  # a 1x1 struct
    for y in rec["Y"]:
        del y["Raster"]
    raw = interpret_mat(Path("rec.mat"), "mat-v5", {"Recording1": rec})
    assert {c.raster for c in raw.channels} == {0}


def test_dspace_channel_length_must_match_its_raster():
    rec = copy.deepcopy(gen.recording())
    rec["Y"][1]["Data"] = rec["Y"][1]["Data"][:, :-1]
    raw = interpret_mat(Path("rec.mat"), "mat-v5", {"Recording1": rec})
    with pytest.raises(RigLogError) as err:
        map_channels(raw, IngestSpec.from_dict(DSPACE))
    assert err.value.channel == DE1
    assert "`v1`" in str(err.value)
    assert "has 199" in str(err.value)
    assert "has 200" in str(err.value)


def test_two_recordings_in_one_file_are_refused():
    rec = gen.recording()
    with pytest.raises(RigLogError) as err:
        interpret_mat(Path("rec.mat"), "mat-v5", {"a": rec, "b": rec})
    assert "recordings" in str(err.value)


def test_plain_variables_v73_equal_v5(tmp_path):
    rng = np.random.default_rng(7)
    t = np.arange(50) * 1e-3
    variables = {"t": t[:, None], "qm": rng.standard_normal((50, 1)), "vir": np.ones((50, 1))}
    scipy.io.savemat(tmp_path / "plain5.mat", variables)
    import h5py

    with h5py.File(tmp_path / "plain73.mat", "w", userblock_size=512) as f:
        writer = gen._Writer(f)
        for name, value in variables.items():
            writer.write(f, name, value)
    with open(tmp_path / "plain73.mat", "r+b") as fh:
        fh.write(gen._header())
    (a,) = load(tmp_path / "plain5.mat", **EMPS)
    (b,) = load(tmp_path / "plain73.mat", **EMPS)
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert b.attrs["format"] == "mat-v7.3"
    np.testing.assert_array_equal(b["q"], variables["qm"][:, 0])


# --------------------------------------------------------------------- corrupt files
@pytest.mark.parametrize("keep", [0.6, 0.2])
@pytest.mark.parametrize("version", ["v5", "v73"])
def test_truncated_dspace_files(fixtures, tmp_path, version, keep):
    data = fixtures[version].read_bytes()
    cut = tmp_path / f"cut_{version}.mat"
    cut.write_bytes(data[: int(len(data) * keep)])
    fmt = {"v5": "mat-v5", "v73": "mat-v7.3"}[version]
    with pytest.raises(RigLogError) as err:
        load(cut, **DSPACE)
    assert err.value.path.endswith(f"cut_{version}.mat")
    assert fmt in str(err.value)


def test_mat_header_cut_short(fixtures, tmp_path):
    cut = tmp_path / "header.mat"
    cut.write_bytes(fixtures["v73"].read_bytes()[:100])
    with pytest.raises(RigLogError) as err:
        load(cut, **DSPACE)
    assert err.value.path.endswith("header.mat")
    assert "the 128-byte" in str(err.value)


def test_v73_without_hdf5_signature(fixtures, tmp_path):
    data = bytearray(fixtures["v73"].read_bytes())
    data[512:520] = b"garbage!"
    bad = tmp_path / "nohdf.mat"
    bad.write_bytes(bytes(data))
    with pytest.raises(RigLogError) as err:
        load(bad, **DSPACE)
    assert err.value.path.endswith("nohdf.mat")
    assert "v7.3" in str(err.value)
    assert "HDF5" in str(err.value)


def test_raw_listing_of_a_recording(fixtures):
    raw = read_raw(fixtures["v73"], IngestSpec.from_dict(DSPACE))
    assert raw.names[:3] == [LASER, DE1, DE2]
    assert [r.name for r in raw.rasters] == ["Periodic Task 1", "Periodic Task 2"]
    assert raw.channels[0].unit == "mm"


# ------------------------------------------------------------- forged and oversized files
def _v73(path: Path, build) -> Path:
    """Write an HDF5 file with MATLAB's 512-byte user block and header; ``build(file)``."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        build(f)
    with open(path, "r+b") as fh:
        fh.write(gen._header())
    return path


def _matlab(obj, cls: str):
    obj.attrs["MATLAB_class"] = np.bytes_(cls)
    return obj


def _peak(call) -> tuple[BaseException, int]:
    """Run ``call``, expecting it to raise; return the exception and tracemalloc's peak."""
    import tracemalloc

    tracemalloc.start()
    try:
        call()
    except Exception as exc:
        peak = tracemalloc.get_traced_memory()[1]
        return exc, peak
    finally:
        tracemalloc.stop()
    raise AssertionError("no exception")


def test_v73_data_set_declared_2gb_with_nothing_stored(tmp_path):
    def build(f):
        _matlab(f.create_dataset("qm", shape=(2**28, 1), dtype="f8"), "double")  # 2 GiB

    path = _v73(tmp_path / "forged.mat", build)
    assert path.stat().st_size < 4096
    exc, peak = _peak(lambda: load(path, **EMPS))
    assert isinstance(exc, RigLogError)
    assert exc.path.endswith("forged.mat") and "mat-v7.3" in str(exc)
    assert "'/qm' declares 2147483648" in str(exc) and "only 0" in str(exc)
    assert peak < 5e6  # bytes: nothing of the declared 2 GB was allocated


def test_v73_compressed_data_set_declaring_more_than_deflate_can_give(tmp_path):
    def build(f):
        d = f.create_dataset("qm", (2**27,), "f8", chunks=(2**14,), compression="gzip")
        d[: 2**14] = 1.0  # one chunk of 8192 written, the rest never stored
        _matlab(d, "double")

    path = _v73(tmp_path / "bomb.mat", build)
    exc, peak = _peak(lambda: load(path, **EMPS))
    assert isinstance(exc, RigLogError)
    assert re.search(
        r"'/qm' declares 1073741824 bytes .* compressed bytes can hold at most", str(exc)
    )
    assert peak < 5e6


def test_v73_wide_fan_out_of_references_is_bounded(tmp_path):
    """Four cells of 1000 references each to the next: 10^12 decoder visits in 40 kB."""

    def build(f):
        refs = f.create_group("#refs#")
        target = _matlab(refs.create_dataset("leaf", data=np.arange(3.0)), "double")
        for k in range(3):
            cell = refs.create_dataset(f"c{k}", data=[target.ref] * 1000, dtype=h5py.ref_dtype)
            target = _matlab(cell, "cell")
        _matlab(f.create_dataset("x", data=[target.ref] * 1000, dtype=h5py.ref_dtype), "cell")

    import h5py

    path = _v73(tmp_path / "fanout.mat", build)
    exc, peak = _peak(lambda: load(path, **EMPS))
    assert isinstance(exc, RigLogError)
    assert exc.path.endswith("fanout.mat") and "mat-v7.3" in str(exc)
    assert "decoding '/#refs#/c1' visits" in str(exc)
    assert peak < 5e6


def test_v73_reference_cycle(tmp_path):
    import h5py

    def build(f):
        refs = f.create_group("#refs#")
        a = _matlab(refs.create_dataset("a", shape=(1,), dtype=h5py.ref_dtype), "cell")
        b = _matlab(refs.create_dataset("b", data=[a.ref], dtype=h5py.ref_dtype), "cell")
        a[0] = b.ref
        _matlab(f.create_dataset("x", data=[a.ref], dtype=h5py.ref_dtype), "cell")

    path = _v73(tmp_path / "cycle.mat", build)
    with pytest.raises(RigLogError) as err:
        load(path, **EMPS)
    assert err.value.path.endswith("cycle.mat")
    assert "cannot" in str(err.value)
    assert "cycle" in str(err.value)


def test_v73_declared_data_above_the_memory_budget(tmp_path, monkeypatch):
    def build(f):
        d = f.create_dataset("qm", data=np.zeros((2_000_000, 1)), compression="gzip")
        _matlab(d, "double")

    path = _v73(tmp_path / "big.mat", build)
    monkeypatch.setenv("DEBIST_MEMORY_BUDGET_GB", "0.01")
    with pytest.raises(ResourceError) as err:
        load(path, **EMPS)
    assert "big.mat" in str(err.value)
    assert "v7.3" in str(err.value)
    monkeypatch.setenv("DEBIST_MEMORY_BUDGET_GB", "1")
    (channel,) = read_mat(path, "mat-v7.3").channels  # the same file within the budget
    assert channel.name == "qm" and channel.data.shape == (2_000_000,)


def test_v5_variable_declaring_more_than_the_file_holds(tmp_path):
    path = tmp_path / "forged5.mat"
    scipy.io.savemat(path, {"qm": np.arange(1000.0)[:, None]})
    data = bytearray(path.read_bytes())
    dims = data.index(struct.pack("<ii", 1000, 1))  # the dimensions sub-element
    data[dims : dims + 8] = struct.pack("<ii", 100_000_000, 1)
    path.write_bytes(bytes(data))
    assert scipy.io.whosmat(path) == [("qm", (100_000_000, 1), "double")]
    exc, peak = _peak(lambda: load(path, **EMPS))
    assert isinstance(exc, RigLogError)
    assert exc.path.endswith("forged5.mat") and "mat-v5" in str(exc)
    assert "declare 800000000 bytes" in str(exc)
    assert "'qm', (100000000, 1) double" in str(exc)
    assert peak < 5e6


def test_v5_declared_data_above_the_memory_budget(tmp_path, monkeypatch):
    path = tmp_path / "big5.mat"
    scipy.io.savemat(path, {"qm": np.zeros((2_000_000, 1))}, do_compression=True)
    monkeypatch.setenv("DEBIST_MEMORY_BUDGET_GB", "0.01")
    with pytest.raises(ResourceError) as err:
        load(path, **EMPS)
    assert "big5.mat" in str(err.value)
    assert "its 1" in str(err.value)
