"""The one mechanism that checks workflow sections: typed config dataclasses and their messages.

Every stage's configuration is a frozen pydantic dataclass built with :data:`CONFIG`
(unknown keys refused, strict types: no ``"10"`` for 10, no 1.5 or ``true`` for an integer,
no ``inf`` or ``nan``). Range constraints are pydantic ``Field`` constraints; rules that
involve several fields live in ``__post_init__`` and raise :class:`ConfigValueError`.
:func:`config_from_section` builds one from a workflow section and turns pydantic's
:class:`~pydantic.ValidationError` into a one-line :class:`~debist.core.errors.WorkflowError`;
:class:`SectionConfig` is the one base whose ``from_dict`` does that for a class that names
its table (``SECTION = "[validate]"``)::

    [identify] M: expected an integer, got 'ten'
    [compare] unknown key 'degre'; did you mean 'degree'? (known keys: degree, ...)

References
----------
pydantic 2 documentation: "Dataclasses", "Strict Mode", "Validators", "Errors"
(https://docs.pydantic.dev/2.x/).
"""

from __future__ import annotations

import dataclasses
import difflib
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from typing import Annotated, Any, ClassVar, Self, TypeVar

import pydantic
from pydantic import BeforeValidator, ConfigDict, Field

from debist.core.errors import WorkflowError

__all__ = [
    "CONFIG",
    "AsTuple",
    "ConfigValueError",
    "Interval",
    "SectionConfig",
    "config_from_section",
    "dotted_key",
    "format_validation_error",
    "unknown_key_message",
]

_C = TypeVar("_C")

#: pydantic configuration of every config dataclass: unknown keys are errors, types are
#: strict (an int is still accepted for a float), numbers are finite.
CONFIG = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


def as_tuple(value: object) -> object:
    """Turn a TOML array (a list) into a tuple; leave anything else to the type check.

    Parameters
    ----------
    value : object
        A field's raw value.

    Returns
    -------
    object
        ``tuple(value)`` for a list, else ``value``.

    Examples
    --------
    >>> as_tuple([1, 2]), as_tuple("x")
    ((1, 2), 'x')
    """
    return tuple(value) if isinstance(value, list) else value


#: Marker for tuple fields: strict mode refuses a list for a tuple, TOML only has arrays.
AsTuple = BeforeValidator(as_tuple)


class ConfigValueError(ValueError):
    """A value breaks a rule of its config class (raised inside pydantic validation).

    :func:`config_from_section` formats it as ``[section] key: expected ..., got ...``
    (or ``[section] key: message``).

    Parameters
    ----------
    key : str or None
        The workflow key at fault; None: the field the validator runs on.
    expected : str, optional
        What the key must hold, e.g. ``"an odd integer"``.
    got : object, optional
        The offending value (echoed with ``repr``).
    message : str, optional
        A free-form explanation instead of ``expected``/``got``.
    """

    _UNSET = object()

    def __init__(
        self,
        key: str | None,
        expected: str | None = None,
        got: object = _UNSET,
        *,
        message: str | None = None,
    ):
        self.key = key
        self.expected = expected
        self.got = got
        self.message = message
        super().__init__(self.text())

    def text(self) -> str:
        """Return the part after ``key:`` (``expected ..., got ...`` or the message)."""
        if self.message is not None:
            return self.message
        got = "" if self.got is self._UNSET else f", got {self.got!r}"
        return f"expected {self.expected}{got}"


def _increasing(pair: tuple[float, float]) -> tuple[float, float]:
    if not pair[0] < pair[1]:
        raise ConfigValueError(None, "[start, end] with start < end")
    return pair


#: A pair ``[start, end]`` of finite numbers with ``start < end`` (ranges, intervals).
Interval = Annotated[
    tuple[float, float],
    AsTuple,
    pydantic.AfterValidator(_increasing),
    Field(description="[start, end] with start < end"),
]

