"""Stage artifacts: the only module that reads and writes stage outputs.

Every stage directory ``<output_dir>/<stage>/`` holds the stage's outputs and a
``manifest.json`` with the stage key, the sha256 of every input and output, the
resolved configuration section and the versions of the libraries that made it.

Writes are atomic: the outputs go to a temporary sibling directory, are hashed,
the manifest is written last, and the directory is then swapped into place. A
failed or interrupted stage leaves the previous state (or nothing), never half a
stage. Parquet and HDF5 outputs are written byte-reproducibly (fixed column order
and dtypes, zstd, no index, no timestamps; HDF5 without object time stamps), so
the same workflow run twice on the same machine gives identical files.

References
----------
DESIGN.md of the project ("Stages and artifacts").
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from pipeline import __version__
from pipeline.errors import ArtifactError

MANIFEST = "manifest.json"
#: Version of the artifact layout; part of every stage key.
SCHEMA_VERSION = 1
_LIBRARIES = ("numpy", "scipy", "pandas", "pyarrow", "h5py", "pysindy")


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
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


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


def code_version() -> str:
    """Return the code version that enters every stage key.

    The package version plus the sha256 of the sources of the ``pipeline``
    package, so that any change of the code reruns the stages it may affect.

    Returns
    -------
    str
        ``"<version>+<first 12 hex digits of the source hash>"``.
    """
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    return f"{__version__}+{digest.hexdigest()[:12]}"


def library_versions() -> dict[str, str]:
    """Return the installed versions of the numerical libraries recorded in manifests.

    Returns
    -------
    dict of str to str
        Distribution name to version (``"absent"`` when not installed).
    """
    versions = {"debist": __version__}
    for name in _LIBRARIES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "absent"
    return versions


def stage_key(stage: str, config: Mapping[str, Any], inputs: Mapping[str, str]) -> str:
    """Compute the key of a stage run.

    Parameters
    ----------
    stage : str
        Stage name.
    config : mapping
        The resolved configuration section of the stage.
    inputs : mapping of str to str
        Input name to sha256 of its content.

    Returns
    -------
    str
        sha256 of the canonical JSON of stage name, schema version, code version,
        configuration and input hashes. No timestamps enter the key.
    """
    payload = {
        "stage": stage,
        "schema": SCHEMA_VERSION,
        "code": code_version(),
        "config": config,
        "inputs": dict(inputs),
    }
    return hashlib.sha256(canonical_json(payload).encode()).hexdigest()


# --------------------------------------------------------------------------- writers


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


@dataclass(frozen=True)
class Figure:
    """A matplotlib figure to be written as PNG (closed after writing).

    Parameters
    ----------
    figure : matplotlib.figure.Figure
        The figure.
    dpi : int, optional
        Resolution [dots per inch].
    """

    figure: Any
    dpi: int = 110


@dataclass(frozen=True)
class MatRecording:
    """A dSPACE ControlDesk recording to be written as a MAT file (the virtual rig's log).

    Parameters
    ----------
    recording : mapping
        The value of :func:`pipeline.rig.dspace.recording`.
    version : {"5", "7.3"}
        MAT file version.
    created : str
        Fixed header timestamp (the file must be a function of its inputs).
    """

    recording: Mapping[str, Any]
    version: str
    created: str


def _write_output(value: Any, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(value, H5Tree):
        _write_h5(value.tree, path)
    elif isinstance(value, MatRecording):
        from pipeline.rig.dspace import write_recording

        write_recording(path, value.recording, version=value.version, created=value.created)
    elif isinstance(value, Figure):
        import matplotlib.pyplot as plt

        value.figure.savefig(path, dpi=value.dpi, metadata={"Software": None})
        plt.close(value.figure)
    elif isinstance(value, str):
        path.write_text(value, encoding="utf-8")
    elif isinstance(value, bytes):
        path.write_bytes(value)
    elif hasattr(value, "to_parquet"):
        _write_parquet(value, path)
    else:
        raise TypeError(f"no writer for output '{path.name}' of type {type(value).__name__}")


# --------------------------------------------------------------------------- stage dirs


@dataclass(frozen=True)
class Manifest:
    """The manifest of one stage directory.

    Attributes
    ----------
    stage : str
        Stage name.
    key : str
        Stage key (see :func:`stage_key`).
    inputs : dict of str to str
        Input name to sha256.
    outputs : dict of str to str
        Output path relative to the stage directory to sha256.
    config : dict
        The resolved configuration section.
    versions : dict of str to str
        Library versions.
    code : str
        Code version (:func:`code_version`).
    summary : dict
        Small stage-specific results for reports (e.g. RMS values).
    """

    stage: str
    key: str
    inputs: dict[str, str]
    outputs: dict[str, str]
    config: dict[str, Any]
    versions: dict[str, str]
    code: str
    summary: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> str:
        """Return the manifest as indented, key-sorted JSON text."""
        return json.dumps(self.__dict__, indent=2, sort_keys=True, default=_json_default) + "\n"


def read_manifest(stage_dir: str | os.PathLike) -> Manifest | None:
    """Read a stage directory's manifest.

    Parameters
    ----------
    stage_dir : path-like
        The stage directory.

    Returns
    -------
    Manifest or None
        None when the directory or its manifest does not exist.

    Raises
    ------
    ArtifactError
        If the manifest exists but cannot be parsed.
    """
    path = Path(stage_dir) / MANIFEST
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return Manifest(**data)
    except (ValueError, TypeError) as exc:
        raise ArtifactError(f"manifest '{path}' is unreadable: {exc}") from exc


def changed_outputs(stage_dir: str | os.PathLike, manifest: Manifest) -> list[str]:
    """List the outputs of a stage whose bytes no longer match the manifest.

    Parameters
    ----------
    stage_dir : path-like
        The stage directory.
    manifest : Manifest
        Its manifest.

    Returns
    -------
    list of str
        Paths (relative to the stage directory) that are missing or modified,
        followed by files present in the directory but absent from the manifest.
    """
    root = Path(stage_dir)
    changed = []
    for rel, digest in sorted(manifest.outputs.items()):
        path = root / rel
        if not path.is_file():
            changed.append(f"{rel} (missing)")
        elif sha256_file(path) != digest:
            changed.append(f"{rel} (modified)")
    listed = set(manifest.outputs) | {MANIFEST}
    for path in sorted(root.rglob("*")):
        rel = path.relative_to(root).as_posix()
        if path.is_file() and rel not in listed:
            changed.append(f"{rel} (not in manifest)")
    return changed


def write_stage(
    stage_dir: str | os.PathLike,
    *,
    stage: str,
    key: str,
    inputs: Mapping[str, str],
    config: Mapping[str, Any],
    outputs: Mapping[str, Any],
    summary: Mapping[str, Any] | None = None,
) -> Manifest:
    """Write a stage's outputs and manifest atomically.

    Parameters
    ----------
    stage_dir : path-like
        Final stage directory; replaced as a whole.
    stage, key : str
        Stage name and key.
    inputs : mapping of str to str
        Input name to sha256.
    config : mapping
        Resolved configuration section (stored in the manifest).
    outputs : mapping of str to object
        Relative output path to value: a pandas DataFrame (Parquet), an
        :class:`H5Tree` (HDF5), a :class:`Figure` (PNG), ``str`` or ``bytes``.
    summary : mapping, optional
        Small JSON-compatible results stored in the manifest for reports.

    Returns
    -------
    Manifest
        The manifest written.

    Raises
    ------
    TypeError
        If an output has no writer. Nothing is left behind in that case.
    """
    final = Path(stage_dir)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.tmp-", dir=final.parent))
    try:
        hashes = {}
        for rel in sorted(outputs):
            path = tmp / rel
            _write_output(outputs[rel], path)
            hashes[rel] = sha256_file(path)
        manifest = Manifest(
            stage=stage,
            key=key,
            inputs=dict(inputs),
            outputs=hashes,
            config=json.loads(canonical_json(config)),
            versions=library_versions(),
            code=code_version(),
            summary=json.loads(canonical_json(dict(summary or {}))),
        )
        (tmp / MANIFEST).write_text(manifest.to_json(), encoding="utf-8")
        _swap_into_place(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return manifest


def _swap_into_place(tmp: Path, final: Path) -> None:
    old = None
    if final.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{final.name}.old-", dir=final.parent))
        old.rmdir()
        os.replace(final, old)
    os.replace(tmp, final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def write_text_files(folder: str | os.PathLike, files: Mapping[str, str]) -> list[Path]:
    """Write new text files (e.g. generated workflows) into a folder, all or none.

    Parameters
    ----------
    folder : path-like
        Target folder (created if missing).
    files : mapping of str to str
        File name -> UTF-8 text.

    Returns
    -------
    list of pathlib.Path
        The files written, in the order given.

    Raises
    ------
    ArtifactError
        If a file of that name exists already: nothing a user has is overwritten, and
        nothing is written.
    """
    final = Path(folder)
    final.mkdir(parents=True, exist_ok=True)
    existing = [name for name in files if (final / name).exists()]
    if existing:
        raise ArtifactError(
            f"'{final / existing[0]}' exists ({len(existing)} file(s) in all): choose another "
            "folder or remove them"
        )
    tmp = Path(tempfile.mkdtemp(prefix=".files.tmp-", dir=final))
    moved: list[Path] = []
    try:
        for name, text in files.items():
            (tmp / name).write_text(text, encoding="utf-8")
        for name in files:
            os.replace(tmp / name, final / name)
            moved.append(final / name)
    except BaseException:
        for path in moved:  # all new files (checked above): take them back
            path.unlink(missing_ok=True)
        raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return [final / name for name in files]


# --------------------------------------------------------------------------- readers


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
