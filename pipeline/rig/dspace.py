"""Writer of dSPACE ControlDesk recordings as MAT files (v5 and v7.3), atomically.

The virtual rig saves its logs the way a lab exports a ControlDesk recording, so that the
ingest stage (:mod:`debist.ingest.mat`) reads them like a measured file. A recording is
one struct variable (``Recording1`` by default) with the fields

``Description``
    Free nested struct of strings and numbers (e.g. ``General.DateTime``, ``.Device``).
``X``
    1 x k struct array of time bases ("rasters"): ``Name = "Time"``, ``Type = "Time"``,
    ``Raster`` (e.g. ``"Periodic Task 1"``), ``Data`` (1 x n) [s], ``Unit = "s"``.
``Y``
    1 x m struct array of channels: ``Name`` (the full block path), ``Type = "Value"``,
    ``Raster`` (the name of its time base), ``Data`` (1 x n), ``Unit``.

Build the nested value with :func:`recording` and write it with :func:`write_recording`;
the same input gives a byte-identical file for the same library versions, and a failed
write leaves an existing target untouched. The layout written:
docs/explanation/implementation.md.

References
----------
dSPACE GmbH, "ControlDesk Measurement and Recording": MAT-file export of recordings.
The MathWorks, "MAT-File Format" (Level 5 header, 128 bytes) and "MAT-File Versions"
(7.3 is HDF5 with the MAT header in a 512-byte user block). The HDF Group, "HDF5 File
Format Specification" (user block, object modification times).
"""

from __future__ import annotations

import functools
import inspect
import io
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import lazy_loader as lazy
import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.core.fileformats import atomic_write

# the libraries below load on first use (lazy_loader): start-up of the CLI
h5py = lazy.load("h5py")
sio = lazy.load("scipy.io", suppress_warning=True)

__all__ = ["MAT_VERSIONS", "Channel", "recording", "write_mat", "write_recording"]

#: Values of the ``version`` argument.
MAT_VERSIONS = ("5", "7.3")
#: Platform written into the MAT header (MATLAB's name for 64-bit Linux).
_PLATFORM = "GLNXA64"
_VARIABLE = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")


@dataclass(frozen=True, eq=False)
class Channel:
    """One recorded channel ``Y(i)`` of a ControlDesk recording.

    Parameters
    ----------
    path : str
        Full block path, the channel's ``Name``, e.g. ``"Model Root/Sensors/Laser/q"``.
    data : array_like, shape (n,)
        Samples in ``unit``; stored as float64 (a read-only copy). NaN is allowed (a
        dropout is data).
    unit : str
        Unit as ControlDesk writes it, e.g. ``"mm"``, ``"kV"``, ``"V"``; may be empty.
    raster : str
        Name of its time base, a key of the ``times`` given to :func:`recording`, e.g.
        ``"Periodic Task 1"``.

    Raises
    ------
    ValueError
        Empty ``path`` or ``raster``, ``data`` not 1-D or not numeric.

    References
    ----------
    dSPACE ControlDesk MAT export: ``Y(i).Name``, ``.Data``, ``.Unit``, ``.Raster``.
    """

    path: str
    data: NDArray[np.float64]
    unit: str
    raster: str

    def __post_init__(self) -> None:
        for key in ("path", "raster"):
            value = getattr(self, key)
            if not isinstance(value, str) or not value:
                raise ValueError(f"Channel `{key}` must be a non-empty string, got {value!r}")
        if not isinstance(self.unit, str):
            raise ValueError(f"Channel '{self.path}': `unit` must be a string, got {self.unit!r}")
        try:
            data = np.array(self.data, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"Channel '{self.path}': `data` must be numeric ({exc})") from None
        if data.ndim != 1:
            raise ValueError(f"Channel '{self.path}': `data` must be 1-D, got shape {data.shape}")
        data.setflags(write=False)
        object.__setattr__(self, "data", data)


def _time_base(raster: str, t: ArrayLike) -> NDArray[np.float64]:
    try:
        arr = np.array(t, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"time base '{raster}' must be numeric ({exc})") from None
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"time base '{raster}' must be 1-D and non-empty, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"time base '{raster}' must be finite")
    return arr


