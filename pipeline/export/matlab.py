"""The identified model as one MATLAB function file (Simulink MATLAB Function block, Octave).

References
----------
Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (classical
RK4); MathWorks, "Function Basics" and "MATLAB Function block" (local functions, fixed-size
code generation); GNU Octave manual, "Function Files".
"""

from __future__ import annotations

import functools
import textwrap

from debist.export.common import ExportInfo, _comment_text, _context, _environment, _literal
from debist.export.scheme import Scheme
from debist.model.termtable import BASE_ONE, BASE_TABLE, S_ACC, S_CREEP, S_POW, S_TANH

__all__ = [
    "MATLAB_FILE",
    "MATLAB_FREE_RUN_FILE",
    "MATLAB_NAME_FILE",
    "m_comment",
    "m_string",
    "matlab_source",
]

#: File name of the MATLAB export (the function's name is the file's).
MATLAB_FILE = "debist_model.m"
#: The function file that returns the workflow's name (a char array).
MATLAB_NAME_FILE = "debist_model_workflow.m"
#: The function file of the whole-record free run (validate's scheme).
MATLAB_FREE_RUN_FILE = "debist_free_run.m"
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


def m_comment(text: str) -> str:
    """Return one line of text for a MATLAB ``%`` comment, refusing text that could leave it.

    Parameters
    ----------
    text : str
        Fixed text, numbers or digests (the exports put no free text into comments).

    Returns
    -------
    str
        ``text`` without trailing blanks.

    Raises
    ------
    ArtifactError
        If ``text`` has a character other than printable ASCII (a line break would end
        the comment).
    """
    return _comment_text(text, (), "a MATLAB comment").rstrip()


def _m_num(x) -> str:
    """Format a MATLAB double literal (``Inf`` for infinities)."""
    return _literal(x, "Inf")


def _m_row(values, fmt=_m_num, indent: int = 8) -> str:
    """Format the elements of one matrix row, wrapped with ``...`` continuations."""
    items = ", ".join(fmt(v) for v in values)
    pad = " " * indent
    lines = textwrap.wrap(items, 92, initial_indent=pad, subsequent_indent=pad)
    return " ...\n".join(lines)


def _m_matrix(rows, name: str, n_cols: int, ints: bool = False) -> str:
    """Format ``NAME = [...];`` (a row vector for one row, ``zeros(r, c)`` when empty)."""
    rows = [list(r) for r in rows]
    if not rows or n_cols == 0:
        return f"    {name} = zeros({len(rows)}, {n_cols});"
    body = "; ...\n".join(_m_row(r, str if ints else _m_num) for r in rows)
    return f"    {name} = [ ...\n{body}];"


def _m_index(values) -> str:
    """Format a row of 1-based indices, runs of consecutive ones as ``a:b``: ``[1:3, 7]``."""
    runs: list[list[int]] = []
    for k in values:
        if runs and k == runs[-1][1] + 1:
            runs[-1][1] = k
        else:
            runs.append([k, k])
    items = [f"{a}" if a == b else f"{a}:{b}" for a, b in runs]
    return f"[{', '.join(items)}]"


def _m_vector(values, name: str, ints: bool = False) -> str:
    """Format ``NAME = [...];`` of one row of doubles (or integers)."""
    values = list(values)
    return _m_matrix([values], name, len(values), ints)


