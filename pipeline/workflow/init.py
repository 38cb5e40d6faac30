"""A first workflow from a lab's own rig logs: what ``debist init`` writes.

:func:`init_workflow` surveys the files (:func:`debist.ingest.survey.survey_file`), maps
their channels to ``time``, ``q``, ``v1``, ``v2`` (:func:`debist.ingest.survey.guess_mapping`,
or as the user says), and writes a minimal, commented workflow: the first file is the
estimation data set, the others validation data sets; ``[ingest]`` holds the first file's
channels and each other file overrides only the channels it names differently; a
``[report]`` table makes ``debist run`` write the report. Every other setting is debist's
default. Before anything is written the text is parsed back, checked like any workflow
(:func:`debist.workflow.schema.check_workflow`) and every file is ingested with it
(:func:`debist.ingest.load.load_rig_log`), so the workflow written is one that runs.

Values are written by tomli-w (file and channel names are arbitrary text: quotes, newlines,
brackets); comments hold only debist's own words. Paths in the workflow are relative to
its folder, as :func:`debist.workflow.loader.load_workflow` resolves them.

References
----------
TOML v1.0.0 (https://toml.io/en/v1.0.0): strings and inline tables; tomli-w
(https://github.com/hukkin/tomli-w), the writer.
"""

from __future__ import annotations

import os
import re
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from debist.core.arguments import check_path_text, check_regular_file
from debist.core.errors import RigLogError, WorkflowError
from debist.core.fileformats import atomic_write
from debist.core.names import is_file_name
from debist.core.units import lookup_unit
from debist.ingest.cache import RawLogCache
from debist.ingest.load import load_rig_log, read_raw
from debist.ingest.sensors import default_range, known_sensor
from debist.ingest.spec import IngestSpec
from debist.ingest.survey import (
    Mapping,
    MappingRequest,
    guess_mapping,
    role_kind,
    survey_file,
)
from debist.workflow.schema import check_workflow

__all__ = ["DEFAULT_OUT", "InitDataSet", "InitResult", "init_workflow", "toml_value"]

#: The workflow file :func:`init_workflow` writes without ``out``: in the working folder.
DEFAULT_OUT = "debist.toml"
#: Column of the comments beside the values.
_COMMENT_AT = 44
_CHANGE = (
    "change the mapping with --time NAME, --q NAME, --v NAME (once per input, v1 first), "
    "--unit ROLE=UNIT (e.g. q=mm, v=kV), or edit the file"
)


@dataclass(frozen=True)
class InitDataSet:
    """One data set of the written workflow.

    Attributes
    ----------
    name : str
        Its ``[datasets.<name>]`` key (from the file name, made a plain file name).
    role : {"estimation", "validation"}
        The first file estimates, the others validate.
    source : str
        The file as the workflow names it: relative to the workflow's folder.
    mapping : debist.ingest.survey.Mapping
        Its channels and what maps to ``time``, ``q``, ``v1``, ...
    """

    name: str
    role: str
    source: str
    mapping: Mapping


@dataclass(frozen=True)
class InitResult:
    """What :func:`init_workflow` wrote.

    Attributes
    ----------
    path : pathlib.Path
        The workflow file.
    text : str
        Its content (TOML).
    datasets : tuple of InitDataSet
        The estimation data set, then the validation data sets, in the order given.
    advice : str
        How to change the mapping (the options of ``debist init``).
    """

    path: Path
    text: str
    datasets: tuple[InitDataSet, ...]
    advice: str = _CHANGE


def toml_value(value: Any) -> str:
    r"""Write one TOML value (string, number, boolean, array) or inline table with tomli-w.

    Parameters
    ----------
    value : str, int, float, bool, list or dict
        A dict becomes an inline table of its items (keys must be bare keys).

    Returns
    -------
    str
        The value as TOML text on one line, strings quoted and escaped.

    Examples
    --------
    >>> print(toml_value('a "b"\n]'))
    "a \"b\"\n]"
    >>> toml_value({"name": "x", "unit": "mm", "range": [-25.0, 25.0]})
    '{ name = "x", unit = "mm", range = [-25.0, 25.0] }'
    """
    import tomli_w

    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, list):  # on one line (tomli-w breaks arrays over lines)
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return tomli_w.dumps({"v": value}).partition(" = ")[2].rstrip("\n")


def _line(text: str, comment: str = "") -> str:
    if not comment:
        return text
    return f"{text.ljust(_COMMENT_AT - 1)} # {comment}"


def _dataset_names(paths: Sequence[Path]) -> list[str]:
    """Name each file's data set: a plain, unique key from the file name up to its first dot."""
    names: list[str] = []
    for i, path in enumerate(paths):
        stem = re.sub(r"[^A-Za-z0-9_-]+", "_", path.name.split(".")[0]).strip("_")[:60]
        if not is_file_name(stem):
            stem = "estimation" if i == 0 else "validation"
        name, k = stem, 2
        while name in names:
            name, k = f"{stem}_{k}", k + 1
        names.append(name)
    return names