#: What pydantic's error types mean, as the ``expected ...`` of a message.
_EXPECTED = {
    "int_type": "an integer",
    "int_parsing": "an integer",
    "int_from_float": "an integer",
    "float_type": "a number",
    "float_parsing": "a number",
    "finite_number": "a finite number",
    "string_type": "a string",
    "string_too_short": "a non-empty string",
    "bool_type": "true or false",
    "bool_parsing": "true or false",
    "tuple_type": "an array",
    "list_type": "an array",
    "dict_type": "a table",
    "mapping_type": "a table",
    "dataclass_type": "a table",
    "dataclass_exact_type": "a table",
    "model_type": "a table",
    "none_required": "nothing",
}
_BOUNDS = {
    "greater_than": ">",
    "greater_than_equal": ">=",
    "less_than": "<",
    "less_than_equal": "<=",
}


def unknown_key_message(
    where: str, key: str, known: Sequence[str], *, known_label: str = "known keys", prefix: str = ""
) -> str:
    """Return the message for an unknown key, with the closest known key as a suggestion.

    Parameters
    ----------
    where : str
        The section, e.g. ``"[compare]"``.
    key : str
        The unknown key.
    known : sequence of str
        The keys the section accepts.
    known_label : str, optional
        How the list of known keys is introduced.
    prefix : str, optional
        Shown before the key (e.g. ``"q."`` for a key of a channel table).

    Returns
    -------
    str
        ``[where] unknown key 'key'; did you mean 'k'? (known keys: ...)``; the
        suggestion only when one is close (:func:`difflib.get_close_matches`).

    References
    ----------
    Python standard library, :func:`difflib.get_close_matches` (Ratcliff/Obershelp ratio).

    Examples
    --------
    >>> unknown_key_message("[compare]", "degre", ["degree", "alpha"])
    "[compare] unknown key 'degre'; did you mean 'degree'? (known keys: degree, alpha)"
    """
    close = difflib.get_close_matches(str(key), list(known), n=1)
    hint = f"; did you mean '{close[0]}'?" if close else ""
    return f"{where} unknown key '{prefix}{key}'{hint} ({known_label}: {', '.join(known)})"


def _base_types(annotation: Any) -> set[Any]:
    """Return the leaf types of an annotation (``Annotated``, unions, tuples unwrapped)."""
    args = [a for a in typing.get_args(annotation) if a is not Ellipsis]
    origin = typing.get_origin(annotation)
    if origin is Annotated:
        return _base_types(args[0])
    if args and origin in (typing.Union, types.UnionType, tuple, list, dict):
        return set().union(*(_base_types(a) for a in args))
    return {annotation}


def _field_info(cls: type, name: object) -> Any:
    fields = getattr(cls, "__pydantic_fields__", {})
    if name in fields:
        return fields[name]
    for info in fields.values():  # loc holds the alias when a field has one
        if info.alias == name:
            return info
    return None


def _expected(err: Mapping[str, Any], info: Any) -> str:
    """Return the ``expected ...`` text of one pydantic error."""
    kind = err["type"]
    ctx = err.get("ctx") or {}
    if kind == "value_error" and isinstance(ctx.get("error"), ConfigValueError):
        return ctx["error"].text()
    if kind in _BOUNDS:
        bound = next(iter(ctx.values()))
        if isinstance(bound, float) and bound.is_integer():
            bound = int(bound)
        leaves = _base_types(info.annotation) if info is not None else set()
        if int in leaves and float not in leaves:
            if kind == "greater_than" and isinstance(bound, int):  # "> 0" reads ">= 1"
                return f"an integer >= {bound + 1}"
            return f"an integer {_BOUNDS[kind]} {bound}"
        return f"a number {_BOUNDS[kind]} {bound}"
    if kind == "literal_error":
        return str(ctx["expected"])
    if kind == "too_short":
        return f"at least {ctx['min_length']} value(s)"
    if kind == "too_long":
        return f"at most {ctx['max_length']} value(s)"
    if kind in _EXPECTED:
        return _EXPECTED[kind]
    return str(err.get("msg", kind)).removeprefix("Value error, ")


