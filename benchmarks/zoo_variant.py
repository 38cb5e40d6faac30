"""Regenerate one plant-zoo member with parts of its rig changed: an ablation of the zoo.

The member is drawn as ``debist zoo`` draws it (seed, index and attempt from its
``truth.json``), the given keys of its rig table are replaced, and the member is simulated
and written as the zoo writes it (logs, minimal workflow, truth) into ``<dir>/<name>``. With
no change the logs are those of the zoo's own member, so a difference in what debist
identifies comes from the change alone. Used for docs/results "Where the gains' bias at the
wells comes from": e.g. a point-sampled laser without lag, no Maxwell-slip elements, no creep.

Run from the repository root, then ``debist run`` the member's workflow::

    python benchmarks/zoo_variant.py --seed 1 --index 0 --dir ideal \\
        --set plant.sensor_average=1 --set plant.sensor_lag=0 \\
        --set 'plant.friction_F=[]' --set 'plant.friction_k=[]' --set plant.friction_c=0.06 \\
        --set prototype.Y_MW=1.0

A value is read as TOML (``[]``, ``0.06``, ``"full"``); the keys are those of the member's
``truth.json`` ``rig`` table (``plant``, ``prototype``, ``experiments``).

References
----------
Masoud & Maas 2025, Sec. 3 and 5.1 (the plant and the rig the zoo draws from).
"""

from __future__ import annotations

import argparse
import copy
import tomllib
from dataclasses import replace
from pathlib import Path

from debist.engine import zoo
from debist.rig.zoo import draw_member


def _override(rig: dict, setting: str) -> None:
    """Set ``section.key=value`` (value in TOML) in the member's rig table."""
    key, _, text = setting.partition("=")
    section, _, name = key.partition(".")
    if not name or section not in rig:
        raise SystemExit(f"--set {setting!r}: expected <{'|'.join(rig)}>.<key>=<value>")
    rig[section][name] = tomllib.loads(f"v = {text}")["v"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, required=True, help="the zoo's seed")
    ap.add_argument("--index", type=int, required=True, help="the member's index (m007: 7)")
    ap.add_argument("--attempt", type=int, default=0, help="the draw (truth.json zoo.attempt)")
    ap.add_argument("--dir", type=Path, required=True, help="folder to write the member into")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = ap.parse_args()
    member = draw_member(args.seed, args.index, args.attempt)
    rig = copy.deepcopy(member.rig)
    for setting in args.set:
        _override(rig, setting)
    try:
        member, cfg, runs, statics = zoo.simulate_member(replace(member, rig=rig))
    except zoo.ZooError as exc:
        raise SystemExit(f"{member.name}: {exc}") from None
    args.dir.mkdir(parents=True, exist_ok=True)
    zoo.write_member(args.dir, member, cfg, runs, statics)
    print(args.dir / member.name)


if __name__ == "__main__":
    main()
