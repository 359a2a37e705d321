"""Config helpers shared by the workflow: one-line validation messages."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import jsonschema

from topoloc.errors import InputError


def validation_message(error: Any) -> str:
    """One line naming the config key of a jsonschema ``ValidationError`` and what is wrong."""
    path = ".".join(str(part) for part in error.absolute_path)
    message = " ".join(str(error.message).split())
    if error.validator == "additionalProperties":
        where = f"under '{path}'" if path else "at the top level"
        return f"config: unknown key {where}: {message}"
    return f"config key '{path or '(top level)'}': {message}"


SCHEMA = Path(__file__).resolve().parents[2] / "workflow" / "schemas" / "config.schema.yaml"


def load(path: str | Path | None = None) -> dict[str, Any]:
    """The config of ``path`` (a YAML file; None: no keys) with every default of the schema filled in, validated.

    InputError with one line naming the file or key when it is not a valid config.
    """
    import jsonschema
    import yaml

    data: Any = {}
    if path is not None:
        try:
            data = yaml.safe_load(Path(path).read_text()) or {}
        except OSError as err:
            raise InputError(path, f"cannot read the config file ({err.strerror})") from err
        except yaml.YAMLError as err:
            raise InputError(path, f"not a YAML file ({str(err).splitlines()[0]})") from err
        if not isinstance(data, dict):
            raise InputError(path, "a config file is a YAML mapping")
    schema = yaml.safe_load(SCHEMA.read_text())
    data.setdefault("region", {"name": "default"})
    validator = jsonschema.validators.extend(jsonschema.Draft202012Validator, {"properties": _fill_defaults})(schema)
    error = jsonschema.exceptions.best_match(validator.iter_errors(data))
    if error is not None:
        raise InputError(str(path or "config"), validation_message(error))
    return data


def _fill_defaults(validator: Any, properties: dict[str, Any], instance: Any, schema: dict[str, Any]) -> Any:
    if isinstance(instance, dict):
        for key, sub in properties.items():
            if "default" in sub and key not in instance:
                instance[key] = copy.deepcopy(sub["default"])
    yield from jsonschema.Draft202012Validator.VALIDATORS["properties"](validator, properties, instance, schema)
