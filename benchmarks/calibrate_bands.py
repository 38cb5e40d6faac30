"""Calibrate the identified curves' bands and masks against the virtual rig's known truth.

For each plant (the full Ritz model of ``workflows/paper-experiment.toml`` and the reduced
model of ``workflows/paper-experiment-reduced.toml``) a fleet of prototypes is generated
(``debist fleet``), run with debist's defaults (``debist batch``), and every curve that
debist marks identified is compared with the truth the rig wrote
(``rig/identification_truth.h5``):

- error where marked: the largest and the median |identified - true| over the marked grid
  points, as % of the true curve's range over the grid;
- coverage: the share of marked points whose band ``[<curve>_lo, <curve>_hi]`` holds the
  truth, pooled over the fleet.

Curves: the restoring force ``c(q) q + F_0`` against the truth ``f``, the damping ``d``
against the plant's ``d`` (the identified d multiplies the friction state z, the plant's the
velocity: they agree only where z ~ q_dot), and the input gains ``g_i`` against
``g_i = 1/2 dC_i/dq`` on both plants (on the full plant the small-signal gains: its DE force is
of the separable form of Eq. 37 to 0.3 % up to 1 kV, the sub-threshold excitation that
identifies g_i, but its 3 kV secant is 0.85-0.93 of them at the well where that DE holds the
beam, seed-1 fleet; the identified g_i there is scored against both, per well, and the static
force at each held input level, ``identify/static.parquet``, is compared with the full model's
force-displacement curve at that level, Fig. 4), and the tangent stiffness k* at each well
(:data:`debist.identify.bands.STIFFNESS_ERROR`). Each g_i is also scored over the q
interval its sub-threshold excitation visits near each well (:mod:`debist.rig.visited`),
marked or not: how much of it is marked, and the error there. The unseen
free-run NRMSE(q) of every member's ``rbf`` row (and ``narx`` where present) is listed too,
and what the validate stage's bootstrap replicates say about it: with p_i the share of member
i's replicates that lose the motion, the fleet's expected number of lost switches sum p_i and
the chance that none is lost, prod (1 - p_i) (MATLAB's ``simsd`` idea, applied to a fleet).

Run from the repository root (about 2-4 minutes per fleet of 10 on 2 cores)::

    python benchmarks/calibrate_bands.py --size 10 --seed 1 --workers 2 --dir /tmp/cal

``--plants zoo`` scores a plant zoo instead (``debist zoo``: members of other plants,
friction laws, sensors and excitations, each with its minimal workflow) against the truth it
wrote per unit mass (``truth.parquet``: the restoring force and g_i; the zoo has no d), the
identified curves divided by the mass they refer to (the identify summary's ``m_q_curves``).

It prints a Markdown table per plant and writes ``<dir>/calibration.json``. ``--add-backbone``
adds terms to every member's backbone and ``--set KEY=VALUE`` sets any other ``[identify]`` key
(e.g. ``--set weights_window=0.5``), so a setting's model error is calibrated on the fleets it
would run on; a dotted key sets any other table's (e.g. ``--set
rig.experiments.identification.ramps=[0,0,1,1]``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
PLANTS = {
    "full": ROOT / "workflows" / "paper-experiment.toml",
    "reduced": ROOT / "workflows" / "paper-experiment-reduced.toml",
}
TRUTH_KEY = {"restoring": "f", "d": "d", "g1": "g1", "g2": "g2"}
#: The accuracy a curve must have where it is marked: 10 % of the true curve's range.
WITHIN = 0.10


def _debist(*args: str) -> None:
    cmd = [sys.executable, str(ROOT / "cli.py"), *args]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode not in (0, 1):  # 1: some member failed, reported below
        raise SystemExit(f"{' '.join(cmd)} exited {done.returncode}:\n{done.stderr[-2000:]}")


def _member_outputs(folder: Path) -> list[tuple[Path, Path]]:
    """(workflow file, output folder) of every fleet member."""
    out = []
    for wf in sorted(folder.glob("*.toml")):
        raw = tomllib.loads(wf.read_text())
        out.append((wf, (wf.parent / raw["workflow"]["output_dir"]).resolve()))
    return out


def _member_data(run: Path) -> tuple[pd.DataFrame, dict]:
    """A member's identified curves and its rig truth, read once for every score."""
    from debist.core.fileformats import read_h5

    curves = pd.read_parquet(run / "identify" / "curves.parquet")
    return curves, read_h5(run / "rig" / "identification_truth.h5")