def _locate(where: str, loc: Sequence[Any], prefix: str) -> tuple[str, str, str]:
    """Section label, key and suffix of an error location.

    ``("M",)`` -> ``[where] M``; ``("slice", 0)`` -> ``[where] slice[0]``;
    ``("published", "a")`` -> ``[where.published] a`` (a sub-table);
    ``("published", 0, "rms")`` -> ``[where.published] rms (entry 1)`` (an array of tables).
    """
    head, rest = str(loc[0]), list(loc[1:])
    if not rest:
        return where, prefix + head, ""
    if isinstance(rest[0], int):
        if len(rest) == 1:
            return where, f"{prefix}{head}[{rest[0]}]", ""
        table = f"{where[:-1]}.{prefix}{head}]"
        return table, ".".join(str(p) for p in rest[1:]), f" (entry {rest[0] + 1})"
    return f"{where[:-1]}.{prefix}{head}]", ".".join(str(p) for p in rest), ""


def format_validation_error(
    exc: pydantic.ValidationError,
    cls: type,
    section: Mapping[str, Any],
    where: str | Callable[[str], str],
    *,
    prefix: str = "",
    known_label: str = "known keys",
    internal: Sequence[str] = (),
) -> str:
    """Turn a pydantic validation error of a config class into one line.

    Parameters
    ----------
    exc : pydantic.ValidationError
        From ``cls(**section)``.
    cls : type
        The config dataclass.
    section : mapping
        The keys given (their values are echoed).
    where : str or callable
        The section label, e.g. ``"[identify]"``, or a function of the top-level key
        giving it (for sections merged from several tables).
    prefix : str, optional
        Put before every key (e.g. ``"q."`` for a channel table inside ``[ingest]``).
    known_label : str, optional
        Introduces the known keys in an unknown-key message.
    internal : sequence of str, optional
        Fields that are not workflow keys (left out of the known keys).

    Returns
    -------
    str
        ``[section] key: expected ..., got ...``, or the unknown-key message with a
        suggestion.
    """
    errors = exc.errors(include_url=False)
    label = where if callable(where) else (lambda _key, w=where: w)
    for err in errors:
        unknown = err["type"] in ("unexpected_keyword_argument", "extra_forbidden")
        if unknown and len(err["loc"]) == 1:
            key = str(err["loc"][0])
            known = field_names(cls, internal)
            return unknown_key_message(
                label(key), key, known, known_label=known_label, prefix=prefix
            )
    err = errors[0]
    loc = tuple(err["loc"])
    error = (err.get("ctx") or {}).get("error")
    if isinstance(error, WorkflowError):  # a helper's own message, already naming its key
        return str(error)
    if isinstance(error, ConfigValueError):
        key = error.key if error.key is not None else (str(loc[0]) if loc else "")
        text = error.text()
        if error.message is None and error.got is ConfigValueError._UNSET and key in section:
            text += f", got {section[key]!r}"
        if not key:  # a rule on the whole table
            key = prefix.rstrip(".")
            return f"{label(key)} {key + ': ' if key else ''}{text}"
        if error.key is None and (info := _field_info(cls, key)) is not None and info.description:
            text = f"expected {info.description}, got {section.get(key)!r}"
        return f"{label(key)} {prefix}{key}: {text}"
    if not loc:
        key = prefix.rstrip(".")
        return f"{label(key)} {key + ': ' if key else ''}{_expected(err, None)}"
    info = _field_info(cls, loc[0])
    same_field = [e for e in errors if e["loc"][:1] == loc[:1]]
    if info is not None and info.description:  # the field says what it holds
        expected, loc = info.description, loc[:1]
    elif len(same_field) > 1 and all(len(e["loc"]) == 2 for e in same_field):
        # a union, each member reporting: "a number or one of 'search'"
        expected, loc = " or ".join(dict.fromkeys(_expected(e, info) for e in same_field)), loc[:1]
    else:
        expected = _expected(err, info)
    table, key, suffix = _locate(label(str(loc[0])), loc, prefix)
    if err["type"] in ("missing", "missing_argument"):
        return f"{table} {key}: required key is missing{suffix}"
    if err["type"] in ("unexpected_keyword_argument", "extra_forbidden"):
        return f"{table} unknown key '{key}'{suffix}"
    got = section[loc[0]] if len(loc) == 1 and loc[0] in section else err.get("input")
    return f"{table} {key}: expected {expected}, got {got!r}{suffix}"


