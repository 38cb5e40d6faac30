"""MAT variables stored as n x k matrices: channel tables ``{ var = ..., column = ... }``."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io

from debist.core.errors import RigLogError, WorkflowError
from debist.ingest.load import load_rig_log
from debist.ingest.spec import ChannelSpec, IngestSpec

N = 200
SECTION = {
    "time": {"var": "X3", "column": 0, "unit": "s"},
    "q": {"var": "X3", "column": 1, "unit": "mm"},
    "v1": {"var": "U", "column": 1, "unit": "kV"},
}


def channels() -> dict[str, np.ndarray]:
    """Two n x 2 [t, value] variables and a vector, seeded."""
    rng = np.random.default_rng(11)
    t = np.arange(N) * 1e-3
    return {
        "X3": np.column_stack([t, rng.standard_normal(N)]),
        "U": np.column_stack([t, rng.uniform(0.0, 2.0, N)]),
        "gain": np.full((N, 1), 0.5),
    }


def mat73_header() -> bytes:
    """The 128-byte MAT header of a v7.3 file (version 0x0200, little-endian)."""
    text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Thu Jan  1 2026 HDF5 schema"
    return text.ljust(116, b" ") + b"\x00" * 8 + (0x0200).to_bytes(2, "little") + b"IM"


def write_v5(path: Path, variables: dict[str, np.ndarray]) -> Path:
    scipy.io.savemat(path, variables)
    return path


def write_v73(path: Path, variables: dict[str, np.ndarray]) -> Path:
    """Write the variables as MATLAB's ``save -v7.3`` does: each array transposed."""
    with h5py.File(path, "w", userblock_size=512) as f:
        for name, value in variables.items():
            data = f.create_dataset(name, data=np.asarray(value, dtype=np.float64).T)
            data.attrs["MATLAB_class"] = np.bytes_(b"double")
    with open(path, "r+b") as fh:
        fh.write(mat73_header())
    return path


WRITERS = {"v5": write_v5, "v73": write_v73}


@pytest.mark.parametrize("version", ["v5", "v73"])
def test_columns_of_matrix_variables(tmp_path, version):
    data = channels()
    path = WRITERS[version](tmp_path / f"x_{version}.mat", data)
    if version == "v73":
        with h5py.File(path, "r") as f:
            assert f["X3"].shape == (2, N)  # MATLAB's transposed storage
    (df,) = load_rig_log(path, IngestSpec.from_dict(SECTION))
    assert df.attrs["format"] == ("mat-v7.3" if version == "v73" else "mat-v5")
    np.testing.assert_array_equal(df["t"], data["X3"][:, 0])
    np.testing.assert_allclose(df["q"], data["X3"][:, 1] * 1e-3, rtol=1e-15)
    np.testing.assert_allclose(df["v1"], data["U"][:, 1] * 1e3, rtol=1e-15)
    assert df.attrs["channels"] == {"t": "X3[:, 0]", "q": "X3[:, 1]", "v1": "U[:, 1]"}


def test_v5_and_v73_give_the_same_table(tmp_path):
    data = channels()
    (a,) = load_rig_log(write_v5(tmp_path / "a.mat", data), IngestSpec.from_dict(SECTION))
    (b,) = load_rig_log(write_v73(tmp_path / "b.mat", data), IngestSpec.from_dict(SECTION))
    assert list(a.columns) == list(b.columns) == ["t", "q", "v1"]
    np.testing.assert_array_equal(a.to_numpy(), b.to_numpy())


@pytest.mark.parametrize("version", ["v5", "v73"])
def test_vector_variable_by_var_with_and_without_column(tmp_path, version):
    data = channels()
    path = WRITERS[version](tmp_path / "x.mat", data)
    for gain in ({"var": "gain"}, {"var": "gain", "column": 0}):
        (df,) = load_rig_log(path, IngestSpec.from_dict({**SECTION, "g": {**gain, "unit": "1"}}))
        assert df["g"].tolist() == [0.5] * N


@pytest.mark.parametrize("version", ["v5", "v73"])
def test_wrong_column_names_file_variable_shape_and_index(tmp_path, version):
    path = WRITERS[version](tmp_path / "x.mat", channels())
    section = {**SECTION, "q": {"var": "X3", "column": 2, "unit": "mm"}}
    with pytest.raises(RigLogError) as info:
        load_rig_log(path, IngestSpec.from_dict(section))
    message = str(info.value)
    assert f"file '{path}'" in message
    assert info.value.channel == "X3" and "`q` selects" in message and "column 2" in message
    assert "variable 'X3'" in message and "200 x 2" in message
    assert "0-based: 0 ... 1" in message


def test_matrix_needs_a_column_and_name_suggests_var(tmp_path):
    path = write_v5(tmp_path / "x.mat", channels())
    section = {**SECTION, "q": {"var": "X3", "unit": "mm"}}
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(section))
    assert "'X3'" in str(err.value)
    assert "a 200" in str(err.value)
    assert "x 2" in str(err.value)
    section = {**SECTION, "q": {"name": "X3", "unit": "mm"}}
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(section))
    assert "200 x" in str(err.value)
    assert "2 matrix" in str(err.value)
    assert 'var = "X3"' in str(err.value)


def test_unknown_variable_lists_variables_with_shapes(tmp_path):
    path = write_v5(tmp_path / "x.mat", channels())
    section = {**SECTION, "q": {"var": "X4", "column": 1, "unit": "mm"}}
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(section))
    assert "'X4'" in str(err.value)
    assert "'X3 (200 x 2)'" in str(err.value)


def test_var_on_a_text_file_is_refused(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("t,q,u\n0,1,2\n1,2,3\n2,3,4\n")
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(SECTION))
    assert "'X3'" in str(err.value)


def test_var_selector_rules():
    spec = ChannelSpec.from_dict("q", {"var": "X3", "column": 1, "unit": "mm"})
    assert spec.selector == "var 'X3' column 1"
    assert spec.to_dict() == {"column": 1, "var": "X3", "unit": "mm"}
    assert ChannelSpec.from_dict("q", spec.to_dict()) == spec
    with pytest.raises(WorkflowError) as err:
        ChannelSpec.from_dict("q", {"var": "X3", "name": "X3"})
    assert "exactly" in str(err.value)
    assert "name" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        ChannelSpec.from_dict("q", {"var": "X3", "column": -1})
    assert "column" in str(err.value)
    assert "got -1" in str(err.value)
