"""The identified model as C99: a header and a source with a fixed-size RK4 step.

References
----------
Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (classical
RK4); ISO/IEC 9899:1999 (C99).
"""

from __future__ import annotations

import functools
import textwrap

from debist.export.common import ExportInfo, _comment_text, _context, _environment, _literal
from debist.export.scheme import Scheme

__all__ = ["C_FILES", "c_comment", "c_sources", "c_string"]

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
    5.2.1.1). ``@`` was the marker of the export's former string templates; it stays
    escaped so that the exported files keep their bytes.

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
    safe = set(range(0x20, 0x7F)) - {ord(c) for c in '"\\?@'}
    body = "".join(chr(b) if b in safe else f"\\{b:03o}" for b in text.encode("utf-8"))
    return f'"{body}"'


def c_comment(text: str) -> str:
    """Return one line of text for a C block comment, refusing text that could leave it.

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
        If ``text`` has a character other than printable ASCII, or ``*/``, ``/*``, ``??``
        (a trigraph) or a backslash (ISO/IEC 9899:1999, 5.2.1.1, 6.4.9).
    """
    return _comment_text(text, ("*/", "/*", "??", "\\"), "a C comment").rstrip()


def _c_array(values, ctype: str, name: str) -> str:
    """Format a ``static const`` array (one padding element when empty: C99 has none)."""
    fmt = str if ctype == "int" else _c_num
    values = list(values) or [0]
    items = ", ".join(fmt(v) for v in values)
    body = textwrap.fill(items, 96, initial_indent="    ", subsequent_indent="    ")
    return f"static const {ctype} {name}[{len(values)}] = {{\n{body}\n}};"


@functools.cache
def _env():
    return _environment(
        {"c_string": c_string, "c_comment": c_comment, "c_num": _c_num, "c_array": _c_array}
    )


def c_sources(
    model, info: ExportInfo | None = None, scheme: Scheme | None = None
) -> dict[str, str]:
    """Return the C99 header and source of the model.

    The source needs only ``math.h`` and ``stddef.h``, uses doubles and allocates nothing.
    It defines ``debist_map_inputs(v, h)``, ``debist_deriv(x, h, dx)`` (``h`` the mapped
    inputs), ``debist_rk4_step(x, v0, v1, dt)`` (one sample in place: ``ns`` RK4 sub-steps,
    inputs ``v`` [V] linear between the two samples; causal),
    ``debist_free_run(v, n, dt, x0, q_out)`` (a whole record in validate's scheme: its input
    interpolation, with the polyphase FIR taps of the band-limited one as a table, ``ns``,
    the divergence bound) and ``debist_curves(q, out)``; the templates
    ``templates/model.h.j2`` and ``templates/model.c.j2`` hold the code.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    info : ExportInfo, optional
        Provenance for the header comment.
    scheme : Scheme, optional
        The free-run scheme and its scores (:func:`debist.export.scheme.run_scheme`);
        default :func:`debist.export.scheme.default_scheme`.

    Returns
    -------
    dict of str to str
        ``debist_model.h`` and ``debist_model.c`` (:data:`C_FILES`) to their text.

    Raises
    ------
    ArtifactError
        If the model has a NaN constant or an empty q range, or the provenance has text
        that cannot go into a comment.

    References
    ----------
    Masoud & Maas 2025, Eq. 37; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1;
    ISO/IEC 9899:1999.
    """
    context = _context(
        model, info, "DEBIST_WORKFLOW", scheme, ("debist_free_run", "debist_rk4_step")
    )
    env = _env()
    return {
        C_FILES[0]: env.get_template("model.h.j2").render(context),
        C_FILES[1]: env.get_template("model.c.j2").render(context),
    }