def recording(
    channels: Sequence[Channel],
    times: Mapping[str, ArrayLike],
    description: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Build the nested value of a ControlDesk recording (``Description``, ``X``, ``Y``).

    Parameters
    ----------
    channels : sequence of Channel
        The channels ``Y(1..m)`` in this order; paths must be unique.
    times : mapping of str to array_like
        Raster name -> time base ``X(k).Data`` [s], shape (n_k,), in this order. Every
        raster must be used by a channel and every channel's raster given.
    description : mapping, optional
        The ``Description`` struct, e.g. ``{"General": {"DateTime": ..., "Device":
        "DS1202 MicroLabBox"}}``: nested mappings of strings and numbers. Omitted when
        None.

    Returns
    -------
    dict
        ``{"Description": {...}, "X": [...], "Y": [...]}`` with ``X`` and ``Y`` lists of
        dicts (struct arrays); ``Data`` as float64 arrays of shape (1, n) [s] or [unit].
        The value :func:`write_recording` writes and :func:`scipy.io.loadmat` with
        ``simplify_cells=True`` reads back (up to the (1, n) shape).

    Raises
    ------
    ValueError
        No channel, duplicate paths, an unknown or unused raster, a channel whose length
        differs from its time base, a time base not 1-D, empty or not finite.

    References
    ----------
    dSPACE ControlDesk MAT export of recordings (struct with ``X``, ``Y``, ``Description``).
    """
    if not channels:
        raise ValueError("a recording needs at least one channel")
    bases = {str(name): _time_base(str(name), t) for name, t in times.items()}
    seen: set[str] = set()
    for ch in channels:
        if not isinstance(ch, Channel):
            raise ValueError(f"channels must be Channel objects, got {type(ch).__name__}")
        if ch.path in seen:
            raise ValueError(f"duplicate channel path '{ch.path}'")
        seen.add(ch.path)
        if ch.raster not in bases:
            raise ValueError(
                f"channel '{ch.path}': raster '{ch.raster}' is not among the time bases "
                f"({', '.join(repr(k) for k in bases)})"
            )
        n = bases[ch.raster].size
        if ch.data.size != n:
            raise ValueError(
                f"channel '{ch.path}' has {ch.data.size} samples but its raster "
                f"'{ch.raster}' has {n}"
            )
    unused = [k for k in bases if k not in {ch.raster for ch in channels}]
    if unused:
        raise ValueError(f"time base '{unused[0]}' is used by no channel")

    out: dict[str, Any] = {}
    if description is not None:
        out["Description"] = _plain(description, "Description")
    out["X"] = [
        {"Name": "Time", "Type": "Time", "Raster": name, "Data": t[None, :], "Unit": "s"}
        for name, t in bases.items()
    ]
    out["Y"] = [
        {
            "Name": ch.path,
            "Type": "Value",
            "Raster": ch.raster,
            "Data": ch.data[None, :],
            "Unit": ch.unit,
        }
        for ch in channels
    ]
    return out


def _plain(value: Any, where: str) -> Any:
    """Copy a description into dicts, str and float64 arrays; reject anything else."""
    if isinstance(value, Mapping):
        return {_field(k, where): _plain(v, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, str):
        return value
    return _numeric(value, where)


def _field(name: object, where: str) -> str:
    if not isinstance(name, str) or not _VARIABLE.fullmatch(name):
        raise ValueError(f"{where}: field name {name!r} is not a MATLAB identifier")
    return name


# ---------------------------------------------------------------------------- headers
def _header_text(version: str, created: str) -> bytes:
    if not isinstance(created, str) or not created.isascii() or not created.isprintable():
        raise ValueError(f"`created` must be a printable ASCII string, got {created!r}")
    if version == "7.3":
        text = (
            f"MATLAB 7.3 MAT-file, Platform: {_PLATFORM}, Created on: {created} HDF5 schema 1.00 ."
        )
    else:
        text = f"MATLAB 5.0 MAT-file, Platform: {_PLATFORM}, Created on: {created}"
    raw = text.encode("ascii")
    if len(raw) > 116:
        raise ValueError(f"`created` = {created!r} is too long for the 116-byte MAT header text")
    return raw.ljust(116, b" ")


def _mat73_header(created: str) -> bytes:
    """Return the 512-byte user block of a v7.3 file: MAT header (version 0x0200), zeros."""
    head = _header_text("7.3", created) + b"\x00" * 8 + b"\x00\x02" + b"IM"
    return head.ljust(512, b"\x00")


def _numeric(value: Any, where: str) -> NDArray[np.float64]:
    """Return a number or real numeric array as float64 (both writers store doubles)."""
    arr = np.asarray(value) if not isinstance(value, bool) else np.asarray(None)
    if arr.dtype.kind not in "iuf":
        raise ValueError(
            f"{where}: cannot store {type(value).__name__} {value!r:.40}; expected a mapping, "
            "a list of mappings, a string or a real number / array"
        )
    return arr.astype(np.float64)


# ----------------------------------------------------------------------------- MAT v5
def _to_v5(value: Any, where: str) -> Any:
    if isinstance(value, Mapping):
        return {_field(k, where): _to_v5(v, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, list):  # struct array 1 x k
        fields = _struct_array_fields(value, where)
        out = np.zeros((1, len(value)), dtype=[(f, object) for f in fields])
        for i, item in enumerate(value):
            for f in fields:
                out[0, i][f] = _to_v5(item[f], f"{where}({i + 1}).{f}")
        return out
    if isinstance(value, str):
        return value
    return _numeric(value, where)


def _struct_array_fields(items: list[Any], where: str) -> list[str]:
    if not items or not all(isinstance(item, Mapping) for item in items):
        raise ValueError(f"{where}: a list must be a non-empty list of mappings (struct array)")
    fields = [_field(f, where) for f in items[0]]
    for i, item in enumerate(items):
        if list(item) != fields:
            raise ValueError(
                f"{where}({i + 1}): fields {list(item)} differ from {fields} of element 1"
            )
    return fields


def _v5_bytes(variables: Mapping[str, Any], created: str) -> bytes:
    text = _header_text("5", created)
    buf = io.BytesIO()
    converted = {name: _to_v5(value, name) for name, value in variables.items()}
    sio.savemat(buf, converted, do_compression=True, oned_as="row")
    data = bytearray(buf.getvalue())
    data[:116] = text
    return bytes(data)


# --------------------------------------------------------------------------- MAT v7.3
@functools.cache
def _group_track_times() -> bool:
    """Whether this h5py's ``create_group`` takes ``track_times`` (asked once, on first use)."""
    return "track_times" in inspect.signature(h5py.Group.create_group).parameters


def _create_group(parent: h5py.Group, name: str) -> h5py.Group:
    if _group_track_times():
        return parent.create_group(name, track_times=False)
    gcpl = h5py.h5p.create(h5py.h5p.GROUP_CREATE)  # older h5py: no track_times keyword
    gcpl.set_obj_track_times(False)
    return h5py.Group(h5py.h5g.create(parent.id, name.encode("utf-8"), gcpl=gcpl))


class _V73Writer:
    """Writes nested values into an open h5py file in MATLAB's v7.3 layout."""

    def __init__(self, file: h5py.File):
        self.file = file
        self.refs = _create_group(file, "#refs#")
        self.count = 0
        empty = self.refs.create_dataset("a", data=np.zeros(2, dtype=np.uint64), track_times=False)
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

    def write(self, parent: h5py.Group, name: str, value: Any) -> h5py.HLObject:
        if isinstance(value, Mapping):
            group = _create_group(parent, name)
            group.attrs["MATLAB_class"] = np.bytes_("struct")
            fields = [_field(k, name) for k in value]
            self._fields(group, fields)
            for k, v in value.items():
                self.write(group, k, v)
            return group
        if isinstance(value, list):  # struct array 1 x k: each field a (k, 1) ref dataset
            fields = _struct_array_fields(value, name)
            group = _create_group(parent, name)
            group.attrs["MATLAB_class"] = np.bytes_("struct")
            self._fields(group, fields)
            for f in fields:
                refs = [self.write(self.refs, self._ref_name(), item[f]).ref for item in value]
                group.create_dataset(
                    f, data=np.array(refs, dtype=h5py.ref_dtype)[:, None], track_times=False
                )
            return group
        if isinstance(value, str):
            codes = np.frombuffer(value.encode("utf-16-le"), dtype="<u2")
            data = codes[:, None] if codes.size else np.array([1, 0], dtype=np.uint64)
            dset = parent.create_dataset(name, data=data, track_times=False)
            dset.attrs["MATLAB_class"] = np.bytes_("char")
            dset.attrs["MATLAB_int_decode"] = np.int32(2)
            if not codes.size:
                dset.attrs["MATLAB_empty"] = np.uint8(1)
            return dset
        arr = np.atleast_2d(_numeric(value, name))
        dset = parent.create_dataset(name, data=arr.T, track_times=False)  # dims reversed
        dset.attrs["MATLAB_class"] = np.bytes_("double")
        return dset

    @staticmethod
    def _fields(group: h5py.Group, names: list[str]) -> None:
        values = np.empty(len(names), dtype=object)
        for i, n in enumerate(names):
            values[i] = np.frombuffer(n.encode("ascii"), dtype="S1")
        group.attrs.create("MATLAB_fields", values, dtype=h5py.vlen_dtype(np.dtype("S1")))


def _write_v73(path: Path, variables: Mapping[str, Any], created: str) -> None:
    header = _mat73_header(created)
    with h5py.File(path, "w", userblock_size=512, libver="earliest") as file:
        writer = _V73Writer(file)
        for name, value in variables.items():
            writer.write(file, name, value)
    with open(path, "r+b") as fh:
        fh.write(header)


def write_mat(
    path: str | os.PathLike[str],
    variables: Mapping[str, Any],
    *,
    version: str,
    created: str,
) -> Path:
    """Write variables to a MAT file (v5 or v7.3), deterministically and atomically.

    Parameters
    ----------
    path : str or PathLike
        Target file; its folder must exist. An existing file is replaced only once the
        new one is complete.
    variables : mapping of str to value
        Variable name (a MATLAB identifier) -> value: a mapping (struct), a non-empty
        list of mappings with equal fields (1 x k struct array), a str (char array) or a
        number / numeric array (stored as double; 1-D arrays as 1 x n rows).
    version : {"5", "7.3"}
        ``"5"``: Level 5 MAT file (zlib-compressed, :func:`scipy.io.savemat`);
        ``"7.3"``: HDF5 in MATLAB's layout (h5py).
    created : str
        Timestamp written into the header's "Created on", e.g. ``time.asctime()`` style
        ``"Fri Nov 21 12:00:00 2025"``; printable ASCII (the only time in the file).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        Unknown ``version``, a variable or field name that is not a MATLAB identifier,
        an unsupported value, ``created`` not printable ASCII or too long for the header.
    OSError
        The file cannot be written (the target is then untouched).

    References
    ----------
    The MathWorks, "MAT-File Format" (Level 5) and "MAT-File Versions" (v7.3 = HDF5 with
    a 512-byte user block); The HDF Group, "HDF5 File Format Specification".
    """
    if version not in MAT_VERSIONS:
        raise ValueError(f"`version` must be one of {', '.join(MAT_VERSIONS)}, got {version!r}")
    for name in variables:
        _field(name, "variable")
    _header_text(version, created)  # check before touching the disk
    target = Path(path)
    if version == "5":
        data = _v5_bytes(variables, created)
        atomic_write(target, lambda tmp: tmp.write_bytes(data))
    else:
        atomic_write(target, lambda tmp: _write_v73(tmp, variables, created))
    return target


def write_recording(
    path: str | os.PathLike[str],
    recording: Mapping[str, Any],
    *,
    version: str,
    variable: str = "Recording1",
    created: str,
) -> Path:
    """Write a ControlDesk recording as a MAT file (v5 or v7.3), deterministically, atomically.

    Parameters
    ----------
    path : str or PathLike
        Target file, conventionally ``*.mat``; its folder must exist.
    recording : mapping
        The value of :func:`recording` (``X`` and ``Y`` required, ``Description`` optional).
    version : {"5", "7.3"}
        MAT file version; :func:`debist.ingest.load.load_rig_log` reads both alike.
    variable, created : str
        Name of the struct variable (``"Recording1"``); header timestamp (:func:`write_mat`).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        ``recording`` without ``X`` or ``Y``, or see :func:`write_mat`.
    OSError
        The file cannot be written (an existing target is untouched).

    References
    ----------
    dSPACE ControlDesk MAT export of recordings; MATLAB MAT-file formats v5 and v7.3.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> t = np.arange(5) * 1e-3
    >>> rec = recording([Channel("Model Root/Laser/q", 2 * t, "mm", "Periodic Task 1")],
    ...                 {"Periodic Task 1": t})
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = write_recording(pathlib.Path(d) / "r.mat", rec, version="7.3",
    ...                         created="Fri Nov 21 12:00:00 2025")
    ...     p.read_bytes()[:10]
    b'MATLAB 7.3'
    """
    if not isinstance(recording, Mapping) or not {"X", "Y"} <= set(recording):
        raise ValueError("`recording` must be a mapping with the fields X and Y (see recording())")
    return write_mat(path, {variable: recording}, version=version, created=created)
