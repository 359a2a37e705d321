"""Config helpers shared by the workflow: one-line validation messages."""

from __future__ import annotations

from typing import Any


def validation_message(error: Any) -> str:
    """One line naming the config key of a jsonschema ``ValidationError`` and what is wrong."""
    path = ".".join(str(part) for part in error.absolute_path)
    message = " ".join(str(error.message).split())
    if error.validator == "additionalProperties":
        where = f"under '{path}'" if path else "at the top level"
        return f"config: unknown key {where}: {message}"
    return f"config key '{path or '(top level)'}': {message}"