def _rig_config(wf: Path):
    """A member's ``[rig]`` (with its ``[physics]``) as the rig reads it, parsed once per member."""
    from debist.rig.experiment import RigConfig

    raw = tomllib.loads(wf.read_text())
    return RigConfig.from_dict(raw["rig"], raw.get("physics", {}))


def _zoo_rows(member: Path) -> list[dict]:
    """A zoo member's restoring force and g_i against its truth per unit mass."""
    run = member / "run"
    curves = pd.read_parquet(run / "identify" / "curves.parquet")
    summary = json.loads((run / "identify" / "summary.json").read_text())
    mass = float(summary.get("m_q_curves", summary["m_q"]))
    truth = pd.read_parquet(member / "truth.parquet")
    q = curves.q.to_numpy()
    inside = (q >= truth.q.iloc[0]) & (q <= truth.q.iloc[-1])
    rows = []
    for name in ("restoring", "g1", "g2"):
        true = np.interp(q, truth.q, truth[name])
        est, lo, hi = (curves[c].to_numpy() / mass for c in (name, f"{name}_lo", f"{name}_hi"))
        marked = curves[f"{name}_identified"].to_numpy() & inside
        rows.append(_score(name, true, est, lo, hi, marked))
    return rows


def calibrate_zoo(
    size: int, seed: int, workers: int, folder: Path, model_error: bool = True,
    settings: dict | None = None,
) -> dict:  # fmt: skip
    """Run a plant zoo (``debist zoo``, then ``debist batch``) and score it like a fleet."""
    zoo = folder / f"zoo-{seed}"
    if not (zoo / "zoo.json").exists():
        _debist("zoo", "--size", str(size), "--seed", str(seed), "--dir", str(zoo))
    members = [(wf, wf.parent / "run") for wf in sorted(zoo.glob("m*/workflow.toml"))]
    _set_members(members, model_error, (), settings)
    _debist("-q", "batch", str(zoo), "--workers", str(workers))
    rows, nrmse = [], []
    for wf, run in members:
        if not (run / "identify" / "curves.parquet").exists():
            nrmse.append({"member": wf.parent.name, "model": "rbf", "nrmse_q": np.nan})
            continue
        rows += [{"member": wf.parent.name, **r} for r in _zoo_rows(wf.parent)]
        table = pd.read_parquet(run / "compare" / "nrmse.parquet")
        for _, r in table[table.role == "validation"].iterrows():
            nrmse.append({"member": wf.parent.name, "model": r.model, "nrmse_q": r.nrmse_q})
    return _summarise("zoo", size, seed, rows, nrmse, [], [])


def _curve_rows(config, run: Path, plant: str, curves: pd.DataFrame, rig: dict) -> list[dict]:
    truth = rig["curves"]
    q = curves.q.to_numpy()
    rows = []
    names = ["restoring", "d", "g1", "g2"]
    for name in names:
        true = np.interp(q, truth["q"], truth[TRUTH_KEY[name]])
        marked = curves[f"{name}_identified"].to_numpy()
        est, lo, hi = (curves[c].to_numpy() for c in (name, f"{name}_lo", f"{name}_hi"))
        rows.append(_score(name, true, est, lo, hi, marked))
    if plant == "full":
        rows += _static_rows(config, run)
    return rows + _stiffness_rows(run, truth)


