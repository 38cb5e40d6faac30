"""Decoder of MATLAB v7.3 MAT files (HDF5 containers) into plain Python values.

The result has the same shape as ``scipy.io.loadmat(path, simplify_cells=True)`` gives
for a v5 file, so :mod:`debist.ingest.mat` interprets both alike: a struct becomes a
``dict``, a struct array or a cell array a ``list``, a char array a ``str``, a numeric
array a squeezed :class:`numpy.ndarray` in MATLAB's (column-major) orientation.

Before any data is read, :func:`load_mat73` surveys the objects the decoder will visit and
refuses a forged or truncated file, a reference graph beyond :data:`MAX_OBJECTS` visits or
a cycle (``RigLogError``), and data beyond the memory budget (``ResourceError``). The
layout read and the bounds: docs/explanation/implementation.md.

References
----------
The MathWorks, "MAT-File Versions" (MATLAB documentation): version 7.3 files use an
HDF5-based format. The HDF Group, "HDF5 File Format Specification", user block;
"HDF5 Reference Manual", H5Dget_storage_size, H5Dget_offset. Deutsch, RFC 1951
(deflate; longest match 258 bytes).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import lazy_loader as lazy
import numpy as np

from debist.core.errors import RigLogError
from debist.core.preflight import DEFLATE_MAX_RATIO, check_memory

# the libraries below load on first use (lazy_loader): start-up of the CLI
h5py = lazy.load("h5py")

__all__ = ["MAX_OBJECTS", "load_mat73"]

_MAX_DEPTH = 32
#: Most objects the decoder may visit (with repetition) and references it may read.
MAX_OBJECTS = 100_000
_SKIP = ("#refs#", "#subsystem#")


def _attr_text(obj: h5py.HLObject, name: str) -> str | None:
    value = obj.attrs.get(name)
    if value is None:
        return None
    if isinstance(value, bytes | np.bytes_):
        return value.decode("ascii", "replace")
    if isinstance(value, np.ndarray) and value.dtype.kind == "S":
        return b"".join(value.ravel().tolist()).decode("ascii", "replace")
    return str(value)


def _field_names(group: h5py.Group) -> list[str]:
    fields = group.attrs.get("MATLAB_fields")
    if fields is None:
        return list(group.keys())
    names = []
    for item in np.ravel(fields):
        if isinstance(item, bytes | np.bytes_):
            names.append(item.decode("ascii", "replace"))
        else:
            names.append(b"".join(np.ravel(item).tolist()).decode("ascii", "replace"))
    return [n for n in names if n in group]


def _is_ref_dataset(obj: h5py.HLObject) -> bool:
    return isinstance(obj, h5py.Dataset) and obj.dtype == h5py.ref_dtype


class _Decoder:
    def __init__(self, file: h5py.File):
        self.file = file

    def node(self, obj: h5py.HLObject, depth: int) -> Any:
        if depth > _MAX_DEPTH:
            raise ValueError(f"objects nested deeper than {_MAX_DEPTH} levels at {obj.name}")
        if isinstance(obj, h5py.Group):
            return self.group(obj, depth)
        return self.dataset(obj, depth)

    def deref(self, ref: h5py.Reference, depth: int) -> Any:
        if not ref:
            raise ValueError("null object reference")
        return self.node(self.file[ref], depth + 1)

    def group(self, group: h5py.Group, depth: int) -> Any:
        cls = _attr_text(group, "MATLAB_class")
        if cls not in (None, "struct"):
            return None  # MATLAB objects (table, timetable, ...) are not rig-log channels
        members = {name: group[name] for name in _field_names(group)}
        if (
            members
            and all(
                _is_ref_dataset(m) and _attr_text(m, "MATLAB_class") in (None, "struct")
                for m in members.values()
            )
            and len({m.shape for m in members.values()}) == 1
        ):
            refs = {name: np.ravel(m[()]) for name, m in members.items()}
            size = len(next(iter(refs.values())))
            return [
                {name: self.deref(refs[name][i], depth) for name in members} for i in range(size)
            ]
        return {name: self.node(m, depth + 1) for name, m in members.items()}

    def dataset(self, data: h5py.Dataset, depth: int) -> Any:
        cls = _attr_text(data, "MATLAB_class")
        if data.attrs.get("MATLAB_empty", 0):
            if cls == "char":
                return ""
            return [] if cls in ("cell", "struct") else np.empty(0)
        if data.dtype == h5py.ref_dtype:
            return [self.deref(ref, depth) for ref in np.ravel(data[()])]
        values = np.asarray(data[()])
        if cls == "char":
            rows = np.atleast_2d(values.T).astype("<u2")
            text = [row.tobytes().decode("utf-16-le", "replace") for row in rows]
            return text[0] if len(text) == 1 else text
        if values.dtype.names and {"real", "imag"} <= set(values.dtype.names):
            values = values["real"] + 1j * values["imag"]
        if cls == "logical":
            values = values.astype(bool)
        return values.T.squeeze()


class _Survey:
    """Walk the objects :class:`_Decoder` will visit, reading references but no data.

    ``cost(obj)`` returns (visits, bytes read) of decoding ``obj``, counting every path
    through the reference graph; each object is surveyed once (memoised by its address).
    """

    def __init__(self, file: h5py.File, path: Path):
        self.file, self.path = file, path
        self.file_size = os.path.getsize(path)
        self.memo: dict[int, tuple[int, int]] = {}
        self.active: set[int] = set()
        self.refs_read = 0

    def fail(self, message: str) -> RigLogError:
        return RigLogError(f"cannot read mat-v7.3 file: {message}", path=self.path)

    def limit(self, visits: int, where: str) -> None:
        if visits > MAX_OBJECTS:
            raise self.fail(
                f"decoding '{where}' visits more than {MAX_OBJECTS} objects through its "
                "object references: a corrupt or forged file"
            )

    def cost(self, obj: h5py.HLObject, depth: int) -> tuple[int, int]:
        if depth > 2 * _MAX_DEPTH + 2:
            raise self.fail(f"objects nested deeper than {_MAX_DEPTH} levels at {obj.name}")
        key = h5py.h5o.get_info(obj.id).addr
        if key in self.memo:
            return self.memo[key]
        if key in self.active:
            raise self.fail(f"object references form a cycle at '{obj.name}'")
        self.active.add(key)
        visits, nbytes = 1, 0
        for child, count in self.children(obj):
            v, b = self.cost(child, depth + 1)
            visits, nbytes = visits + count * v, nbytes + count * b
            self.limit(visits, obj.name)
        if isinstance(obj, h5py.Dataset) and not obj.attrs.get("MATLAB_empty", 0):
            nbytes += self.declared(obj)
        self.active.discard(key)
        self.memo[key] = (visits, nbytes)
        return visits, nbytes

    def children(self, obj: h5py.HLObject) -> list[tuple[h5py.HLObject, int]]:
        """Objects the decoder visits from ``obj``, each with how often."""
        if isinstance(obj, h5py.Group):
            if _attr_text(obj, "MATLAB_class") not in (None, "struct"):
                return []
            self.limit(len(obj), obj.name)
            return [(obj[name], 1) for name in _field_names(obj)]
        if obj.attrs.get("MATLAB_empty", 0) or obj.dtype != h5py.ref_dtype:
            return []
        self.declared(obj)
        self.refs_read += obj.size
        self.limit(self.refs_read, obj.name)
        # Object references are file addresses: read them as such to group repeated
        # targets, and dereference one reference per distinct target.
        addresses = np.zeros(obj.shape, dtype=np.uint64)
        if obj.size:
            obj.id.read(h5py.h5s.ALL, h5py.h5s.ALL, addresses, mtype=h5py.h5t.STD_REF_OBJ)
        addresses = np.ravel(addresses)
        _, first, counts = np.unique(addresses, return_index=True, return_counts=True)
        refs = np.ravel(obj[()])
        return [(self.file[refs[i]], int(n)) for i, n in zip(first, counts, strict=True) if refs[i]]

    def declared(self, data: h5py.Dataset) -> int:
        """Bytes the data set declares; refuse it if it cannot hold them."""
        nbytes = int(data.size) * int(data.id.get_type().get_size())
        if h5py.check_vlen_dtype(data.dtype) is not None or nbytes == 0:
            return nbytes
        stored = int(data.id.get_storage_size())
        plist = data.id.get_create_plist()
        filtered = plist.get_nfilters() > 0
        what = f"data set '{data.name}' declares {nbytes} bytes ({data.shape} x {data.dtype})"
        if stored > self.file_size:
            raise self.fail(
                f"{what} and {stored} bytes of storage, more than the file's "
                f"{self.file_size} bytes: the file is truncated or forged"
            )
        if plist.get_layout() == h5py.h5d.CONTIGUOUS and stored:
            end = int(data.id.get_offset() or 0) + stored
            if end > self.file_size:
                raise self.fail(
                    f"{what} stored up to byte {end}, beyond the end of the file "
                    f"({self.file_size} bytes): the file is truncated"
                )
        bound = DEFLATE_MAX_RATIO * stored if filtered else stored
        if nbytes > bound:
            held = (
                f"{stored} compressed bytes can hold at most {bound}"
                if filtered
                else f"only {stored} are stored"
            )
            raise self.fail(f"{what} but {held}: the file is truncated or forged")
        return nbytes


def load_mat73(path: Path) -> dict[str, Any]:
    """Read every variable of a MATLAB v7.3 MAT file.

    Parameters
    ----------
    path : Path
        The file (MAT header in a 512-byte user block, then HDF5).

    Returns
    -------
    dict
        Variable name -> value, decoded as described in the module notes.

    Raises
    ------
    OSError
        h5py cannot open the file (truncated, not HDF5).
    ValueError
        A dangling object reference or absurd nesting (corrupt file).
    RigLogError
        Before any data is read: a data set declares more than the file can hold, the
        reference graph makes the decoder visit more than :data:`MAX_OBJECTS` objects,
        or references form a cycle (see the module notes); names the file and the
        data set.
    ResourceError
        The data the decoder would read exceeds the memory budget.

    References
    ----------
    The HDF Group, "HDF5 Reference Manual" (H5Dget_storage_size); RFC 1951 (deflate).
    """
    path = Path(path)
    with h5py.File(path, "r") as file:
        survey = _Survey(file, path)
        names = [name for name in file if name not in _SKIP]
        survey.limit(len(names), "/")
        visits = nbytes = 0
        for name in names:
            v, b = survey.cost(file[name], 0)
            visits, nbytes = visits + v, nbytes + b
            survey.limit(visits, "/")
        check_memory(
            nbytes,
            f"file '{path}'",
            "decoding its MAT v7.3 variables",
            f"the data sets' declared sizes over {visits} object visits",
        )
        decoder = _Decoder(file)
        return {name: decoder.node(file[name], 0) for name in names}
