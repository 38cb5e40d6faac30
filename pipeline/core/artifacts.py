"""Stage artifacts: the only module that reads and writes stage folders.

Every stage folder ``<output_dir>/<stage>/`` holds the stage's outputs, ``summary.json``
(the small results that reports print, hashed like every output), ``manifest.json`` and
``timings.json``. The manifest holds the stage key, the code fingerprint and library
versions, the resolved configuration, the sha256 of every input, of every upstream stage's
manifest (the chain) and of every output. It is byte-deterministic: no time stamps, no
absolute paths; wall times go to ``timings.json``, which no hash covers.

Writes are atomic: the outputs go to a temporary sibling folder, are hashed, the manifest
is written last, and the folder is swapped into place (old folder moved aside, new one
moved in, old one removed) with SIGINT and SIGTERM deferred until it is done. A process
killed in between (SIGKILL, power loss) leaves ``.<stage>.tmp-*`` or ``.<stage>.old-*`` folders
(:data:`SWAP_FOLDER`), which :func:`debist.engine.outdir.recover` resolves. A stage folder is
only ever replaced when every file in it is listed by its manifest: a file debist did not
write is never deleted.

The output folder as a whole (its owner, its lock and the recovery of leftovers) is
:mod:`debist.engine.outdir`; the run's digest over the stages' manifests is :func:`run_digest`.

References
----------
POSIX ``rename(2)`` (atomic replacement within a file system); Python documentation,
:mod:`signal` (handlers run in the main thread); dvc's run cache
(https://dvc.org/doc/user-guide/project-structure/internal-files) as the model of stages
addressed by the hash of their inputs.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import re
import secrets
import shutil
import signal
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from importlib import metadata
from pathlib import Path
from typing import Any

from debist import __version__
from debist.core.errors import ArtifactError, DebistError, OutputDirError
from debist.core.faults import fault_point
from debist.core.fileformats import (
    Figure,
    FileWriter,
    H5Tree,
    atomic_write,
    canonical_json,
    read_h5,
    read_parquet,
    sha256_file,
    write_output,
)

__all__ = [
    "MANIFEST",
    "SCHEMA_VERSION",
    "SET_ASIDE",
    "SUMMARY",
    "SWAP_FOLDER",
    "TIMINGS",
    "Figure",
    "FileWriter",
    "H5Tree",
    "Manifest",
    "adopt_stage",
    "canonical_json",
    "changed_outputs",
    "checked_output",
    "foreign_files",
    "foreign_message",
    "inside",
    "library_versions",
    "manifest_digest",
    "read_h5",
    "read_manifest",
    "read_parquet",
    "read_summary",
    "remove_tree",
    "run_digest",
    "set_aside",
    "sha256_file",
    "stage_key",
    "write_stage",
    "write_text_files",
]

MANIFEST = "manifest.json"
#: The stage's small results for reports: an output like any other (hashed).
SUMMARY = "summary.json"
#: Wall times of the stage [s]: the one file of a stage folder that no hash covers.
TIMINGS = "timings.json"
#: Version of the artifact layout; part of every stage key.
SCHEMA_VERSION = 2
#: Files of a stage folder that its manifest does not list as outputs.
_UNLISTED = frozenset({MANIFEST, TIMINGS})
#: Names of the temporary (``tmp``) and moved-aside (``old``) folders of a stage swap.
SWAP_FOLDER = re.compile(r"^\.(?P<stage>[A-Za-z0-9_-]+)\.(?P<kind>tmp|old)-[0-9a-f]+$")
_SIGNALS = {signal.SIGINT, signal.SIGTERM}


def sha256_bytes(data: bytes) -> str:
    """Return the hex sha256 digest of ``data``.

    Parameters
    ----------
    data : bytes
        The content.

    Returns
    -------
    str
        64 hexadecimal characters.

    Examples
    --------
    >>> sha256_bytes(b"")[:12]
    'e3b0c44298fc'
    """
    return hashlib.sha256(data).hexdigest()


def library_versions(names: Sequence[str]) -> dict[str, str]:
    """Return the installed versions of libraries, and debist's own.

    Parameters
    ----------
    names : sequence of str
        Distribution names (e.g. ``"numpy"``).

    Returns
    -------
    dict of str to str
        ``"debist"`` and each name to its version (``"absent"`` when not installed).
    """
    return {"debist": __version__, **{name: _version(name) for name in names}}


@functools.cache
def _version(name: str) -> str:
    """Return the installed version of a distribution, read once per process (3 ms a lookup)."""
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "absent"


def stage_key(
    stage: str,
    *,
    code: str,
    versions: Mapping[str, str],
    config: Mapping[str, Any],
    inputs: Mapping[str, str],
    upstream: Mapping[str, str],
) -> str:
    """Compute the key of a stage run.

    Parameters
    ----------
    stage : str
        Stage name.
    code : str
        Fingerprint of the code the stage runs (:func:`debist.engine.fingerprint.code_fingerprint`).
    versions : mapping of str to str
        Versions of the libraries the stage uses.
    config : mapping
        The resolved configuration of the stage.
    inputs : mapping of str to str
        Input name to sha256 of its content (source files, upstream outputs).
    upstream : mapping of str to str
        Upstream stage to the sha256 of its ``manifest.json``.

    Returns
    -------
    str
        sha256 of the canonical JSON of all of the above and the schema version. No time
        stamps or paths enter the key.
    """
    payload = {
        "stage": stage,
        "schema": SCHEMA_VERSION,
        "code": code,
        "versions": dict(versions),
        "config": config,
        "inputs": dict(inputs),
        "upstream": dict(upstream),
    }
    return sha256_bytes(canonical_json(payload).encode())


@dataclass(frozen=True)
class Manifest:
    """The manifest of one stage folder.

    Attributes
    ----------
    stage : str
        Stage name.
    key : str
        Stage key (:func:`stage_key` of the fields below).
    code : str
        Fingerprint of the stage's code.
    versions : dict of str to str
        Versions of the libraries the stage used.
    config : dict
        The resolved configuration.
    inputs : dict of str to str
        Input name to sha256.
    upstream : dict of str to str
        Upstream stage to the sha256 of its ``manifest.json``: the chain.
    outputs : dict of str to str
        Output path relative to the stage folder to sha256 (``summary.json`` included).
    summary : dict
        The content of ``summary.json`` once checked against its hash (not part of the
        manifest file; empty until loaded).
    """

    stage: str
    key: str
    code: str
    versions: dict[str, str]
    config: dict[str, Any]
    inputs: dict[str, str]
    upstream: dict[str, str]
    outputs: dict[str, str]
    summary: dict[str, Any] = field(default_factory=dict, compare=False)

    def to_json(self) -> str:
        """Return the manifest file's text: indented, key-sorted JSON without ``summary``."""
        data = asdict(self)
        del data["summary"]
        return json.dumps(data, indent=2, sort_keys=True) + "\n"

    def expected_key(self) -> str:
        """Return the key that this manifest's own fields give (a check against edits)."""
        return stage_key(
            self.stage,
            code=self.code,
            versions=self.versions,
            config=self.config,
            inputs=self.inputs,
            upstream=self.upstream,
        )