def _visited_rows(config, run: Path, curves: pd.DataFrame, rig: dict) -> list[dict]:
    """g_i over the q interval its sub-threshold excitation visits near each well.

    The intervals of :func:`debist.rig.visited.visited_intervals` (the identification log's
    dwell positions where ``v_i^2`` is at least 10 % of its excitation-block maximum, 1st to
    99th percentile, per well): one row per curve and well with the grid points inside, how
    many are marked, and the largest and median ``|identified - true|`` over all of them as a
    fraction of the true curve's range (marked or not: what marking there would show).
    """
    from debist.rig.profiles import make_profile
    from debist.rig.visited import excitation_blocks, rest_points, visited_intervals

    exp = config.experiments["identification"]
    segments = make_profile(exp.profile, **exp.profile_kwargs()).segments
    truth = rig["curves"]
    log = pd.read_parquet(run / "ingest" / "identification.parquet")
    q = curves.q.to_numpy()
    wells, barrier = rest_points(truth["q"], truth["f"])
    block = excitation_blocks(segments, log.t.to_numpy())
    rows = []
    for name in ("g1", "g2"):
        true = np.interp(q, truth["q"], truth[name])
        err = np.abs(curves[name].to_numpy() - true) / np.ptp(true)
        marked = curves[f"{name}_identified"].to_numpy()
        h = log[f"v{name[1:]}"].to_numpy() ** 2
        for lo, hi in visited_intervals(log.q.to_numpy(), h, block, rig["states"]["q_dot"],
                                        wells, barrier):  # fmt: skip
            inside = (q >= lo) & (q <= hi)
            rows.append({
                "curve": name, "q_lo": lo, "q_hi": hi, "points": int(inside.sum()),
                "marked": int((inside & marked).sum()),
                "max_error": float(err[inside].max()) if inside.any() else np.nan,
                "median_error": float(np.median(err[inside])) if inside.any() else np.nan,
            })  # fmt: skip
    return rows


def _stiffness_rows(run: Path, truth: dict) -> list[dict]:
    """k* at the identified wells at rest against the slope of the true restoring force there.

    One row ``k*`` per member: ``lacking`` is ``|k*_true / k*_identified - 1|`` per well (the
    bootstrap's reach is not subtracted: :data:`debist.identify.bands.STIFFNESS_ERROR` is the
    95th percentile of these), ``inside`` counts the wells whose ``k_lo .. k_hi`` holds the truth.
    """
    eq = pd.read_parquet(run / "identify" / "equilibria.parquet")
    q, f = np.asarray(truth["q"]), np.asarray(truth["f"])
    slope = np.gradient(f, q)
    roots = [i for i in np.flatnonzero(np.diff(np.sign(f)) != 0) if slope[i] > 0]
    wells = eq[(eq.model == "rbf") & (eq.level == 0) & eq.static_stable & eq.identified]
    if not roots or wells.empty:
        return []
    true = np.array([slope[min(roots, key=lambda i: abs(q[i] - x))] for x in wells.q])
    est = wells.k.to_numpy()
    ratio = np.abs(true / est - 1.0)
    lo = wells.get("k_lo", pd.Series(np.nan, index=wells.index)).to_numpy()
    hi = wells.get("k_hi", pd.Series(np.nan, index=wells.index)).to_numpy()
    return [{
        "curve": "k*", "marked": int(est.size), "max_error": float(ratio.max()),
        "median_error": float(np.median(ratio)), "inside": int(np.sum((lo <= true) & (true <= hi))),
        "lacking": ratio.tolist(),
    }]  # fmt: skip


def _static_rows(config, run: Path) -> list[dict]:
    from debist.physics.statics import force_displacement

    static = pd.read_parquet(run / "identify" / "static.parquet")
    prototype = config.rig.prototype
    rows = []
    for _, part in static.groupby("level"):
        marked = part.F_identified.to_numpy()
        if not marked.any():
            continue
        v1, v2 = part[["v1", "v2"]].iloc[0]
        full = force_displacement(prototype, part.q.to_numpy(), v1=v1, v2=v2)
        ok = np.asarray(full.converged)
        rows.append(
            _score(
                "static F", full.F[ok], part.F.to_numpy()[ok], part.F_lo.to_numpy()[ok],
                part.F_hi.to_numpy()[ok], marked[ok],
            )
        )  # fmt: skip
    return rows


