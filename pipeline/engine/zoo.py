"""Write a plant zoo: per member its rig logs, a minimal workflow and its truth.

``debist zoo --size N --seed S --dir D`` draws members with :func:`debist.rig.zoo.draw_member`,
simulates each one's records on the virtual rig and writes ``D/<member>/``:

- ``estimation.mat``, ``unseen_1.mat``, ``unseen_2.mat``: dSPACE ControlDesk recordings;
- ``workflow.toml``: channels, units, the input map and the data-set roles, nothing else;
- ``truth.json``: the plant's parameters (SI), the records (profile, length, measurement
  floor), the wells and the barrier;
- ``truth.parquet``: ``q`` [m] on a 0.05 mm grid over the visited range in the logged
  coordinate, ``restoring`` [m/s^2], ``g1``, ``g2`` [m/(s^2 V^2)] per unit mass (the
  plant's ``m_q(q)``), and ``m_q`` [kg]: the quantities of ``identify/curves.parquet`` with
  ``m_q = 1``.

A member is written to a scratch folder and moved into place whole; ``D/zoo.json`` lists the
members. It is written first, marked unfinished, and marked finished when every member is
there: a zoo stopped part way (Ctrl-C, SIGTERM, a kill) is recognised as such, ``debist batch``
refuses it naming the command that finishes it, and rerunning with the same seed keeps the
members present and adds the missing ones; nothing a user has is overwritten.

References
----------
Masoud & Maas 2025, Eq. 37 (the curves), Eq. 41 (NRMSE), Sec. 5.1 (rig).
"""

from __future__ import annotations

import json
import os
import re
import secrets
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from debist.core import progress
from debist.core.artifacts import remove_tree
from debist.core.errors import OutputDirError
from debist.core.fileformats import atomic_write, canonical_json, write_output
from debist.core.metrics import nrmse
from debist.engine.zooindex import MEMBER_WORKFLOW, ZOO_FILE, ZooError, read_zoo
from debist.rig.config import RigConfig
from debist.rig.dspace import write_recording
from debist.rig.experiment import CREATED, rig_recording, run_experiments
from debist.rig.run import RigRun, true_curves
from debist.rig.visited import rest_points
from debist.rig.zoo import ZOO_VERSION, ZooMember, draw_member, member_ok, sub_threshold

__all__ = ["ZooResult", "member_workflow", "simulate_member", "write_member", "write_zoo"]

#: Draws tried per member before the zoo gives up.
MAX_ATTEMPTS = 12
#: Spacing of the truth grid [m].
TRUTH_STEP = 0.05e-3


@dataclass(frozen=True)
class ZooResult:
    """What :func:`write_zoo` did.

    Attributes
    ----------
    folder : pathlib.Path
        The zoo's folder.
    members : tuple of str
        Member names, in index order.
    written : tuple of str
        Members written by this call (the others were there already).
    rejected : dict of str to list of str
        Per member, why earlier draws were rejected.
    """

    folder: Path
    members: tuple[str, ...]
    written: tuple[str, ...]
    rejected: dict[str, list[str]] = field(default_factory=dict)


def member_workflow(member: ZooMember) -> str:
    """Return a member's minimal workflow: channels, units, input map, data-set roles.

    Parameters
    ----------
    member : ZooMember
        The member.

    Returns
    -------
    str
        TOML text; the data sets point at ``<record>.mat`` beside it and the output folder
        is ``run`` beside it.
    """
    lines = [
        f"# Zoo member {member.name} of seed {member.seed} (debist zoo): channels, units,",
        "# the input map and the data-set roles; every other setting is debist's default.",
        "",
        "[workflow]",
        f'name = "zoo-{member.seed}-{member.name}"',
        'output_dir = "run"',
        "",
        "[ingest]",
        'q = { regex = "Laser/q$", unit = "mm" }',
        'v1 = { regex = "DE1/v_mon$", unit = "kV" }',
        'v2 = { regex = "DE2/v_mon$", unit = "kV" }',
        "",
        "[identify]",
        'input_map = "v2"',
    ]
    for name, role in member.roles.items():
        lines += ["", f"[datasets.{name}]", f'source = "{name}.mat"', f'role = "{role}"']
    return "\n".join(lines) + "\n"


