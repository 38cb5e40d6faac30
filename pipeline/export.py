"""The identified model as self-contained code for a controller: C99, MATLAB or NumPy.

``debist export`` writes the RBF model of Eq. 37 (with its backbone and physics prior) as
plain source files a controller or a Simulink model can build without debist (C99, a MATLAB
function file for a Simulink MATLAB Function block or Octave, or NumPy): the term table
of :meth:`pipeline.identify.model.RBFModel.table_model` as constant arrays, the state
derivative, one classical RK4 step with inputs linear between two samples (the scheme of
debist's free run with ``substeps = 1`` and ``interpolation = "linear"``, so the exported
code reproduces :func:`pipeline.simulate.simulate` to rounding), and the characteristic
curves restoring force, d(q) and g_i(q) as a lookup table. The generators are pure functions
returning file contents; :func:`load_identified` reads a run's identified model and checks
that the identify stage is up to date.

References
----------
Masoud & Maas 2025, Eq. 37-40; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1
(classical RK4); ISO/IEC 9899:1999 (C99); MathWorks, "Function Basics" and "MATLAB Function
block" (local functions, fixed-size code generation); NumPy ``numpy.interp`` (the table
semantics).
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline import __version__
from pipeline.errors import ArtifactError, WorkflowError
from pipeline.termtable import BASE_GAUSS, BASE_TABLE, S_POW, S_TANH

__all__ = [
    "CURVE_POINTS",
    "C_FILES",
    "FORMATS",
    "MATLAB_FILE",
    "PYTHON_FILE",
    "ExportInfo",
    "c_sources",
    "curve_table",
    "export_files",
    "load_identified",
    "matlab_source",
    "python_source",
]

#: Export formats of ``debist export --format``.
FORMATS = ("c", "matlab", "python")
#: File names of the C export (header, source).
C_FILES = ("debist_model.h", "debist_model.c")
#: File name of the MATLAB export (the function's name is the file's).
MATLAB_FILE = "debist_model.m"
#: File name of the Python export.
PYTHON_FILE = "debist_model.py"
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
        The run digest (:func:`pipeline.outdir.run_digest`); None when a stage of the
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


# ------------------------------------------------------------------ model arrays
def _arrays(model) -> dict[str, Any]:
    """Collect the constants of the exported model from its term table."""
    tm = model.table_model()
    t = tm.table
    lag = float(model.T_z) > 0
    return {
        "n_inputs": t.n_inputs,
        "n_states": 3 if lag else 2,
        "lag": lag,
        "T_z": float(model.T_z),
        "m_q": float(tm.mass[0]),
        "v_c": float(t.coulomb_velocity),
        "input_map": t.input_map,
        "q_range": (float(model.q_range[0]), float(model.q_range[1])),
        "max_step": 1.5 * float(model.T_z) if lag else np.inf,
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
        ``restoring`` (``c(q) q + F_0`` [N], the static force at v = 0), ``d`` [N s/m],
        ``g1`` .. ``gN`` [N/V^2 when h = v^2]; per unit mass when ``m_q = 1``.
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


# ------------------------------------------------------------------ header text
def _describe(info: ExportInfo, arr: dict[str, Any], names: list[str]) -> list[str]:
    """Lines of the header comment shared by every format (without comment markers)."""
    lo, hi = arr["q_range"]
    hmap = "v^2" if arr["input_map"] == "v2" else "v"
    lag = arr["lag"]
    state = "[q, q_dot, z]" if lag else "[q, q_dot]"
    lines = [
        "The identified model of debist (Masoud & Maas 2025, Eq. 37):",
        "  m_q q'' = sum_k w_k term_k(q, s, h),  h_i = h(v_i) = " + hmap,
        "  friction state z' = (q_dot - z) / T_z, s = z"
        if arr["lag"]
        else "  T_z = 0: no friction state, s = q_dot",
        f"State x = {state}" + ("; start with z = q_dot (the filter at rest)." if lag else "."),
        f"Inputs v [V] (n = {arr['n_inputs']}); mapped inputs h [V^2 or V].",
        "Units: q [m], q_dot [m/s], t and dt [s], v [V]; forces [N] with",
        f"  m_q = {arr['m_q']!r} (per unit mass [m/s^2] when m_q = 1).",
        f"Valid q range (estimation data): [{lo!r}, {hi!r}] m; outside it the",
        "  Gaussian bases are held at the range's edge and the tables at their ends."
        if arr["clipped"]
        else "  Gaussian bases decay (not clipped) and the tables hold their end values.",
    ]
    if info.identified:
        for name in names:
            if name in info.identified:
                spans = ", ".join(f"[{a!r}, {b!r}]" for a, b in info.identified[name])
                lines.append(f"Curve {name} identified (95 % band) on q in: {spans or 'none'} m")
    if arr["lag"]:
        lines.append(
            f"RK4 is stable for dt <= 1.5 T_z = {arr['max_step']!r} s; "
            "split longer sample times into sub-steps."
        )
    lines += [
        "rk4_step: one classical RK4 step with the inputs linear between v0 (at t) and",
        "  v1 (at t + dt), as debist's free run (substeps = 1, interpolation = linear).",
        f"Curves table: {len(names)} curves ({', '.join(names)}) on {CURVE_POINTS} points,",
        "  interpolated linearly, held outside the grid.",
        f"Workflow: {info.workflow or 'n/a'}",
        f"Run digest: {info.run_digest or 'n/a (not every stage of the workflow has run)'}",
        f"identify/manifest.json sha256: {info.identify_manifest or 'n/a'}",
        f"Generated by debist {info.version} (debist export); do not edit.",
    ]
    return lines


# ------------------------------------------------------------------ C99
def _literal(x: float, infinity: str) -> str:
    """Format a double that round-trips (``repr``), ``infinity`` (signed) for infinities."""
    x = float(x)
    if np.isnan(x):
        raise ArtifactError("the model has a NaN constant: it cannot be exported")
    if np.isinf(x):
        return infinity if x > 0 else f"-{infinity}"
    return repr(x)


def _c_num(x: float) -> str:
    """Format a C double literal (``HUGE_VAL`` for infinities)."""
    return _literal(x, "HUGE_VAL")


def _c_array(ctype: str, name: str, values, fmt=_c_num) -> str:
    """Format a ``static const`` array (one padding element when empty: C99 has none)."""
    values = list(values) or [0]
    items = ", ".join(fmt(v) for v in values)
    body = textwrap.fill(items, 96, initial_indent="    ", subsequent_indent="    ")
    return f"static const {ctype} {name}[{len(values)}] = {{\n{body}\n}};\n"


def _fill(template: str, fields: dict[str, str]) -> str:
    """Replace every ``@NAME@`` of a template (C braces make ``str.format`` awkward)."""
    for key, value in fields.items():
        template = template.replace(f"@{key}@", value)
    if "@" in template:
        raise AssertionError(f"unfilled field in template: {template[template.index('@') :][:40]}")
    return template


_C_HEADER = """
#ifndef DEBIST_MODEL_H
#define DEBIST_MODEL_H

