"""The docs site's config reference, generated from ``config.schema.yaml``: every key, its type, default and description.

The mkdocs hook (``docs/hooks/topoloc_docs.py``) calls :func:`config_reference` at every docs build, so the page can
never fall behind the schema; the schema is the one place that holds the defaults.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

from topoloc.config import schema

_NOTE = ("Generated from `src/topoloc/config.schema.yaml` when the docs are built; do not edit. A config file sets "
         "only the keys it changes: it is merged over the defaults below (`config/config.yaml` for the default "
         "region; the other files under `config/` are overlays, see `config/README.md`).")


def _cell(text: Any) -> str:
    """``text`` fit for one markdown table cell."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _prose(text: Any) -> str:
    """A description fit for one table cell, its ``<name>`` placeholders shown as text, not read as HTML."""
    return _cell(text).replace("<", "&lt;").replace(">", "&gt;")


def _type(node: dict[str, Any]) -> str:
    kind = node.get("type", "any")
    kinds = kind if isinstance(kind, list) else [kind]
    if "enum" in node:
        return "one of " + ", ".join(f"`{v}`" for v in node["enum"])
    if "items" in node and "enum" in node["items"]:
        return " or ".join(kinds) + " of " + ", ".join(f"`{v}`" for v in node["items"]["enum"])
    if "items" in node and "type" in node["items"]:
        inner = node["items"]["type"]
        return " or ".join(kinds) + " of " + (" or ".join(inner) if isinstance(inner, list) else inner)
    return " or ".join(kinds)


def _default(node: dict[str, Any], required: bool) -> str:
    if required:
        return "required"
    if "default" not in node:
        return ""
    default = node["default"]
    if isinstance(default, dict) and "properties" in node:
        return "(below)" if not default else f"`{json.dumps(default)}`"
    return f"`{json.dumps(default)}`"


def keys(node: dict[str, Any], prefix: str = "") -> Iterator[tuple[str, dict[str, Any], bool]]:
    """(dotted key, schema node, required) for every key under ``node``, depth first in schema order."""
    required = set(node.get("required", []))
    for name, child in node.get("properties", {}).items():
        key = f"{prefix}{name}"
        yield key, child, name in required
        yield from keys(child, key + ".")
        if isinstance(child.get("additionalProperties"), dict):  # a mapping of named entries (odometry.drives)
            entry = child["additionalProperties"]
            yield f"{key}.<name>", entry, False
            yield from keys(entry, f"{key}.<name>.")
        if isinstance(child.get("items"), dict) and "properties" in child["items"]:
            yield from keys(child["items"], f"{key}[].")


def config_reference(tree: dict[str, Any] | None = None) -> str:
    """The config reference page (markdown) of the schema ``tree`` (default: the package's schema)."""
    tree = schema() if tree is None else tree
    lines = ["# Config reference", "", _NOTE, ""]
    for section, node in tree.get("properties", {}).items():
        lines += [f"## `{section}`", "", _prose(node.get("description", "")), ""]
        rows = list(keys({"properties": {section: node}, "required": tree.get("required", [])}))
        if "properties" in node:  # the section's own row would repeat the text above
            rows = rows[1:]
        lines += ["| key | type | default | description |", "|---|---|---|---|"]
        for key, child, req in rows:
            cells = [f"`{key}`", _cell(_type(child)), _cell(_default(child, req)), _prose(child.get("description", ""))]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)