def _m_indices(context: dict) -> dict:
    """1-based index vectors and largest powers of the vectorised ``deriv`` of the MATLAB file.

    The file evaluates the terms as arrays (Octave interprets scalar loops slowly) with the
    C export's arithmetic per term: a power ``q^n`` is element ``n + 1`` of a running
    product ``1, q, q q, ...`` (the C export's repeated multiplication), a factor absent from
    a term is a product with 1.0 (exact), the sum runs over the terms in their order.
    """
    kind, skind = context["base_kind"], context["term_skind"]

    def where(values, wanted):
        return [k + 1 for k, v in enumerate(values) if v == wanted]

    spow = [p for p, k in zip(context["term_spow"], skind, strict=True) if k == S_POW]
    acc = where(skind, S_ACC)
    return {
        "one_bases": where(kind, BASE_ONE),
        "table_bases": where(kind, BASE_TABLE),
        "sum_terms": [j for j in range(1, len(skind) + 1) if j not in acc],
        "pow_terms": where(skind, S_POW),
        "tanh_terms": where(skind, S_TANH),
        "creep_terms": where(skind, S_CREEP),
        "acc_terms": acc,
        # q^(a - 1) of an inertia term's force (q^0 = 1 for a = 0, as the C export's loop)
        "acc_dpow": [max(context["term_qpow"][j - 1] - 1, 0) for j in acc],
        "q_max": max(context["term_qpow"], default=0),
        "s_max": max(spow, default=0),
        "h_max": [
            max((row[i] for row in context["term_hpow"]), default=0)
            for i in range(context["n_inputs"])
        ],
    }


@functools.cache
def _env():
    return _environment(
        {
            "m_string": m_string,
            "m_comment": m_comment,
            "m_num": _m_num,
            "m_vector": _m_vector,
            "m_index": _m_index,
            "m_matrix": _m_matrix,
        }
    )


def matlab_source(
    model, info: ExportInfo | None = None, scheme: Scheme | None = None
) -> dict[str, str]:
    """Return MATLAB function files of the model (Simulink MATLAB Function block, Octave).

    ``debist_model.m`` defines ``[x_next, curves] = debist_model(x, v0, v1, dt)``: one
    sample of ``ns`` RK4 sub-steps (the causal step: inputs [V] linear between the two
    samples) and the characteristic curves at ``q = x(1)`` from the lookup table;
    ``debist_free_run.m`` defines ``[q, x] = debist_free_run(v, dt, x0, n_out)``, the free
    run of a whole record in the scheme validate scored (its input interpolation, ``ns``,
    divergence bound), with the model's local functions of its own. The model is in local
    functions with the constants as literal fixed-size double arrays (no cell arrays,
    strings, ``persistent`` or ``containers.Map``), so that Simulink can generate code
    from it. The terms are evaluated as arrays (an interpreter's loops are slow) with the
    C export's products per term, summed in the terms' order; the curves are looked up
    only when the caller asks for them.
    ``debist_model_workflow.m`` returns the workflow's name. The templates
    ``templates/model.m.j2``, ``free_run.m.j2``, ``model_core.m.j2`` (the local functions
    both files carry) and ``model_workflow.m.j2`` hold the code.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    info : ExportInfo, optional
        Provenance for the help text.
    scheme : Scheme, optional
        The free-run scheme and its scores (:func:`debist.export.scheme.run_scheme`);
        default :func:`debist.export.scheme.default_scheme`.

    Returns
    -------
    dict of str to str
        ``debist_model.m`` (:data:`MATLAB_FILE`), ``debist_free_run.m``
        (:data:`MATLAB_FREE_RUN_FILE`) and ``debist_model_workflow.m``
        (:data:`MATLAB_NAME_FILE`) to their text.

    Raises
    ------
    ArtifactError
        If the model has a NaN constant or an empty q range, or the provenance has text
        that cannot go into a comment.

    References
    ----------
    Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1;
    MathWorks, "MATLAB Function block" and "Local Functions"; GNU Octave manual, "Function
    Files".
    """
    context = _context(
        model,
        info,
        "returned by debist_model_workflow()",
        scheme,
        ("debist_free_run", "debist_model"),
    )
    context.update(_m_indices(context))
    env = _env()
    return {
        MATLAB_FILE: env.get_template("model.m.j2").render(context),
        MATLAB_FREE_RUN_FILE: env.get_template("free_run.m.j2").render(context),
        MATLAB_NAME_FILE: env.get_template("model_workflow.m.j2").render(context),
    }
