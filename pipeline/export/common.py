"""Shared pieces of every export: provenance, constants, curve table, literals, templates.

Every export renders jinja2 templates (``templates/*.j2`` of this package). A template may
insert nothing but integers and :class:`Code`, the text an escaping or formatting filter
returns: a raw string or float in ``{{ ... }}`` is an error when rendering, so no free text
(a workflow's name, provenance) and no number reaches the code without its language's
escaping or exact literal.

References
----------
Masoud & Maas 2025, Eq. 37 (the term table); NumPy ``numpy.interp`` (the table semantics);
jinja2 3.1, "API" (``Environment``, ``PackageLoader``, ``StrictUndefined``, ``finalize``).
"""

from __future__ import annotations

import numbers
import textwrap
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import jinja2
import numpy as np

from debist import __version__
from debist.core.errors import ArtifactError
from debist.export.scheme import Scheme, default_scheme
from debist.model.termtable import BASE_GAUSS, BASE_TABLE, S_ACC, S_CREEP, S_POW, S_TANH
from debist.simulate.freerun import EDGE_PAD

__all__ = ["CURVE_POINTS", "Code", "ExportInfo", "curve_table"]

#: Grid points of the characteristic-curve lookup table (as ``curves.parquet``).
CURVE_POINTS = 201


@dataclass(frozen=True)
class ExportInfo:
    """Provenance written into the header comment of every exported file.

    Attributes
    ----------
    workflow : str
        The workflow's name.
    run_digest : str or None
        The run digest (:func:`debist.core.artifacts.run_digest`); None when a stage of the
        workflow has not run.
    identify_manifest : str or None
        sha256 of ``identify/manifest.json`` (names the identified model even without a
        run digest).
    identified : dict of str to list
        Per curve (``restoring``, ``d``, ``g1`` ...) the q intervals ``[a, b]`` [m] where
        ``curves.parquet`` marks it identified; empty when unknown.
    version : str
        debist's version.
    """

    workflow: str = ""
    run_digest: str | None = None
    identify_manifest: str | None = None
    identified: dict[str, list[list[float]]] = field(default_factory=dict)
    version: str = __version__


def _arrays(model) -> dict[str, Any]:
    """Collect the constants of the exported model from its term table.

    The state is ``[q, q_dot]``, then z with the friction lag (T_z > 0), then the C creep
    states w_k of Eq. 26 and the E Maxwell-slip deflections delta_e
    (the layout of :class:`debist.model.termtable.TableModel`, without z when T_z = 0).
    ``inertia`` maps each power a of the inertia terms (:data:`S_ACC`) to its coefficient
    mu_a of the mass ``m(q) = m_q + sum_a mu_a q^a`` (minus the sum of their weights).
    """
    tm = model.table_model()
    t = tm.table
    lag = float(model.T_z) > 0
    x_extra = 3 if lag else 2
    inertia: dict[int, float] = {}
    for j in np.flatnonzero(t.term_skind == S_ACC):
        a = int(t.term_qpow[j])
        inertia[a] = inertia.get(a, 0.0) - float(tm.weights[0, j])
    return {
        "n_inputs": t.n_inputs,
        "n_states": x_extra + t.n_extra,
        "x_extra": x_extra,
        "lag": lag,
        "n_creep": t.n_creep,
        "creep_base": t.creep_base.tolist(),
        "creep_rate": float(t.creep_rate),
        "n_slip": t.n_slip,
        "slip_width": t.slip_width.tolist(),
        "T_z": float(model.T_z),
        "m_q": float(tm.mass[0]),
        "v_c": float(t.coulomb_velocity),
        "input_map": t.input_map,
        "q_range": (float(model.q_range[0]), float(model.q_range[1])),
        "max_step": tm.max_step(),  # 1.5 T_z and 1.5 / lambda (inf without either)
        "clipped": bool(np.isfinite(t.base_lo[t.base_kind == BASE_GAUSS]).any()),
        "base_kind": t.base_kind.tolist(),
        "base_centre": t.base_centre.tolist(),
        "base_width": t.base_width.tolist(),
        "base_lo": t.base_lo.tolist(),
        "base_hi": t.base_hi.tolist(),
        "base_table": t.base_table.tolist(),
        "table_q": t.table_q.tolist(),
        "tables": t.tables.tolist(),
        "term_names": list(t.names),
        "term_base": t.term_base.tolist(),
        "term_qpow": t.term_qpow.tolist(),
        "term_skind": t.term_skind.tolist(),
        "term_spow": t.term_spow.tolist(),
        "term_hpow": t.term_hpow.tolist(),
        "weights": tm.weights[0].tolist(),
        "has_inertia": t.has_inertia,
        "inertia": dict(sorted(inertia.items())),
    }


