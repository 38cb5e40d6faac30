"""The identified model as a NumPy-only Python module.

References
----------
Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (classical
RK4); NumPy ``numpy.interp``.
"""

from __future__ import annotations

import functools
import textwrap

from debist.export.common import ExportInfo, _comment_text, _context, _environment, _literal
from debist.export.scheme import Scheme

__all__ = ["PYTHON_FILE", "py_docstring", "py_repr", "python_source"]

#: File name of the Python export.
PYTHON_FILE = "debist_model.py"


def py_repr(x: str | float | int) -> str:
    """Return the Python literal of a string or number (``repr``, which round-trips).

    Parameters
    ----------
    x : str, float or int
        Exactly one of these built-in types: ``repr`` of anything else (a NumPy scalar,
        an object with its own ``__repr__``) need not be a literal.

    Returns
    -------
    str
        A literal that evaluates to ``x`` (quotes and escapes included for a string).

    Raises
    ------
    TypeError
        If ``x`` is of another type.
    """
    if type(x) not in (str, float, int):
        raise TypeError(f"py_repr takes a str, float or int, not {type(x).__name__}")
    return repr(x)


def py_docstring(text: str) -> str:
    """Return one line of text for the module's docstring, refusing text that could leave it.

    Parameters
    ----------
    text : str
        Fixed text, numbers or digests (the exports put no free text into docstrings).

    Returns
    -------
    str
        ``text``.

    Raises
    ------
    ArtifactError
        If ``text`` has a character other than printable ASCII, a quote or a backslash.
    """
    return _comment_text(text, ('"', "\\"), "a Python docstring")


def _py_num(x) -> str:
    """Format a Python float literal (the module's ``INF`` for infinities)."""
    return _literal(x, "INF")


def _py_list(values, kind: str = "float", indent: int = 4) -> str:
    """Format a wrapped Python list literal of ``kind`` float, int or str."""
    fmt = {"float": _py_num, "int": str, "str": py_repr}[kind]
    items = ", ".join(fmt(v) for v in values)
    if not items:
        return "[]"
    pad = " " * indent
    return "[\n" + textwrap.fill(items, 96, initial_indent=pad, subsequent_indent=pad) + "\n]"


@functools.cache
def _env():
    return _environment({"py_repr": py_repr, "py_docstring": py_docstring, "py_list": _py_list})


def python_source(
    model, info: ExportInfo | None = None, scheme: Scheme | None = None
) -> dict[str, str]:
    """Return a NumPy-only Python module of the model.

    The module defines ``map_inputs(v)``, ``deriv(x, h)`` (``h`` the mapped inputs),
    ``rk4_step(x, v0, v1, dt)`` (one sample of ``ns`` RK4 sub-steps, returns the new state;
    inputs [V] linear between the two samples; causal), ``fine_inputs(v)`` and
    ``free_run(v, dt, x0, n_out=None)`` (a whole record in validate's scheme: its input
    interpolation, ``ns``, the divergence bound), ``initial_state(q0, q_dot0)`` and
    ``curves(q)``, and the constants as module-level arrays; the template
    ``templates/model.py.j2`` holds the code.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    info : ExportInfo, optional
        Provenance for the module docstring.
    scheme : Scheme, optional
        The free-run scheme and its scores (:func:`debist.export.scheme.run_scheme`);
        default :func:`debist.export.scheme.default_scheme`.

    Returns
    -------
    dict of str to str
        ``debist_model.py`` (:data:`PYTHON_FILE`) to its text.

    Raises
    ------
    ArtifactError
        If the model has a NaN constant or an empty q range, or the provenance has text
        that cannot go into the docstring.

    References
    ----------
    Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1.
    """
    context = _context(model, info, "WORKFLOW", scheme)
    return {PYTHON_FILE: _env().get_template("model.py.j2").render(context)}
