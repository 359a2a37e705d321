"""Read the road ways of an OSM file (.osm, .osm.bz2, .osm.pbf) with pyosmium."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path

import osmium
from osmium.osm import NODE, WAY

from topoloc.errors import InputError

#: Every highway class a car may use, from fast to slow. Config may select a subset.
DRIVABLE_HIGHWAY_CLASSES: tuple[str, ...] = (
    "motorway",
    "motorway_link",
    "trunk",
    "trunk_link",
    "primary",
    "primary_link",
    "secondary",
    "secondary_link",
    "tertiary",
    "tertiary_link",
    "unclassified",
    "residential",
    "living_street",
    "service",
    "road",
)

OSM_SUFFIXES: tuple[str, ...] = (".osm", ".osm.bz2", ".osm.pbf")

_NO_ACCESS = {"no", "private"}
_ONEWAY_FORWARD = {"yes", "true", "1"}
_ONEWAY_BACKWARD = {"-1", "reverse"}


@dataclass(frozen=True)
class Way:
    """One OSM way that carries cars.

    ``oneway`` is +1 (travel only along ``refs``), -1 (only against) or 0 (both). ``lanes`` and ``width_m`` are
    the ``lanes`` and ``width`` tags (traffic lanes; carriageway width in metres), NaN where untagged or unreadable.
    """

    osm_id: int
    refs: tuple[int, ...]
    highway: str
    name: str
    oneway: int
    lanes: float = float("nan")
    width_m: float = float("nan")


@dataclass
class RawNetwork:
    """The drivable ways of a file and the WGS84 location (lon, lat) of every node they use.

    ``missing_node_refs`` counts node references without a location (ways cut at an
    extract's border); such a way is kept as the runs of nodes that have one.
    """

    ways: list[Way] = field(default_factory=list)
    lonlat: dict[int, tuple[float, float]] = field(default_factory=dict)
    missing_node_refs: int = 0

    def highway_counts(self) -> dict[str, int]:
        """Number of ways per highway class."""
        counts: dict[str, int] = {}
        for way in self.ways:
            counts[way.highway] = counts.get(way.highway, 0) + 1
        return dict(sorted(counts.items()))


def osm_suffix(path: str | Path) -> str:
    """The OSM suffix of ``path`` (``.osm``, ``.osm.bz2`` or ``.osm.pbf``), or raise InputError."""
    name = Path(path).name.lower()
    for suffix in sorted(OSM_SUFFIXES, key=len, reverse=True):
        if name.endswith(suffix):
            return suffix
    raise InputError(path, f"not an OSM file: expected a name ending in {', '.join(OSM_SUFFIXES)}")


def read_road_network(
    path: str | Path,
    highway_classes: Iterable[str] = DRIVABLE_HIGHWAY_CLASSES,
    exclude_private: bool = False,
) -> RawNetwork:
    """Read the ways of ``highway_classes`` that cars may use, with their node locations.

    Ways tagged ``area=yes`` are skipped, and with ``exclude_private`` so are
    ways closed to the public (``access``, ``vehicle``, ``motor_vehicle`` or
    ``motorcar`` = ``no``/``private``). Raises :class:`InputError` naming the file when it is missing,
    empty, unreadable, or holds no such way.
    """
    path = Path(path)
    osm_suffix(path)
    if not path.is_file():
        raise InputError(path, "OSM file not found")
    if path.stat().st_size == 0:
        raise InputError(path, "OSM file is empty")
    classes = set(highway_classes)
    network = RawNetwork()
    try:
        processor = (
            osmium.FileProcessor(str(path), NODE | WAY)
            .with_locations()
            .with_filter(osmium.filter.KeyFilter("highway"))
        )
        for obj in processor:
            if not obj.is_way():
                continue
            way = _drivable_way(obj, classes, exclude_private)
            if way is None:
                continue
            # Extracts clip ways at their border: keep each run of nodes that has locations.
            run: list[int] = []
            for node in [*obj.nodes, None]:
                if node is not None and node.location.valid():
                    network.lonlat[node.ref] = (node.location.lon, node.location.lat)
                    run.append(node.ref)
                    continue
                if node is not None:
                    network.missing_node_refs += 1
                if len(run) >= 2:
                    network.ways.append(replace(way, refs=tuple(run)))
                run = []
    except RuntimeError as err:
        raise InputError(path, f"cannot read OSM data ({err})") from err
    if not network.ways:
        raise InputError(path, f"no drivable roads (highway in {sorted(classes)}) in this OSM data")
    return network


def _drivable_way(obj: osmium.osm.Way, classes: set[str], exclude_private: bool) -> Way | None:
    tags = obj.tags
    highway = tags.get("highway")
    if highway not in classes or tags.get("area") == "yes":
        return None
    if exclude_private and any(tags.get(key) in _NO_ACCESS for key in ("access", "vehicle", "motor_vehicle", "motorcar")):
        return None
    refs = tuple(node.ref for node in obj.nodes)
    if len(refs) < 2:
        return None
    return Way(obj.id, refs, highway, tags.get("name", ""), _oneway(tags, highway), _number(tags.get("lanes")),
               _metres(tags.get("width")))


def _number(value: str | None) -> float:
    """A positive number tag (``lanes=2``), NaN when absent or not a number (``lanes=2;3``)."""
    try:
        number = float(value) if value is not None else float("nan")
    except ValueError:
        return float("nan")
    return number if number > 0 else float("nan")


def _metres(value: str | None) -> float:
    """A length tag in metres (``width=7``, ``7.5 m``, ``7,5``); NaN when absent or in other units (feet, inches)."""
    if value is None:
        return float("nan")
    text = value.strip().replace(",", ".")
    text = text[:-1].strip() if text.endswith("m") else text
    return _number(text)


def _oneway(tags: osmium.osm.TagList, highway: str) -> int:
    value = tags.get("oneway", "")
    if value in _ONEWAY_FORWARD:
        return 1
    if value in _ONEWAY_BACKWARD:
        return -1
    if value == "no":
        return 0
    # Implied one-way roads (OSM wiki: motorways and roundabouts).
    if highway == "motorway" or tags.get("junction") in {"roundabout", "circular"}:
        return 1
    return 0
