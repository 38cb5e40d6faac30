"""Write the dSPACE ControlDesk recording fixtures (MAT v5 and MAT v7.3) of the ingest tests.

Run ``python tests/data/make_dspace_fixtures.py [OUTDIR]`` to (re)write
``dspace_v5.mat`` and ``dspace_v73.mat`` (default OUTDIR: this folder). The tests import
this module and regenerate the files into a temporary folder, so the committed copies
and the generator cannot drift apart unnoticed (``test_committed_fixtures_match_generator``).

The recording is synthetic (seeded), shaped like a ControlDesk MAT export: a struct with
``X`` (two time bases, "Periodic Task 1" at 1 ms and "Periodic Task 2" at 5 ms),
``Y`` (channels with the full block path as ``Name``, ``Raster``, ``Data``, ``Unit``,
``Type``) and ``Description``. The v7.3 file is written with h5py in MATLAB's layout:
512-byte user block with the MAT header (version 0x0200), ``MATLAB_class`` attributes,
char arrays as uint16, struct arrays as object references into ``#refs#``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import h5py
import numpy as np
import scipy.io

VARIABLE = "Recording1"
N_FAST, DT_FAST = 200, 1e-3
N_SLOW, DT_SLOW = 40, 5e-3
CREATED = "Fri Nov 21 12:00:00 2025"


def recording() -> dict:
    """Return the recording as nested Python values (dicts, lists of dicts, str, arrays)."""
    rng = np.random.default_rng(20251121)
    t1 = np.arange(N_FAST) * DT_FAST
    t2 = np.arange(N_SLOW) * DT_SLOW
    v1 = np.where(t1 >= 0.05, 3.0, 0.0)  # a 3 kV step at 50 ms
    v2 = np.where(t1 >= 0.12, 2.5, 0.0)
    q = 1.2 * (1.0 - np.exp(-np.maximum(t1 - 0.05, 0.0) / 0.01)) + 0.01 * rng.standard_normal(
        N_FAST
    )
    force = 0.4 + 0.05 * rng.standard_normal(N_SLOW)
    temp = 23.0 + 0.1 * rng.standard_normal(N_SLOW)

    def x(raster, t):
        return {"Name": "Time", "Type": "Time", "Raster": raster, "Data": t[None, :], "Unit": "s"}

    def y(path, raster, data, unit):
        return {
            "Name": path,
            "Type": "Value",
            "Raster": raster,
            "Data": data[None, :],
            "Unit": unit,
        }

    fast, slow = "Periodic Task 1", "Periodic Task 2"
    return {
        "Description": {"General": {"DateTime": CREATED, "Device": "DS1202 MicroLabBox"}},
        "X": [x(fast, t1), x(slow, t2)],
        "Y": [
            y("Model Root/Sensors/Laser/q", fast, q, "mm"),
            y("Model Root/Amplifier/DE1/v_DE1", fast, v1, "kV"),
            y("Model Root/Amplifier/DE2/v_DE2", fast, v2, "kV"),
            y("Model Root/Amplifier/DE1/v_DE1_ref", fast, v1, "kV"),
            y("Model Root/Sensors/Force/F", slow, force, "N"),
            y("Model Root/Sensors/Temperature/T", slow, temp, "degC"),
        ],
    }


# ----------------------------------------------------------------------------- MAT v5
def _to_v5(value):
    if isinstance(value, dict):
        return {k: _to_v5(v) for k, v in value.items()}
    if isinstance(value, list):  # struct array 1 x k
        fields = list(value[0])
        out = np.zeros((1, len(value)), dtype=[(f, object) for f in fields])
        for i, item in enumerate(value):
            for f in fields:
                out[0, i][f] = _to_v5(item[f])
        return out
    return value


def write_v5(path: Path, rec: dict | None = None) -> None:
    """Write the recording as MAT v5 with scipy (compressed)."""
    rec = recording() if rec is None else rec
    scipy.io.savemat(path, {VARIABLE: _to_v5(rec)}, do_compression=True, oned_as="row")


# --------------------------------------------------------------------------- MAT v7.3
def _header() -> bytes:
    text = f"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: {CREATED} HDF5 schema 1.00 ."
    head = text.encode("ascii").ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM"
    return head.ljust(512, b"\x00")


class _Writer:
    def __init__(self, file: h5py.File):
        self.file = file
        self.refs = file.create_group("#refs#")
        self.count = 0
        empty = self.refs.create_dataset("a", data=np.zeros(2, dtype=np.uint64))
        empty.attrs["MATLAB_class"] = np.bytes_("canonical empty")
        empty.attrs["MATLAB_empty"] = np.uint8(1)

    def _ref_name(self) -> str:
        self.count += 1
        n, name = self.count, ""
        while True:
            n, r = divmod(n, 26)
            name = chr(ord("a") + r) + name
            if n == 0:
                return name

    def write(self, parent: h5py.Group, name: str, value) -> h5py.HLObject:
        if isinstance(value, dict):
            group = parent.create_group(name)
            group.attrs["MATLAB_class"] = np.bytes_("struct")
            self._fields(group, list(value))
            for k, v in value.items():
                self.write(group, k, v)
            return group
        if isinstance(value, list):  # struct array 1 x k: each field a (k, 1) ref dataset
            group = parent.create_group(name)
            group.attrs["MATLAB_class"] = np.bytes_("struct")
            fields = list(value[0])
            self._fields(group, fields)
            for f in fields:
                refs = [self.write(self.refs, self._ref_name(), item[f]).ref for item in value]
                group.create_dataset(f, data=np.array(refs, dtype=h5py.ref_dtype)[:, None])
            return group
        if isinstance(value, str):
            codes = np.frombuffer(value.encode("utf-16-le"), dtype="<u2")
            data = codes[:, None] if codes.size else np.array([1, 0], dtype=np.uint64)
            dset = parent.create_dataset(name, data=data)
            dset.attrs["MATLAB_class"] = np.bytes_("char")
            dset.attrs["MATLAB_int_decode"] = np.int32(2)
            if not codes.size:
                dset.attrs["MATLAB_empty"] = np.uint8(1)
            return dset
        arr = np.atleast_2d(np.asarray(value, dtype=np.float64))
        dset = parent.create_dataset(name, data=arr.T)  # MATLAB dims reversed
        dset.attrs["MATLAB_class"] = np.bytes_("double")
        return dset

    @staticmethod
    def _fields(group: h5py.Group, names: list[str]) -> None:
        values = np.empty(len(names), dtype=object)
        for i, n in enumerate(names):
            values[i] = np.frombuffer(n.encode("ascii"), dtype="S1")
        group.attrs.create("MATLAB_fields", values, dtype=h5py.vlen_dtype(np.dtype("S1")))


def write_v73(path: Path, rec: dict | None = None) -> None:
    """Write the recording as MAT v7.3 (HDF5 in MATLAB's layout) with h5py."""
    rec = recording() if rec is None else rec
    with h5py.File(path, "w", userblock_size=512, libver="earliest") as file:
        _Writer(file).write(file, VARIABLE, rec)
    with open(path, "r+b") as fh:
        fh.write(_header())


def main(outdir: Path) -> None:
    """Write both fixtures into ``outdir``."""
    write_v5(outdir / "dspace_v5.mat")
    write_v73(outdir / "dspace_v73.mat")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent)