#define DEBIST_N_STATES @N_STATES@
#define DEBIST_N_INPUTS @N_INPUTS@
#define DEBIST_N_CURVES @N_CURVES@ /* restoring, d, g1..gN */
#define DEBIST_M_Q @M_Q@
#define DEBIST_T_Z @T_Z@
#define DEBIST_Q_MIN @Q_MIN@
#define DEBIST_Q_MAX @Q_MAX@

#ifdef __cplusplus
extern "C" {
#endif

/* h[i] = h(v[i]) [V^2 or V] from the inputs v [V]. */
void debist_map_inputs(const double v[], double h[]);
/* dx = f(x, h): x, dx [DEBIST_N_STATES]; h the MAPPED inputs [DEBIST_N_INPUTS]. */
void debist_deriv(const double x[], const double h[], double dx[]);
/* One RK4 step of dt [s] in place; inputs v [V] linear from v0 (at t) to v1 (at t + dt). */
void debist_rk4_step(double x[], const double v0[], const double v1[], double dt);
/* out[DEBIST_N_CURVES] = restoring(q), d(q), g_1(q)..g_N(q) from the lookup table. */
void debist_curves(double q, double out[]);

#ifdef __cplusplus
}
#endif

#endif /* DEBIST_MODEL_H */
"""

_C_SOURCE = """
#include <math.h>

#include "debist_model.h"

#define N_BASES @N_BASES@
#define N_TERMS @N_TERMS@
#define N_TABLES @N_TABLES@
#define N_GRID @N_GRID@
#define N_CURVE_POINTS @N_CURVE_POINTS@
#define V_C @V_C@

/* Bases: kind 0 = 1, 1 = Gaussian of q clipped to [lo, hi], 2 = row base_table of tables.
 * Terms: weight * basis * q^qpow * S(s) * prod_i h_i^hpow_i with S: 0 = 1, 1 = s^spow,
 * 2 = tanh(s / V_C); s = z (friction state) or q_dot.
@TERMS@
 */
@CONSTANTS@

