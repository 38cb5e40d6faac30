"""The identified model as one MATLAB function file (Simulink MATLAB Function block, Octave).

References
----------
Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (classical
RK4); MathWorks, "Function Basics" and "MATLAB Function block" (local functions, fixed-size
code generation); GNU Octave manual, "Function Files".
"""

from __future__ import annotations

import textwrap

from debist.export.common import ExportInfo, _arrays, _describe, _fill, _literal, curve_table
from debist.model.termtable import BASE_GAUSS, BASE_TABLE, S_POW, S_TANH

__all__ = ["MATLAB_FILE", "MATLAB_NAME_FILE", "m_string", "matlab_source"]

#: File name of the MATLAB export (the function's name is the file's).
MATLAB_FILE = "debist_model.m"
#: The function file that returns the workflow's name (a char array).
MATLAB_NAME_FILE = "debist_model_workflow.m"
#: Characters a MATLAB literal carries as they are; every other one becomes a char code.
_M_PLAIN = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789 _.,:;()+=/-")


def m_string(text: str) -> str:
    r"""Return a MATLAB char-array expression of ``text`` that no character can break out of.

    Runs of letters, digits, spaces and ``_.,:;()+=/-`` are quoted as they are; other ASCII
    characters (quotes, ``%``, line breaks, control characters) are written as
    ``char([...])`` of their codes, and non-ASCII text as
    ``native2unicode(uint8([...]), 'UTF-8')`` of its UTF-8 bytes, which gives the same
    characters in MATLAB (UTF-16 chars) and in Octave (UTF-8 chars) (MathWorks,
    "native2unicode"; GNU Octave manual, "Character Arrays").

    Parameters
    ----------
    text : str
        Any text (e.g. a workflow name).

    Returns
    -------
    str
        A MATLAB expression of class char, ``''`` for the empty text.

    Examples
    --------
    >>> print(m_string("it's 3 kV\n"))
    ['it', char([39]), 's 3 kV', char([10])]
    >>> print(m_string("\u00e9"))
    native2unicode(uint8([195 169]), 'UTF-8')
    """
    parts: list[str] = []
    run, kind = "", None  # the current run and its kind: plain, ascii, utf8
    for ch in text:
        new = "plain" if ch in _M_PLAIN else "ascii" if ord(ch) < 128 else "utf8"
        if new != kind and run:
            parts.append(_m_part(run, kind))
            run = ""
        run, kind = run + ch, new
    if run:
        parts.append(_m_part(run, kind))
    if not parts:
        return "''"
    return parts[0] if len(parts) == 1 else f"[{', '.join(parts)}]"


def _m_part(run: str, kind: str | None) -> str:
    if kind == "plain":
        return f"'{run}'"
    if kind == "ascii":
        return f"char([{' '.join(str(ord(c)) for c in run)}])"
    return f"native2unicode(uint8([{' '.join(map(str, run.encode('utf-8')))}]), 'UTF-8')"


_M_NAME = """function name = debist_model_workflow()
%DEBIST_MODEL_WORKFLOW The name of the workflow debist_model.m was identified by.
%   name = debist_model_workflow() returns it as a char row (as written in the workflow).
name = @NAME@;
end
"""


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
    lines = _describe(info, arr, names, "returned by debist_model_workflow()")
    describe = "".join(f"%   {line}".rstrip() + "\n" for line in lines)
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
    return {
        MATLAB_FILE: _fill(_M_MAIN, fields),
        MATLAB_NAME_FILE: _M_NAME.replace("@NAME@", m_string(info.workflow)),
    }