def curve_table(model, n: int = CURVE_POINTS) -> tuple[np.ndarray, list[str], np.ndarray]:
    """Tabulate the characteristic curves on the model's q range.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    n : int, optional
        Grid points.

    Returns
    -------
    q : ndarray, shape (n,)
        Ascending grid over ``model.q_range`` [m].
    names : list of str
        ``restoring`` (``c(q) q + F_0`` [F], the static force at v = 0), ``d`` [F s/m],
        ``g1`` .. ``gN`` [F/V^2 when h = v^2]: F is N with q in m and ``m_q`` in kg, an
        acceleration [unit of q/s^2] when ``m_q = 1`` (per unit mass).
    values : ndarray, shape (2 + n_inputs, n)
        The curves on the grid.

    Raises
    ------
    ArtifactError
        If the model's ``q_range`` is empty.

    References
    ----------
    Masoud & Maas 2025, Eq. 37-40, Fig. 14.
    """
    lo, hi = (float(x) for x in model.q_range)
    if not hi > lo:
        raise ArtifactError(f"the model's q_range {model.q_range} is empty: nothing to tabulate")
    q = np.linspace(lo, hi, n)
    cur = model.curves(q)
    rows = [cur["cq"] + float(model.backbone.get("F_0", 0.0)), cur["d"]]
    rows += [cur["g"][:, j] for j in range(model.n_inputs)]
    names = ["restoring", "d", *[f"g{j + 1}" for j in range(model.n_inputs)]]
    return q, names, np.asarray(rows)


def _units(m_q: float, q_unit: str) -> dict[str, str]:
    """Return the units of the exported model: q's, and the force unit its terms sum to.

    With ``m_q = 1`` the equation is per unit mass and its terms are accelerations
    [u/s^2]; with q in metres and ``m_q`` a mass [kg] they are forces [N]; with q in another
    unit u (an electrical circuit's voltage, say) ``m_q`` is in the model's own mass unit M
    (not kg) and the terms in [M u/s^2] (not N).
    """
    u = q_unit
    if m_q == 1.0:
        force = f"{u}/s^2"
        says = f"m_q = 1 [1]: per unit mass, the terms are accelerations [{u}/s^2]"
    elif u == "m":
        force = "N"
        says = f"m_q = {m_q!r} [kg], the terms are forces [N]"
    else:
        force = f"M {u}/s^2"
        says = (
            f"m_q = {m_q!r} [M] in the model's own mass unit M (q is in {u}, not m),"
            f" the terms are forces [M {u}/s^2]"
        )
    return {"u_q": u, "u_force": force, "u_says": says}


def _percent(x: float | None) -> str:
    """NRMSE [1] as a percentage with four significant digits, ``n/a`` for None or NaN."""
    if x is None or not np.isfinite(x):
        return "n/a"
    return f"{100.0 * x:.4g} %"


def _also(scheme: Scheme, values: list[tuple[float, ...]], bracket: bool = True) -> str:
    """Return `` ([a, b], ... unit)``: q values given again in the report unit, or ``""``.

    ``values`` are tuples of q values [unit of q]; each is written ``[a, b]`` (or a lone
    number with ``bracket`` False), six significant digits, in ``scheme.shown()``'s unit.
    """
    shown = scheme.shown()
    if shown is None or not values:
        return ""
    factor, unit = shown

    def one(group: tuple[float, ...]) -> str:
        text = ", ".join(f"{factor * float(x):.6g}" for x in group)
        return f"[{text}]" if bracket else text

    return f" ({', '.join(one(g) for g in values)} {unit})"