def read_manifest(stage_dir: str | os.PathLike) -> Manifest | None:
    """Read a stage folder's manifest.

    Parameters
    ----------
    stage_dir : path-like
        The stage folder.

    Returns
    -------
    Manifest or None
        None when the folder or its manifest does not exist.

    Raises
    ------
    ArtifactError
        If the manifest exists but cannot be parsed: not JSON, not an object, nested too
        deeply, or without the fields of a manifest (a damaged manifest: the stage is stale,
        see :func:`set_aside`).
    """
    path = Path(stage_dir) / MANIFEST
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(data, dict):
            raise TypeError(f"expected a JSON object, got {type(data).__name__}")
        if "summary" in data and "upstream" not in data:  # layout 1 (before the chain)
            data = {
                "stage": data["stage"],
                "key": f"layout-1:{data['key']}",  # never equal to a computed key: stale
                "code": str(data.get("code", "")),
                "versions": data.get("versions", {}),
                "config": data.get("config", {}),
                "inputs": data.get("inputs", {}),
                "upstream": {},
                "outputs": data["outputs"],
            }
        return Manifest(**data)
    except RecursionError:
        raise ArtifactError(f"manifest '{path}' is unreadable: nested too deeply") from None
    except (ValueError, TypeError, KeyError) as exc:
        raise ArtifactError(f"manifest '{path}' is unreadable: {exc}") from exc


