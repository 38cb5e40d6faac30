"""The identified model as a NumPy-only Python module.

References
----------
Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (classical
RK4); NumPy ``numpy.interp``.
"""

from __future__ import annotations

import textwrap

from debist.export.common import ExportInfo, _arrays, _describe, _literal, curve_table
from debist.model.termtable import BASE_GAUSS, BASE_TABLE, S_POW, S_TANH

__all__ = ["PYTHON_FILE", "python_source"]

#: File name of the Python export.
PYTHON_FILE = "debist_model.py"


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
    doc = "\n".join(_describe(info, arr, names, "WORKFLOW"))
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
WORKFLOW = {info.workflow!r}
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
