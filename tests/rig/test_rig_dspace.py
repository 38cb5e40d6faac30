"""dSPACE ControlDesk MAT writer of the virtual rig: v5 and v7.3, read back by ingest."""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
import scipy.io

from debist.ingest.load import load_rig_log
from debist.ingest.mat73 import load_mat73
from debist.ingest.spec import IngestSpec
from debist.rig import dspace
from debist.rig.dspace import Channel, recording, write_mat, write_recording
from debist.rig.profiles import identification_profile

CREATED = "Sat Nov 22 09:30:00 2025"
FAST, SLOW = "Periodic Task 1", "Periodic Task 2"
K0, N, DT = 3000, 3000, 1e-3  # 3 s of the identification profile from t = 3 s
SPEC = {
    "q": {"regex": "Laser/q$", "unit": "mm"},
    "v1": {"regex": "Model Root/.*/v_DE1$", "unit": "kV"},
    "v2": {"regex": "Model Root/.*/v_DE2$"},  # unit from the file: kV
    "r1": {"name": "Model Root/Reference/r_DE1", "unit": "V"},
    "r2": {"regex": "r_DE2$", "unit": "V"},
}


@pytest.fixture(scope="module")
def signals() -> dict[str, np.ndarray]:
    exc = identification_profile(seed=4)
    rng = np.random.default_rng(11)
    window = slice(K0, K0 + N)
    r1, r2 = exc.r1[window].copy(), exc.r2[window].copy()
    return {
        "t": exc.t[window].copy(),
        "r1": r1,  # [V]
        "r2": r2,
        "v1": r1 / 1e3 + 0.002 * rng.standard_normal(N),  # measured [kV]
        "v2": r2 / 1e3 + 0.002 * rng.standard_normal(N),
        "q": -10.0 + 0.5 * rng.standard_normal(N).cumsum() / np.sqrt(N),  # [mm]
        "t_slow": exc.t[window][::10].copy(),
        "temp": 23.0 + 0.1 * rng.standard_normal(N // 10),
    }


def _rec(s: dict[str, np.ndarray]) -> dict:
    channels = [
        Channel("Model Root/Sensors/Laser/q", s["q"], "mm", FAST),
        Channel("Model Root/Amplifier/DE1/v_DE1", s["v1"], "kV", FAST),
        Channel("Model Root/Amplifier/DE2/v_DE2", s["v2"], "kV", FAST),
        Channel("Model Root/Reference/r_DE1", s["r1"], "V", FAST),
        Channel("Model Root/Reference/r_DE2", s["r2"], "V", FAST),
        Channel("Model Root/Sensors/Temperature/T", s["temp"], "degC", SLOW),
    ]
    description = {"General": {"DateTime": CREATED, "Device": "DS1202 MicroLabBox", "Rev": 3}}
    return recording(channels, {FAST: s["t"], SLOW: s["t_slow"]}, description)


@pytest.fixture(scope="module")
def files(signals, tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("rig")
    rec = _rec(signals)
    return {
        "5": write_recording(out / "rig_v5.mat", rec, version="5", created=CREATED),
        "7.3": write_recording(out / "rig_v73.mat", rec, version="7.3", created=CREATED),
    }


# ---------------------------------------------------------------------- round trip
@pytest.mark.parametrize("version", ["5", "7.3"])
def test_ingest_reads_the_recording_in_si_units(files, signals, version):
    (df,) = load_rig_log(files[version], IngestSpec.from_dict(SPEC))
    assert list(df.columns) == ["t", "q", "v1", "v2", "r1", "r2"]
    assert len(df) == N
    np.testing.assert_array_equal(df["t"], signals["t"])
    np.testing.assert_array_equal(df["q"], signals["q"] * 1e-3)  # mm -> m
    np.testing.assert_array_equal(df["v1"], signals["v1"] * 1e3)  # kV -> V
    np.testing.assert_array_equal(df["v2"], signals["v2"] * 1e3)
    np.testing.assert_array_equal(df["r1"], signals["r1"])  # the references, extra columns
    np.testing.assert_array_equal(df["r2"], signals["r2"])
    assert df["t"].iloc[0] == pytest.approx(3.0)
    pulse = (df["t"] >= 4.7 - 1e-9) & (df["t"] < 5.3 - 1e-9)  # the first 3 kV pulse, on DE 1
    assert pulse.sum() == 600
    assert df["r1"][pulse].eq(3000.0).all() and df["r2"][pulse].eq(0.0).all()
    assert df["r1"][~pulse].max() <= 1000.0 + 1e-9  # noise, rest
    assert df.attrs["units"] == {"t": "s", "q": "m", "v1": "V", "v2": "V", "r1": "V", "r2": "V"}
    assert df.attrs["channels"]["r1"] == "Model Root/Reference/r_DE1"
    assert df.attrs["channels"]["t"] == FAST
    assert df.attrs["format"] == {"5": "mat-v5", "7.3": "mat-v7.3"}[version]


def test_v5_and_v73_give_identical_tables(files):
    spec = IngestSpec.from_dict(SPEC)
    (a,) = load_rig_log(files["5"], spec)
    (b,) = load_rig_log(files["7.3"], spec)
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    for key in ("units", "channels", "segment", "n_segments", "first_index"):
        assert a.attrs[key] == b.attrs[key]


def test_layout_matches_controldesk_export(files, signals):
    v5 = scipy.io.loadmat(files["5"], simplify_cells=True)["Recording1"]
    v73 = load_mat73(files["7.3"])["Recording1"]
    for rec in (v5, v73):
        assert list(rec) == ["Description", "X", "Y"]
        assert rec["Description"]["General"]["Device"] == "DS1202 MicroLabBox"
        assert rec["Description"]["General"]["Rev"] == 3.0
        assert [x["Raster"] for x in rec["X"]] == [FAST, SLOW]
        assert {x["Name"] for x in rec["X"]} == {"Time"} and rec["X"][1]["Unit"] == "s"
        assert [y["Unit"] for y in rec["Y"]] == ["mm", "kV", "kV", "V", "V", "degC"]
        assert [y["Type"] for y in rec["Y"]] == ["Value"] * 6
        assert rec["Y"][5]["Raster"] == SLOW
        np.testing.assert_array_equal(rec["Y"][5]["Data"], signals["temp"])
    with h5py.File(files["7.3"], "r") as f:
        assert f["Recording1"].attrs["MATLAB_class"] == b"struct"
        assert f["Recording1/Y"]["Data"].shape == (6, 1)  # 1 x 6 struct array, reversed
        assert f["#refs#/a"].attrs["MATLAB_class"] == b"canonical empty"
    head = files["7.3"].read_bytes()[:128]
    assert head.startswith(
        b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: " + CREATED.encode()
    )
    assert head[124:128] == b"\x00\x02IM"


# ------------------------------------------------------------------ determinism
@pytest.mark.parametrize("version", ["5", "7.3"])
def test_same_input_gives_byte_identical_files(signals, tmp_path, version, monkeypatch):
    a = write_recording(tmp_path / "a.mat", _rec(signals), version=version, created=CREATED)
    b = write_recording(tmp_path / "b.mat", _rec(signals), version=version, created=CREATED)
    assert a.read_bytes() == b.read_bytes()
    c = write_recording(tmp_path / "c.mat", _rec(signals), version=version, created="Mon Jan 5")
    diff = np.flatnonzero(
        np.frombuffer(a.read_bytes(), np.uint8) != np.frombuffer(c.read_bytes(), np.uint8)
    )
    assert diff.size > 0 and diff.max() < 116  # only the header's "Created on" differs
    if version == "7.3":  # the group-creation fallback of older h5py writes the same bytes
        monkeypatch.setattr(dspace, "_group_track_times", lambda: False)
        d = write_recording(tmp_path / "d.mat", _rec(signals), version=version, created=CREATED)
        assert d.read_bytes() == a.read_bytes()


def test_v5_header_carries_created_not_the_clock(files):
    head = files["5"].read_bytes()[:128]
    assert head[:116].decode("ascii").rstrip() == (
        f"MATLAB 5.0 MAT-file, Platform: GLNXA64, Created on: {CREATED}"
    )
    assert head[126:128] == b"IM"


# -------------------------------------------------------------------- atomicity
def _listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_failure_midway_through_v73_leaves_existing_file_untouched(signals, tmp_path, monkeypatch):
    target = tmp_path / "log.mat"
    target.write_bytes(b"previous recording")
    calls = {"n": 0}
    original = h5py.Group.create_dataset

    def flaky(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 8:
            raise RuntimeError("disk full (simulated)")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(h5py.Group, "create_dataset", flaky)
    with pytest.raises(RuntimeError) as err:
        write_recording(target, _rec(signals), version="7.3", created=CREATED)
    assert "simulated" in str(err.value)
    assert calls["n"] == 8  # the file was half written when it failed
    assert target.read_bytes() == b"previous recording"
    assert _listing(tmp_path) == ["log.mat"]


@pytest.mark.parametrize("version", ["5", "7.3"])
@pytest.mark.parametrize("step", ["fsync", "replace"])
def test_failure_after_writing_removes_the_temporary_file(
    signals, tmp_path, monkeypatch, version, step
):
    target = tmp_path / "log.mat"
    seen = []

    def boom(*args, **kwargs):
        seen.extend(p.name for p in tmp_path.iterdir())
        raise OSError(f"{step} failed (simulated)")

    monkeypatch.setattr(os, step, boom)
    with pytest.raises(OSError) as err:
        write_recording(target, _rec(signals), version=version, created=CREATED)
    assert "simulated" in str(err.value)
    assert len(seen) == 1 and seen[0].startswith(".log.mat.") and seen[0].endswith(".tmp")
    assert _listing(tmp_path) == []  # no target, no temporary file


def test_overwrite_replaces_and_keeps_umask_permissions(signals, tmp_path):
    target = tmp_path / "log.mat"
    target.write_bytes(b"old")
    old = os.umask(0o027)
    try:
        write_recording(target, _rec(signals), version="5", created=CREATED)
    finally:
        os.umask(old)
    assert target.read_bytes()[:10] == b"MATLAB 5.0"
    assert _listing(tmp_path) == ["log.mat"]
    new = tmp_path / "new.mat"
    old = os.umask(0o027)
    try:
        write_recording(new, _rec(signals), version="7.3", created=CREATED)
    finally:
        os.umask(old)
    assert new.stat().st_mode & 0o777 == 0o640  # not mkstemp's 0o600


def test_missing_folder_is_an_error_without_residue(signals, tmp_path):
    with pytest.raises(FileNotFoundError):
        write_recording(tmp_path / "no" / "log.mat", _rec(signals), version="5", created=CREATED)
    assert _listing(tmp_path) == []


# ------------------------------------------------------------------- bad input
def test_bad_arguments_are_rejected_before_touching_the_disk(signals, tmp_path):
    rec = _rec(signals)
    target = tmp_path / "x.mat"
    with pytest.raises(ValueError) as err:
        write_recording(target, rec, version="7", created=CREATED)
    assert "`version`" in str(err.value)
    assert "of 5" in str(err.value)
    assert "7.3" in str(err.value)
    assert "'7'" in str(err.value)
    with pytest.raises(ValueError) as err:
        write_recording(target, rec, version="5", variable="1rec", created=CREATED)
    assert "MATLAB" in str(err.value) and "identifier" in str(err.value)
    with pytest.raises(ValueError) as err:
        write_recording(target, rec, version="7.3", created="Sa 22. Nov \u00e9")
    assert "printable" in str(err.value)
    with pytest.raises(ValueError) as err:
        write_recording(target, rec, version="5", created="x" * 80)
    assert "too" in str(err.value) and "long" in str(err.value)
    with pytest.raises(ValueError) as err:
        write_recording(target, {"X": []}, version="5", created=CREATED)
    assert "fields" in str(err.value)
    with pytest.raises(ValueError) as err:
        write_mat(target, {"Y": [{"a": 1.0}, {"b": 2.0}]}, version="7.3", created=CREATED)
    assert "fields" in str(err.value)
    for bad in (None, True, b"x", {"a": object()}):
        for version in ("5", "7.3"):
            with pytest.raises(ValueError) as err:
                write_mat(target, {"v": bad}, version=version, created=CREATED)
            assert "cannot" in str(err.value) and "store" in str(err.value)
    assert _listing(tmp_path) == []


def test_recording_checks_channels_and_rasters():
    t = np.arange(5) * 1e-3
    q = Channel("Model Root/q", np.ones(5), "mm", FAST)
    with pytest.raises(ValueError) as err:
        recording([Channel("Model Root/v", np.ones(5), "V", "Task 9")], {FAST: t})
    assert "'Task 9'" in str(err.value)
    with pytest.raises(ValueError) as err:
        recording([q], {FAST: t[:4]})
    assert "'Model Root/q'" in str(err.value)
    assert "has 5" in str(err.value)
    assert "has 4" in str(err.value)
    with pytest.raises(ValueError) as err:
        recording([q, q], {FAST: t})
    assert "'Model Root/q'" in str(err.value)
    with pytest.raises(ValueError) as err:
        recording([q], {FAST: t, SLOW: t})
    assert f"'{SLOW}'" in str(err.value)
    with pytest.raises(ValueError) as err:
        Channel("Model Root/q", np.ones((2, 3)), "mm", FAST)
    assert "be 1-D" in str(err.value)
    with pytest.raises(ValueError) as err:
        recording([q], {FAST: t}, {"General": {"Date Time": "today"}})
    assert "'Date Time'" in str(err.value)
    rec = recording([q], {FAST: t})
    assert list(rec) == ["X", "Y"]  # no Description when none is given
    assert rec["Y"][0]["Data"].shape == (1, 5) and rec["Y"][0]["Data"].dtype == np.float64
    assert not q.data.flags.writeable