/* numpy.interp: linear inside the grid, end values held outside. */
static double interp(double x, const double *xp, const double *fp, int n)
{
    int lo = 0, hi = n - 1;
    if (n == 1 || x <= xp[0]) return fp[0];
    if (x >= xp[n - 1]) return fp[n - 1];
    while (hi - lo > 1) {
        int mid = (lo + hi) / 2;
        if (xp[mid] <= x) lo = mid; else hi = mid;
    }
    return (fp[hi] - fp[lo]) / (xp[hi] - xp[lo]) * (x - xp[lo]) + fp[lo];
}

static double ipow(double x, int n)
{
    double r = 1.0;
    while (n-- > 0) r *= x;
    return r;
}

void debist_map_inputs(const double v[], double h[])
{
    int i;
    for (i = 0; i < DEBIST_N_INPUTS; i++) h[i] = @HMAP@;
}

void debist_deriv(const double x[], const double h[], double dx[])
{
    const double q = x[0];
    @S_LINE@
    double b[N_BASES];
    double acc = 0.0;
    int j, k, i;
    for (k = 0; k < N_BASES; k++) {
        if (base_kind[k] == @BASE_GAUSS@) {
            const double qc = fmin(fmax(q, base_lo[k]), base_hi[k]);
            const double diff = qc - base_centre[k];
            b[k] = exp(-(diff * diff) / (2.0 * (base_width[k] * base_width[k])));
        } else if (base_kind[k] == @BASE_TABLE@) {
            b[k] = interp(q, table_q, tables + base_table[k] * N_GRID, N_GRID);
        } else {
            b[k] = 1.0;
        }
    }
    for (j = 0; j < N_TERMS; j++) {
        double term = b[term_base[j]] * ipow(q, term_qpow[j]);
        if (term_skind[j] == @S_POW@) term *= ipow(s, term_spow[j]);
        else if (term_skind[j] == @S_TANH@) term *= tanh(s / V_C);
        for (i = 0; i < DEBIST_N_INPUTS; i++)
            term *= ipow(h[i], term_hpow[j * DEBIST_N_INPUTS + i]);
        acc += weights[j] * term;
    }
    dx[0] = x[1];
    dx[1] = acc / DEBIST_M_Q;
}