def _source(path: Path, out: Path) -> str:
    """Name a file relative to the workflow's folder, as the loader resolves it back.

    The path as given is kept when it resolves to the same file from the resolved folder
    (no symbolic link in between changes what ``..`` means), else the resolved path is
    used; absolute when the two are on different drives (Windows).
    """
    folder = out.parent.resolve()
    for a, b in ((os.path.abspath(path), os.path.abspath(out.parent)), (path.resolve(), folder)):
        try:
            rel = Path(os.path.relpath(a, b)).as_posix()
        except ValueError:  # another drive
            continue
        if (folder / rel).resolve() == path.resolve():
            return rel
    return path.resolve().as_posix()


def _channel_comment(guess) -> str:
    check = ": check it" if guess.assumed else ""
    return f"{guess.why}; unit {guess.unit_why}{check}"


def _ranged(guess) -> tuple[dict[str, Any], str]:
    """Return a channel's table, with its sensor's documented ``range`` for ``q``, and why.

    ``q``'s measuring range makes ingest refuse (or split at) samples at the sensor's limits:
    the range of a known sensor (:func:`debist.ingest.sensors.default_range`) is written in
    the recorded unit; for another sensor the comment asks for one.
    """
    table = guess.table()
    if guess.role != "q":
        return table, ""
    unit = lookup_unit(guess.unit)
    found = None if unit is None else default_range(guess.channel.name, unit.si, unit.factor)
    if found is None:
        return table, "no documented range known for this sensor: add range = [lo, hi]"
    lo, hi, _note = found
    sensor = known_sensor(guess.channel.name, unit.si)
    why = f"range: the {sensor.name}'s, {sensor.lo:g} to {sensor.hi:g} {sensor.unit} (datasheet)"
    return {**table, "range": [round(lo, 9), round(hi, 9)]}, why


def render(name: str, datasets: Sequence[InitDataSet], sample_time: float | None) -> str:
    """Write the workflow's text: comments in debist's words, values by tomli-w.

    Parameters
    ----------
    name : str
        The workflow's name (a plain file name: its output folder is ``runs/<name>``).
    datasets : sequence of InitDataSet
        The estimation data set first.
    sample_time : float or None
        [s] written to ``[ingest]`` when given.

    Returns
    -------
    str
        TOML text.
    """
    first = datasets[0].mapping
    n_files = len(datasets)
    lines = [
        f"# A debist workflow written by `debist init` from {n_files} rig log(s): the first is",
        "# the estimation data set, the others are validation data sets (free runs, never fitted).",
        "# Paths are relative to this file. Check the channel mapping in [ingest]: the comment",
        "# beside each channel says what the guess rests on. Every setting not written here is",
        "# debist's default (docs/reference/workflow-keys.md). Run it with: debist run <this file>",
        "",
        "[workflow]",
        _line(f"name = {toml_value(name)}"),
        _line(
            f"output_dir = {toml_value(f'runs/{name}')}", "artifacts and report, beside this file"
        ),
        "",
        _line("[ingest]", "the first file's channels, units as recorded"),
    ]
    if sample_time is not None:
        lines.append(_line(f"sample_time = {toml_value(sample_time)}", "[s] given: --sample-time"))
    if first.survey.time_bases and not any(g.role == "time" for g in first.guesses):
        lines.append("# time: the recording's own time base")
    for guess in first.guesses:
        table, why = _ranged(guess)
        comment = "; ".join(c for c in (_channel_comment(guess), why) if c)
        lines.append(_line(f"{guess.role} = {toml_value(table)}", comment))
    lines += [
        "",
        "[identify]",
        _line('input_map = "v2"', 'h(v) = v^2, a DE\'s force; "v" for a rig linear in v'),
    ]
    base = {g.role: _ranged(g)[0] for g in first.guesses}
    for ds in datasets:
        lines += ["", f"[datasets.{ds.name}]", f"source = {toml_value(ds.source)}"]
        lines.append(f"role = {toml_value(ds.role)}")
        for guess in ds.mapping.guesses:
            table, why = _ranged(guess)
            if base.get(guess.role) != table:
                text = f"{guess.role} = {toml_value(table)}"
                comment = "; ".join(c for c in (_channel_comment(guess), why) if c)
                lines.append(_line(text, "its own: " + comment))
    lines += ["", _line("[report]", "<output_dir>/report/report.html after each run"), ""]
    return "\n".join(lines)


def _verify(text: str, datasets: Sequence[InitDataSet], folder: Path, cache) -> None:
    """Parse the text back, check it as a workflow and ingest every file with it."""
    raw = tomllib.loads(text)
    check_workflow(raw)
    for ds in datasets:
        table = raw["datasets"][ds.name]
        path = ds.mapping.survey.path
        if (folder / table["source"]).resolve() != path.resolve():  # pragma: no cover
            raise AssertionError(f"the source of [datasets.{ds.name}] does not name '{path}'")
        ingest = {
            **raw["ingest"],
            **{k: v for k, v in table.items() if k not in ("source", "role")},
        }
        spec = IngestSpec.from_dict(ingest, where=f"[datasets.{ds.name}]")
        try:
            load_rig_log(path, spec, cache)
        except RigLogError as exc:
            raise RigLogError(f"{exc} (with the mapping debist init chose; {_CHANGE})") from None