def _held_gain_rows(config, run: Path, curves: pd.DataFrame, rig: dict) -> list[dict]:
    """The full plant's identified g_i at each true well against its two candidate truths.

    Per well (``rest_points`` of the true restoring force) and input i held in the log
    (``identify/static.parquet``, level V_i): the median over +-0.7 mm of the identified g_i
    divided by the small-signal gain ``1/2 dC_i/dq`` (the truth of :func:`_curve_rows`) and by
    the held level's secant ``(F(q, 0) - F(q, V_i)) / V_i^2`` of the full model's
    force-displacement curves (Fig. 4), and the secant's ratio to the small-signal gain: where
    they differ, Eq. 37's separable ``g_i(q) h(v_i)`` cannot match both. ``holds``: whether
    input i pushes the beam away from the barrier at that well (it holds it there at V_i; at
    the other well it switches it over).
    """
    from debist.physics.statics import force_displacement
    from debist.rig.visited import rest_points

    prototype = config.rig.prototype
    static = pd.read_parquet(run / "identify" / "static.parquet")
    truth = rig["curves"]
    wells, barrier = rest_points(truth["q"], truth["f"])
    levels = {i: float(static[f"v{i}"].max()) for i in (1, 2)}
    levels = {i: held for i, held in levels.items() if held > 0}
    rows = []
    for well in wells:
        q = np.linspace(well - 0.7e-3, well + 0.7e-3, 9)
        at_rest = force_displacement(prototype, q, v1=0.0, v2=0.0).F
        for i, held in levels.items():
            v = {"v1": held if i == 1 else 0.0, "v2": held if i == 2 else 0.0}
            secant = (at_rest - force_displacement(prototype, q, **v).F) / held**2
            small = np.interp(q, truth["q"], truth[f"g{i}"])
            est = np.interp(q, curves.q, curves[f"g{i}"])
            rows.append({
                "curve": f"g{i}", "well": float(well), "level": held,
                "holds": bool(np.median(small) * (well - barrier) > 0),
                "to_small_signal": float(np.median(est / small)),
                "to_secant": float(np.median(est / secant)),
                "secant_to_small_signal": float(np.median(secant / small)),
            })  # fmt: skip
    return rows


def _score(name, true, est, lo, hi, marked) -> dict:
    span = float(np.ptp(true))
    err = np.abs(est - true)[marked] / span if marked.any() else np.array([])
    inside = ((true >= lo) & (true <= hi))[marked]
    return {
        "curve": name,
        "marked": int(marked.sum()),
        "max_error": float(err.max()) if err.size else np.nan,
        "median_error": float(np.median(err)) if err.size else np.nan,
        "inside": int(inside.sum()),
        "lacking": _lacking(name, true, est, lo, hi, marked).tolist(),
    }


def _pooled_values(name: str, lacking: np.ndarray) -> list[float]:
    """What one member's curve adds to its group's pool of lacking half-widths.

    Pointwise for the restoring force, d and the static force; for a gain g_i (a gain error:
    every point of a prototype's curve off by about the same factor) the largest over its
    marked points, so that the group's 95th percentile is that of the prototypes, a band that
    holds a prototype's whole curve in 95 % of them (a pointwise percentile would let the
    one or two prototypes whose gain is 20 % off fall outside at every marked point).
    """
    from debist.identify.bands import relative_model_error

    if relative_model_error(name):
        return [float(np.max(lacking))] if len(lacking) else []
    return [float(x) for x in lacking]


def _lacking(name, true, est, lo, hi, marked) -> np.ndarray:
    """Per marked point, the half-width the band lacks to hold the truth, in quadrature.

    As a fraction of what the stage multiplies the model error by
    (:func:`debist.identify.bands.error_level`): the estimate's scale over the marked points
    (the larger of its range and its largest magnitude; the stage takes it over the supported
    points, a superset, so the calibrated term is, if anything, wider there), for a one-signed
    gain g_i its local magnitude: ``sqrt(err^2 - reach^2)`` where the band's reach toward the
    truth falls short of the error ``err``, else 0
    (:func:`debist.identify.bands.curve_bands` adds the term as ``hypot(reach, term)``).
    """
    from debist.identify.bands import error_level

    if not marked.any():
        return np.array([])
    e, t = est[marked], true[marked]
    scale = max(float(np.ptp(e)), float(np.max(np.abs(e))))
    level = error_level(name, e, np.ones(e.size, dtype=bool), scale)
    reach = np.maximum(np.where(t > e, hi[marked] - e, e - lo[marked]), 0.0)
    err = np.abs(t - e)
    return np.sqrt(np.maximum(err**2 - reach**2, 0.0)) / level