void debist_rk4_step(double x[], const double v0[], const double v1[], double dt)
{
    double vm[DEBIST_N_INPUTS], h0[DEBIST_N_INPUTS], hm[DEBIST_N_INPUTS];
    double h1[DEBIST_N_INPUTS];
    double k1[DEBIST_N_STATES], k2[DEBIST_N_STATES], k3[DEBIST_N_STATES];
    double k4[DEBIST_N_STATES], xs[DEBIST_N_STATES];
    int i;
    /* the midpoint input is the mean of v0 and v1, computed as numpy.interp does */
    for (i = 0; i < DEBIST_N_INPUTS; i++) vm[i] = (v1[i] - v0[i]) * 0.5 + v0[i];
    debist_map_inputs(v0, h0);
    debist_map_inputs(vm, hm);
    debist_map_inputs(v1, h1);
    debist_deriv(x, h0, k1);
    for (i = 0; i < DEBIST_N_STATES; i++) xs[i] = x[i] + 0.5 * dt * k1[i];
    debist_deriv(xs, hm, k2);
    for (i = 0; i < DEBIST_N_STATES; i++) xs[i] = x[i] + 0.5 * dt * k2[i];
    debist_deriv(xs, hm, k3);
    for (i = 0; i < DEBIST_N_STATES; i++) xs[i] = x[i] + dt * k3[i];
    debist_deriv(xs, h1, k4);
    for (i = 0; i < DEBIST_N_STATES; i++)
        x[i] = x[i] + (dt / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
}

void debist_curves(double q, double out[])
{
    int c;
    for (c = 0; c < DEBIST_N_CURVES; c++)
        out[c] = interp(q, curve_q, curve_values + c * N_CURVE_POINTS, N_CURVE_POINTS);
}
"""


def _c_comment(lines: list[str]) -> str:
    return "/*\n" + "".join(f" * {line}".rstrip() + "\n" for line in lines) + " */\n"


def c_sources(model, info: ExportInfo | None = None) -> dict[str, str]:
    """Return the C99 header and source of the model.

    The source needs only ``math.h``, uses doubles and allocates nothing. It defines
    ``debist_map_inputs(v, h)``, ``debist_deriv(x, h, dx)`` (``h`` the mapped inputs),
    ``debist_rk4_step(x, v0, v1, dt)`` (in place, inputs ``v`` [V] linear between the two
    samples, midpoint their mean) and ``debist_curves(q, out)``.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    info : ExportInfo, optional
        Provenance for the header comment.

    Returns
    -------
    dict of str to str
        ``debist_model.h`` and ``debist_model.c`` (:data:`C_FILES`) to their text.

    Raises
    ------
    ArtifactError
        If the model has a NaN constant or an empty q range.

    References
    ----------
    Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1;
    ISO/IEC 9899:1999.
    """
    info = info or ExportInfo()
    arr = _arrays(model)
    cq, names, cval = curve_table(model)
    head = _c_comment(_describe(info, arr, names))
    n_in, n_x = arr["n_inputs"], arr["n_states"]
    lo, hi = arr["q_range"]
    lines = {
        "N_STATES": str(n_x),
        "N_INPUTS": str(n_in),
        "N_CURVES": str(len(names)),
        "M_Q": f"({_c_num(arr['m_q'])})",
        "T_Z": f"({_c_num(arr['T_z'])})",
        "Q_MIN": f"({_c_num(lo)})",
        "Q_MAX": f"({_c_num(hi)})",
    }
    header = head + _fill(_C_HEADER, lines)
    tables = [v for row in arr["tables"] for v in row]
    hpow = [v for row in arr["term_hpow"] for v in row]
    const = "".join(
        [
            _c_array("int", "base_kind", arr["base_kind"], str),
            _c_array("double", "base_centre", arr["base_centre"]),
            _c_array("double", "base_width", arr["base_width"]),
            _c_array("double", "base_lo", arr["base_lo"]),
            _c_array("double", "base_hi", arr["base_hi"]),
            _c_array("int", "base_table", arr["base_table"], str),
            _c_array("double", "table_q", arr["table_q"]),
            _c_array("double", "tables", tables),
            _c_array("int", "term_base", arr["term_base"], str),
            _c_array("int", "term_qpow", arr["term_qpow"], str),
            _c_array("int", "term_skind", arr["term_skind"], str),
            _c_array("int", "term_spow", arr["term_spow"], str),
            _c_array("int", "term_hpow", hpow, str),
            _c_array("double", "weights", arr["weights"]),
            _c_array("double", "curve_q", cq),
            _c_array("double", "curve_values", [v for row in cval for v in row]),
        ]
    )
    if arr["lag"]:
        s_line = "const double s = x[2];\n    dx[2] = (x[1] - s) / DEBIST_T_Z;"
    else:
        s_line = "const double s = x[1];"
    fields = {
        "N_BASES": str(len(arr["base_kind"])),
        "N_TERMS": str(len(arr["weights"])),
        "N_TABLES": str(len(arr["tables"])),
        "N_GRID": str(len(arr["table_q"])),
        "N_CURVE_POINTS": str(len(cq)),
        "V_C": f"({_c_num(arr['v_c'])})",
        "TERMS": "\n".join(f" *   {j:3d} {name}" for j, name in enumerate(arr["term_names"])),
        "CONSTANTS": const.rstrip("\n"),
        "HMAP": "v[i] * v[i]" if arr["input_map"] == "v2" else "v[i]",
        "S_LINE": s_line,
        "BASE_GAUSS": str(BASE_GAUSS),
        "BASE_TABLE": str(BASE_TABLE),
        "S_POW": str(S_POW),
        "S_TANH": str(S_TANH),
    }
    source = head + _fill(_C_SOURCE, fields)
    return {C_FILES[0]: header, C_FILES[1]: source}


# ------------------------------------------------------------------ Python
def _py_num(x) -> str:
    """Format a Python float literal (the module's ``INF`` for infinities)."""
    return _literal(x, "INF")


def _py_list(values, fmt=_py_num, indent: int = 4) -> str:
    """Format a wrapped Python list literal."""
    items = ", ".join(fmt(v) for v in values)
    if not items:
        return "[]"
    pad = " " * indent
    return "[\n" + textwrap.fill(items, 96, initial_indent=pad, subsequent_indent=pad) + "\n]"


def python_source(model, info: ExportInfo | None = None) -> dict[str, str]:
    """Return a NumPy-only Python module of the model.

    The module defines ``map_inputs(v)``, ``deriv(x, h)`` (``h`` the mapped inputs),
    ``rk4_step(x, v0, v1, dt)`` (returns the new state; inputs [V] linear between the two
    samples, midpoint their mean), ``initial_state(q0, q_dot0)`` and ``curves(q)``, and the
    constants as module-level arrays.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    info : ExportInfo, optional
        Provenance for the module docstring.

    Returns
    -------
    dict of str to str
        ``debist_model.py`` (:data:`PYTHON_FILE`) to its text.

    Raises
    ------
    ArtifactError
        If the model has a NaN constant or an empty q range.

    References
    ----------
    Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1.
    """
    info = info or ExportInfo()
    arr = _arrays(model)
    cq, names, cval = curve_table(model)
    doc = "\n".join(_describe(info, arr, names)).replace("\\", "/")
    n_in, J = arr["n_inputs"], len(arr["weights"])
    G = len(arr["table_q"])

    def ints(values):
        return f"np.array({_py_list(values, str)}, dtype=np.int64)"

    tables = [v for row in arr["tables"] for v in row]
    hpow = [v for row in arr["term_hpow"] for v in row]
    curves = [v for row in cval for v in row]
    lag = arr["lag"]
    s_lines = "s = x[2]\n    z_dot = (x[1] - s) / T_Z\n" if lag else "s = x[1]\n"
    out_state = "[x[1], acc, z_dot]" if lag else "[x[1], acc]"
    init = "[q0, q_dot0, q_dot0]" if lag else "[q0, q_dot0]"
    hmap = "v * v" if arr["input_map"] == "v2" else "v.copy()"
    text = f'''"""{doc}
"""

import numpy as np

INF = float("inf")
N_STATES = {arr["n_states"]}
N_INPUTS = {n_in}
M_Q = {arr["m_q"]!r}
T_Z = {arr["T_z"]!r}
V_C = {arr["v_c"]!r}
Q_RANGE = ({arr["q_range"][0]!r}, {arr["q_range"][1]!r})
CURVE_NAMES = {_py_list(names, repr)}
TERM_NAMES = {_py_list(arr["term_names"], repr)}

BASE_KIND = {ints(arr["base_kind"])}
BASE_CENTRE = np.array({_py_list(arr["base_centre"])})
BASE_WIDTH = np.array({_py_list(arr["base_width"])})
BASE_LO = np.array({_py_list(arr["base_lo"])})
BASE_HI = np.array({_py_list(arr["base_hi"])})
BASE_TABLE = {ints(arr["base_table"])}
TABLE_Q = np.array({_py_list(arr["table_q"])})
TABLES = np.array({_py_list(tables)}).reshape({len(arr["tables"])}, {G})
TERM_BASE = {ints(arr["term_base"])}
TERM_QPOW = {ints(arr["term_qpow"])}
TERM_SKIND = {ints(arr["term_skind"])}
TERM_SPOW = {ints(arr["term_spow"])}
TERM_HPOW = {ints(hpow)}.reshape({J}, {n_in})
WEIGHTS = np.array({_py_list(arr["weights"])})
CURVE_Q = np.array({_py_list(cq)})
CURVE_VALUES = np.array({_py_list(curves)}).reshape({len(names)}, {len(cq)})

_GAUSS = BASE_KIND == {BASE_GAUSS}
_TABLE = np.flatnonzero(BASE_KIND == {BASE_TABLE})
_SPOW = TERM_SKIND == {S_POW}
_STANH = TERM_SKIND == {S_TANH}


def map_inputs(v):
    """Mapped inputs h(v) [V^2 or V] of the inputs v [V], shape (N_INPUTS,)."""
    v = np.asarray(v, dtype=float)
    return {hmap}


def initial_state(q0, q_dot0):
    """State at q0 [m], q_dot0 [m/s] with the friction filter at rest, shape (N_STATES,)."""
    return np.array({init}, dtype=float)


def _ipow(x, n):
    """x ** n for integer powers n >= 0 by repeated multiplication (as the C export)."""
    out = np.ones(np.shape(n))
    for _ in range(int(np.max(n, initial=0))):
        out = np.where(n > 0, out * x, out)
        n = n - 1
    return out


def bases(q):
    """Every basis at position q [m], shape (n_bases,)."""
    qc = np.minimum(np.maximum(q, BASE_LO), BASE_HI)
    diff = qc - BASE_CENTRE
    out = np.where(_GAUSS, np.exp(-(diff * diff) / (2.0 * (BASE_WIDTH * BASE_WIDTH))), 1.0)
    for k in _TABLE:
        out[k] = np.interp(q, TABLE_Q, TABLES[BASE_TABLE[k]])
    return out


def deriv(x, h):
    """State derivative at state x (N_STATES,) and MAPPED inputs h (N_INPUTS,)."""
    q = float(x[0])
    {s_lines.rstrip()}
    h = np.asarray(h, dtype=float)
    term = bases(q)[TERM_BASE] * _ipow(q, TERM_QPOW)
    term = term * np.where(_SPOW, _ipow(s, TERM_SPOW), np.where(_STANH, np.tanh(s / V_C), 1.0))
    for i in range(N_INPUTS):
        term = term * _ipow(h[i], TERM_HPOW[:, i])
    acc = 0.0
    for w, t in zip(WEIGHTS, term):
        acc += w * t
    acc = acc / M_Q
    return np.array({out_state})


def rk4_step(x, v0, v1, dt):
    """One RK4 step of dt [s]; inputs [V] linear from v0 (at t) to v1 (at t + dt).

    Returns the new state (N_STATES,); x is not modified.
    """
    x = np.asarray(x, dtype=float)
    v0, v1 = np.asarray(v0, dtype=float), np.asarray(v1, dtype=float)
    h0, hm, h1 = map_inputs(v0), map_inputs((v1 - v0) * 0.5 + v0), map_inputs(v1)
    k1 = deriv(x, h0)
    k2 = deriv(x + 0.5 * dt * k1, hm)
    k3 = deriv(x + 0.5 * dt * k2, hm)
    k4 = deriv(x + dt * k3, h1)
    return x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def curves(q):
    """Characteristic curves CURVE_NAMES at q [m] from the lookup table, shape (N_CURVES,)."""
    return np.array([np.interp(q, CURVE_Q, row) for row in CURVE_VALUES])
'''
    return {PYTHON_FILE: text}


# ------------------------------------------------------------------ MATLAB / Octave
def _m_num(x) -> str:
    """Format a MATLAB double literal (``Inf`` for infinities)."""
    return _literal(x, "Inf")


def _m_row(values, fmt=_m_num, indent: int = 8) -> str:
    """Format the elements of one matrix row, wrapped with ``...`` continuations."""
    items = ", ".join(fmt(v) for v in values)
    pad = " " * indent
    lines = textwrap.wrap(items, 92, initial_indent=pad, subsequent_indent=pad)
    return " ...\n".join(lines)


def _m_matrix(name: str, rows, n_cols: int, fmt=_m_num) -> str:
    """Format ``NAME = [...];`` (a row vector for one row, ``zeros(r, c)`` when empty)."""
    rows = [list(r) for r in rows]
    if not rows or n_cols == 0:
        return f"    {name} = zeros({len(rows)}, {n_cols});\n"
    body = "; ...\n".join(_m_row(r, fmt) for r in rows)
    return f"    {name} = [ ...\n{body}];\n"


def _m_ints(name: str, values) -> str:
    values = list(values)
    return _m_matrix(name, [values], len(values), str)


_M_MAIN = """function [x_next, curves] = debist_model(x, v0, v1, dt)
%DEBIST_MODEL One RK4 step of debist's identified model, and its characteristic curves.
%   [x_next, curves] = debist_model(x, v0, v1, dt)
%     x       state @STATE@ (@N_STATES@ x 1): q [m], q_dot [m/s]@Z_DOC@
%     v0, v1  inputs [V] (@N_INPUTS@ x 1) at t and t + dt, linear in between
%     dt      step [s]
%     x_next  state at t + dt (@N_STATES@ x 1)
%     curves  restoring(q) [N], d(q) [N s/m], g_1(q) .. g_N(q) at q = x(1) from the
%             lookup table (@N_CURVES@ x 1; per unit mass when m_q = 1)
%   Plain doubles of fixed size, no cell arrays, strings or persistent data: usable in a
%   Simulink MATLAB Function block (code generation) and in Octave. In Simulink:
%     function x_next = step(x, v0, v1, dt)   % MATLAB Function block, x as a Unit Delay
%     x_next = debist_model(x, v0, v1, dt);
%
@DESCRIBE@
x = x(:);
v0 = v0(:);
v1 = v1(:);
% the midpoint input is the mean of v0 and v1, computed as numpy.interp does
vm = (v1 - v0) * 0.5 + v0;
h0 = map_inputs(v0);
hm = map_inputs(vm);
h1 = map_inputs(v1);
k1 = deriv(x, h0);
k2 = deriv(x + 0.5 * dt * k1, hm);
k3 = deriv(x + 0.5 * dt * k2, hm);
k4 = deriv(x + dt * k3, h1);
x_next = x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
curves = lookup_curves(x(1));
end


function h = map_inputs(v)
% h = h(v) [V^2 or V] of the inputs v [V].
h = @HMAP@;
end


function dx = deriv(x, h)
% dx = f(x, h): the state derivative at x for the MAPPED inputs h (Eq. 37).
% Bases: kind 0 = 1, 1 = Gaussian of q clipped to [lo, hi], 2 = row base_table of tables.
% Terms: weight * basis * q^qpow * S(s) * prod_i h_i^hpow_i with S: 0 = 1, 1 = s^spow,
% 2 = tanh(s / V_C); s = z (friction state) or q_dot.
@TERMS@
@CONSTANTS@
    q = x(1);
    s = x(@S_INDEX@);
    b = zeros(@N_BASES@, 1);
    for k = 1:@N_BASES@
        if base_kind(k) == @BASE_GAUSS@
            qc = min(max(q, base_lo(k)), base_hi(k));
            dq = qc - base_centre(k);
            b(k) = exp(-(dq * dq) / (2.0 * (base_width(k) * base_width(k))));
@TABLE_BRANCH@        else
            b(k) = 1.0;
        end
    end
    acc = 0.0;
    for j = 1:@N_TERMS@
        term = b(term_base(j) + 1) * ipow(q, term_qpow(j));
        if term_skind(j) == @S_POW@
            term = term * ipow(s, term_spow(j));
        elseif term_skind(j) == @S_TANH@
            term = term * tanh(s / @V_C@);
        end
        for i = 1:@N_INPUTS@
            term = term * ipow(h(i), term_hpow(j, i));
        end
        acc = acc + weights(j) * term;
    end
    dx = zeros(@N_STATES@, 1);
    dx(1) = x(2);
    dx(2) = acc / @M_Q@;
@Z_LINE@end


function r = ipow(x, n)
% x^n for an integer n >= 0 by repeated multiplication (as the C export).
r = 1.0;
while n > 0
    r = r * x;
    n = n - 1;
end
end


function y = interp_held(x, xp, fp)
% numpy.interp: linear inside the grid xp (ascending), end values held outside.
n = numel(xp);
if n == 1 || x <= xp(1)
    y = fp(1);
elseif x >= xp(n)
    y = fp(n);
else
    lo = 1;
    hi = n;
    while hi - lo > 1
        mid = floor((lo + hi) / 2);
        if xp(mid) <= x
            lo = mid;
        else
            hi = mid;
        end
    end
    y = (fp(hi) - fp(lo)) / (xp(hi) - xp(lo)) * (x - xp(lo)) + fp(lo);
end
end


function out = lookup_curves(q)
% restoring(q), d(q), g_1(q) .. g_N(q) from the lookup table (@N_CURVES@ x 1).
@CURVES@
    out = zeros(@N_CURVES@, 1);
    for c = 1:@N_CURVES@
        out(c) = interp_held(q, curve_q, curve_values(c, :));
    end
end
"""

_M_TABLE_BRANCH = """        elseif base_kind(k) == @BASE_TABLE@
            b(k) = interp_held(q, table_q, tables(base_table(k) + 1, :));
"""


def matlab_source(model, info: ExportInfo | None = None) -> dict[str, str]:
    """Return a MATLAB function file of the model (Simulink MATLAB Function block, Octave).

    ``debist_model.m`` defines ``[x_next, curves] = debist_model(x, v0, v1, dt)``: one RK4
    step (inputs [V] linear between the two samples, midpoint their mean) and the
    characteristic curves at ``q = x(1)`` from the lookup table; the model is in local
    functions with the constants as literal fixed-size double arrays (no cell arrays,
    strings, ``persistent`` or ``containers.Map``), so that Simulink can generate code
    from it, and the same arithmetic in the same order as the C export.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    info : ExportInfo, optional
        Provenance for the help text.

    Returns
    -------
    dict of str to str
        ``debist_model.m`` (:data:`MATLAB_FILE`) to its text.

    Raises
    ------
    ArtifactError
        If the model has a NaN constant or an empty q range.

    References
    ----------
    Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1;
    MathWorks, "MATLAB Function block" and "Local Functions"; GNU Octave manual, "Function
    Files".
    """
    info = info or ExportInfo()
    arr = _arrays(model)
    cq, names, cval = curve_table(model)
    describe = "".join(f"%   {line}".rstrip() + "\n" for line in _describe(info, arr, names))
    lag = arr["lag"]
    n_in, n_x = arr["n_inputs"], arr["n_states"]
    has_tables = BASE_TABLE in arr["base_kind"]
    const = [
        _m_ints("base_kind", arr["base_kind"]),
        _m_matrix("base_centre", [arr["base_centre"]], len(arr["base_centre"])),
        _m_matrix("base_width", [arr["base_width"]], len(arr["base_width"])),
        _m_matrix("base_lo", [arr["base_lo"]], len(arr["base_lo"])),
        _m_matrix("base_hi", [arr["base_hi"]], len(arr["base_hi"])),
    ]
    if has_tables:
        const += [
            _m_ints("base_table", arr["base_table"]),
            _m_matrix("table_q", [arr["table_q"]], len(arr["table_q"])),
            _m_matrix("tables", arr["tables"], len(arr["table_q"])),
        ]
    const += [
        _m_ints("term_base", arr["term_base"]),
        _m_ints("term_qpow", arr["term_qpow"]),
        _m_ints("term_skind", arr["term_skind"]),
        _m_ints("term_spow", arr["term_spow"]),
        _m_matrix("term_hpow", arr["term_hpow"], n_in, str),
        _m_matrix("weights", [arr["weights"]], len(arr["weights"])),
    ]
    curves = _m_matrix("curve_q", [cq], len(cq)) + _m_matrix("curve_values", cval, len(cq))
    fields = {
        "STATE": "[q; q_dot; z]" if lag else "[q; q_dot]",
        "Z_DOC": ", z [m/s] (start with z = q_dot)" if lag else "",
        "N_STATES": str(n_x),
        "N_INPUTS": str(n_in),
        "N_CURVES": str(len(names)),
        "DESCRIBE": describe.rstrip("\n"),
        "HMAP": "v .* v" if arr["input_map"] == "v2" else "v",
        "TERMS": "\n".join(f"%   {j + 1:3d} {name}" for j, name in enumerate(arr["term_names"])),
        "CONSTANTS": "".join(const).rstrip("\n"),
        "S_INDEX": "3" if lag else "2",
        "N_BASES": str(len(arr["base_kind"])),
        "BASE_GAUSS": str(BASE_GAUSS),
        "TABLE_BRANCH": _M_TABLE_BRANCH.replace("@BASE_TABLE@", str(BASE_TABLE))
        if has_tables
        else "",
        "N_TERMS": str(len(arr["weights"])),
        "S_POW": str(S_POW),
        "S_TANH": str(S_TANH),
        "V_C": f"({_m_num(arr['v_c'])})",
        "M_Q": f"({_m_num(arr['m_q'])})",
        "Z_LINE": f"    dx(3) = (x(2) - s) / ({_m_num(arr['T_z'])});\n" if lag else "",
        "CURVES": curves.rstrip("\n"),
    }
    return {MATLAB_FILE: _fill(_M_MAIN, fields)}


def export_files(model, fmt: str, info: ExportInfo | None = None) -> dict[str, str]:
    """Return the files of an export format.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    fmt : {"c", "matlab", "python"}
        :func:`c_sources`, :func:`matlab_source` or :func:`python_source`.
    info : ExportInfo, optional
        Provenance for the header comments.

    Returns
    -------
    dict of str to str
        File name to text.

    Raises
    ------
    WorkflowError
        If ``fmt`` is unknown.
    """
    if fmt == "c":
        return c_sources(model, info)
    if fmt == "matlab":
        return matlab_source(model, info)
    if fmt == "python":
        return python_source(model, info)
    raise WorkflowError(f"--format must be one of {FORMATS}, got {fmt!r}")


# ------------------------------------------------------------------ a run's model
def load_identified(runner):
    """Read the identified model of a run after checking that identify is up to date.

    Parameters
    ----------
    runner : pipeline.runner.Runner
        The workflow's runner.

    Returns
    -------
    model : RBFModel
        From ``identify/model.h5``.
    info : ExportInfo
        Workflow name, run digest, sha256 of ``identify/manifest.json`` and the identified
        intervals of ``identify/curves.parquet``.

    Raises
    ------
    WorkflowError
        If the workflow has no identify stage (no data sets).
    ArtifactError
        If the identify stage is missing or stale (naming why: never run, outputs
        changed such as a modified ``model.h5``, config or upstream changed).
    """
    from pipeline import artifacts
    from pipeline.identify.bands import identified_intervals
    from pipeline.identify.model import RBFModel

    wf = runner.wf
    if "identify" not in runner.stages():
        raise WorkflowError(
            f"workflow '{wf.path}' has no identify stage (no [[datasets]]): nothing to export"
        )
    state = next(s for s in runner.status() if s.stage == "identify")
    sdir = wf.stage_dir("identify")
    if state.state != "up to date":
        raise ArtifactError(
            f"stage 'identify' in '{sdir}' is {state.state} ({state.reason}): run "
            f"`debist identify {wf.path}` (or `debist run`) first"
        )
    model = RBFModel.from_tree(artifacts.read_h5(sdir / "model.h5"))
    manifest = artifacts.read_manifest(sdir)
    identified: dict[str, list[list[float]]] = {}
    if manifest is not None and "curves.parquet" in manifest.outputs:
        frame = artifacts.read_parquet(sdir / "curves.parquet")
        for col in frame.columns:
            if col.endswith("_identified"):
                mask = frame[col].to_numpy(dtype=bool)
                identified[col[: -len("_identified")]] = identified_intervals(
                    frame["q"].to_numpy(), mask
                )
    info = ExportInfo(
        workflow=wf.name,
        run_digest=runner.digest(),
        identify_manifest=artifacts.manifest_digest(sdir),
        identified=identified,
    )
    return model, info