def _scheme_lines(scheme: Scheme, u: str, entries: tuple[str, str], slips: bool) -> list[str]:
    """Return the header lines on the scheme and what it scores on the run's records."""
    ns = scheme.substeps
    at = f" at the run's dt = {scheme.dt!r} s" if scheme.dt is not None else ""
    how = (
        [
            f"  band-limited (the record odd-reflected by {EDGE_PAD} samples at each end, then the",
            "  polyphase Kaiser(8) FIR of scipy.signal.resample_poly, its taps in the code),",
        ]
        if scheme.interpolation == "bandlimited"
        else ["  linear between samples (as numpy.interp),"]
    )
    free, step = entries
    lines = [
        f"Scheme (debist's validate stage{at}): ns = {ns} classical RK4 sub-steps per",
        "  sample, h = dt / ns, the stages reading the inputs at t, t + h/2, t + h"
        + (";" if slips else "."),
        *(["  the slip deflections are clipped after every sub-step."] if slips else []),
        f"  {free} (a whole record): the inputs interpolated",
        *how,
        "  from the given initial state x0; stops where a state is not finite or",
        f"  |q| > {scheme.q_limit!r} {u}{_also(scheme, [(scheme.q_limit,)], False)} (the rest"
        " NaN): it reproduces validate's free run.",
        f"  {step} (one sample, causal): the same ns sub-steps, the inputs linear",
        "  between v0 (at t) and v1 (at t + dt)"
        + (
            "; with band-limited scoring it is NOT the scored scheme."
            if scheme.interpolation == "bandlimited"
            else ", as validate: it reproduces the scored free run."
        ),
    ]
    start = (
        "q and q_dot at its first sample of a cubic fitted to its first samples"
        f" ([validate] init_samples = {scheme.init_samples}, scored from that sample on)"
        if scheme.init_samples
        else "its first sample's q and q_dot (differentiated)"
    )
    lines += [
        "  Validate starts each record's free run at rest in the other states, from",
        f"  {start}.",
    ]
    if not scheme.records:
        lines.append("NRMSE(q) on the run's records: n/a (exported without the run's records).")
        return lines
    lines.append(
        "NRMSE(q) on the run's records (Eq. 41), computed at export by debist's simulator:"
    )
    for rec in scheme.records:
        validate = f", validate ns = {rec.substeps}" if rec.substeps != ns else ""
        free_nrmse = _percent(rec.free_run) + (
            f" (diverged at sample {rec.free_run_diverged})" if rec.free_run_diverged >= 0 else ""
        )
        step_nrmse = _percent(rec.step) + (
            f" (diverged at sample {rec.step_diverged})" if rec.step_diverged >= 0 else ""
        )
        lines += [
            f"  {_record_name(rec.name)} (dt = {rec.dt!r} s{validate}): {free} {free_nrmse}"
            f" (validate reported {_percent(rec.reported)}), {step} {step_nrmse}",
        ]
    return lines


def _record_name(name: str) -> str:
    """Return a data set's name for a comment: as it is when plain ASCII, else a placeholder."""
    plain = name.replace("_", "").replace("-", "").replace(".", "")
    return name if plain.isascii() and plain.isalnum() else "(name not plain ASCII)"


def _model_lines(arr: dict[str, Any], scheme: Scheme, u: str) -> list[str]:
    """Return the header's equations of motion, friction, creep and slip (Eq. 26, 37)."""
    hmap = "v^2" if arr["input_map"] == "v2" else "v"
    lag = arr["lag"]
    lines = ["The identified model of debist (Masoud & Maas 2025, Eq. 37):"]
    if arr["has_inertia"]:
        mus = [f"mu_{a} = {mu!r}" for a, mu in arr["inertia"].items()]
        lines += [
            "  m(q) q'' = sum_j weight_j term_j(q, s, h) - 1/2 m'(q) q_dot^2,  h_i = h(v_i) = "
            + hmap
            + ",",
            "  the sum over every term but the inertia terms (kind S_ACC, term q^a), which make",
            "  the position-dependent mass m(q) = m_q + sum_a mu_a q^a, mu_a = -weight (Lagrange's",
            "  equation of the kinetic energy 1/2 m(q) q_dot^2); here",
            *textwrap.wrap(", ".join(mus), 88, initial_indent="  ", subsequent_indent="  "),
        ]
    else:
        lines += ["  m_q q'' = sum_j weight_j term_j(q, s, h),  h_i = h(v_i) = " + hmap]
    lines += [
        "  friction state z' = (q_dot - z) / T_z, s = z"
        if lag
        else "  T_z = 0: no friction state, s = q_dot",
    ]
    if arr["n_creep"]:
        lines += [
            "  creep states (Eq. 26): w_k' = b_k(q) q_dot - lambda w_k,",
            f"  lambda = {arr['creep_rate']!r} 1/s; terms of kind S_CREEP read w_k",
        ]
    if arr["n_slip"]:
        widths = ", ".join(repr(w) for w in arr["slip_width"])
        lines += [
            "  Maxwell-slip deflections (Al-Bender, Lampaert & Swevers 2005):",
            "  delta_e' = q_dot, 0 while |delta_e| >= Delta_e and q_dot delta_e > 0;",
            "  after every RK4 sub-step delta_e is clipped to [-Delta_e, Delta_e];",
            f"  Delta_e = [{widths}] {u}{_also(scheme, [tuple(arr['slip_width'])])}",
        ]
    return lines