def _with_sub_threshold(member: ZooMember, v_sub: float) -> ZooMember:
    rig = json.loads(json.dumps(member.rig))
    for exp in rig["experiments"].values():
        exp["v_sub"] = float(np.round(v_sub, 1))
    return replace(member, rig=rig, traits={**member.traits, "v_sub": float(np.round(v_sub, 1))})


def _record_problem(member: ZooMember, runs: dict[str, RigRun], barrier: float) -> str | None:
    """Why a member's simulated records are unusable (None if they are not)."""
    rig = member.rig_params()
    for name, run in runs.items():
        if not run.success:
            return f"{name}: the plant integration failed ({run.message})"
        if np.any(np.abs(run.q_true + rig.sensor_offset) >= 0.98 * rig.sensor_range):
            return f"{name}: q leaves the laser's range"
    side = np.sign(runs["estimation"].q_true - barrier)
    if not (np.any(side > 0) and np.any(side < 0)):
        return "estimation: the beam never leaves its well"
    return None


def simulate_member(member: ZooMember) -> tuple[ZooMember, RigConfig, dict[str, RigRun], dict]:
    """Simulate a drawn member's records, its sub-threshold level set from its statics.

    Parameters
    ----------
    member : ZooMember
        A draw (:func:`debist.rig.zoo.draw_member`), possibly with its ``rig`` table changed.

    Returns
    -------
    member : ZooMember
        The member with its sub-threshold level ``v_sub`` [V] in every experiment.
    cfg : RigConfig
        Its rig.
    runs : dict of str to RigRun
        Its simulated records, by experiment name.
    statics : dict
        ``wells`` and ``barrier`` of the restoring force at v = 0 [m].

    Raises
    ------
    ZooError
        If the restoring force has no barrier or a record is unusable (the reason named).

    References
    ----------
    Masoud & Maas 2025, Sec. 3, 5.1.
    """
    member = _with_sub_threshold(member, sub_threshold(member.rig_params()))
    cfg = RigConfig.from_dict(member.rig, {})
    wide = true_curves(cfg.rig, np.linspace(-20e-3, 20e-3, 801))
    try:
        wells, barrier = rest_points(wide["q"], wide["f"])
    except ValueError:
        raise ZooError("the restoring force has no barrier") from None
    with progress.listening(None):
        runs, _ = run_experiments(cfg)
    problem = _record_problem(member, runs, barrier)
    if problem is not None:
        raise ZooError(problem)
    return member, cfg, runs, {"wells": wells, "barrier": barrier}


def _simulate(seed: int, index: int) -> tuple[ZooMember, RigConfig, dict, dict, list[str]]:
    """Draw member ``index`` until its statics and its records are usable; simulate it."""
    rejected: list[str] = []
    for attempt in range(MAX_ATTEMPTS):
        member = draw_member(seed, index, attempt)
        if not member_ok(member.rig_params()):
            rejected.append(f"draw {attempt}: not bistable and switchable at 3 kV")
            continue
        try:
            return (*simulate_member(member), rejected)
        except ZooError as exc:
            rejected.append(f"draw {attempt}: {exc}")
    raise ZooError(
        f"zoo seed {seed}: member {index} has no viable draw in {MAX_ATTEMPTS} "
        f"({'; '.join(rejected[-3:])})"
    )


