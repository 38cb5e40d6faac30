"""Decoder of MATLAB v7.3 MAT files (HDF5 containers) into plain Python values.

The result has the same shape as ``scipy.io.loadmat(path, simplify_cells=True)`` gives
for a v5 file, so :mod:`pipeline.ingest.mat` interprets both alike: a struct becomes a
``dict``, a struct array or a cell array a ``list``, a char array a ``str``, a numeric
array a squeezed :class:`numpy.ndarray` in MATLAB's (column-major) orientation.

Notes
-----
Layout written by MATLAB (``save -v7.3``) and read here:

- a 512-byte HDF5 user block holding the 128-byte MAT header (version ``0x0200``);
- one HDF5 object per variable at the root; every object carries the attribute
  ``MATLAB_class`` (``"double"``, ``"char"``, ``"struct"``, ``"cell"``, ...);
- dimensions are stored reversed (a MATLAB ``1 x n`` array is an HDF5 ``(n, 1)``
  dataset), so arrays are transposed back;
- ``char`` arrays are ``uint16`` UTF-16 code units (``MATLAB_int_decode = 2``);
- an empty array is a dataset holding its dimensions, with ``MATLAB_empty = 1``;
- a scalar struct is a group with one member per field (order in ``MATLAB_fields``);
  a struct *array* is a group whose fields are datasets of object references (no
  ``MATLAB_class``), one per element; a cell array is a dataset of object references
  with ``MATLAB_class = "cell"``; the referenced objects live in the group ``#refs#``.

References
----------
The MathWorks, "MAT-File Versions" (MATLAB documentation): version 7.3 files use an
HDF5-based format. The HDF Group, "HDF5 File Format Specification", user block.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np

__all__ = ["load_mat73"]

_MAX_DEPTH = 32
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
    """
    with h5py.File(path, "r") as file:
        decoder = _Decoder(file)
        return {name: decoder.node(file[name], 0) for name in file if name not in _SKIP}