def config_from_section(
    cls: type[_C],
    section: Mapping[str, Any],
    where: str | Callable[[str], str],
    *,
    prefix: str = "",
    known_label: str = "known keys",
    internal: Sequence[str] = (),
    extra: Mapping[str, Any] | None = None,
) -> _C:
    """Build the config dataclass ``cls`` from a workflow section, or say in one line why not.

    Parameters
    ----------
    cls : type
        A pydantic dataclass configured with :data:`CONFIG`.
    section : mapping of str to value
        The keys given in the workflow.
    where : str or callable
        Where the section sits (e.g. ``"[identify]"``), or a function of the key giving it.
    prefix, known_label : str, optional
        Put before every key in the messages (e.g. ``"q."``); introduces the known keys.
    internal : sequence of str, optional
        Fields that are not workflow keys: refused in ``section``, filled from ``extra``.
    extra : mapping, optional
        Values of ``internal`` fields (e.g. the role of a channel table).

    Returns
    -------
    object
        ``cls(**section, **extra)``.

    Raises
    ------
    WorkflowError
        On a section that is not a table, an unknown key (suggesting the closest), or a
        value of the wrong type, out of range or breaking a rule of the class.

    References
    ----------
    pydantic 2, "Dataclasses" and "Error Handling" (https://docs.pydantic.dev/2.x/).

    Examples
    --------
    >>> from debist.model.sindy import SindyConfig
    >>> config_from_section(SindyConfig, {"degree": "3"}, "[compare]")
    Traceback (most recent call last):
    ...
    debist.core.errors.WorkflowError: [compare] degree: expected an integer, got '3'
    """
    label = where if callable(where) else (lambda _key, w=where: w)
    if not isinstance(section, Mapping):
        what = prefix.rstrip(".")
        head = f"{label(what)} {what}:" if what else label("")
        key = dotted_key(label(what), what)
        raise WorkflowError(f"{head} expected a table, got {section!r}", key=key, value=section)
    for key in section:
        if key in internal:
            known = field_names(cls, internal)
            raise WorkflowError(
                unknown_key_message(label(key), key, known, known_label=known_label, prefix=prefix),
                key=dotted_key(label(key), prefix + key),
                value=section[key],
            )
    try:
        return cls(**section, **(extra or {}))
    except pydantic.ValidationError as exc:
        message = format_validation_error(
            exc, cls, section, where, prefix=prefix, known_label=known_label, internal=internal
        )
        raise WorkflowError(message, **_offending(exc, section, label, prefix)) from None


def dotted_key(label: str, key: str) -> str | None:
    """Return a workflow key as ``--set`` names it: ``"[identify]", "M"`` -> ``"identify.M"``.

    Examples
    --------
    >>> dotted_key("[ingest]", "q.unit"), dotted_key("[compare]", "")
    ('ingest.q.unit', 'compare')
    """
    section = label.strip().removeprefix("[").removesuffix("]")
    return ".".join(part for part in (section, key) if part) or None


