"""mkdocs hook: the workflow-key reference, written from the JSON Schema of a workflow file.

``reference/workflow-keys.md`` holds the marker ``<!-- workflow-keys -->``; when the site is
built, :func:`on_page_markdown` replaces it with one table per section and sub-table (key,
type, default, description) rendered from :func:`debist.workflow_schema`, the schema that
``debist schema`` prints. :func:`render` is importable on its own (``tests/cli/test_docs.py``
checks that the page lists every key the schema has).

References
----------
mkdocs, "Hooks" and the ``on_page_markdown`` event (https://www.mkdocs.org/user-guide/configuration/#hooks);
JSON Schema 2020-12 (https://json-schema.org/draft/2020-12/json-schema-validation).
"""

from __future__ import annotations

import json
from typing import Any

PAGE = "reference/workflow-keys.md"
MARKER = "<!-- workflow-keys -->"


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """Replace the marker of the workflow-key page by the tables (mkdocs event)."""
    if page.file.src_uri != PAGE:
        return markdown
    import debist

    return markdown.replace(MARKER, render(debist.workflow_schema()))


def render(schema: dict[str, Any]) -> str:
    """Return the Markdown of every section of a workflow schema, in the schema's order.

    Parameters
    ----------
    schema : dict
        A JSON Schema as :func:`debist.workflow_schema` returns it.

    Returns
    -------
    str
        Headings ``## [section]`` and ``### [section.table]``, each with its description and
        a table of its keys: key, type, default, description. A table that several keys hold
        (a channel, the prototype's parameters) is written once and referred to after that.
    """
    out: list[str] = []
    seen: dict[str, str] = {}
    for name, node in schema["properties"].items():
        _section(out, f"[{name}]", node, schema["$defs"], 2, seen)
    return "\n".join(out) + "\n"


#: Placeholders of the tables whose keys are names, by the definition they hold.
_PLACEHOLDERS = {"ChannelSpec": "<channel>", "ExperimentConfig": "<experiment>"}


def _def_name(node: dict[str, Any]) -> str | None:
    return node["$ref"].rsplit("/", 1)[-1] if "$ref" in node else None


def _resolve(node: dict[str, Any], defs: dict[str, Any]) -> dict[str, Any]:
    """Return a node with its ``$ref`` followed (the node's own description wins)."""
    if "$ref" not in node:
        return node
    target = dict(defs[_def_name(node)])
    if node.get("description"):
        target["description"] = node["description"]
    return target


def _is_table(node: dict[str, Any], defs: dict[str, Any]) -> bool:
    """Whether a node is a table with keys of its own (not a table of plain values)."""
    node = _resolve(node, defs)
    extra = node.get("additionalProperties")
    return node.get("type") == "object" and (
        "properties" in node or (isinstance(extra, dict) and _is_table(extra, defs))
    )


def _sub_table(node: dict[str, Any], defs: dict[str, Any]) -> tuple[dict, bool] | None:
    """Return the table a key holds, and whether it holds an array of them.

    The table is the key's own, or one of its alternatives (``refine``: a table or a
    boolean); an array of tables is written ``[[validate.published]]``.
    """
    if _is_table(node, defs):
        return node, False
    items = node.get("items")
    if node.get("type") == "array" and isinstance(items, dict) and _is_table(items, defs):
        return {**items, "description": node.get("description", "")}, True
    for option in node.get("anyOf", ()):
        if _is_table(option, defs):
            return {**option, "description": node.get("description", "")}, False
    return None


def _heading(out: list[str], title: str, node: dict[str, Any], level: int) -> None:
    out += [f"{'#' * level} {title}", "", _cell(node.get("description", "")), ""]


