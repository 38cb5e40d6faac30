"""Write the dSPACE ControlDesk recording fixtures (MAT v5 and MAT v7.3) of the ingest tests.

Run ``python tests/data/make_dspace_fixtures.py [OUTDIR]`` to (re)write
``dspace_v5.mat`` and ``dspace_v73.mat`` (default OUTDIR: this folder). The tests import
this module and regenerate the files into a temporary folder (no ``.mat`` fixture is
committed), so the tests and the generator cannot drift apart.

The recording is synthetic (seeded), shaped like a ControlDesk MAT export: a struct with
``X`` (two time bases, "Periodic Task 1" at 1 ms and "Periodic Task 2" at 5 ms),
``Y`` (channels with the full block path as ``Name``, ``Raster``, ``Data``, ``Unit``,
``Type``) and ``Description``. It is built and written by the library writer
:mod:`debist.rig.dspace` (MAT v5 with scipy; MAT v7.3 with h5py in MATLAB's layout:
512-byte user block with the MAT header (version 0x0200), ``MATLAB_class`` attributes,
char arrays as uint16, struct arrays as object references into ``#refs#``), with the fixed
header date ``CREATED``, so both files are byte-identical from run to run.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from debist.rig import dspace

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

    fast, slow = "Periodic Task 1", "Periodic Task 2"
    channels = [
        dspace.Channel("Model Root/Sensors/Laser/q", q, "mm", fast),
        dspace.Channel("Model Root/Amplifier/DE1/v_DE1", v1, "kV", fast),
        dspace.Channel("Model Root/Amplifier/DE2/v_DE2", v2, "kV", fast),
        dspace.Channel("Model Root/Amplifier/DE1/v_DE1_ref", v1, "kV", fast),
        dspace.Channel("Model Root/Sensors/Force/F", force, "N", slow),
        dspace.Channel("Model Root/Sensors/Temperature/T", temp, "degC", slow),
    ]
    description = {"General": {"DateTime": CREATED, "Device": "DS1202 MicroLabBox"}}
    return dspace.recording(channels, {fast: t1, slow: t2}, description)


def write_v5(path: Path, rec: dict | None = None) -> None:
    """Write the recording as MAT v5 with scipy (compressed)."""
    rec = recording() if rec is None else rec
    dspace.write_recording(path, rec, version="5", variable=VARIABLE, created=CREATED)


def write_v73(path: Path, rec: dict | None = None) -> None:
    """Write the recording as MAT v7.3 (HDF5 in MATLAB's layout) with h5py."""
    rec = recording() if rec is None else rec
    dspace.write_recording(path, rec, version="7.3", variable=VARIABLE, created=CREATED)


# The low-level v7.3 writer and header, for tests that write plain variables into an open
# h5py file (tests/ingest/test_ingest_mat.py::test_plain_variables_v73_equal_v5).
_Writer = dspace._V73Writer


def _header() -> bytes:
    return dspace._mat73_header(CREATED)


def main(outdir: Path) -> None:
    """Write both fixtures into ``outdir``."""
    write_v5(outdir / "dspace_v5.mat")
    write_v73(outdir / "dspace_v73.mat")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent)