def manifest_digest(stage_dir: str | os.PathLike) -> str | None:
    """Return the sha256 of a stage folder's ``manifest.json`` (None when it has none).

    Parameters
    ----------
    stage_dir : path-like
        The stage folder.

    Returns
    -------
    str or None
        64 hexadecimal characters, or None.
    """
    path = Path(stage_dir) / MANIFEST
    return sha256_file(path) if path.is_file() else None


def run_digest(output_dir: str | os.PathLike, stages: Sequence[str]) -> str | None:
    """Return the digest of a run: sha256 over its stages' manifests, in stage order.

    Parameters
    ----------
    output_dir : path-like
        The workflow's output folder.
    stages : sequence of str
        The workflow's stages, in execution order.

    Returns
    -------
    str or None
        sha256 of the lines ``"<stage> <sha256 of manifest.json>"``; None when a stage has
        no manifest.
    """
    lines = []
    for stage in stages:
        digest = manifest_digest(Path(output_dir) / stage)
        if digest is None:
            return None
        lines.append(f"{stage} {digest}\n")
    return sha256_bytes("".join(lines).encode())


def read_summary(stage_dir: str | os.PathLike, manifest: Manifest) -> dict[str, Any]:
    """Read a stage's ``summary.json`` after checking it against its manifest.

    Parameters
    ----------
    stage_dir : path-like
        The stage folder.
    manifest : Manifest
        Its manifest.

    Returns
    -------
    dict
        The summary (empty for a stage without one).

    Raises
    ------
    ArtifactError
        If ``summary.json`` is missing or does not hash to the manifest: a report is never
        printed from content the manifest does not vouch for.
    """
    if SUMMARY not in manifest.outputs:
        return {}
    path = checked_output(stage_dir, manifest, SUMMARY)
    return json.loads(path.read_text(encoding="utf-8"))


def checked_output(stage_dir: str | os.PathLike, manifest: Manifest, rel: str) -> Path:
    """Return the path of one output after checking its bytes against the manifest.

    Parameters
    ----------
    stage_dir : path-like
        The stage folder.
    manifest : Manifest
        Its manifest.
    rel : str
        The output's path relative to the stage folder, as the manifest lists it.

    Returns
    -------
    pathlib.Path
        The file, whose sha256 is the one the manifest records.

    Raises
    ------
    ArtifactError
        If the manifest does not list ``rel``, or the file is missing or does not hash to
        the manifest: nothing is read from content the manifest does not vouch for.
    """
    expected = manifest.outputs.get(rel)
    path = inside(Path(stage_dir), rel)
    if expected is None:
        raise ArtifactError(f"'{path}' is not an output of this stage (its manifest lacks it)")
    if not path.is_file() or sha256_file(path) != expected:
        raise ArtifactError(
            f"'{path}' is missing or changed since the stage wrote it (run `debist verify`)"
        )
    return path


def changed_outputs(stage_dir: str | os.PathLike, manifest: Manifest) -> list[str]:
    """List the outputs of a stage whose bytes no longer match the manifest.

    Parameters
    ----------
    stage_dir : path-like
        The stage folder.
    manifest : Manifest
        Its manifest.

    Returns
    -------
    list of str
        Paths (relative to the stage folder) that are missing or modified, followed by
        files present in the folder but absent from the manifest (``timings.json``
        excepted).
    """
    root = Path(stage_dir)
    changed = []
    for rel, digest in sorted(manifest.outputs.items()):
        path = root / rel
        if not path.is_file():
            changed.append(f"{rel} (missing)")
        elif sha256_file(path) != digest:
            changed.append(f"{rel} (modified)")
    listed = set(manifest.outputs) | _UNLISTED
    for path in sorted(root.rglob("*")):
        rel = path.relative_to(root).as_posix()
        if not path.is_dir() and rel not in listed:
            changed.append(f"{rel} (not in manifest)")
    return changed