def _set_members(
    members: list[tuple[Path, Path]],
    on: bool,
    backbone: tuple[str, ...],
    settings: dict | None = None,
) -> None:
    """Write ``[identify] model_error``, the extra ``backbone`` terms and ``settings`` into every
    member's workflow file (a rewrite only where it changes). A key of ``settings`` is an
    ``[identify]`` key, or with dots a path from the file's root (e.g.
    ``rig.experiments.identification.ramps``)."""
    import tomli_w

    from debist.identify.config import IdentifyConfig

    default = list(IdentifyConfig.from_dict({}).backbone)
    for wf, _ in members:
        text = wf.read_text()
        before, raw = tomllib.loads(text), tomllib.loads(text)
        section = raw.setdefault("identify", {})
        section["model_error"] = on
        if backbone:  # a workflow without the key has the default backbone
            terms = list(section.get("backbone", default))
            section["backbone"] = terms + [t for t in backbone if t not in terms]
        for key, value in (settings or {}).items():
            *path, last = key.split(".") if "." in key else ("identify", key)
            table = raw
            for name in path:
                table = table.setdefault(name, {})
            table[last] = value
        # an unset model_error is the default, true: setting it so is no change
        before.setdefault("identify", {}).setdefault("model_error", True)
        if raw != before:
            wf.write_text(tomli_w.dumps(raw))


def calibrate(
    plant: str,
    size: int,
    seed: int,
    workers: int,
    folder: Path,
    model_error: bool = True,
    backbone: tuple[str, ...] = (),
    settings: dict | None = None,
) -> dict:
    """Run one fleet and score it; returns the summary (see the module docstring).

    ``backbone``: terms added to every member's ``[identify] backbone`` (e.g.
    ``physics_creep``, whose model error :data:`debist.identify.bands.MODEL_ERROR_CREEP` is
    calibrated so); ``settings``: other ``[identify]`` keys set in every member (e.g.
    ``{"weights_window": 0.5}``).
    """
    fleet = folder / plant
    if not any(fleet.glob("*.toml")):
        _debist("fleet", str(PLANTS[plant]), "--size", str(size), "--seed", str(seed),
                "--dir", str(fleet))  # fmt: skip
    members = _member_outputs(fleet)
    _set_members(members, model_error, backbone, settings)
    _debist("-q", "batch", *(str(wf) for wf, _ in members), "--workers", str(workers))
    rows, nrmse, visited, held = [], [], [], []
    for wf, run in members:
        if not (run / "identify" / "curves.parquet").exists():
            nrmse.append({"member": wf.stem, "model": "rbf", "nrmse_q": np.nan, "failed": True})
            continue
        curves, rig = _member_data(run)
        config = _rig_config(wf)
        rows += [{"member": wf.stem, **r} for r in _curve_rows(config, run, plant, curves, rig)]
        visited += [{"member": wf.stem, **r} for r in _visited_rows(config, run, curves, rig)]
        if plant == "full":
            held += [{"member": wf.stem, **r} for r in _held_gain_rows(config, run, curves, rig)]
        table = pd.read_parquet(run / "compare" / "nrmse.parquet")
        for _, r in table[table.role == "validation"].iterrows():
            nrmse.append({"member": wf.stem, "model": r.model, "nrmse_q": r.nrmse_q, **_spread(r)})
    return _summarise(plant, size, seed, rows, nrmse, visited, held)


