"""Reader of MATLAB MAT files: dSPACE ControlDesk recordings and plain variables.

Two layouts are understood, in MAT v5/v7 (via :func:`scipy.io.loadmat`) and v7.3 (via
h5py, :mod:`debist.ingest.mat73`) alike:

dSPACE ControlDesk recording
    One top-level struct with the fields ``X`` and ``Y``. ``X(1..k)`` are the time bases
    ("rasters"): structs with ``Name``, ``Data`` (1 x n), ``Unit`` and usually ``Raster``
    (the raster's name, e.g. ``"Periodic Task 1"``). ``Y(1..m)`` are the channels: structs
    with ``Name`` (the full block path, e.g. ``"Model Root/Sensors/Laser/q"``), ``Data``,
    ``Unit`` and either ``XIndex`` (1-based index into ``X``) or ``Raster`` (a raster name
    matching ``X(k).Raster`` or ``X(k).Name``) telling which time base it belongs to; with
    a single ``X`` neither is needed. Channels are named by ``Y(i).Name``; the time base
    is named by ``X(k).Raster`` (else ``X(k).Name``).
Plain variables
    Any other file: every numeric vector or scalar variable is a channel named by the
    variable, e.g. the EMPS benchmark's ``t``, ``qm``, ``vir`` (n x 1) and ``gtau`` (1 x 1).
Matrix variables
    In any file, every numeric top-level variable (vectors and n x k matrices, samples in
    rows) is also kept in :attr:`~debist.ingest.raw.RawLog.variables`, where a channel
    table ``{ var = "X3", column = 1 }`` selects one column, e.g. of a data set storing each
    channel as an n x 2 ``[t, value]`` matrix. v7.3 files store arrays transposed (an n x 2
    matrix is an HDF5 data set of shape (2, n)); :mod:`~debist.ingest.mat73` transposes
    them back, so both versions give the same orientation.

Before a v4/v5/v7 file is loaded, :func:`scipy.io.whosmat` lists each variable's shape
and class without reading its data; a file whose variables declare more bytes than it
can hold (its size times :data:`~debist.core.preflight.DEFLATE_MAX_RATIO`, since v7
variables may be zlib-compressed) is refused as truncated or forged, and the declared
total is checked against the memory budget. v7.3 files are bounded the same way by
:func:`~debist.ingest.mat73.load_mat73`.

References
----------
dSPACE GmbH, "ControlDesk Measurement and Recording", MAT-file export of recordings
(struct with fields ``X``, ``Y``, ``Description``). The MathWorks, "MAT-File Format"
(miCOMPRESSED data elements hold a zlib stream).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import lazy_loader as lazy
import numpy as np

from debist.core.errors import DebistError, RigLogError
from debist.core.preflight import DEFLATE_MAX_RATIO, check_memory
from debist.ingest.mat73 import load_mat73
from debist.ingest.raw import RawChannel, RawLog

# the libraries below load on first use (lazy_loader): start-up of the CLI
sio = lazy.load("scipy.io", suppress_warning=True)

__all__ = ["check_declared", "interpret_mat", "read_mat"]

#: Bytes per element of the MATLAB classes whose size ``whosmat`` reveals (char arrays
#: become numpy unicode strings, 4 bytes per character); struct, cell, sparse and object
#: variables are counted as 0 (their contents are not listed).
_CLASS_BYTES = {
    "double": 8,
    "single": 4,
    "int8": 1,
    "uint8": 1,
    "int16": 2,
    "uint16": 2,
    "int32": 4,
    "uint32": 4,
    "int64": 8,
    "uint64": 8,
    "logical": 1,
    "char": 4,
}


def _as_list(value: Any) -> list[Any]:
    if isinstance(value, list | tuple):
        return list(value)
    if isinstance(value, np.ndarray) and value.dtype == object:
        return list(value.ravel())
    return [value]


def _text(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, str):
        return value.strip()
    if isinstance(value, list | tuple):
        return " ".join(_text(v) for v in value).strip()
    if isinstance(value, np.ndarray):
        if value.size == 0:
            return ""
        if value.dtype.kind in "US":
            return "".join(str(v) for v in value.ravel()).strip()
        if value.size == 1:
            return _text(value.item())
    return str(value).strip()


def _array(value: Any) -> np.ndarray:
    return np.asarray(value).squeeze()


def _is_recording(value: Any) -> bool:
    return isinstance(value, Mapping) and "X" in value and "Y" in value


def _raster_of(y: Mapping[str, Any], i: int, x_list: list[Any], path: Path) -> int | None:
    name = _text(y.get("Name")) or f"Y({i + 1})"
    if "XIndex" in y and np.size(y["XIndex"]) == 1:
        k = int(np.asarray(y["XIndex"]).item()) - 1
        if not 0 <= k < len(x_list):
            raise RigLogError(
                f"XIndex = {k + 1} but the recording has {len(x_list)} time base(s) X",
                path=path,
                channel=name,
            )
        return k
    raster = _text(y.get("Raster"))
    if raster:
        for field in ("Raster", "Name"):
            hits = [k for k, x in enumerate(x_list) if _text(x.get(field)) == raster]
            if len(hits) == 1:
                return hits[0]
    if len(x_list) == 1:
        return 0
    return None


def _dspace(path: Path, fmt: str, var: str, rec: Mapping[str, Any]) -> RawLog:
    x_list = _as_list(rec["X"])
    y_list = _as_list(rec["Y"])
    rasters = []
    for k, x in enumerate(x_list):
        if not isinstance(x, Mapping) or "Data" not in x:
            raise RigLogError(
                f"dSPACE recording '{var}': X({k + 1}) is not a struct with a field Data",
                path=path,
            )
        label = _text(x.get("Raster")) or _text(x.get("Name")) or f"X({k + 1})"
        if label in (r.name for r in rasters):
            label = f"{label} (X({k + 1}))"
        rasters.append(RawChannel(label, _array(x["Data"]), _text(x.get("Unit")) or None, k))
    channels = []
    for i, y in enumerate(y_list):
        if not isinstance(y, Mapping) or "Data" not in y:
            raise RigLogError(
                f"dSPACE recording '{var}': Y({i + 1}) is not a struct with a field Data",
                path=path,
            )
        name = _text(y.get("Name")) or f"Y({i + 1})"
        raster = _raster_of(y, i, x_list, path)
        channels.append(RawChannel(name, _array(y["Data"]), _text(y.get("Unit")) or None, raster))
    return RawLog(path, fmt, tuple(channels), rasters=tuple(rasters))


def interpret_mat(path: Path, fmt: str, variables: Mapping[str, Any]) -> RawLog:
    """Turn the variables of a MAT file into a :class:`~debist.ingest.raw.RawLog`.

    Parameters
    ----------
    path : Path
        The file, for messages.
    fmt : str
        ``"mat-v5"``, ``"mat-v7.3"`` or ``"mat-v4"``.
    variables : dict
        Variable name -> value as given by ``loadmat(..., simplify_cells=True)`` or
        :func:`~debist.ingest.mat73.load_mat73`.

    Returns
    -------
    RawLog
        The channels of the single dSPACE recording if there is one, else one channel
        per numeric vector or scalar variable; in both cases the numeric vector and
        matrix variables in ``variables``.

    Raises
    ------
    RigLogError
        Several dSPACE recordings in one file, a malformed recording, or no numeric
        variable at all.
    """
    matrices = tuple(
        RawChannel(name, arr)
        for name, value in variables.items()
        if not name.startswith("__") and not isinstance(value, Mapping | list | str)
        if (arr := _array(value)).dtype.kind in "biuf" and 1 <= arr.ndim <= 2
    )
    log = _interpret(path, fmt, variables, matrices)
    return dataclasses.replace(log, variables=matrices)


def _interpret(
    path: Path, fmt: str, variables: Mapping[str, Any], matrices: tuple[RawChannel, ...]
) -> RawLog:
    recordings = [k for k, v in variables.items() if _is_recording(v)]
    if len(recordings) > 1:
        raise RigLogError(
            "several dSPACE recordings in one file (" + ", ".join(recordings) + "); "
            "export one recording per file",
            path=path,
        )
    if recordings:
        return _dspace(path, fmt, recordings[0], variables[recordings[0]])
    channels = []
    for name, value in variables.items():
        if name.startswith("__") or isinstance(value, Mapping | list | str):
            continue
        arr = _array(value)
        if arr.dtype.kind in "biuf" and arr.ndim <= 1:
            channels.append(RawChannel(name, arr))
    if not channels and not matrices:
        raise RigLogError(
            "no numeric vector variable in the MAT file (variables: "
            + (", ".join(k for k in variables if not k.startswith("__")) or "none")
            + ")",
            path=path,
        )
    return RawLog(path, fmt, tuple(channels))


def check_declared(path: Path, fmt: str) -> int:
    """Compare the sizes a MAT v4/v5/v7 file declares with what it can hold.

    Parameters
    ----------
    path : Path
        The file.
    fmt : str
        ``"mat-v5"`` or ``"mat-v4"``.

    Returns
    -------
    int
        The declared bytes of its numeric, char and logical variables.

    Raises
    ------
    RigLogError
        If they exceed the file size times :data:`~debist.core.preflight.DEFLATE_MAX_RATIO`
        (v5/v7, which may be compressed) or the file size (v4), naming the largest
        variable and its declared shape and size.
    ResourceError
        If they exceed the memory budget.

    References
    ----------
    SciPy, ``scipy.io.whosmat`` (variable headers without the data); RFC 1951 (deflate's
    largest expansion).
    """
    listing = sio.whosmat(path)
    sizes = [
        (int(np.prod(shape, dtype=object)) * _CLASS_BYTES.get(cls, 0), name, shape, cls)
        for name, shape, cls in listing
    ]
    total = sum(size for size, *_ in sizes)
    if not sizes or not total:
        return 0
    file_size = path.stat().st_size
    bound = file_size * (DEFLATE_MAX_RATIO if fmt != "mat-v4" else 1)
    size, name, shape, cls = max(sizes, key=lambda item: item[0])
    if total > bound:
        how = f"even compressed (x{DEFLATE_MAX_RATIO})" if fmt != "mat-v4" else "uncompressed"
        raise RigLogError(
            f"cannot read {fmt} file: its variables declare {total} bytes (the largest, "
            f"'{name}', {shape} {cls}, {size} bytes), more than a file of {file_size} bytes "
            f"can hold {how}: the file is truncated or forged",
            path=path,
        )
    check_memory(
        total,
        f"file '{path}'",
        f"loading its {len(sizes)} MAT variables (the largest, '{name}', {shape} {cls})",
        "declared sizes",
    )
    return total


def read_mat(path: Path, fmt: str) -> RawLog:
    """Read a MAT file (v4/v5/v7 with scipy, v7.3 with h5py).

    Parameters
    ----------
    path : Path
        The file.
    fmt : str
        ``"mat-v5"``, ``"mat-v4"`` or ``"mat-v7.3"`` as found by
        :func:`~debist.ingest.detect.detect_format`.

    Returns
    -------
    RawLog
        See :func:`interpret_mat`.

    Raises
    ------
    RigLogError
        The file is truncated or corrupt (the scipy / h5py exception is chained and
        quoted), declares more data than it can hold (:func:`check_declared`,
        :func:`~debist.ingest.mat73.load_mat73`), or see :func:`interpret_mat`.
    ResourceError
        Its declared data exceed the memory budget (before it is read).
    """
    try:
        if fmt == "mat-v7.3":
            variables = load_mat73(path)
        else:
            check_declared(path, fmt)
            variables = sio.loadmat(path, simplify_cells=True)
    except DebistError:
        raise
    except Exception as exc:
        raise RigLogError(
            f"cannot read {fmt} file, it is truncated or corrupt ({type(exc).__name__}: {exc})",
            path=path,
        ) from exc
    return interpret_mat(path, fmt, variables)