def foreign_files(stage_dir: str | os.PathLike) -> list[str]:
    """List the files of an existing stage folder that debist did not write there.

    Parameters
    ----------
    stage_dir : path-like
        The stage folder (need not exist).

    Returns
    -------
    list of str
        Paths relative to the folder: every file when the folder has no manifest (or an
        unreadable one), else the files its manifest does not list. Empty for a missing
        folder. Such a folder is never replaced.
    """
    root = Path(stage_dir)
    if not root.exists():
        return []
    if not root.is_dir():
        return ["."]
    try:
        manifest = read_manifest(root)
    except ArtifactError:
        manifest = None
    listed = set(manifest.outputs) | _UNLISTED if manifest is not None else set()
    return [
        path.relative_to(root).as_posix()
        for path in sorted(root.rglob("*"))
        if not path.is_dir() and path.relative_to(root).as_posix() not in listed
    ]


#: Name of a stage folder set aside by :func:`set_aside` (kept for the user, not verified).
SET_ASIDE = re.compile(r"[A-Za-z_]+\.damaged-[0-9a-f]{8}")


def set_aside(stage_dir: str | os.PathLike) -> Path:
    """Move a stage folder whose manifest is damaged out of the way, keeping every file.

    The folder is renamed to ``<stage>.damaged-<8 hex digits>`` beside it, so that the stage
    can be recomputed and nothing in it is lost or overwritten.

    Parameters
    ----------
    stage_dir : path-like
        The stage folder.

    Returns
    -------
    pathlib.Path
        Where the folder now is.

    References
    ----------
    POSIX ``rename(2)`` (one step on one file system).
    """
    root = Path(stage_dir)
    while True:
        target = root.with_name(f"{root.name}.damaged-{secrets.token_hex(4)}")
        if not target.exists():
            break
    root.rename(target)
    return target


def write_stage(
    stage_dir: str | os.PathLike,
    *,
    stage: str,
    key: str,
    code: str,
    versions: Mapping[str, str],
    config: Mapping[str, Any],
    inputs: Mapping[str, str],
    upstream: Mapping[str, str],
    outputs: Mapping[str, Any],
    summary: Mapping[str, Any] | None = None,
    timings: Mapping[str, float] | None = None,
) -> Manifest:
    """Write a stage's outputs, summary and manifest atomically.

    Parameters
    ----------
    stage_dir : path-like
        Final stage folder; replaced as a whole.
    stage, key, code : str
        Stage name, key and code fingerprint.
    versions : mapping of str to str
        Library versions.
    config : mapping
        Resolved configuration (stored in the manifest).
    inputs : mapping of str to str
        Input name to sha256.
    upstream : mapping of str to str
        Upstream stage to the sha256 of its manifest.
    outputs : mapping of str to object
        Relative output path to value (see :func:`debist.core.fileformats.write_output`).
    summary : mapping, optional
        Small JSON-compatible results for reports, written as ``summary.json``.
    timings : mapping of str to float, optional
        Wall times [s] of the stage's parts and in all (``stage``), for the unhashed
        ``timings.json``; this call's writing time is added as ``write``.

    Returns
    -------
    Manifest
        The manifest written, with its ``summary``.

    Raises
    ------
    OutputDirError
        If the existing stage folder holds files its manifest does not list (nothing is
        touched), an output name is not a relative path inside the stage folder, or the
        stage folder is a symbolic link.
    TypeError
        If an output has no writer. Nothing is left behind in that case.
    """
    final = Path(stage_dir)
    if final.is_symlink():
        raise OutputDirError(
            f"stage folder '{final}' is a symbolic link (to '{os.readlink(final)}'): debist "
            "writes its stages only as real folders inside the output folder; remove the link"
        )
    foreign = foreign_files(final)
    if foreign:
        raise OutputDirError(_foreign_message(final, foreign))
    if SUMMARY in outputs or MANIFEST in outputs or TIMINGS in outputs:
        raise TypeError(f"output names {SUMMARY}, {MANIFEST}, {TIMINGS} are reserved")
    started = time.perf_counter()
    tmp = _new_swap_folder(final)
    try:
        hashes = {}
        summary_json = json.dumps(
            json.loads(canonical_json(dict(summary or {}))), indent=2, sort_keys=True
        )
        for rel, value in [*sorted(outputs.items()), (SUMMARY, summary_json + "\n")]:
            path = inside(tmp, rel)
            write_output(value, path)
            hashes[rel] = sha256_file(path)
        manifest = Manifest(
            stage=stage,
            key=key,
            code=code,
            versions=dict(versions),
            config=json.loads(canonical_json(config)),
            inputs=dict(inputs),
            upstream=dict(upstream),
            outputs=hashes,
        )
        times = dict(timings or {})
        if times:
            times["write"] = time.perf_counter() - started
            if "stage" in times:
                times["stage"] += times["write"]
        (tmp / TIMINGS).write_text(json.dumps(times, indent=2) + "\n", encoding="utf-8")
        (tmp / MANIFEST).write_text(manifest.to_json(), encoding="utf-8")
        fault_point(f"swap:{stage}:written")
        _swap_into_place(tmp, final, stage)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return Manifest(**{**asdict(manifest), "summary": json.loads(summary_json)})


