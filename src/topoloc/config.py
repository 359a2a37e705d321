"""The pipeline config: the schema shipped with the package is the only source of defaults.

:func:`load` reads a config file, fills in every default of ``config.schema.yaml``
and validates it; :func:`validate_and_fill` does the same to a config that is
already a dict (the workflow's). Code reads the validated config with ``conf[key]``:
it never carries defaults of its own.
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import jsonschema
import yaml

from topoloc.errors import InputError

#: The JSON schema of the config (every key documented, with its default).
SCHEMA_PATH = Path(__file__).with_name("config.schema.yaml")


@functools.cache
def schema() -> dict[str, Any]:
    """The config schema (read once)."""
    return yaml.safe_load(SCHEMA_PATH.read_text())


def _where_and_what(error: Any) -> tuple[str, str]:
    path = ".".join(str(part) for part in error.absolute_path)
    message = " ".join(str(error.message).split())
    if error.validator == "additionalProperties":
        where = f"under '{path}'" if path else "at the top level"
        return "config", f"unknown key {where}: {message}"
    return f"config key '{path or '(top level)'}'", message


def validate_and_fill(config: dict[str, Any], source: str | Path | None = None) -> dict[str, Any]:
    """Fill every schema default into ``config`` (in place) and validate it; returns ``config``.

    InputError with one line naming the key (and ``source``, the file, when given) when
    the config is not valid.
    """
    validator = _FILLING_VALIDATOR(schema())
    error = jsonschema.exceptions.best_match(validator.iter_errors(config))
    if error is not None:
        where, message = _where_and_what(error)
        raise InputError(f"{source}: {where}" if source is not None else where, message)
    if "odometry" in config:
        try:
            check_drives(config["odometry"])
        except InputError as err:
            raise InputError(f"{source}: {err.where}" if source is not None else err.where, err.message) from None
    return config


#: The keys every drive of ``odometry.drives`` needs, per ``odometry.source`` (the others ignore drives).
REQUIRED_DRIVE_KEYS = {"kitti_poses": ("poses",), "kitti_stereo": ("sequence",), "simulated": (), "rendered": ()}


def check_drives(odometry: Mapping[str, Any]) -> None:
    """InputError naming the drive and key when a drive lacks what ``odometry.source`` needs.

    A ``kitti_*`` source needs at least one drive, each with its files (:data:`REQUIRED_DRIVE_KEYS`), and
    either a gps file or ``odometry.origin`` to be placed on the map.
    """
    source = odometry["source"]
    if source not in ("kitti_poses", "kitti_stereo"):
        return
    drives = odometry["drives"]
    if not drives:
        raise InputError("config key 'odometry.drives'", f"odometry.source {source} needs at least one drive")
    for name, drive in drives.items():
        for key in REQUIRED_DRIVE_KEYS[source]:
            if not drive.get(key):
                raise InputError(f"config key 'odometry.drives.{name}.{key}'",
                                 f"drive {name} has no {key}, which odometry.source {source} needs")
        if not drive.get("gps") and not odometry["origin"]:
            raise InputError(f"config key 'odometry.drives.{name}.gps'",
                             f"drive {name} has no gps file and odometry.origin is not set: "
                             "set one of them to place the drive on the map")


def load(path: str | Path | Sequence[str | Path] | None = None,
         overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The config of ``path`` (a YAML file, or several merged in order as Snakemake's ``--configfile`` does; None: no
    keys) updated by ``overrides``, defaults filled, validated.

    ``overrides`` is deep-merged onto the file (nested mappings merge, other values replace).
    A config without a region gets ``region.name: default``. InputError with one line naming
    the file or key when it is not a valid config.
    """
    paths = [] if path is None else [path] if isinstance(path, (str, Path)) else list(path)
    data: dict[str, Any] = {}
    for one in paths:
        data = deep_merge(data, _yaml_mapping(Path(one), str(one), "the config file"))
    data = deep_merge(data, overrides or {})
    data.setdefault("region", {"name": "default"})
    return validate_and_fill(data, paths[-1] if paths else None)


def region_configs(config: Mapping[str, Any], base_dir: str | Path = ".") -> dict[str, dict[str, Any]]:
    """The config of each region of ``config['regions']`` by name (empty when it names none).

    An entry is a config file (relative to ``base_dir``) or a mapping (which may name a config file under
    ``file``: the mapping's other keys are merged onto that file's); either is merged onto ``config`` without
    its ``regions`` key, then filled and validated. A region that names drives (``odometry.drives``) has those
    drives only: the run's drives are another region's data, not merged into it. InputError with one line naming the entry, the file or the
    key: a file that cannot be read, a region named twice, a region config that names regions itself.
    """
    base = {k: v for k, v in config.items() if k != "regions"}
    configs: dict[str, dict[str, Any]] = {}
    for index, entry in enumerate(config.get("regions") or []):
        where = f"regions.{index}"
        if isinstance(entry, str):
            data = _yaml_mapping(Path(base_dir) / entry, f"{where}: {entry}")
            where = f"{where} ({entry})"
        elif "file" in entry:
            data = deep_merge(_yaml_mapping(Path(base_dir) / str(entry["file"]), f"{where}.file: {entry['file']}"),
                              {k: v for k, v in entry.items() if k != "file"})
            where = f"{where} ({entry['file']})"
        else:
            data = entry
        if data.get("regions"):
            raise InputError(where, "a region's config cannot name regions itself")
        own = deep_merge(base, {k: v for k, v in data.items() if k != "regions"})
        if (data.get("odometry") or {}).get("drives"):
            own["odometry"]["drives"] = copy.deepcopy(data["odometry"]["drives"])  # a region's drives are its own
        merged = validate_and_fill(own, where)
        name = merged["region"]["name"]
        if name in configs:
            raise InputError(where, f"region {name!r} is named twice in regions")
        configs[name] = merged
    return configs


def _yaml_mapping(path: Path, where: str, what: str = "the region's config file") -> dict[str, Any]:
    """The mapping of a config file; InputError naming ``where`` when it cannot be read or is not one."""
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except OSError as err:
        raise InputError(where, f"cannot read {what} ({err.strerror})") from err
    except yaml.YAMLError as err:
        raise InputError(where, f"not a YAML file ({str(err).splitlines()[0]})") from err
    if not isinstance(data, dict):
        raise InputError(where, "a config file is a YAML mapping")
    return data


def dotted_overrides(items: list[str]) -> dict[str, Any]:
    """Overrides for :func:`load` from ``SECTION.KEY=VALUE`` strings (values are YAML: 20, 0.01, gru, null)."""
    overrides: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise InputError(item, "an override is SECTION.KEY=VALUE")
        *parents, last = key.split(".")
        node = overrides
        for part in parents:
            node = node.setdefault(part, {})
        node[last] = yaml.safe_load(value)
    return overrides


def deep_merge(base: Mapping[str, Any], update: Mapping[str, Any]) -> dict[str, Any]:
    """A deep copy of ``base`` with ``update`` merged in: nested mappings merge, other values replace."""
    merged = copy.deepcopy(dict(base))
    for key, value in update.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = deep_merge(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def _fill_defaults(validator: Any, properties: dict[str, Any], instance: Any, schema: dict[str, Any]) -> Any:
    if isinstance(instance, dict):
        for key, sub in properties.items():
            if "default" in sub and key not in instance:
                instance[key] = copy.deepcopy(sub["default"])
    yield from jsonschema.Draft202012Validator.VALIDATORS["properties"](validator, properties, instance, schema)


_FILLING_VALIDATOR = jsonschema.validators.extend(jsonschema.Draft202012Validator, {"properties": _fill_defaults})