def _truth_frame(cfg: RigConfig, runs: dict[str, RigRun]) -> Any:
    """Truth curves per unit mass over the visited range, in the logged coordinate."""
    import pandas as pd

    offset = cfg.rig.sensor_offset
    q_all = np.concatenate([r.q_true for r in runs.values()]) + offset
    lo = np.floor(q_all.min() / TRUTH_STEP) * TRUTH_STEP
    hi = np.ceil(q_all.max() / TRUTH_STEP) * TRUTH_STEP
    q = np.round(np.arange(lo, hi + 0.5 * TRUTH_STEP, TRUTH_STEP), 9)
    c = true_curves(cfg.rig, q - offset)
    frame = pd.DataFrame(
        {
            "q": q,
            "restoring": c["f"] / c["m_q"],
            "g1": c["g1"] / c["m_q"],
            "g2": c["g2"] / c["m_q"],
            "m_q": c["m_q"],
        }
    )
    frame.attrs = {
        "units": {"q": "m", "restoring": "m/s^2", "g1": "m/(s^2 V^2)", "g2": "m/(s^2 V^2)",
                  "m_q": "kg"},
        "coordinate": "logged q: the tip displacement plus the laser's zero offset",
        "per": "unit mass: each force over the plant's m_q(q)",
        "model": cfg.rig.model,
    }  # fmt: skip
    return frame


def _truth_json(member: ZooMember, cfg: RigConfig, runs: dict[str, RigRun], statics: dict) -> str:
    offset = cfg.rig.sensor_offset
    records = {}
    for name, run in runs.items():
        exp = cfg.experiments[name]
        q_true = run.q_true + offset
        side = np.sign(run.q_true - statics["barrier"])
        records[name] = {
            "role": member.roles[name],
            "profile": member.traits["estimation_profile"] if name == "estimation"
            else member.traits["unseen_profiles"][int(name[-1]) - 1],
            "duration": exp.duration,
            "samples": int(run.t.size),
            "floor_nrmse_q": 100.0 * nrmse(run.q, q_true),
            "well_changes": int(np.count_nonzero(np.diff(side[side != 0]))),
        }  # fmt: skip
    truth = {
        "zoo": {"version": ZOO_VERSION, "seed": member.seed, "index": member.index,
                "attempt": member.attempt, "name": member.name},
        "traits": member.traits,
        "rig": member.rig,
        "plant": cfg.rig.to_dict(),
        "records": records,
        "wells": [float(w) + offset for w in statics["wells"]],
        "barrier": float(statics["barrier"]) + offset,
        "units": "SI; NRMSE in percent (Eq. 41, logged q against true q)",
        "truth_curves": "truth.parquet: per unit mass, over the logged coordinate",
    }  # fmt: skip
    return json.dumps(json.loads(canonical_json(truth)), indent=1, sort_keys=True) + "\n"


def write_member(folder: Path, member: ZooMember, cfg, runs, statics) -> None:
    """Write a member into a scratch folder beside its place, then move it there whole.

    Parameters
    ----------
    folder : Path
        The zoo folder; the member goes to ``folder / member.name``.
    member, cfg, runs, statics
        As :func:`simulate_member` returns them.

    Raises
    ------
    OSError
        If the member's folder exists and is not empty, or cannot be written (the scratch folder is
        removed; nothing is left behind).
    """
    final = folder / member.name
    tmp = folder / f".{member.name}.{secrets.token_hex(4)}.tmp"
    tmp.mkdir()
    try:
        for name, run in runs.items():
            write_recording(tmp / f"{name}.mat", rig_recording(run, name, cfg),
                            version=cfg.experiments[name].format, created=CREATED)  # fmt: skip
        write_output(_truth_frame(cfg, runs), tmp / "truth.parquet")
        atomic_write(tmp / "truth.json", _truth_json(member, cfg, runs, statics))
        atomic_write(tmp / MEMBER_WORKFLOW, member_workflow(member))
        os.rename(tmp, final)
    except BaseException:
        remove_tree(tmp)
        raise


#: A member's scratch folder (:func:`write_member`), left behind only by a killed process.
_SCRATCH = re.compile(r"\.m\d{3}\.[0-9a-f]{8}\.tmp")