def adopt_stage(
    source_dir: str | os.PathLike, stage_dir: str | os.PathLike, *, stage: str, key: str
) -> Manifest | None:
    """Copy another run's stage folder that made this stage's exact computation, if it did.

    The copy is taken when ``source_dir`` holds a manifest with the same key (the same code,
    library versions, configuration, input and upstream hashes) and the copied outputs match
    the hashes of the copied manifest; it is written beside ``stage_dir`` and swapped into
    place as :func:`write_stage` does. Only the files the manifest lists (and the timings)
    are copied, each a regular file inside ``source_dir``.

    Parameters
    ----------
    source_dir : path-like
        The stage folder of the other run (only read).
    stage_dir : path-like
        This run's stage folder; nothing is adopted when it exists.
    stage, key : str
        The stage's name and its key in this run.

    Returns
    -------
    Manifest or None
        The copy's manifest, with its checked summary; None when nothing was adopted.
    """
    source, final = Path(source_dir), Path(stage_dir)
    if source.is_symlink() or not source.is_dir() or os.path.lexists(final):
        return None
    try:
        manifest = read_manifest(source)
    except ArtifactError:
        return None
    if manifest is None or manifest.key != key:
        return None
    tmp = _new_swap_folder(final)
    try:
        for rel in [*sorted(manifest.outputs), TIMINGS, MANIFEST]:
            path = inside(source, rel)
            if path.is_symlink() or not path.is_file():
                if rel == TIMINGS:
                    continue
                raise OutputDirError(f"'{path}' is not a regular file")
            target = inside(tmp, rel)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, target)
        copied = read_manifest(tmp)
        if copied is None or copied.key != key or changed_outputs(tmp, copied):
            raise OutputDirError(f"'{source}' changed while it was copied")
        summary = read_summary(tmp, copied)
        _swap_into_place(tmp, final, stage)
    except (OSError, DebistError):
        shutil.rmtree(tmp, ignore_errors=True)
        return None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return replace(copied, summary=summary)