def _describe(
    info: ExportInfo,
    arr: dict[str, Any],
    names: list[str],
    name_ref: str,
    scheme: Scheme,
    entries: tuple[str, str],
) -> list[str]:
    """Lines of the header comment shared by every format (without comment markers).

    Only fixed text and numbers: the workflow's name, which is free text from the workflow
    file, is never put into a comment or docstring; each format emits it as an escaped
    string literal (``name_ref`` names that constant). ``entries`` names the format's
    whole-record free run and its per-sample step. Data-set names (checked to be
    letters, digits, ``_``, ``-`` and ``.``) name the records' scores.
    """
    lo, hi = arr["q_range"]
    units = _units(arr["m_q"], scheme.q_unit)
    u = units["u_q"]
    lag = arr["lag"]
    extra = [f"w{k + 1}" for k in range(arr["n_creep"])]
    extra += [f"delta{e + 1}" for e in range(arr["n_slip"])]
    state = "[" + ", ".join(["q", "q_dot", *(["z"] if lag else []), *extra]) + "]"
    lines = _model_lines(arr, scheme, u)
    at_rest = ["z = q_dot (the filter at rest)"] if lag else []
    at_rest += ["w = 0, delta = 0 (at rest)"] if extra else []
    lines += [
        f"State x = {state}" + (f"; start with {' and '.join(at_rest)}." if at_rest else "."),
        f"Inputs v [V] (n = {arr['n_inputs']}); mapped inputs h [V^2 or V].",
        f"Units: q [{u}], q_dot [{u}/s], t and dt [s], v [V];",
        f"  {units['u_says']}.",
        f"Valid q range (estimation data): [{lo!r}, {hi!r}] {u}{_also(scheme, [(lo, hi)])};"
        " outside it the",
        "  Gaussian bases are held at the range's edge and the tables at their ends."
        if arr["clipped"]
        else "  Gaussian bases decay (not clipped) and the tables hold their end values.",
    ]
    if info.identified:
        for name in names:
            if name in info.identified:
                found = info.identified[name]
                spans = ", ".join(f"[{a!r}, {b!r}]" for a, b in found)
                also = _also(scheme, [tuple(x) for x in found])
                lines.append(f"Curve {name} identified on q in: {spans} {u}{also}" if spans
                             else f"Curve {name} identified on q in: none")  # fmt: skip
    if np.isfinite(arr["max_step"]):
        lines.append(
            f"RK4 is stable for h = dt / ns <= {arr['max_step']!r} s (1.5 T_z, 1.5 / lambda)."
        )
    lines += _scheme_lines(scheme, u, entries, bool(arr["n_slip"]))
    lines += [
        f"Curves table: {len(names)} curves ({', '.join(names)}) on {CURVE_POINTS} points,",
        "  interpolated linearly, held outside the grid.",
        f"Workflow: its name is the string {name_ref} (as written in the workflow file)",
        f"Run digest: {info.run_digest or 'n/a (not every stage of the workflow has run)'}",
        f"identify/manifest.json sha256: {info.identify_manifest or 'n/a'}",
        f"Generated by debist {info.version} (debist export); do not edit.",
    ]
    return lines