def _unindexed_zoo(folder: Path, seed: int) -> dict[str, Any] | None:
    """Index a zoo stopped before it wrote ``zoo.json`` (by an older debist), else None.

    Such a folder holds only complete member folders (``m000``, ...) of this seed and version,
    by their ``truth.json``, and scratch folders.
    """
    names = []
    for entry in folder.iterdir():
        if entry.name.startswith("."):  # scratch folders; hidden files are not looked at
            continue
        try:
            zoo = json.loads((entry / "truth.json").read_text(encoding="utf-8"))["zoo"]
        except (OSError, ValueError, KeyError, TypeError):
            return None
        if zoo != {**zoo, "seed": seed, "version": ZOO_VERSION, "name": entry.name}:
            return None
        names.append(entry.name)
    names.sort()
    return {"version": ZOO_VERSION, "seed": seed, "size": len(names), "members": names}


def _check_folder(folder: Path, seed: int) -> dict[str, Any] | None:
    """Return the folder's zoo index if it is a zoo of this seed, None if new; else refuse."""
    index = read_zoo(folder)
    if index is None:
        if folder.exists() and any(p for p in folder.iterdir() if not p.name.startswith(".")):
            index = _unindexed_zoo(folder, seed)
            if index is not None:
                return index
            raise OutputDirError(
                f"'{folder}' holds files and is not a zoo: choose an empty or new folder "
                "(debist never overwrites a user's files)"
            )
        return None
    if index.get("seed") != seed or index.get("version") != ZOO_VERSION:
        raise OutputDirError(
            f"'{folder}' holds a zoo of seed {index.get('seed')} (version "
            f"{index.get('version')}), not seed {seed} (version {ZOO_VERSION}): choose "
            "another folder"
        )
    return index


def write_zoo(folder: str | os.PathLike, size: int, seed: int) -> ZooResult:
    """Write a plant zoo of ``size`` members drawn from ``seed`` into ``folder``.

    Parameters
    ----------
    folder : path-like
        The zoo's folder: new, empty, or a zoo of the same seed (its members are kept,
        missing ones added).
    size : int
        Members (>= 1).
    seed : int
        The zoo's seed (>= 0).

    Returns
    -------
    ZooResult

    Raises
    ------
    ValueError
        For ``size < 1`` or a negative seed.
    OutputDirError
        If the folder holds other files, or a zoo of another seed.
    ZooError
        If a member has no viable draw (the members written before it stay, and the zoo
        stays marked unfinished).

    References
    ----------
    Masoud & Maas 2025, Sec. 3, 5.1.
    """
    if size < 1 or seed < 0:
        raise ValueError(f"zoo size must be >= 1 and seed >= 0, got {size} and {seed}")
    folder = Path(folder)
    index = _check_folder(folder, seed)
    folder.mkdir(parents=True, exist_ok=True)
    for entry in folder.iterdir():  # the scratch folder of a member being written when killed
        if _SCRATCH.fullmatch(entry.name) and entry.is_dir():
            remove_tree(entry)
    names = [f"m{i:03d}" for i in range(max(size, index["size"] if index else 0))]
    info = {"version": ZOO_VERSION, "seed": seed, "size": len(names), "members": names}
    if index != {**info, "complete": True}:  # unfinished until every member is there
        atomic_write(folder / ZOO_FILE, json.dumps({**info, "complete": False}, indent=1) + "\n")
    written, rejected = [], {}
    task = "zoo: members"
    progress.report(task, 0, size)
    for i in range(size):
        name = names[i]
        if (folder / name / "truth.json").is_file():
            progress.report(task, i + 1, size)
            continue
        if (folder / name).exists():
            raise OutputDirError(f"'{folder / name}' exists but is not a complete zoo member")
        member, cfg, runs, statics, why = _simulate(seed, i)
        write_member(folder, member, cfg, runs, statics)
        written.append(name)
        if why:
            rejected[name] = why
        progress.report(task, i + 1, size)
    # the members there without a gap: those asked for, and any further ones of earlier runs
    present = next((k for k, n in enumerate(names) if not (folder / n / "truth.json").is_file()),
                   len(names))  # fmt: skip
    info = {**info, "size": present, "members": names[:present], "complete": True}
    atomic_write(folder / ZOO_FILE, json.dumps(info, indent=1) + "\n")
    return ZooResult(folder, tuple(names[:size]), tuple(written), rejected)