def _offending(
    exc: pydantic.ValidationError,
    section: Mapping[str, Any],
    label: Callable[[str], str],
    prefix: str,
) -> dict[str, Any]:
    """Return the ``key`` and ``value`` of the error :func:`format_validation_error` reports.

    An unknown key first, else the first error; a helper's own :class:`WorkflowError` keeps its.
    """
    errors = exc.errors(include_url=False)
    unknown = [
        e
        for e in errors
        if e["type"] in ("unexpected_keyword_argument", "extra_forbidden") and len(e["loc"]) == 1
    ]
    err = (unknown or errors)[0]
    inner = (err.get("ctx") or {}).get("error")
    if isinstance(inner, WorkflowError):
        return {"key": inner.key, "value": inner.value}
    loc = tuple(err["loc"])
    name = str(loc[0]) if loc else ""
    if isinstance(inner, ConfigValueError) and inner.key is not None:
        name = inner.key
    if isinstance(inner, ConfigValueError) and inner.got is not ConfigValueError._UNSET:
        value = inner.got
    elif err["type"] in ("missing", "missing_argument"):
        value = None
    elif not name:  # a rule on the whole table
        value = dict(section)
    else:
        value = section.get(name, err.get("input"))
    key = prefix + name if name else prefix.rstrip(".")
    return {"key": dotted_key(label(name), key), "value": value}


def field_names(cls: type, internal: Sequence[str] = ()) -> list[str]:
    """Return the workflow keys of a config dataclass (aliases where set), in field order.

    Parameters
    ----------
    cls : type
        A (pydantic) dataclass.
    internal : sequence of str, optional
        Fields that are not workflow keys.

    Returns
    -------
    list of str
        The keys.
    """
    infos = getattr(cls, "__pydantic_fields__", None)
    if infos is None:
        return [f.name for f in dataclasses.fields(cls) if f.name not in internal]
    return [(i.alias or n) for n, i in infos.items() if n not in internal]


class SectionConfig:
    """Base of the configuration dataclasses of the workflow's tables.

    A subclass is a frozen pydantic dataclass built with :data:`CONFIG` that names its table;
    :meth:`from_dict` builds it from that table through :func:`config_from_section`, so every
    table is checked, and its errors worded, by one mechanism.

    Attributes
    ----------
    SECTION : str
        The workflow table, for the messages (e.g. ``"[validate]"``).
    KNOWN_LABEL : str
        Introduces the known keys in an unknown-key message.
    INTERNAL : tuple of str
        Fields that are not workflow keys: refused in a table, filled by the caller.

    Examples
    --------
    >>> @pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
    ... class Demo(SectionConfig):
    ...     SECTION: ClassVar[str] = "[demo]"
    ...     n: int = 1
    >>> Demo.from_dict({"n": 3}).n
    3
    >>> Demo.from_dict({"m": 3})
    Traceback (most recent call last):
    ...
    debist.core.errors.WorkflowError: [demo] unknown key 'm' (known keys: n)
    """

    SECTION: ClassVar[str] = ""
    KNOWN_LABEL: ClassVar[str] = "known keys"
    INTERNAL: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def from_dict(
        cls,
        section: Mapping[str, Any] | None,
        where: str | Callable[[str], str] | None = None,
    ) -> Self:
        """Build and check the configuration from its workflow table.

        Parameters
        ----------
        section : mapping of str to value or None
            The table's keys (None or empty: every default).
        where : str or callable, optional
            The table's label for the messages, or a function of the key giving it
            (default :attr:`SECTION`).

        Returns
        -------
        SectionConfig
            An instance of the subclass.

        Raises
        ------
        WorkflowError
            On a table that is not a table, an unknown key (with a suggestion), or an
            invalid value: ``[section] key: expected ..., got ...``.
        """
        return config_from_section(
            cls,
            {} if section is None else section,
            cls.SECTION if where is None else where,
            known_label=cls.KNOWN_LABEL,
            internal=cls.INTERNAL,
        )