def _summarise(plant, size, seed, rows, nrmse, visited, held) -> dict:
    """The per-curve summary, the pooled lacking half-widths and the rows of one calibration."""
    scores = pd.DataFrame(rows)
    lacking = scores.pop("lacking")
    summary = (
        scores.groupby("curve")
        .agg(marked=("marked", "sum"), inside=("inside", "sum"),
             max_error=("max_error", "max"), median_error=("median_error", "median"))
        .assign(coverage=lambda s: s.inside / s.marked)
    )  # fmt: skip
    pooled = {
        name: [v for x in lacking[scores.curve == name] for v in _pooled_values(name, x)]
        for name in summary.index
    }
    return {
        "plant": plant,
        "size": size,
        "seed": seed,
        "curves": summary.reset_index().to_dict(orient="records"),
        "lacking": pooled,
        "members": scores.to_dict(orient="records"),
        "visited": visited,
        "held": held,
        "nrmse": nrmse,
    }


def _spread(row: pd.Series) -> dict:
    """A compare-table row's bootstrap replicates (the validate stage's columns, ``rbf`` only):
    the share that lose the motion and the 95 % range of their NRMSE(q); empty without them."""
    if not np.isfinite(row.get("replicates_poor", np.nan)):
        return {}
    return {"poor": row.replicates_poor, "lo": row.nrmse_q_lo, "hi": row.nrmse_q_hi}


def _replicates_markdown(nr: pd.DataFrame) -> list[str]:
    """What the estimation uncertainty alone says about the fleet's unseen free runs: with
    p_i the share of member i's replicates that lose the motion, sum p_i members are expected
    to lose it and prod (1 - p_i) is the chance that none does (members independent)."""
    rbf = nr[nr.model == "rbf"]
    if "poor" not in rbf or rbf.poor.isna().all():
        return []
    rbf = rbf.dropna(subset=["poor"])
    p = rbf.poor.to_numpy()
    above = rbf.member[rbf.lo > 0.01].str[-3:].tolist()
    return [
        "",
        f"Bootstrap replicates (unseen record, {len(rbf)} members): {p.sum():.2f} members expected"
        f" to lose the motion, P(none does) = {np.prod(1.0 - p):.2f}; members at most 1 %:"
        f" {int((rbf.nrmse_q <= 0.01).sum())}; members whose replicates' 95 % range lies above"
        f" 1 %: {', '.join(above) or 'none'}",
    ]


def _markdown(result: dict) -> str:
    lines = [
        f"**{result['plant']} plant**, fleet of {result['size']} (seed {result['seed']})",
        *_table_head("curve", "marked points", "max / median error where marked",
                     "band holds the truth"),
    ]  # fmt: skip
    for c in result["curves"]:
        lines.append(
            f"| {c['curve']} | {c['marked']} | {100 * c['max_error']:.1f} / "
            f"{100 * c['median_error']:.1f} % | {100 * c['coverage']:.0f} % |"
        )
    lines += _visited_markdown(result.get("visited", []))
    lines += _held_markdown(result.get("held", []))
    nr = pd.DataFrame(result["nrmse"])
    if not nr.empty:
        lines += _table_head("model", "unseen NRMSE(q): median", "max", "members")
        for model, g in nr.groupby("model"):
            lines.append(
                f"| {model} | {100 * g.nrmse_q.median():.2f} % | {100 * g.nrmse_q.max():.2f} % "
                f"| {g.nrmse_q.notna().sum()} |"
            )
        lines += _replicates_markdown(nr)
    return "\n".join(lines)


