"""Reading and writing the file formats of stage outputs: Parquet, HDF5, PNG, text.

Used by :mod:`debist.core.artifacts` (which re-exports the readers) and the stages; written
byte-reproducibly: Parquet with fixed column order and dtypes, zstd, no index,
provenance in the key-value metadata; HDF5 without object time stamps; PNG without
the software tag; canonical JSON with sorted keys.

References
----------
Apache Parquet format specification (key-value metadata); HDF5 User Guide, "Dataset
creation properties" (``track_times``); PNG specification, tEXt chunks.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import secrets
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from debist.core.errors import ArtifactError

__all__ = [
    "MAX_PNG_WIDTH",
    "REPORT_DPI",
    "Figure",
    "FileWriter",
    "H5Tree",
    "atomic_write",
    "canonical_json",
    "png_bytes",
    "read_h5",
    "read_parquet",
    "sha256_file",
    "write_output",
]


def atomic_write(
    path: str | os.PathLike,
    content: str | bytes | Callable[[Path], None],
    *,
    replace: bool = True,
) -> Path:
    """Write a file so that a reader sees the old file or the whole new one, never a part.

    The content goes to a fresh file beside ``path`` (mode 0o666 less the umask, like any new
    file), is flushed to disk (``fsync``) and moved over ``path`` with :func:`os.replace`;
    the folder is then synced (POSIX, best effort) so the rename survives a power cut. On any
    error, Ctrl-C included, the temporary file is removed and ``path`` is untouched. The one
    atomic file write of debist (artifacts, reports, rig logs, exports, the folder marker).
    With ``replace=False`` the finished file is hard-linked to ``path`` instead (``link(2)``
    never replaces a name), so a file that appeared at ``path`` meanwhile stays as it is;
    where the file system has no hard links, ``path`` is created exclusively
    (``O_CREAT | O_EXCL``) and the content copied into it.

    Parameters
    ----------
    path : path-like
        The file to write (its folder must exist).
    content : str, bytes or callable
        Text (written as UTF-8), bytes, or ``write(tmp)`` that writes the temporary file
        itself (e.g. an HDF5 writer).
    replace : bool, optional
        Replace an existing ``path`` (default); if False, an existing ``path`` is an error.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    FileExistsError
        With ``replace=False``, if ``path`` exists (also when it appeared during the write);
        it is left as it was.
    OSError
        What the file system raises (no space, read-only, permissions); nothing is left.

    References
    ----------
    POSIX ``rename(2)``, ``link(2)``, ``open(2)`` (``O_EXCL``) and ``fsync(2)``.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = atomic_write(Path(d) / "a.txt", "one")
    ...     sorted(p.name for p in Path(d).iterdir()), path.read_text()
    (['a.txt'], 'one')
    """
    path = Path(path)
    folder = path.parent
    for _ in range(16):
        tmp = folder / f".{path.name}.{secrets.token_hex(6)}.tmp"
        try:  # mode 0o666 minus the umask, like any new file (mkstemp would give 0o600)
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            break
        except FileExistsError:
            continue
    else:  # pragma: no cover - 16 collisions of 48 random bits
        raise FileExistsError(f"cannot create a temporary file beside '{path}'")
    try:
        if isinstance(content, str):
            tmp.write_bytes(content.encode("utf-8"))
        elif isinstance(content, bytes):
            tmp.write_bytes(content)
        else:
            content(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        if replace:
            os.replace(tmp, path)
        else:
            _link_new(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
    if os.name == "posix":  # make the rename durable; best effort
        with contextlib.suppress(OSError):
            fd = os.open(folder, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
    return path


def _link_new(tmp: Path, path: Path) -> None:
    """Give the finished ``tmp`` the name ``path`` unless that name exists; remove ``tmp``."""
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise
    except OSError:  # no hard links here (some network and FAT file systems)
        with open(path, "xb") as out, open(tmp, "rb") as src:
            try:
                while block := src.read(1 << 20):
                    out.write(block)
                out.flush()
                os.fsync(out.fileno())
            except BaseException:
                out.close()
                os.unlink(path)
                raise
    tmp.unlink()


def sha256_file(path: str | os.PathLike) -> str:
    """Return the hex sha256 digest of a file's bytes.

    Parameters
    ----------
    path : path-like
        File to hash.

    Returns
    -------
    str
        64 hexadecimal characters.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    """
    return sha256_identified(path)[0]


#: What changes when a file is written or replaced: ``(st_dev, st_ino, st_size,
#: st_mtime_ns, st_ctime_ns)``.
FileIdentity = tuple[int, int, int, int, int]


def _identity(st: os.stat_result) -> FileIdentity:
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


def file_identity(path: str | os.PathLike) -> FileIdentity | None:
    """Return what tells a file from another one, or from itself after a write.

    Parameters
    ----------
    path : path-like
        The file (symbolic links followed).

    Returns
    -------
    tuple of int or None
        ``(st_dev, st_ino, st_size, st_mtime_ns, st_ctime_ns)``: another file renamed over
        the path has another inode, a write in place moves the change time; None when the
        file cannot be stat'ed (missing).

    References
    ----------
    POSIX ``stat(2)`` (``st_ctime`` is updated by every write and every change of the inode).
    """
    try:
        return _identity(os.stat(path))
    except OSError:
        return None


def sha256_identified(path: str | os.PathLike) -> tuple[str, FileIdentity | None]:
    """Return the hex sha256 digest of a file's bytes and the identity of the file hashed.

    The bytes are hashed through one open file descriptor whose ``fstat`` is taken before and
    after: the identity is that of the file whose bytes were hashed, and None when the file
    changed while it was read (the digest then describes no version of it).

    Parameters
    ----------
    path : path-like
        File to hash.

    Returns
    -------
    digest : str
        64 hexadecimal characters.
    identity : tuple of int or None
        As :func:`file_identity`; compare it with :func:`file_identity` of the path later to
        tell whether the path still names those bytes.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.

    References
    ----------
    FIPS 180-4 (SHA-256); POSIX ``fstat(2)``.
    """
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        before = _identity(os.fstat(fh.fileno()))
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
        after = _identity(os.fstat(fh.fileno()))
    return digest.hexdigest(), before if before == after else None


def canonical_json(obj: Any) -> str:
    """Serialise ``obj`` to canonical JSON (sorted keys, no spaces, NumPy scalars as floats).

    Parameters
    ----------
    obj : object
        JSON-compatible data; NumPy scalars, arrays and paths are converted.

    Returns
    -------
    str
        The canonical text, identical for equal content.
    """
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=_json_default)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise TypeError(f"cannot serialise {type(obj).__name__} in a stage config")


def _write_parquet(frame: Any, path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pandas(frame, preserve_index=False)
    meta = dict(table.schema.metadata or {})
    attrs = getattr(frame, "attrs", {}) or {}
    if attrs:
        meta[b"debist"] = canonical_json(attrs).encode()
    table = table.replace_schema_metadata(meta)
    pq.write_table(table, path, compression="zstd", write_statistics=True)


def _write_h5_group(group: Any, tree: Mapping[str, Any]) -> None:
    for name, value in tree.items():
        if name == "attrs":
            for key, attr in value.items():
                group.attrs[key] = attr
        elif isinstance(value, Mapping):
            _write_h5_group(group.create_group(name), value)
        else:
            data = np.asarray(value)
            if data.dtype.kind == "U":
                data = data.astype(object)
                group.create_dataset(name, data=data, dtype=_h5_str(), track_times=False)
            else:
                group.create_dataset(name, data=data, track_times=False)


def _h5_str() -> Any:
    import h5py

    return h5py.string_dtype("utf-8")


def _write_h5(tree: Mapping[str, Any], path: Path) -> None:
    import h5py

    with h5py.File(path, "w", libver=("earliest", "v110")) as fh:
        _write_h5_group(fh, tree)


@dataclass(frozen=True)
class H5Tree:
    """A nested mapping to be written as an HDF5 file.

    Parameters
    ----------
    tree : mapping
        Group name to nested mapping, dataset name to array-like; the key
        ``"attrs"`` of a mapping holds that group's attributes.
    """

    tree: Mapping[str, Any]


#: Resolution of the figures the HTML report shows [dots per inch]: a 9-inch-wide figure is
#: 1944 px (1920 with :data:`MAX_PNG_WIDTH`), twice the 60rem (960 CSS px) column it fills,
#: sharp on a 2x (HiDPI) screen.
REPORT_DPI = 216
#: Widest PNG written [px]: twice the report's 960 CSS px column, what a 2x (HiDPI) screen
#: shows of a figure that fills it; a wider figure gets a lower resolution (same layout).
MAX_PNG_WIDTH = 1920


@dataclass(frozen=True)
class Figure:
    """A matplotlib figure to be written as PNG (a ``matplotlib.figure.Figure``, no pyplot).

    Parameters
    ----------
    figure : matplotlib.figure.Figure
        The figure.
    dpi : int, optional
        Resolution [dots per inch].
    """

    figure: Any
    dpi: int = 110


def png_bytes(figure: Any, dpi: int = 110) -> bytes:
    """Render a figure to PNG bytes, the same bytes for the same figure.

    Parameters
    ----------
    figure : matplotlib.figure.Figure
        The figure.
    dpi : int, optional
        Resolution [dots per inch]; lowered so that the PNG is at most
        :data:`MAX_PNG_WIDTH` pixels wide (pixels nobody is shown cost rendering time).

    Returns
    -------
    bytes
        The PNG file.

    References
    ----------
    matplotlib ``Figure.savefig``: ``metadata={"Software": None}`` leaves out the only
    field that would differ between matplotlib builds of one version.
    """
    dpi = min(float(dpi), MAX_PNG_WIDTH / float(figure.get_figwidth()))
    buf = io.BytesIO()
    figure.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    return buf.getvalue()


@dataclass(frozen=True)
class FileWriter:
    """An output written by a function of its path (e.g. a MAT file of the virtual rig).

    Parameters
    ----------
    write : callable
        Called as ``write(path)``; must write the file deterministically (the same bytes
        for the same inputs) and nothing else.
    """

    write: Callable[[Path], Any]


def write_output(value: Any, path: Path) -> None:
    """Write one stage output in the format its type asks for.

    Parameters
    ----------
    value : object
        :class:`H5Tree` (HDF5), :class:`FileWriter`, :class:`Figure` (PNG), ``str``
        (UTF-8 text), ``bytes``, or an object with ``to_parquet`` (a pandas DataFrame,
        written as Parquet with its ``attrs`` as metadata).
    path : pathlib.Path
        Target file; its folder is created.

    Raises
    ------
    TypeError
        If no writer handles the type of ``value``.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(value, H5Tree):
        _write_h5(value.tree, path)
    elif isinstance(value, FileWriter):
        value.write(path)
    elif isinstance(value, Figure):
        path.write_bytes(png_bytes(value.figure, value.dpi))
    elif isinstance(value, str):
        path.write_text(value, encoding="utf-8")
    elif isinstance(value, bytes):
        path.write_bytes(value)
    elif hasattr(value, "to_parquet"):
        _write_parquet(value, path)
    else:
        raise TypeError(f"no writer for output '{path.name}' of type {type(value).__name__}")


