"""Terminal reports of a workflow's results: rich tables built from the stages' summaries.

Every number printed comes from a stage's ``summary.json``, read only after its sha256 was
checked against the stage's manifest (:func:`debist.core.artifacts.read_summary`); wall times,
which no hash covers, are not printed here.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from typing import Any

from rich.markup import escape
from rich.table import Table

from debist.core.metrics import POOR_SHARE
from debist.core.units import lookup_unit, pretty_unit

#: How identified quantities are labelled in reports (summary key -> label). The backbone's
#: polynomial coefficients are basis terms the RBF sums add to, not the beam's physics: the
#: physical damping, stiffness and frequency at each well are in the equilibria table.
PARAMETER_LABELS = {
    "m_q": "mass m_q",
    "d_v": "backbone coefficient d_v (a basis term; the damping d(q*) is in the equilibria)",
    "F_c": "Coulomb friction F_c",
    "F_0": "offset force F_0",
    "k_1": "backbone coefficient k_1 (a basis term; the stiffness k* is in the equilibria)",
    "k_3": "backbone coefficient k_3 (a basis term)",
    "s_c": "scale of the analytical c(q) q, s_c",
    "s_d": "scale of the analytical d(q), s_d",
}


#: Dimension of each backbone parameter in the force unit F, q and the mapped input h.
_DIMENSIONS = {
    "k_1": "F/q",
    "k_3": "F/q**3",
    "d_v": "F*s/q",
    "F_c": "F",
    "F_0": "F",
    "s_c": "1",
    "s_d": "1",
}


def display_factors(
    q_unit: str, report_unit: str | None, per_unit_mass: bool
) -> tuple[dict[str, float], str]:
    """Factors that show q and the quantities made of q in the report unit.

    The identify stage records q in its SI unit and forces in N or, per unit mass, as
    accelerations of q; a table, page or figure multiplies a quantity of dimension ``q``,
    ``F``, ``F/q``, ``F/q3`` (per q cubed) or ``Fs/q`` by its factor here. Forces in N keep
    their unit; a per-unit-mass force (q/s^2) scales with q.

    Parameters
    ----------
    q_unit : str
        The SI unit q is recorded in (``"m"``, ``"V"``).
    report_unit : str or None
        ``[validate] report_unit``; None: mm for q in m, else q's own unit.
    per_unit_mass : bool
        Whether the forces are per unit mass (``m_q = 1``).

    Returns
    -------
    factors : dict of str to float
        Dimension -> factor (``"q"``, ``"F"``, ``"F/q"``, ``"F/q3"``, ``"Fs/q"``).
    unit : str
        The report unit as :func:`debist.validate.freerun.report_factor` spells it.

    Raises
    ------
    WorkflowError
        If ``report_unit`` cannot express q.

    References
    ----------
    Masoud & Maas 2025, Eq. 37 (the terms' dimensions).

    Examples
    --------
    >>> factors, unit = display_factors("m", None, False)
    >>> unit, factors["q"], factors["F"], factors["F/q"], factors["Fs/q"]
    ('mm', 1000.0, 1.0, 0.001, 0.001)
    >>> display_factors("m", "mm", True)[0]["F"]  # per unit mass: m/s^2 -> mm/s^2
    1000.0
    """
    from debist.validate.freerun import report_factor

    f, shown = report_factor(q_unit, report_unit)
    force = f if per_unit_mass else 1.0  # a per-unit-mass force is an acceleration of q
    factors = {"q": f, "F": force, "F/q": force / f, "F/q3": force / f**3, "Fs/q": force / f}
    return factors, shown


def physics_factor(report_unit: str | None) -> tuple[float, str]:
    """Factor and unit that show the physics model's q [m] in the workflow's report unit.

    The design analysis (Section 3) computes q in m whatever unit the data record q in; a
    report unit that cannot express a length (q of the data in V, ``report_unit = "mV"``)
    leaves the physics in mm, :func:`debist.validate.freerun.report_factor`'s default.

    Parameters
    ----------
    report_unit : str or None
        ``[validate] report_unit``; None: mm.

    Returns
    -------
    factor : float
        Multiply q [m] by it.
    unit : str
        The unit as :func:`debist.validate.freerun.report_factor` spells it.

    References
    ----------
    Masoud & Maas 2025, Section 3 (q, the tip displacement [m]).

    Examples
    --------
    >>> physics_factor(None), physics_factor("um"), physics_factor("mV")
    ((1000.0, 'mm'), (1000000.0, 'µm'), (1000.0, 'mm'))
    """
    from debist.core.errors import WorkflowError
    from debist.validate.freerun import report_factor

    try:
        return report_factor("m", report_unit)
    except WorkflowError:  # the data's q is not a length: the physics keeps mm
        return report_factor("m", None)


def display_summary(summary: dict[str, Any], report_unit: str | None = None) -> dict[str, Any]:
    """Return the identify summary with q and every quantity made of q in the report unit.

    The stage records SI (q in m, forces in N or, per unit mass, in q/s^2); a table or page
    shows q, its ranges, q*, the RMS errors and what is per length of q (stiffness N/mm,
    damping N s/mm) in one unit, :func:`debist.validate.freerun.report_factor`'s. Forces in
    N, masses, energies (the barrier, J or J/kg) and per-unit-mass stiffness (1/s^2) keep
    their units; a per-unit-mass force is an acceleration of q (mm/s^2).

    Parameters
    ----------
    summary : dict
        The identify stage's manifest summary (its ``units``: ``q`` SI, ``per_unit_mass``).
    report_unit : str, optional
        ``[validate] report_unit``; None: mm for q in m, else q's own unit.

    Returns
    -------
    dict
        A converted copy (``units.q`` the report unit, ``units.q_si`` the recorded one), or
        ``summary`` itself when the units agree already.

    Raises
    ------
    WorkflowError
        If ``report_unit`` cannot express q.

    References
    ----------
    Masoud & Maas 2025, Eq. 37 (the terms' dimensions); BIPM SI Brochure, 9th ed. (2019),
    Sec. 5.4 (one unit per quantity).

    The identify stage words its excitation warnings with q in mm (q in m) or q's own unit;
    with another report unit their positions are rewritten in it.

    Examples
    --------
    >>> s = {"units": {"q": "m", "per_unit_mass": False}, "q_range": [-0.016, 0.016],
    ...      "backbone": {"k_1": 9.1, "F_0": -0.0068}, "identified": {"d": [[-0.01, 0.0]]}}
    >>> d = display_summary(s)
    >>> d["units"]["q"], d["q_range"], d["backbone"], d["identified"]
    ('mm', [-16.0, 16.0], {'k_1': 0.0091, 'F_0': -0.0068}, {'d': [[-10.0, 0.0]]})
    >>> display_summary(d) is d  # shown in mm already
    True
    >>> said = "g1: never active for q in [-17.8, -10.7] and [2.0, 3.5] mm: g1 ..."
    >>> display_summary({**s, "excitation": {"warnings": [said]}}, "m")["excitation"]
    {'warnings': ['g1: never active for q in [-0.0178, -0.0107] and [0.002, 0.0035] m: g1 ...']}
    """
    import copy

    from debist.validate.freerun import report_factor

    if not summary:  # no identify stage: nothing to convert
        return summary
    given = summary.get("units") or {}
    q_si = given.get("q_si", given.get("q", "m"))
    f, shown = report_factor(q_si, report_unit)
    said_f, said = report_factor(q_si, None)  # the stage words positions in this unit
    if shown == given.get("q", "m") and ("q_si" in given or (said == shown and f == 1.0)):
        return summary  # shown in the report unit already
    per_mass = given.get("per_unit_mass", summary.get("m_q") == 1.0)
    by_dim, _ = display_factors(q_si, report_unit, per_mass)
    out = copy.deepcopy(summary)
    out["units"] = {**given, "q": shown, "q_si": q_si}

    def scale(value: Any, k: float) -> Any:
        if isinstance(value, list):
            return [scale(v, k) for v in value]
        number = isinstance(value, int | float) and not isinstance(value, bool)
        return value * k if number else value

    for key in ("q_range", "q_data_range"):
        if key in out:
            out[key] = scale(out[key], f)
    out["identified"] = {n: scale(v, f) for n, v in (out.get("identified") or {}).items()}
    dims = {"k_1": "F/q", "k_3": "F/q3", "d_v": "Fs/q", "F_c": "F", "F_0": "F", "g_0": "F",
            "g_h": "F"}  # fmt: skip
    for key, dim in dims.items():
        if key in out.get("backbone", {}):
            out["backbone"][key] = scale(out["backbone"][key], by_dim[dim])
    refine = out.get("refine") or {}
    for item in [refine, *(refine.get("candidates") or [])]:
        for key in [k for k in item if k.endswith("_error")]:
            item[key] = scale(item[key], f)
    slip = out.get("slip") or {}
    slip_dims = {"Delta": "q", "k": "F/q", "F": "F", "F_total": "F", "k_total": "F/q"}
    for key, dim in slip_dims.items():
        if key in slip:
            slip[key] = scale(slip[key], by_dim[dim])
    if out.get("inertia"):
        out["inertia"]["q"] = scale(out["inertia"]["q"], f)
    design = out.get("design") or {}
    for row in design.get("equilibria") or []:
        for key, dim in (("q", "q"), ("k", "F/q"), ("k_lo", "F/q"), ("k_hi", "F/q"), ("d", "Fs/q"),
                         ("d_lo", "Fs/q"), ("d_hi", "Fs/q")):  # fmt: skip
            if row.get(key) is not None:
                row[key] = scale(row[key], by_dim[dim])
    if design.get("reason"):
        damping = (by_dim["Fs/q"], summary_units(out)["damping"])
        design["reason"] = _reworded(design["reason"], f, shown, damping)
    excitation = out.get("excitation") or {}
    if excitation.get("warnings") and said != shown:
        excitation["warnings"] = [
            _rescaled(w, f / said_f, said, shown) for w in excitation["warnings"]
        ]
    return out


_NUMBER = r"([-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)"


def _sig(x: float) -> str:
    """Four significant digits, without an exponent from 1e-4 to 1e7 (``12350``, ``0.0178``)."""
    if x == 0 or not math.isfinite(x) or not 1e-4 <= abs(x) < 1e7:
        return f"{x:.4g}"
    decimals = 3 - math.floor(math.log10(abs(x)))
    text = f"{round(x, decimals):.{max(decimals, 0)}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


def _rescaled(text: str, factor: float, old: str, new: str) -> str:
    """Rewrite the q positions of an excitation warning from ``old`` to ``new``.

    The runs of intervals (``[a, b] and [c, d] mm``) and the RBF width (``sigma = x mm``) of
    :mod:`debist.identify.excitation`'s words are multiplied by ``factor``.
    """
    unit = re.escape(old)
    pair = rf"\[{_NUMBER}, {_NUMBER}\]"

    def run(m: re.Match) -> str:
        spans = re.sub(
            pair,
            lambda p: f"[{_sig(float(p.group(1)) * factor)}, {_sig(float(p.group(2)) * factor)}]",
            m.group(1),
        )
        return f"{spans} {new}"

    text = re.sub(rf"((?:{pair})(?: and {pair})*) {unit}(?![\w/^])", run, text)
    return re.sub(
        rf"sigma = {_NUMBER} {unit}(?![\w/^])",
        lambda m: f"sigma = {_sig(float(m.group(1)) * factor)} {new}",
        text,
    )


def _reworded(reason: str, factor: float, unit: str, damping: tuple[float, str] = (1.0, "")) -> str:
    """Write the stability verdict's positions (``in [a, b]``, ``at q = x``) in the report unit.

    A negative damping it names (``d = x``, recorded per length of q in SI and without a
    unit) is multiplied by ``damping[0]`` and given the unit ``damping[1]``.
    """

    def span(m: re.Match) -> str:
        lo, hi = float(m.group(1)) * factor, float(m.group(2)) * factor
        return f"[{_sig(lo)}, {_sig(hi)}] {unit}"

    def point(m: re.Match) -> str:
        return f"at q = {_sig(float(m.group(1)) * factor)} {unit}"

    def damped(m: re.Match) -> str:
        return f"damping d = {float(m.group(1)) * damping[0]:.4g} {damping[1]}".rstrip()

    reason = re.sub(rf"\[{_NUMBER}, {_NUMBER}\]", span, reason)
    reason = re.sub(rf"damping d = {_NUMBER}", damped, reason)
    return re.sub(rf"at q = {_NUMBER}", point, reason)


def sindy_units(summary: dict[str, Any]) -> str:
    """Name the units SINDy's coefficients refer to: q, q_dot, q_ddot in SI, as fitted.

    Parameters
    ----------
    summary : dict
        The identify summary (its ``units``: ``q`` or ``q_si``, the recorded SI unit);
        q in m when it has none.

    Returns
    -------
    str
        E.g. ``"q [m], q_dot [m/s], q_ddot [m/s^2]"``.

    Examples
    --------
    >>> sindy_units({"units": {"q": "mm", "q_si": "m"}})
    'q [m], q_dot [m/s], q_ddot [m/s^2]'
    """
    given = (summary or {}).get("units") or {}
    q = given.get("q_si", given.get("q", "m"))
    return f"q [{q}], q_dot [{q}/s], q_ddot [{q}/s^2]"


def summary_units(summary: dict[str, Any]) -> dict[str, Any]:
    """Units of the identify stage's quantities, derived from the data and the model form.

    The force unit F of Eq. 37 is N when ``m_q`` is a mass and the acceleration of q
    (``q/s^2``) when the curves are identified per unit mass (``m_q = 1``); a parameter's
    unit follows from its term: ``k_1`` [F/q], ``k_3`` [F/q^3], ``d_v`` [F s/q],
    ``F_0``, ``F_c`` [F], ``g_0,i`` [F/h] with ``h = v^2`` or ``v``.

    Parameters
    ----------
    summary : dict
        The identify stage's manifest summary (its ``units`` entry: ``q``, ``v1..vN``,
        ``input_map``, ``per_unit_mass``; q in m, inputs in V, ``h = v^2`` and
        ``m_q == 1`` meaning per unit mass where a summary lacks it).

    Returns
    -------
    dict
        ``q``, ``force``, ``mass`` (``"kg"`` or ``"1"``), ``barrier`` (F q), ``inputs``
        (one unit per input), ``quantities`` (the quantity each input's unit measures:
        ``"voltage"``, ``"acceleration"``, ``"force"``, ...; ``"input"`` when unknown),
        ``input_map`` (``"v2"`` or ``"v"``), ``g_0``, ``s_g`` and ``s_k`` (one unit per input),
        ``stiffness`` (F/q) and ``damping`` (F s/q) and one unit per scalar backbone
        parameter (``k_1``, ``k_3``, ``d_v``, ``F_c``, ``F_0``, ``s_c``, ``s_d``).

    References
    ----------
    Masoud & Maas 2025, Eq. 37-40.
    """
    given = summary.get("units") or {}
    q = given.get("q", "m")
    n_inputs = len(summary.get("backbone", {}).get("g_0") or []) or sum(
        1 for k in given if k[:1] == "v" and k[1:].isdigit()
    )
    inputs = [given.get(f"v{i + 1}", "V") for i in range(n_inputs)]
    per_mass = given.get("per_unit_mass", summary.get("m_q") == 1.0)
    power = "**2" if given.get("input_map", "v2") == "v2" else ""
    force = f"({q})/s**2" if per_mass else "N"

    def unit(dim: str, h: str = "1") -> str:
        expr = dim.replace("F", f"({force})").replace("q", f"({q})")
        return pretty_unit(expr.replace("h", f"({h}){power}"))

    def si_unit(dim: str) -> str:  # the barrier keeps SI (J, J/kg): not a quantity of q
        q_si = given.get("q_si", q)
        si_force = f"({q_si})/s**2" if per_mass else "N"
        return pretty_unit(dim.replace("F", f"({si_force})").replace("q", f"({q_si})"))

    out: dict[str, Any] = {k: unit(d) for k, d in _DIMENSIONS.items()}
    out.update(
        q=pretty_unit(q),
        force=pretty_unit(force),
        mass="1" if per_mass else "kg",
        barrier=_energy(si_unit("F*q"), per_mass),
        inputs=[pretty_unit(v) for v in inputs],
        quantities=[_quantity(v) for v in inputs],
        input_map=given.get("input_map", "v2"),
        stiffness=unit("F/q"),
        damping=unit("F*s/q"),
        g_0=[unit("F/h", v) for v in inputs],
        g_h=[unit("F/h**2", v) for v in inputs],
        s_g=["1"] * n_inputs,
        s_gh=["1"] * n_inputs,
        s_k=["1"] * n_inputs,
    )
    return out


def _quantity(unit: str) -> str:
    """Return the quantity an input's unit measures (``"voltage"``, ``"acceleration"``)."""
    found = lookup_unit(unit)
    return found.quantity if found is not None and found.quantity[:1] != "[" else "input"


def de_inputs(units: dict[str, Any]) -> bool:
    """Whether the inputs are DE voltages with ``h = v^2``, so ``g_i = 1/2 dC_i/dq``.

    Parameters
    ----------
    units : dict
        :func:`summary_units` of the identify summary.

    Returns
    -------
    bool
        True when every input is a voltage and the input map is ``v^2`` (Eq. 33, 37): only
        then is ``2 g_i`` a capacitance gradient ``dC_i/dq`` [F/m] and a switching level a
        voltage.

    References
    ----------
    Masoud & Maas 2025, Eq. 18, 33, 37.
    """
    kinds = units.get("quantities") or []
    return units.get("input_map", "v2") == "v2" and bool(kinds) and set(kinds) == {"voltage"}


def switching_word(units: dict[str, Any], i: int) -> str:
    """Name the switching level of input ``i`` by its input's quantity.

    Parameters
    ----------
    units : dict
        :func:`summary_units` of the identify summary.
    i : int
        The input, 1-based.

    Returns
    -------
    str
        ``"switching voltage"``, ``"switching acceleration"``, ``"switching force"`` ...,
        or ``"switching level"`` when the quantity is unknown.
    """
    kinds = units.get("quantities") or []
    kind = kinds[i - 1] if 0 < i <= len(kinds) else "input"
    return f"switching {kind if kind != 'input' else 'level'}"


def _energy(unit: str, per_mass: bool = False) -> str:
    """Name an energy unit: ``"J"`` for ``N m``, ``"J/kg"`` for ``m^2/s^2`` per unit mass.

    Any other unit is returned as given.
    """
    found = lookup_unit(unit.replace(" ", "*"))
    if found is not None and found.factor == 1.0 and found.si == "J":
        return "J"
    if per_mass and found is not None and found.factor == 1.0 and found.si == "m^2*s^-2":
        return "J/kg"
    return unit


def _fmt(value: Any, digits: int = 4) -> str:
    if value is None:
        return "-"
    if isinstance(value, float) and math.isnan(value):
        return "diverged"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def slip_rows(summary: dict[str, Any]) -> list[tuple[str, str, float]]:
    """Rows of the identified Maxwell-slip elements as physics: deflection, stiffness, force.

    Parameters
    ----------
    summary : dict
        The identify stage's manifest summary (its ``slip`` entry, when the model has them).

    Returns
    -------
    list of (label, unit, value)
        Per element its break-away deflection Delta_e [q], stiffness k_e [F/q] and slip force
        F_e = k_e Delta_e [F]; then the total slip force (gross sliding) and the presliding
        stiffness sum k_e. Empty without elements.

    References
    ----------
    Al-Bender, Lampaert & Swevers 2005.
    """
    slip = summary.get("slip")
    if not slip:
        return []
    units = summary_units(summary)
    q, force = units["q"], units["force"]
    rows = []
    for e, (width, k, f) in enumerate(zip(slip["Delta"], slip["k"], slip["F"], strict=True)):
        name = f"Maxwell-slip element {e + 1}"
        rows += [
            (f"{name}: break-away deflection Delta", q, width),
            (f"{name}: stiffness k", units["stiffness"], k),
            (f"{name}: slip force k Delta", force, f),
        ]
    rows += [
        ("Maxwell-slip: total slip force (gross sliding)", force, slip["F_total"]),
        ("Maxwell-slip: presliding stiffness sum k", units["stiffness"], slip["k_total"]),
    ]
    return rows


def inertia_rows(summary: dict[str, Any]) -> list[tuple[str, str, float]]:
    """Rows of an identified position-dependent inertia m(q): the mass at three positions.

    Parameters
    ----------
    summary : dict
        The identify stage's manifest summary (its ``inertia`` entry: the positions ``q``
        [unit of q] and the masses ``m`` [kg] there, when the model has m(q)).

    Returns
    -------
    list of (label, unit, value)
        ``m(q)`` at each position (the edges of the estimation range and q = 0). Empty with
        the constant m_q of Eq. 37.

    References
    ----------
    Lagrange's equation with kinetic energy 1/2 m(q) q_dot^2 (Goldstein, Classical
    Mechanics, Sec. 1.4).
    """
    inertia = summary.get("inertia")
    if not inertia:
        return []
    units = summary_units(summary)
    return [
        (f"mass m(q) at q = {_fmt(float(q))} {units['q']}", units["mass"], float(m))
        for q, m in zip(inertia["q"], inertia["m"], strict=True)
    ]


def term_rows(summary: dict[str, Any]) -> list[tuple[str, str, float]]:
    """Return the terms beyond Eq. 37 as rows (:func:`slip_rows`, :func:`inertia_rows`)."""
    return slip_rows(summary) + inertia_rows(summary)


def identify_table(summary: dict[str, Any]) -> Table:
    """Tabulate the identified model, with published values where the workflow gives them.

    Parameters
    ----------
    summary : dict
        The identify stage's manifest summary.

    Returns
    -------
    rich.table.Table
    """
    units = summary_units(summary)
    q = units["q"]
    per_mass = units["mass"] == "1"
    table = Table(
        title="Identified model (Eq. 37-40)",
        caption=escape(f"per unit mass (m_q = 1): forces in {units['force']}")
        if per_mass
        else None,
    )
    published = summary.get("published") or {}
    table.add_column("quantity")
    table.add_column("identified", justify="right")
    if published:
        table.add_column("published", justify="right")
    rows = [("T_z", "s", summary["T_z"], None), *mass_rows(summary, units["mass"])]
    if "creep_rate" in summary:  # Eq. 26's Y_MW / eta_MW, identified with the creep term
        rows.append(("creep rate lambda", "1/s", summary["creep_rate"], None))
    rows += [(label, unit, value, None) for label, unit, value in term_rows(summary)]
    for key, value in summary["backbone"].items():
        if not isinstance(value, list):
            rows.append((PARAMETER_LABELS.get(key, key), units.get(key, "?"), value, key))
        elif key in ("g_0", "g_h", "s_g", "s_gh", "s_k") and any(value):
            label = {
                "g_0": "backbone coefficient (a basis term; g_i(q) in Fig. 14)",
                "g_h": "input force quadratic in h(v_i), the departure from Eq. 37's g_i h(v_i),",
                "s_g": "scale of the analytical g_i,",
                "s_gh": "scale of the full model's DE force g_h,i(q) h(v_i)^2 (Fig. 4),",
                "s_k": "scale of the analytical creep force k_bar k_i(q) q_eps,i (Eq. 26),",
            }[key]
            rows += [
                (f"{label} {key},{i + 1}", units[key][i], v, f"{key}_{i + 1}")
                for i, v in enumerate(value)
            ]
    for label, unit, value, key in rows:
        cells = [escape(f"{label} [{unit}]"), _fmt(value)]
        if published:
            cells.append(_fmt(published.get(key)) if key else "")
        table.add_row(*cells)
    for label, key in [
        ("condition number", "condition"),
        ("rank / columns", None),
        ("nonzero parameters", "n_params"),
        ("R^2 of Eq. 40", "fit_r2"),
    ]:
        value = f"{summary['rank']} / {summary['n_columns']}" if key is None else _fmt(summary[key])
        table.add_row(label, value, *([""] if published else []))
    for name, spans in (summary.get("identified") or {}).items():
        text = identified_text(name, spans, summary)
        label = escape(f"{name} identified on q [{q}] in")
        table.add_row(label, text, *([""] if published else []))
    refine = summary.get("refine")
    if refine:
        _refine_rows(table, refine, q, [""] if published else [])
    return table


def _refine_rows(table: Table, refine: dict[str, Any], q: str, pad: list[str]) -> None:
    """Add the simulation-error refinement's rows (free-run RMS in ``q``, its verdict)."""
    # a rejection names its reason (whole record, held-out windows or stability)
    verdict = "accepted" if refine["accepted"] else refine.get("message", "rejected")
    for label, key in [
        ("windows: equation error", "window_rms_equation_error"),
        ("windows: simulation error", "window_rms_simulation_error"),
        ("held-out windows: equation error", "holdout_rms_equation_error"),
        ("held-out windows: simulation error", "holdout_rms_simulation_error"),
        ("estimation: equation error", "full_rms_equation_error"),
        ("estimation: simulation error", "full_rms_simulation_error"),
    ]:
        if math.isfinite(_num_or_nan(refine.get(key))):  # no held-out blocks: no such rows
            table.add_row(escape(f"free-run RMS, {label} [{q}]"), _fmt(refine[key]), *pad)
    table.add_row("refinement", escape(f"{verdict}, {refine['nfev']} evaluations"), *pad)
    if refine.get("candidates"):  # several ridge weights: each one's free-run error
        tried = "; ".join(
            f"{c['prior']:g}: "
            # NaN is a diverged free run, unless the weight was never run (nfev 0)
            + (_fmt(_num_or_nan(c["full_rms_simulation_error"])) if c.get("nfev", 1) else "-")
            + ("" if c["accepted"] else " (rejected)")
            for c in refine["candidates"]
        )
        kept = f"{refine['prior']:g}" if refine["accepted"] else "none"
        label = f"refinement ridge prior: kept {kept}, estimation free-run RMS [{q}] per weight"
        table.add_row(escape(label), escape(tried), *pad)
    elif refine.get("prior"):
        table.add_row("refinement ridge prior", _fmt(refine["prior"]), *pad)


def nrmse_table(rows: list[dict[str, Any]]) -> Table:
    """Tabulate NRMSE (Eq. 41, Table 2 of the paper) per data set and model.

    Parameters
    ----------
    rows : list of dict
        Rows of ``nrmse.parquet``.

    Returns
    -------
    rich.table.Table
    """
    table = Table(title="Free-run validation (NRMSE, Eq. 41)")
    params = bool(rows) and "n_params" in rows[0]
    keys = _nrmse_keys(rows)
    cols = ["data set", "role", "model"]
    cols += [f"NRMSE({k.removeprefix('nrmse_')})" for k in keys] + ["RMS(q)"]
    for col in cols + (["params"] if params else []):
        table.add_column(col, justify="left" if col in ("data set", "role", "model") else "right")
    table.add_column("verdict")
    for r in rows:
        status = r.get("status") or "diverged"
        failed = status if status != "ok" else "diverged"
        pct = [
            ("n/a" if not_modelled(r, k) else failed if math.isnan(r[k]) else f"{100 * r[k]:.2f} %")
            for k in keys
        ]
        extra = [str(r["n_params"])] if params else []
        rms_cell = failed if math.isnan(r["rms_q"]) else f"{_fmt(r['rms_q'])} {r['rms_unit']}"
        word = r.get("verdict") or verdict(r, rows)
        table.add_row(r["dataset"], r["role"], r["model"], *pct, rms_cell, *extra, word)
    return table


def _nrmse_keys(rows: list[dict[str, Any]]) -> list[str]:
    """Return the NRMSE columns of a table's rows, in the order the reports show them."""
    keys = ["nrmse_q", "nrmse_phi", "nrmse_q_dot", "nrmse_q_ddot"]
    return [k for k in keys if rows and k in rows[0]]


def nrmse_frame(rows: list[dict[str, Any]]) -> Any:
    """Return the NRMSE table the CLI prints (:func:`nrmse_table`) as numbers in a DataFrame.

    Parameters
    ----------
    rows : list of dict
        Rows of ``nrmse.parquet`` (NRMSE stored as fractions).

    Returns
    -------
    pandas.DataFrame
        Columns ``data set, role, model``, ``NRMSE(q) [%]`` and the others the rows have
        (``NRMSE(phi) [%]``, ``NRMSE(q_dot) [%]``, ``NRMSE(q_ddot) [%]``: percent of the
        measured range, Eq. 41; NaN where the model does not predict the quantity or did
        not finish), ``RMS(q)`` and ``RMS(q) unit``, ``params`` when the rows have it,
        ``status`` and ``verdict`` (the CLI's words).

    Examples
    --------
    >>> rows = [{"dataset": "a", "role": "validation", "model": "rbf", "nrmse_q": 0.0123,
    ...          "rms_q": 0.2, "rms_unit": "mm", "status": "ok", "nrmse_q_baseline": 0.3}]
    >>> frame = nrmse_frame(rows)
    >>> round(float(frame.loc[0, "NRMSE(q) [%]"]), 6), frame.loc[0, "verdict"]
    (1.23, 'ok')
    """
    import pandas as pd

    keys = _nrmse_keys(rows)
    params = bool(rows) and "n_params" in rows[0]
    records = []
    for r in rows:
        record: dict[str, Any] = {"data set": r["dataset"], "role": r["role"], "model": r["model"]}
        for k in keys:
            value = math.nan if not_modelled(r, k) else _num_or_nan(r[k])
            record[f"NRMSE({k.removeprefix('nrmse_')}) [%]"] = 100.0 * value
        record["RMS(q)"] = _num_or_nan(r["rms_q"])
        record["RMS(q) unit"] = r["rms_unit"]
        if params:
            record["params"] = int(r["n_params"])
        record["status"] = r.get("status") or "diverged"
        record["verdict"] = verdict(r, rows)
        records.append(record)
    return pd.DataFrame.from_records(records)


#: Models that predict q only (a NARX model): their velocity and acceleration columns are "n/a".
OUTPUT_ONLY = ("narx",)


def not_modelled(row: dict[str, Any], key: str) -> bool:
    """Whether column ``key`` of an NRMSE row is one its model does not predict.

    Examples
    --------
    >>> not_modelled({"model": "narx"}, "nrmse_q_dot")
    True
    >>> not_modelled({"model": "rbf"}, "nrmse_q_dot")
    False
    """
    return row.get("model") in OUTPUT_ONLY and key in ("nrmse_q_dot", "nrmse_q_ddot")


def _num_or_nan(value: Any) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        return math.nan
    return out


def verdict(row: dict[str, Any], rows: list[dict[str, Any]] | None = None) -> str:
    """Word the verdict of an NRMSE row (Eq. 41), never empty.

    Parameters
    ----------
    row : dict
        A row of ``nrmse.parquet`` (``nrmse_q``, ``nrmse_q_baseline``, ``status``,
        ``reason``, ``diverged``, ``model``, ``dataset``, ``simulation_only``,
        ``under_excited``, ``extrapolated``).
    rows : list of dict, optional
        The whole table: a row is also called worse than another model whose free run of
        the same data set has a lower NRMSE(q).

    Returns
    -------
    str
        ``"unstable: ..."``, ``"diverged: ..."``, ``"not better than the mean ..."``,
        ``"poor: ..."`` (above :data:`~debist.core.metrics.POOR_SHARE` of the mean's NRMSE),
        ``"fragile: ..."`` (more than 2.5 % of the bootstrap replicates lose the motion),
        ``"worse than <model> (x %)"``, or ``"ok"``; the last three may combine. A row with
        ``under_excited`` starts with ``"under-excited: <why>"``, one with ``extrapolated``
        (an input applied where the estimation never applied it,
        :func:`debist.identify.driven.beyond_driven`) with ``"extrapolated: <where>"``, then
        one with ``simulation_only`` (its model's fitted curves identified nowhere,
        :func:`debist.identify.bands.simulation_only`) with ``"simulation only: <which>"``;
        each replaces ``"ok"``.

    Examples
    --------
    >>> verdict({"nrmse_q": 0.201, "nrmse_q_baseline": 0.230, "status": "ok"})
    'poor: 87 % of the mean baseline error (a lost switch?)'
    >>> rows = [{"model": "rbf", "dataset": "a", "nrmse_q": 0.02, "nrmse_q_baseline": 0.3},
    ...         {"model": "narx", "dataset": "a", "nrmse_q": 0.01, "nrmse_q_baseline": 0.3}]
    >>> verdict(rows[0], rows), verdict(rows[1], rows)
    ('worse than narx (1.00 %)', 'ok')
    >>> verdict({"nrmse_q": 0.004, "nrmse_q_baseline": 0.2, "replicates": 40,
    ...          "replicates_poor": 0.05, "nrmse_q_hi": 0.193})
    'fragile: 5 % of 40 bootstrap replicates lose the motion (95 % of their NRMSE(q) up to 19.3 %)'
    >>> verdict({"nrmse_q": 0.004, "nrmse_q_baseline": 0.2, "replicates": 100,
    ...          "replicates_poor": 0.01, "nrmse_q_hi": 0.0149})
    'ok'
    >>> verdict({"nrmse_q": 0.004, "nrmse_q_baseline": 0.2,
    ...          "under_excited": "one spectral line at 2 Hz in 'a'"})
    "under-excited: one spectral line at 2 Hz in 'a'"
    >>> verdict({"nrmse_q": 0.004, "nrmse_q_baseline": 0.2,
    ...          "simulation_only": "d, g1, g2 identified nowhere"})
    'simulation only: d, g1, g2 identified nowhere'
    >>> verdict({"nrmse_q": 0.004, "nrmse_q_baseline": 0.2,
    ...          "extrapolated": "v2 applied at q = 3 to 9 mm (40 samples), where ..."})
    'extrapolated: v2 applied at q = 3 to 9 mm (40 samples), where ...'
    """
    words = _verdict(row, rows)
    caveats = [
        f"{label}: {text}"
        for label, text in (
            ("under-excited", row.get("under_excited")),
            ("extrapolated", row.get("extrapolated")),
            ("simulation only", row.get("simulation_only")),
        )
        if isinstance(text, str) and text
    ]
    if not caveats:
        return words
    return "; ".join(caveats) + ("" if words == "ok" else f"; {words}")


def _verdict(row: dict[str, Any], rows: list[dict[str, Any]] | None) -> str:
    """Word the verdict of :func:`verdict` without the under-excitation."""
    if row.get("status") == "unstable":
        return f"unstable: {row.get('reason', '')}"
    base = _num_or_nan(row.get("nrmse_q_baseline"))
    value = _num_or_nan(row.get("nrmse_q"))
    if math.isnan(value):
        return "diverged: left twice the estimation range" if row.get("diverged") else "not scored"
    if not math.isnan(base) and value >= base:
        return f"not better than the mean (NRMSE {100 * base:.1f} %): q is not predicted"
    words = []
    if not math.isnan(base) and value > POOR_SHARE * base:
        words.append(
            f"poor: {100 * value / base:.0f} % of the mean baseline error (a lost switch?)"
        )
    top = _num_or_nan(row.get("nrmse_q_hi"))  # the replicates' 97.5 %: a lost switch there
    if not math.isnan(base) and top > POOR_SHARE * base:
        words.append(
            f"fragile: {100 * _num_or_nan(row.get('replicates_poor')):.0f} % of "
            f"{int(row['replicates'])} bootstrap replicates lose the motion (95 % of their "
            f"NRMSE(q) up to {100 * top:.1f} %)"
        )
    better = [
        (_num_or_nan(r.get("nrmse_q")), r.get("model"))
        for r in rows or []
        if r.get("dataset") == row.get("dataset") and r.get("model") != row.get("model")
    ]
    better = [(v, m) for v, m in better if v < value]
    if better:
        v, m = min(better)
        words.append(f"worse than {m} ({100 * v:.2f} %)")
    return "; ".join(words) or "ok"


def identified_text(name: str, spans: list, summary: dict[str, Any]) -> str:
    """Word where a curve is identified, or why nowhere.

    Parameters
    ----------
    name : str
        Curve name (``restoring``, ``d``, ``g1`` ..).
    spans : list of [float, float]
        The intervals of q where it is marked identified [unit of q in the summary].
    summary : dict
        The identify summary (its ``bands``: ``model_error`` per curve kind and the band
        ``tolerance``).

    Returns
    -------
    str
        ``"[a, b], [c, d]"``; or ``"nowhere: ..."`` with the reason the calibrated model error
        gives when it alone makes the band too wide (a gain's model error is a share of its
        local magnitude, so its band is narrow enough only where the gain is small).

    References
    ----------
    Kennedy & O'Hagan 2001, J. R. Stat. Soc. B 63(3), 425-464 (model discrepancy beside
    parameter uncertainty).

    Examples
    --------
    >>> bands = {"bands": {"model_error": {"d": 0.652, "g": 0.576}, "tolerance": 0.2}}
    >>> identified_text("d", [], bands)[:60]
    'nowhere: its calibrated model error alone (65 % of its scale'
    >>> identified_text("g1", [[0.1, 0.2]], bands)
    '[0.1, 0.2]'
    """
    if spans:
        return ", ".join(f"[{_sig(a)}, {_sig(b)}]" for a, b in spans)
    bands = summary.get("bands") or {}
    kind = "g" if name[:1] == "g" and name[1:].isdigit() else name
    err, tol = (bands.get("model_error") or {}).get(kind), bands.get("tolerance")
    if err is None or tol is None:
        return "nowhere"
    if kind == "g":
        return (
            f"nowhere: its calibrated model error ({100 * err:.0f} % of the local gain) keeps the "
            f"band within the tolerance ({100 * tol:.0f} % of its scale) only where the gain is "
            f"below {100 * tol / (2 * err):.0f} % of its scale, where the data support it nowhere"
        )
    if 2 * err > tol:
        return (
            f"nowhere: its calibrated model error alone ({100 * err:.0f} % of its scale each side) "
            f"is wider than the band tolerance ({100 * tol:.0f} %)"
        )
    return (
        f"nowhere: its band is wider than the tolerance ({100 * tol:.0f} % of its scale) or the "
        "data do not support it (the excitation warnings say where)"
    )


def with_verdicts(table: Any) -> Any:
    """Add a ``verdict`` column to an NRMSE table: the words the display prints for each row.

    Parameters
    ----------
    table : pandas.DataFrame
        Rows of ``nrmse.parquet`` (a ``verdict`` column already there is recomputed: a row's
        verdict depends on the other models' rows of its data set).

    Returns
    -------
    pandas.DataFrame
        ``table`` with ``verdict`` = :func:`verdict` of each row against the whole table.

    Examples
    --------
    >>> import pandas as pd
    >>> t = pd.DataFrame({"dataset": ["a", "a"], "model": ["rbf", "narx"], "status": "ok",
    ...                   "nrmse_q": [0.30, 0.01], "nrmse_q_baseline": [0.25, 0.25]})
    >>> with_verdicts(t).verdict.tolist()
    ['not better than the mean (NRMSE 25.0 %): q is not predicted', 'ok']
    """
    rows = table.drop(columns="verdict", errors="ignore").to_dict(orient="records")
    return table.assign(verdict=[verdict(r, rows) for r in rows])


def published_table(
    rows: list[dict[str, Any]], published: list[dict[str, Any]], order: list[str] | None = None
) -> Table | None:
    """Our free-run RMS beside the published results on the same data sets.

    Parameters
    ----------
    rows : list of dict
        Rows of ``nrmse.parquet``.
    published : list of dict
        ``{model = "...", rms = {dataset = value}}`` entries of ``[validate]``.
    order : list of str, optional
        Data set order of the workflow (default: as in the first entry).

    Returns
    -------
    rich.table.Table or None
        None when nothing is published.
    """
    if not published:
        return None
    sets = list(published[0]["rms"])
    if order:
        sets = sorted(sets, key=lambda s: order.index(s) if s in order else len(order))
    unit = rows[0]["rms_unit"] if rows else ""
    table = Table(title=escape(f"Free-run RMS error [{unit}] against published results"))
    table.add_column("model")
    for s in sets:
        table.add_column(s, justify="right")
    by_model: dict[str, dict[str, float]] = {}
    for r in rows:
        by_model.setdefault(r["model"], {})[r["dataset"]] = r["rms_q"]
    for model, values in by_model.items():
        table.add_row(f"debist {model} (this run)", *[_fmt(values.get(s), 3) for s in sets])
    for entry in published:
        table.add_row(entry["model"], *[_fmt(entry["rms"].get(s), 3) for s in sets])
    return table


def analyze_table(summary: dict[str, Any], report_unit: str | None = None) -> Table:
    """Tabulate the design analysis: equilibria, bifurcation points, full vs reduced model.

    Parameters
    ----------
    summary : dict
        Summary of the analyze stage's manifest (lengths in [m]).
    report_unit : str, optional
        ``[validate] report_unit``: the equilibria q are shown in it (:func:`physics_factor`;
        default mm); the design lengths b and z_b stay in mm, as Fig. 3 draws them.

    Returns
    -------
    rich.table.Table

    References
    ----------
    Masoud & Maas 2025, Section 3.3, Fig. 3, 4, 7.
    """
    f, unit = physics_factor(report_unit)
    table = Table(title=f"Design analysis at b = {1e3 * summary['b']:.2f} mm (Section 3)")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for state, points in summary["operating_points"].items():
        cells = [
            f"{_point(f * p['q'], f * 1e-3)}" + ("" if p["stable"] else " (unstable)")
            for p in points
        ]
        v1, v2 = state.removeprefix("v1_").removesuffix("kV").split("kV_v2_")
        label = escape(f"equilibria q [{unit}], (v1, v2) ({v1}, {v2}) kV")
        table.add_row(label, ", ".join(cells) or "none")
    table.add_row(escape("pitchfork z_b,min [mm]"), _fmt(1e3 * summary["z_b_min"]))
    table.add_row(escape("switching limit z_b,max [mm]"), _fmt(1e3 * summary["z_b_max"]))
    table.add_row("full vs reduced NRMSE(q), Fig. 7", f"{100 * summary['nrmse_q']:.2f} %")
    table.add_row("full vs reduced NRMSE(phi), Fig. 7", f"{100 * summary['nrmse_phi']:.2f} %")
    return table


def _point(value: float, mm: float) -> str:
    """Write a position to a micrometre (``mm``: one millimetre in the shown unit), signed."""
    decimals = max(0, 3 - math.floor(math.log10(mm))) if mm > 0 else 3
    return f"{round(value, decimals) + 0.0:+.{decimals}f}"


def rig_table(summary: dict[str, Any], report_unit: str | None = None) -> Table:
    """Tabulate the virtual rig's experiments.

    Parameters
    ----------
    summary : dict
        Summary of the rig stage's manifest (per experiment; lengths in [m]).
    report_unit : str, optional
        ``[validate] report_unit`` for the q range (default mm,
        :func:`debist.validate.freerun.report_factor`).

    Returns
    -------
    rich.table.Table

    Raises
    ------
    WorkflowError
        If ``report_unit`` is not a length unit.
    """
    from debist.validate.freerun import report_factor

    f, unit = report_factor("m", report_unit)
    digits = max(0, 2 - round(math.log10(f / 1e3)))  # 0.01 mm
    table = Table(title="Virtual rig")
    for col in ("experiment", "samples", f"q range [{unit}]", "well changes", "saturated", "nfev"):
        table.add_column(escape(col), justify="left" if col == "experiment" else "right")
    for name, s in summary.items():
        table.add_row(
            name,
            str(s["samples"]),
            f"{f * s['q_min']:+.{digits}f} ... {f * s['q_max']:+.{digits}f}",
            str(s["well_changes"]),
            str(s["saturated"]),
            str(s["nfev"]),
        )
    return table


def mass_rows(summary: dict[str, Any], unit: str) -> list[tuple[str, str, Any, str | None]]:
    """Rows of the identified model's mass: m_q and, with ``effective_mass``, its ratio lambda.

    With the effective-mass scale applied (:mod:`debist.identify.mass`) the model's m_q is the
    rigid mass whose effective value at the wells, with the lagged damping's apparent mass, is
    the physical one; the ratio lambda says by how much the fitted curves were scaled up.

    A model identified per unit mass (``m_q = 1``, ``unit == "1"``) has no physical mass: its
    curves are accelerations of q (forces per the unknown mass), m_q is 1, and with the scale
    applied m_q is the rigid mass in multiples of the effective mass at the wells (``1 /
    lambda``), which its rows say in words with the unit ``-``.

    Parameters
    ----------
    summary : dict
        The identify summary (``m_q`` and optionally ``effective_mass``).
    unit : str
        The mass unit (``kg``, or ``1`` per unit mass).

    Returns
    -------
    list of (label, unit, value, published key)

    References
    ----------
    Masoud & Maas 2025, Eq. 37 (m_q, the mass of the reduced coordinate q).
    """
    info = summary.get("effective_mass")
    per_mass = unit == "1"
    if per_mass:
        plain = (
            "mass m_q: the unit mass (per-unit-mass model: its forces are accelerations of q, "
            "per the unknown physical mass)",
            "-", summary["m_q"], "m_q",
        )  # fmt: skip
        rigid = (
            "rigid mass m_q, in multiples of the effective mass at the wells (per-unit-mass "
            "model: the curves are per the effective mass, the physical one is unknown)",
            "-", summary["m_q"], "m_q",
        )  # fmt: skip
    else:
        plain = ("mass m_q", unit, summary["m_q"], "m_q")
        rigid = ("rigid mass m_q (effective mass at the wells: m_q lambda, the physical one)",
                 unit, summary["m_q"], "m_q")  # fmt: skip
    if not info:
        return [plain]
    if info.get("applied"):
        return [
            rigid,
            ("effective-mass ratio lambda (the fitted curves divided by it)", "-",
             info["ratio"], None),
        ]  # fmt: skip
    return [
        plain,
        (f"effective-mass ratio lambda (not applied: {info.get('reason', '')})", "-",
         info["ratio"], None),
    ]  # fmt: skip


def small_signal_cells(
    row: dict[str, Any], fmt: Callable[..., str], units: Sequence[str] | None = None
) -> list[str]:
    """Cells ``d``, ``k*``, ``f_n``, ``zeta``, ``barrier`` of a design-table row.

    Empty but at a well (``static_stable``); ``k*`` and ``f_n`` carry their 95 % band in
    brackets where the row has one (``k_lo``, ``k_hi``, ``f_n_lo``, ``f_n_hi``:
    :func:`debist.identify.bands.stiffness_bands`); ``d`` and ``zeta`` say "not identified"
    where the damping curve is not identified at ``q*`` (``d_identified`` False).

    Parameters
    ----------
    row : dict
        One equilibria record of the identify summary's ``design``.
    fmt : callable
        Number formatter ``fmt(value, digits) -> str``.
    units : sequence of str, length 5, optional
        A unit to write after each value (before its band); default none (a table header
        carries them).

    Returns
    -------
    list of str, length 5
    """
    if not row.get("static_stable"):
        return [""] * 5
    cells = []
    for i, key in enumerate(("d", "k", "f_n", "zeta", "barrier")):
        text = fmt(row.get(key))
        if units and units[i] and row.get(key) is not None:
            text += f" {units[i]}"
        lo, hi = _num_or_nan(row.get(f"{key}_lo")), _num_or_nan(row.get(f"{key}_hi"))
        if math.isfinite(lo) and math.isfinite(hi):
            text += f" ({fmt(lo, 3)}-{fmt(hi, 3)})"
        if key in ("d", "zeta") and row.get("d_identified") is not None and not row["d_identified"]:
            text += " (not identified)"
        cells.append(text)
    return cells


def stiffness_caption(summary: dict[str, Any]) -> str:
    """Say what the brackets of the design table's ``k*`` and ``f_n`` hold (model error or not)."""
    from debist.identify.bands import STIFFNESS_BOOTSTRAP_LABEL, STIFFNESS_LABEL

    bands = summary.get("bands") or {}
    if bands.get("stiffness_label"):  # the identify stage's own words
        return str(bands["stiffness_label"])
    return STIFFNESS_LABEL if bands.get("model_error") else STIFFNESS_BOOTSTRAP_LABEL


def equilibrium_kind(row: dict[str, Any]) -> str:
    """Describe one equilibrium row: well, well with negative damping, or saddle.

    A row the data do not support (``identified`` false: the force curve it sits on is not
    identified at ``q*``, :func:`debist.identify.design.mark_identified`) says so.

    Parameters
    ----------
    row : dict
        One row of the identify summary's ``design.equilibria``.

    Returns
    -------
    str
    """
    well = bool(row.get("static_stable"))
    kind = ("well" if row.get("stable") else "well, negative damping") if well else "saddle"
    if row.get("identified") is False:
        kind += " (not identified at q*)"
    return kind


def auto_line(summary: dict[str, Any]) -> str:
    """Describe the hyper-parameter search of ``[identify.auto]`` in one line (or ``""``).

    Parameters
    ----------
    summary : dict
        The identify stage's manifest summary (its ``auto`` entry).

    Returns
    -------
    str
        The chosen setting, the number of candidates and folds, the best mean score with its
        standard error; when the folds disagree (``undecided``) a warning that the choice
        is not supported by the estimation data; and the candidates left out before the
        search (``auto_skipped``).
    """
    auto, skipped = summary.get("auto"), summary.get("auto_skipped", "")
    if not auto:
        return f"hyper-parameters: {skipped}" if skipped else ""
    chosen = ", ".join(f"{k} = {v!r}" for k, v in auto["chosen"].items())
    best = auto["candidates"][auto["best"]]
    score = (
        f"best held-out NRMSE(q) {100 * best['mean']:.3g} % +- {100 * best['se']:.2g} %"
        if best["mean"] is not None and best["se"] is not None
        else "no candidate scored"
    )
    line = (
        f"hyper-parameters: {chosen}, chosen among {auto['n_candidates']} candidates by "
        f"blocked {auto['folds']}-fold cross-validation ({score}; identify/autotune.parquet)"
    )
    if auto.get("undecided"):
        line += (
            ": undecided, the folds disagree (one lost a switch?), so the one-standard-error "
            "rule admits nearly every candidate; the estimation data do not support the choice"
        )
    return f"{line}; {skipped}" if skipped else line


def switching_note(row: dict[str, Any]) -> str:
    """Return the caveat of one switching-voltage row, or ``""`` when the data support it.

    The identified model's switching voltage of input i rests on the restoring force and
    ``g_i`` between its well and the fold where the well vanishes; where either is not
    identified there (:func:`debist.identify.design.mark_switching`) the number is the
    model's, not the data's, and the row says so.

    Parameters
    ----------
    row : dict
        One row of the identify summary's ``design.switching``.

    Returns
    -------
    str
        ``" (not identified: g<i> or the restoring force between the well and the fold)"``
        or ``""``.
    """
    value = row.get("v_switch")
    if row.get("identified") is False and value is not None and value == value:  # not NaN
        i = row.get("input")
        return f" (not identified: g{i} or the restoring force between the well and the fold)"
    return ""


#: Console width [characters] below which the design table is printed as lines
#: (:func:`design_lines`): its nine columns need about 120 to stay readable.
DESIGN_TABLE_WIDTH = 120


def _wells(design: dict[str, Any]):
    """Yield the equilibria shown with their inputs as text (at held levels only wells)."""
    for r in design["equilibria"]:
        if r["level"] != 0 and not r["static_stable"]:
            continue  # at held levels only the wells
        yield r, ", ".join(_fmt(r[k], 4) for k in sorted(r) if k[:1] == "v" and k[1:].isdigit())


def _switching_text(r: dict[str, Any], units: dict[str, Any]) -> str:
    """Word a switching row: its level with unit (or why there is none) and its caveat."""
    unit = dict(enumerate(units["inputs"], 1)).get(r["input"], "V")
    text = f"{_fmt(r['v_switch'], 4)} {unit}" if r["v_switch"] is not None else r["reason"]
    return text + switching_note(r)


def _design_heading(summary: dict[str, Any]) -> tuple[str, str]:
    """Title and caption (plain text) of the design table."""
    design = summary["design"]
    analytical = any(r.get("model") == "analytical" for r in design["equilibria"])
    title = "Equilibria and switching (identified" + (" beside analytical)" if analytical else ")")
    caption = (
        f"identified model: {design['verdict']} ({design['reason']}); at each well the "
        "total damping d(q*), the tangent stiffness k* = dF/dq and f_n = sqrt(k*/m_q)/(2 pi); "
        + stiffness_caption(summary)
    )
    return title, caption


def design_lines(summary: dict[str, Any]) -> list[str]:
    """Word the design table of :func:`design_table` one line per row, for a narrow terminal.

    Parameters
    ----------
    summary : dict
        The identify stage's manifest summary (its ``design`` entry).

    Returns
    -------
    list of str
        A title line, one line per equilibrium (``model kind at q* = ... [unit] (inputs ...):
        d(q*) ..., k* ..., f_n ..., zeta ..., barrier ...``) and per switching level, and the
        caption; empty without design numbers.

    References
    ----------
    Masoud & Maas 2025, Sec. 3.3, Eq. 37.
    """
    if not summary.get("design"):
        return []
    units = summary_units(summary)
    title, caption = _design_heading(summary)
    names = ("d(q*)", "k*", "f_n", "zeta", "barrier")
    unit = (units["damping"], units["stiffness"], "Hz", "", units["barrier"])
    lines = [title + ":"]
    for r, volts in _wells(summary["design"]):
        cells = small_signal_cells(r, _fmt, unit)
        parts = [f"{n} {c}" for n, c in zip(names, cells, strict=True) if c and c != "-"]
        lines.append(
            f"  {r['model']} {equilibrium_kind(r)} at q* = {_fmt(r['q'])} {units['q']} "
            f"(inputs {volts})" + (": " + ", ".join(parts) if parts else "")
        )
    for r in summary["design"]["switching"]:
        word = switching_word(units, r["input"])
        lines.append(f"  {r['model']} {word}, input {r['input']}: {_switching_text(r, units)}")
    return [*lines, caption]


def design_table(summary: dict[str, Any]) -> Table | None:
    """Tabulate the identified model's equilibria and switching voltages (and the analytical).

    Parameters
    ----------
    summary : dict
        The identify stage's manifest summary (its ``design`` entry).

    Returns
    -------
    rich.table.Table or None
        None when the summary has no design numbers.

    References
    ----------
    Masoud & Maas 2025, Sec. 3.3, Eq. 37.
    """
    design = summary.get("design")
    if not design:
        return None
    units = summary_units(summary)
    inputs = sorted(set(units["inputs"])) or ["V"]
    title, caption = _design_heading(summary)
    table = Table(title=title, caption=escape(caption))
    cols = (
        "model",
        f"inputs [{', '.join(inputs)}]",
        f"q* [{units['q']}]",
        "kind",
        f"d(q*) [{units['damping']}]",
        f"k* [{units['stiffness']}]",
        "f_n [Hz]",
        "zeta [1]",
        f"barrier [{units['barrier']}]",
    )
    for i, col in enumerate(cols):
        table.add_column(escape(col), justify="left" if i in (0, 3) else "right")
    for r, volts in _wells(design):
        small = small_signal_cells(r, _fmt)
        table.add_row(r["model"], volts, _fmt(r["q"]), equilibrium_kind(r), *small)
    for r in design["switching"]:
        label = f"{switching_word(units, r['input'])}, input {r['input']}"
        table.add_row(r["model"], label, "", escape(_switching_text(r, units)), *[""] * 5)
    return table


def wrap_equation(equation: str, indent: str = "    ") -> list[str]:
    """Split an equation ``lhs = t1 + t2 - t3 ...`` into one line per term, signs kept.

    Parameters
    ----------
    equation : str
        One equation as SINDy prints it (terms joined by `` + `` and `` - ``).
    indent : str, optional
        Put before every term line.

    Returns
    -------
    list of str
        ``["lhs =", "    1.9e-01", "    + 1.4e+02 q", "    - 1.0e+01 q_dot", ...]``.

    Examples
    --------
    >>> wrap_equation("q_ddot = 2.0 + 3.5e-01 q - 1.0e+00 q_dot")
    ['q_ddot =', '    2.0', '    + 3.5e-01 q', '    - 1.0e+00 q_dot']
    """
    lhs, sep, rhs = equation.partition(" = ")
    if not sep:
        return [equation]
    pieces = re.split(r" ([+-]) (?=[0-9.])", rhs)
    lines = [f"{lhs} =", indent + pieces[0]]
    lines += [
        f"{indent}{sign} {term}" for sign, term in zip(pieces[1::2], pieces[2::2], strict=True)
    ]
    return lines
