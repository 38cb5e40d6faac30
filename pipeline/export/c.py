"""The identified model as C99: a header and a source with a fixed-size RK4 step.

References
----------
Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (classical
RK4); ISO/IEC 9899:1999 (C99).
"""

from __future__ import annotations

import textwrap

from debist.export.common import ExportInfo, _arrays, _describe, _fill, _literal, curve_table
from debist.model.termtable import BASE_GAUSS, BASE_TABLE, S_POW, S_TANH

__all__ = ["C_FILES", "c_sources", "c_string"]

#: File names of the C export (header, source).
C_FILES = ("debist_model.h", "debist_model.c")


def _c_num(x: float) -> str:
    """Format a C double literal (``HUGE_VAL`` for infinities)."""
    return _literal(x, "HUGE_VAL")


def c_string(text: str) -> str:
    r"""Return a C99 string literal of ``text`` (UTF-8 bytes; anything but plain ASCII escaped).

    Printable ASCII other than ``"``, ``\``, ``?`` and ``@`` stays as it is; every other
    byte becomes a three-digit octal escape, so no character of ``text`` can end the
    literal, continue a line or form a trigraph (ISO/IEC 9899:1999, 6.4.4.4, 6.4.5,
    5.2.1.1), and none can be taken for a field of the export's template (``@``).

    Parameters
    ----------
    text : str
        Any text (e.g. a workflow name).

    Returns
    -------
    str
        The literal, quotes included.

    Examples
    --------
    >>> print(c_string('a*/"b\n??/'))
    "a*/\042b\012\077\077/"
    """
    safe = set(range(0x20, 0x7F)) - {ord(c) for c in '"\\?@'}  # @: the template's marker
    body = "".join(chr(b) if b in safe else f"\\{b:03o}" for b in text.encode("utf-8"))
    return f'"{body}"'


def _c_array(ctype: str, name: str, values, fmt=_c_num) -> str:
    """Format a ``static const`` array (one padding element when empty: C99 has none)."""
    values = list(values) or [0]
    items = ", ".join(fmt(v) for v in values)
    body = textwrap.fill(items, 96, initial_indent="    ", subsequent_indent="    ")
    return f"static const {ctype} {name}[{len(values)}] = {{\n{body}\n}};\n"


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
/* The name of the workflow the model was identified by (UTF-8, NUL-terminated). */
extern const char DEBIST_WORKFLOW[];

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

const char DEBIST_WORKFLOW[] = @WORKFLOW@;

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
    head = _c_comment(_describe(info, arr, names, "DEBIST_WORKFLOW"))
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
        "WORKFLOW": c_string(info.workflow),
        "HMAP": "v[i] * v[i]" if arr["input_map"] == "v2" else "v[i]",
        "S_LINE": s_line,
        "BASE_GAUSS": str(BASE_GAUSS),
        "BASE_TABLE": str(BASE_TABLE),
        "S_POW": str(S_POW),
        "S_TANH": str(S_TANH),
    }
    source = head + _fill(_C_SOURCE, fields)
    return {C_FILES[0]: header, C_FILES[1]: source}