def _literal(x: float, infinity: str) -> str:
    """Format a double that round-trips (``repr``), ``infinity`` (signed) for infinities."""
    x = float(x)
    if np.isnan(x):
        raise ArtifactError("the model has a NaN constant: it cannot be exported")
    if np.isinf(x):
        return infinity if x > 0 else f"-{infinity}"
    return repr(x)


class Code(str):
    """Text formatted or escaped for the target language: what a template may insert."""


def _comment_text(text: str, forbidden: tuple[str, ...], where: str) -> str:
    """Return ``text`` for a comment line: printable ASCII without ``forbidden``.

    Raises
    ------
    ArtifactError
        If ``text`` has another character or a forbidden sequence (it could end the
        comment); the exports put only fixed text, numbers and digests into comments.
    """
    text = str(text)
    bad = [c for c in text if not " " <= c <= "~"] + [f for f in forbidden if f in text]
    if bad:
        raise ArtifactError(f"{text!r} cannot be written into {where}: it holds {bad[0]!r}")
    return text


def _only_code(value):
    """Pass integers and :class:`Code` (the ``finalize`` of the export templates)."""
    if isinstance(value, jinja2.Undefined):
        str(value)  # StrictUndefined: raises UndefinedError naming the missing value
    if isinstance(value, Code) or (
        isinstance(value, numbers.Integral) and not isinstance(value, bool)
    ):
        return value
    raise TypeError(
        f"an export template inserts a {type(value).__name__} without a filter: {value!r:.60}"
    )


def _code(fn: Callable[..., str]) -> Callable[..., Code]:
    """Wrap a formatting or escaping function as a filter that returns :class:`Code`."""

    def filt(*args, **kwargs) -> Code:
        return Code(fn(*args, **kwargs))

    return filt


def _flatten(rows) -> list:
    """Concatenate the rows of a matrix (row-major)."""
    return [v for row in rows for v in row]


def _environment(filters: dict[str, Callable[..., str]]) -> jinja2.Environment:
    """Return the jinja2 environment of one language: its ``filters`` and the templates.

    Missing values are errors (``StrictUndefined``), nothing is HTML-escaped, block tags
    take their line with them, and ``{{ ... }}`` inserts only integers and :class:`Code`
    (every filter of ``filters`` returns it).
    """
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("debist.export", "templates"),
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
        autoescape=False,
        trim_blocks=True,
        lstrip_blocks=True,
        finalize=_only_code,
    )
    env.filters.update({name: _code(fn) for name, fn in filters.items()})
    env.filters["flatten"] = _flatten
    env.filters["width"] = _code(lambda n, w: f"{n:{w}d}")
    return env


def _context(
    model,
    info: ExportInfo | None,
    name_ref: str,
    scheme: Scheme | None = None,
    entries: tuple[str, str] = ("free_run", "rk4_step"),
) -> dict[str, Any]:
    """Collect the values of the export templates: constants, curves, scheme and provenance.

    ``name_ref`` names where the format keeps the workflow's name (see :func:`_describe`);
    ``scheme`` is the free-run scheme (:func:`debist.export.scheme.default_scheme` when
    None); ``entries`` the names of the format's whole-record free run and per-sample step.
    """
    info = info or ExportInfo()
    scheme = scheme or default_scheme(model)
    arr = _arrays(model)
    cq, names, cval = curve_table(model)
    taps = scheme.taps()
    return {
        **arr,
        **_units(arr["m_q"], scheme.q_unit),
        "describe": _describe(info, arr, names, name_ref, scheme, entries),
        "substeps": scheme.substeps,
        "n_fine": 2 * scheme.substeps,
        "bandlimited": scheme.interpolation == "bandlimited",
        "q_limit": scheme.q_limit,
        "edge_pad": EDGE_PAD,
        "taps": taps.tolist(),
        "n_taps": taps.shape[1],
        "half_taps": (taps.shape[1] - 1) // 2,
        "workflow": info.workflow,
        "curve_names": names,
        "curve_q": cq.tolist(),
        "curve_values": cval.tolist(),
        "BASE_GAUSS": BASE_GAUSS,
        "BASE_TABLE": BASE_TABLE,
        "S_POW": S_POW,
        "S_TANH": S_TANH,
        "S_CREEP": S_CREEP,
        "S_ACC": S_ACC,
    }