def inside(folder: Path, rel: str) -> Path:
    """Return ``folder / rel`` if it stays inside ``folder`` (relative, no ``..``), else refuse it.

    Parameters
    ----------
    folder : pathlib.Path
        The folder every write must stay in.
    rel : str
        A relative path from input or a stage (hostile until checked).

    Returns
    -------
    pathlib.Path

    Raises
    ------
    OutputDirError
        For an absolute path, ``..`` or ``.`` parts, a NUL byte, or a path that resolves
        (through symlinks) outside ``folder``.
    """
    parts = Path(rel).parts
    path = folder / rel
    if (
        not parts
        or Path(rel).is_absolute()
        or any(p in ("..", ".") or "\x00" in p for p in parts)
        or not path.resolve().is_relative_to(folder.resolve())
    ):
        raise OutputDirError(
            f"output {rel!r} would be written outside its stage folder '{folder}': refused"
        )
    return path


@contextmanager
def _signals_held() -> Iterator[None]:
    """Defer SIGINT and SIGTERM until the block ends (main thread; elsewhere a no-op).

    Python runs signal handlers in the main thread, whichever thread the OS delivered the
    signal to, so replacing the handlers there defers a signal reliably (a thread's signal
    mask does not: another thread of the process, e.g. a BLAS worker, may receive it). A
    deferred signal is handed to the previous handler when the block ends.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    previous = {
        s: signal.signal(s, lambda signum, _frame: pending.append(signum)) for s in _SIGNALS
    }
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        for s in pending:
            handler = previous[s]
            if callable(handler):
                handler(s, None)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(s)


def remove_tree(path: str | os.PathLike) -> None:
    """Remove a folder debist wrote, or a symbolic link or file in its place (never a target).

    Parameters
    ----------
    path : path-like
        A stage folder, a swap leftover, or a link that replaced one.
    """
    path = Path(path)
    if path.is_symlink() or not path.is_dir():
        path.unlink(missing_ok=True)
    else:
        shutil.rmtree(path)


def _new_swap_folder(final: Path) -> Path:
    """Create the temporary folder a stage folder is written in, beside it (SWAP_FOLDER)."""
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.parent / f".{final.name}.tmp-{secrets.token_hex(6)}"
    os.mkdir(tmp)  # mode 0o777 less the umask, unlike tempfile.mkdtemp's 0o700
    return tmp


def _swap_into_place(tmp: Path, final: Path, stage: str) -> None:
    with _signals_held():
        old = None
        if os.path.lexists(final):
            old = final.parent / f".{final.name}.old-{secrets.token_hex(6)}"
            os.replace(final, old)
            fault_point(f"swap:{stage}:moved-old")
        os.replace(tmp, final)
        fault_point(f"swap:{stage}:moved-new")
        if old is not None:
            remove_tree(old)


def _foreign_message(folder: Path, files: Sequence[str]) -> str:
    shown = ", ".join(f"'{f}'" for f in files[:5])
    more = f" and {len(files) - 5} more" if len(files) > 5 else ""
    return (
        f"stage folder '{folder}' holds files debist did not write: {shown}{more}; "
        "move them elsewhere (debist never deletes a file it did not write)"
    )


def foreign_message(folder: str | os.PathLike, files: Sequence[str]) -> str:
    """Return the message that names the foreign files of a stage folder.

    Parameters
    ----------
    folder : path-like
        The stage folder.
    files : sequence of str
        Its foreign files (:func:`foreign_files`).

    Returns
    -------
    str
        One line naming the folder and up to five files.
    """
    return _foreign_message(Path(folder), files)


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
    OutputDirError
        If a file of that name exists already: nothing a user has is overwritten, and
        nothing is written.
    """
    final = Path(folder)
    final.mkdir(parents=True, exist_ok=True)
    existing = [name for name in files if (final / name).exists()]
    if existing:
        raise OutputDirError(
            f"'{final / existing[0]}' exists ({len(existing)} file(s) in all): choose another "
            "folder or remove them"
        )
    written: list[Path] = []
    try:
        for name, text in files.items():
            try:  # a file that appeared meanwhile is kept, never replaced
                written.append(atomic_write(inside(final, name), text, replace=False))
            except FileExistsError:
                raise OutputDirError(
                    f"'{final / name}' exists: choose another folder or remove it"
                ) from None
    except BaseException:
        for path in written:  # all new files (checked above): take them back
            path.unlink(missing_ok=True)
        raise
    return written