def _check_out(out: Path, paths: Sequence[Path], force: bool) -> None:
    if out.is_dir():
        raise WorkflowError(f"--out '{out}' is a folder: give the workflow file to write")
    if any(out.resolve() == p.resolve() for p in paths):
        raise WorkflowError(f"--out '{out}' is one of the rig logs: give another file name")
    if os.path.lexists(out) and not force:
        raise _exists(out)


def _exists(out: Path) -> WorkflowError:
    return WorkflowError(
        f"'{out}' exists: debist init never overwrites a file (choose another --out, "
        "or pass --force to replace it)"
    )


def init_workflow(
    data: Sequence[str | os.PathLike[str]],
    out: str | os.PathLike[str] | None = None,
    *,
    force: bool = False,
    request: MappingRequest | None = None,
) -> InitResult:
    r"""Write a minimal workflow for a lab's own rig logs (``debist init``).

    Parameters
    ----------
    data : sequence of path-like
        Rig logs, at least one: the first the estimation data set, the others validation.
    out : path-like, optional
        The workflow file to write (its folder created); default :data:`DEFAULT_OUT`.
    force : bool, optional
        Replace an existing ``out`` (never one of the rig logs).
    request : MappingRequest, optional
        Channels and units that replace the guess, for every file.

    Returns
    -------
    InitResult
        The file written, its text and each data set's channel mapping.

    Raises
    ------
    WorkflowError
        No file; a FIFO, socket or device, or a name this locale cannot encode, among the
        files or as ``out``; ``out`` exists (without ``force``; also when it appeared while
        init ran: it is never replaced then), is a folder or a rig log; a channel
        that cannot be guessed or is missing (naming file, channels and option); files with
        different numbers of inputs.
    RigLogError
        A rig log that cannot be read, or does not ingest with the chosen mapping.
    OSError
        The workflow cannot be written (nothing is left then).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     log = Path(tmp) / "run 1.csv"
    ...     rows = "".join(f"{k / 100},{k % 7},{k % 3}\n" for k in range(50))
    ...     _ = log.write_text("time_s,laser [mm],HV1 [kV]\n" + rows)
    ...     done = init_workflow([log], Path(tmp) / "rig.toml")
    ...     [(g.role, g.channel.name, g.unit) for g in done.datasets[0].mapping.guesses]
    [('time', 'time_s', 's'), ('q', 'laser [mm]', 'mm'), ('v1', 'HV1 [kV]', 'kV')]
    """
    paths = [Path(p) for p in data]
    if not paths:
        raise WorkflowError("debist init: give at least one rig log (the estimation data)")
    out = Path(DEFAULT_OUT if out is None else out)
    for path in paths:
        check_regular_file(path, "rig log")
        check_path_text(path, "rig log")
    check_path_text(out.absolute(), "--out")
    _check_out(out, paths, force)
    request = request or MappingRequest()
    cache = RawLogCache(read_raw)
    mappings = [guess_mapping(survey_file(p, cache), request) for p in paths]
    peaks: dict[str, float] = {}
    for guess in (g for m in mappings for g in m.guesses if g.assumed):
        kind = role_kind(guess.role)
        peaks[kind] = max(peaks.get(kind, 0.0), guess.channel.peak)
    if len(mappings) > 1 and peaks:  # one assumed unit per role for every file
        mappings = [guess_mapping(m.survey, request, peaks) for m in mappings]
    n_inputs = [sum(g.role.startswith("v") for g in m.guesses) for m in mappings]
    for path, n in zip(paths[1:], n_inputs[1:], strict=True):
        if n != n_inputs[0]:
            raise WorkflowError(
                f"file '{path}': {n} input(s), but the estimation file '{paths[0]}' has "
                f"{n_inputs[0]}; pass --v NAME once per input"
            )
    datasets = tuple(
        InitDataSet(name, "estimation" if i == 0 else "validation", _source(m.survey.path, out), m)
        for i, (name, m) in enumerate(zip(_dataset_names(paths), mappings, strict=True))
    )
    stem = re.sub(r"[^A-Za-z0-9_-]+", "_", out.name.split(".")[0]).strip("_")[:60]
    text = render(stem if is_file_name(stem) else "debist", datasets, request.sample_time)
    _verify(text, datasets, out.parent.resolve(), cache)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:  # without force, a file that appeared at out meanwhile is kept, never replaced
        atomic_write(out, text, replace=force)
    except FileExistsError:
        raise _exists(out) from None
    return InitResult(out, text, datasets)