def _table_head(*columns: str) -> list[str]:
    """A blank line, then a Markdown table's header and rule for ``columns``."""
    return ["", "| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]


def _visited_markdown(visited: list[dict]) -> list[str]:
    """Lines of the table of g_i over the intervals its sub-threshold excitation visits.

    ``within 10 %`` counts the intervals where the identified g_i is within :data:`WITHIN` of
    the true range at every grid point, marked or not: the most intervals that any mask could
    mark while keeping the error where marked within that share, whatever its band.
    """
    if not visited:
        return []
    lines = _table_head("curve", "visited well intervals", "fully marked", "points marked",
                        f"within {100 * WITHIN:.0f} % over the whole interval",
                        "max / median error over the visited points (marked or not)")  # fmt: skip
    for name, g in pd.DataFrame(visited).groupby("curve"):
        full = int((g.marked == g.points).sum())
        within = int((g.max_error <= WITHIN).sum())
        lines.append(
            f"| {name} | {len(g)} | {full} | {g.marked.sum()} of {g.points.sum()} | {within} "
            f"| {100 * g.max_error.max():.1f} / {100 * g.median_error.median():.1f} % |"
        )
    return lines


def _held_markdown(held: list[dict]) -> list[str]:
    """Lines of the table of g_i at the wells against the small-signal gain and the secant."""
    if not held:
        return []
    lines = _table_head("curve at the wells (+-0.7 mm)", "identified / small-signal gain",
                        "identified / held-level secant", "secant / small-signal gain")  # fmt: skip
    cols = ("to_small_signal", "to_secant", "secant_to_small_signal")
    for (name, holds), g in pd.DataFrame(held).groupby(["curve", "holds"]):
        cells = [f"{g[c].min():.2f}-{g[c].max():.2f} (median {g[c].median():.2f})" for c in cols]
        where = "where it holds the beam" if holds else "where it switches it"
        lines.append(f"| {name} {where} ({len(g)} wells) | " + " | ".join(cells) + " |")
    return lines


#: Curves of the calibration -> key of :data:`debist.identify.bands.MODEL_ERROR`.
GROUPS = {"restoring": "restoring", "d": "d", "g1": "g", "g2": "g", "static F": "F", "k*": "k"}


def _model_error_table(results: list[dict]) -> str:
    """The 95th percentile of the lacking half-width per curve group, pooled over the plants.

    A fraction of the curve's scale; for the gains g_i of their local magnitude, the largest
    over each prototype's marked points (:func:`_pooled_values`).
    """
    pooled: dict[str, list[float]] = {}
    for r in results:
        for name, values in r["lacking"].items():
            pooled.setdefault(GROUPS[name], []).extend(values)
    lines = _table_head("curve", "values (marked points; g: prototype curves)",
                        "model error (95th pct.)")[1:]  # fmt: skip
    table = {}
    for key, values in pooled.items():
        table[key] = round(float(np.percentile(values, 95)), 3) if values else 0.0
        lines.append(f"| {key} | {len(values)} | {table[key]} |")
    stiffness = table.pop("k", None)
    return "\n".join([*lines, "", f"MODEL_ERROR = {table}", f"STIFFNESS_ERROR = {stiffness}"])


def main() -> None:
    """Parse the arguments, calibrate each plant, print and save the tables."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", type=int, default=10)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--dir", type=Path, required=True)
    p.add_argument("--plants", default="full,reduced", help="full, reduced and/or zoo")
    p.add_argument(
        "--add-backbone", default="",
        help="comma-separated backbone terms added to every member (e.g. physics_creep)",
    )  # fmt: skip
    p.add_argument(
        "--model-error", choices=("on", "off"), default="on",
        help="off: bootstrap-only bands, and print the model-error term they lack",
    )  # fmt: skip
    p.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE",
        help="an [identify] key set in every member, VALUE in TOML (e.g. weights_window=0.5); "
        "a dotted KEY is a path from the workflow's root (rig.experiments.identification.ramps)",
    )  # fmt: skip
    args = p.parse_args()
    settings = {}
    for item in args.set:
        key, _, value = item.partition("=")
        settings[key.strip()] = tomllib.loads(f"value = {value}")["value"]
    sys.path.insert(0, str(ROOT))
    on = args.model_error == "on"
    extra = tuple(t for t in args.add_backbone.split(",") if t)
    results = [
        calibrate_zoo(args.size, args.seed, args.workers, args.dir, on, settings)
        if plant == "zoo"
        else calibrate(plant, args.size, args.seed, args.workers, args.dir, on, extra, settings)
        for plant in args.plants.split(",")
    ]
    for r in results:
        print(_markdown(r), end="\n\n")
    if not on:  # what the bootstrap bands lack: MODEL_ERROR of pipeline/identify/bands.py
        print(_model_error_table(results))
    (args.dir / "calibration.json").write_text(json.dumps(results, indent=1, default=float))


if __name__ == "__main__":
    main()