def _section(
    out: list[str], title: str, node: dict[str, Any], defs: dict, level: int, seen: dict
) -> None:
    if _def_name(node) is not None:
        seen.setdefault(_def_name(node), title)
    node = _resolve(node, defs)
    _heading(out, title, node, level)
    if "anyOf" in node and all(_is_table(o, defs) for o in node["anyOf"]):
        for option in node["anyOf"]:
            method = _resolve(option, defs)["properties"]["method"]["const"]
            _section(out, f'{title} method = "{method}"', option, defs, level + 1, seen)
        return
    rows, tables, extra_row = [], [], None
    extra = node.get("additionalProperties")
    if isinstance(extra, dict) and _is_table(extra, defs):  # first: it names the shared table
        placeholder = _PLACEHOLDERS.get(_def_name(extra) or "", "<name>")
        sub = seen.get(_def_name(extra) or "", f"{title[:-1]}.{placeholder}]")
        if _def_name(extra) not in seen:
            tables.append((sub, extra))
            seen.setdefault(_def_name(extra) or sub, sub)
        what = _cell(_resolve(extra, defs).get("description", "")).split(". ")[0]
        extra_row = f"| `{placeholder}` | table | | {what} (its keys: `{sub}`) |"
    elif isinstance(extra, dict):
        text = _cell(extra.get("description", ""))
        extra_row = f"| `<key>` | {_type(extra, defs)} | | {text} |"
    elif extra is True:
        extra_row = "| `<key>` | any | | A key of the table the description names. |"
    for key, prop in node.get("properties", {}).items():
        found = _sub_table(prop, defs)
        if found is None:
            rows.append(_row(key, prop, defs))
            continue
        table, many = found
        sub = f"[{title[:-1]}.{key}]]" if many else f"{title[:-1]}.{key}]"
        sub = seen.get(_def_name(table) or "", sub)
        rows.append(_row(key, prop, defs, f"its keys: `{sub}`"))
        if _def_name(table) not in seen:
            tables.append((sub, table))
            if _def_name(table):
                seen[_def_name(table)] = sub
    if extra_row:
        rows.append(extra_row)
    if rows:
        out += ["| key | type | default | description |", "|---|---|---|---|", *rows, ""]
    for sub_title, table in tables:
        _section(out, sub_title, table, defs, min(level + 1, 4), seen)


def _row(key: str, prop: dict[str, Any], defs: dict[str, Any], note: str = "") -> str:
    text = _cell(prop.get("description", ""))
    text = f"{text} ({note})" if note else text
    return f"| `{key}` | {_type(prop, defs)} | {_default(prop)} | {text} |"


def _type(node: dict[str, Any], defs: dict[str, Any]) -> str:
    """Return a key's type in words: TOML types, allowed values and ranges."""
    if "$ref" in node:
        return "table" if _is_table(node, defs) else _type(_resolve(node, defs), defs)
    if "const" in node:
        return f"`{_toml(node['const'])}`"
    if "enum" in node:
        return "one of " + ", ".join(f"`{_toml(v)}`" for v in node["enum"])
    if "anyOf" in node:
        kinds = [_type(o, defs) for o in node["anyOf"] if o.get("type") != "null"]
        return " or ".join(dict.fromkeys(kinds))
    kind = node.get("type")
    if kind == "array":
        if "prefixItems" in node:
            return "[" + ", ".join(_type(i, defs) for i in node["prefixItems"]) + "]"
        items = node.get("items")
        return f"array of {_type(items, defs)}" if items else "array"
    if kind == "object":
        extra = node.get("additionalProperties")
        return f"table of {_type(extra, defs)}" if isinstance(extra, dict) else "table"
    words = {"string": "string", "integer": "integer", "number": "float", "boolean": "boolean"}
    text = words.get(kind, "any")
    limits = [
        f"{op} {_toml(node[k])}"
        for k, op in (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="),
                      ("exclusiveMaximum", "<"))
        if k in node
    ]  # fmt: skip
    if "minLength" in node:
        limits.append("not empty")
    return f"{text} ({', '.join(limits)})" if limits else text


def _default(node: dict[str, Any]) -> str:
    if "default" not in node or node["default"] is None:
        return ""
    return f"`{_toml(node['default'])}`"


def _toml(value: Any) -> str:
    """Return a value as TOML writes it (``true``, ``"auto"``, ``[1, 2]``, ``{}``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _cell(text: str) -> str:
    """Return text for one Markdown table cell: one line, pipes and brackets escaped.

    Brackets outside code spans are escaped: ``[s] [m]`` would read as a reference link.
    """
    parts = " ".join(text.split()).replace("|", "\\|").split("`")
    for i in range(0, len(parts), 2):  # outside code spans
        parts[i] = parts[i].replace("[", "\\[").replace("]", "\\]")
    return "`".join(parts)