def read_parquet(path: str | os.PathLike) -> Any:
    """Read a Parquet artifact into a DataFrame, restoring the ``attrs`` metadata.

    Parameters
    ----------
    path : path-like
        Parquet file written by this module.

    Returns
    -------
    pandas.DataFrame
        The table, with ``attrs`` as stored.

    Raises
    ------
    ArtifactError
        If the file is missing or unreadable.
    """
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (OSError, ValueError) as exc:
        raise ArtifactError(f"cannot read artifact '{path}': {exc}") from exc
    frame = table.to_pandas()
    raw = (table.schema.metadata or {}).get(b"debist")
    if raw:
        frame.attrs.update(json.loads(raw))
    return frame


def read_h5(path: str | os.PathLike) -> dict[str, Any]:
    """Read an HDF5 artifact into a nested dict (the inverse of :class:`H5Tree`).

    Parameters
    ----------
    path : path-like
        HDF5 file written by this module.

    Returns
    -------
    dict
        Nested mapping of NumPy arrays; each group's attributes under ``"attrs"``.

    Raises
    ------
    ArtifactError
        If the file is missing or unreadable.
    """
    import h5py

    def load(group: Any) -> dict[str, Any]:
        out: dict[str, Any] = {"attrs": {k: _attr(v) for k, v in group.attrs.items()}}
        for name, item in group.items():
            if isinstance(item, h5py.Group):
                out[name] = load(item)
            elif item.dtype.kind == "O":
                out[name] = np.array([s.decode() if isinstance(s, bytes) else s for s in item[()]])
            else:
                out[name] = item[()]
        return out

    try:
        with h5py.File(path, "r") as fh:
            return load(fh)
    except OSError as exc:
        raise ArtifactError(f"cannot read artifact '{path}': {exc}") from exc


def _attr(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value
