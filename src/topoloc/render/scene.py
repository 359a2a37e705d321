"""The street scene of a drive: buildings (OSM footprints or procedural facades) and the road surface.

* **OSM buildings**: every area tagged ``building=*`` (closed ways and multipolygon relations, read with
  pyosmium; ``building=roof`` / ``canopy`` / ``no`` are skipped), projected to the road graph's CRS. Its
  height is the ``height`` (or ``building:height``) tag in metres, else ``building:levels`` times
  ``level_height_m`` plus 1 m, else drawn uniformly from ``default_height_m`` with the building's own seed.
* **Procedural facades** fill the road sides where the map has no buildings: blocks of 8-24 m with gaps
  of 1.5-6 m, set back behind the sidewalk, 8-14 m deep, each seeded by its road edge, side and index.
  A block is dropped when it comes closer than ``procedural_gap_m`` to an OSM building or reaches into
  any road or its sidewalk.
* Footprints are cut back to ``clearance_m`` from the driven path (arcades and passages the route goes
  through become open), and only those within ``view_distance_m`` of the path are kept.
* Every building gets its own facade texture, seeded by its OSM area id (or its procedural key), so the
  same place looks the same in every drive and condition.
* The **road surface** comes from the road graph; it is drawn lazily in 64 m cells with a 64 m margin.
"""

from __future__ import annotations

import logging
import re
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import osmium
import pyproj
import shapely
from numpy.typing import NDArray
from tqdm import tqdm

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.render.raycast import Walls
from topoloc.render.textures import (
    SIDEWALK_M,
    TEXEL_M,
    TILE_H,
    TILE_W,
    Road,
    draw_ground,
    edge_widths,
    facade_texture,
    grain_tile,
)

log = logging.getLogger(__name__)

SKIPPED_BUILDINGS = {"no", "roof", "canopy", "carport", "ruins", "collapsed"}
PROCEDURAL_KEY = 10**12
ATLAS_COLUMNS = 64
CELL_M = 64.0
_STRIDE = TILE_W + 2  # atlas columns per facade tile: the tile and a wrap-around column on each side
_NUMBER = re.compile(r"^\s*([0-9]+(?:[.,][0-9]+)?)\s*(m|meters|metres)?\s*$")


@dataclass(frozen=True)
class Building:
    """A footprint (shapely Polygon, map metres), its height in metres, a texture ``key`` and its ``source``."""

    key: int
    polygon: shapely.Polygon
    height: float
    source: str = "osm"


def parse_height(tags: dict[str, str], level_height_m: float) -> float | None:
    """Height in metres from ``height`` / ``building:height`` or ``building:levels``; None when absent or unreadable."""
    for key in ("height", "building:height"):
        match = _NUMBER.match(tags.get(key, ""))
        if match and float(match.group(1).replace(",", ".")) > 0:
            return float(match.group(1).replace(",", "."))
    match = _NUMBER.match(tags.get("building:levels", ""))
    if match and float(match.group(1).replace(",", ".")) > 0:
        return float(match.group(1).replace(",", ".")) * level_height_m + 1.0
    return None


def _buildings_from(objects: Any, to_map: pyproj.Transformer, conf: dict[str, Any], seed: int,
                    closed_ways: bool = False) -> list[Building]:
    """Buildings of the pyosmium areas (``closed_ways``: of the closed ways instead) tagged ``building``."""
    lo, hi = conf["default_height_m"]
    out: list[Building] = []
    for obj in objects:
        if obj.tags.get("building") in SKIPPED_BUILDINGS:
            continue
        if obj.is_area() and not closed_ways:
            rings = [([(n.lon, n.lat) for n in outer if n.location.valid()],
                      [[(n.lon, n.lat) for n in inner if n.location.valid()] for inner in obj.inner_rings(outer)])
                     for outer in obj.outer_rings()]
        elif closed_ways and obj.is_way() and obj.is_closed():
            rings = [([(n.lon, n.lat) for n in obj.nodes if n.location.valid()], [])]
        else:
            continue
        tags = {k: obj.tags.get(k, "") for k in ("height", "building:height", "building:levels")}
        height = parse_height(tags, float(conf["level_height_m"]))
        if height is None:
            height = float(np.random.default_rng([seed, 5, obj.id]).uniform(lo, hi))
        for shell, holes in rings:
            if len(shell) < 4:
                continue
            project = lambda ll: np.column_stack(to_map.transform(*np.asarray(ll, float).T))  # noqa: E731
            polygon = shapely.make_valid(shapely.Polygon(project(shell), [project(h) for h in holes if len(h) >= 4]))
            for part in getattr(polygon, "geoms", [polygon]):
                if isinstance(part, shapely.Polygon) and part.area > 1.0:
                    out.append(Building(int(obj.id), part, height, "osm"))
    return out


def read_buildings(path: str | Path, crs: str, conf: dict[str, Any], seed: int) -> list[Building]:
    """Buildings of an OSM file in ``crs``; heights from tags, else seeded from ``conf['default_height_m']``.

    Closed ways and multipolygon relations are assembled into areas by pyosmium. A file whose objects are
    not sorted by id (osmnx writes such files) cannot be assembled: then closed ways alone are read.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "OSM file not found")
    to_map = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    building = osmium.filter.KeyFilter("building")
    try:
        try:
            return _buildings_from(osmium.FileProcessor(str(path)).with_areas().with_filter(building), to_map, conf, seed)
        except RuntimeError as err:
            if "out of order" not in str(err):
                raise
            log.warning("%s: objects not sorted by id (%s); reading buildings from closed ways only", path, err)
            processor = osmium.FileProcessor(str(path), osmium.osm.NODE | osmium.osm.WAY).with_locations().with_filter(building)
            return _buildings_from(processor, to_map, conf, seed, closed_ways=True)
    except RuntimeError as err:
        raise InputError(path, f"cannot read OSM data ({err})") from err


def graph_roads(graph: RoadGraph) -> list[Road]:
    """Every edge as a :class:`Road`; centre markings stop short of junctions (nodes of degree >= 3)."""
    widths = edge_widths(graph.edges)
    node_width: dict[int, float] = {}
    for (u, v), w in zip(zip(graph.edges.u, graph.edges.v), widths):
        node_width[u] = max(node_width.get(u, 0.0), w)
        node_width[v] = max(node_width.get(v, 0.0), w)
    degree = graph.nodes.degree
    roads = []
    for e, coords in enumerate(graph.geometry):
        u, v = graph.edges.u.iat[e], graph.edges.v.iat[e]
        trim = lambda n: node_width[n] / 2 + 4.0 if degree.at[n] >= 3 else 0.0  # noqa: E731
        roads.append(Road(np.asarray(coords, float), float(widths[e]), int(graph.edges.oneway.iat[e]) == 0, trim(u), trim(v)))
    return roads


def procedural_buildings(roads: list[Road], edge_ids: list[int], real: list[Building], conf: dict[str, Any],
                         seed: int) -> list[Building]:
    """Seeded blocks along both sides of the roads ``edge_ids`` (indices into ``roads``) where the map has none."""
    lines = np.array([shapely.LineString(r.coords) for r in roads], dtype=object)
    reach = np.array([r.width / 2 + SIDEWALK_M - 0.5 for r in roads])
    road_tree = shapely.STRtree(lines)
    real_tree = shapely.STRtree([b.polygon for b in real]) if real else None
    gap_to_real = float(conf["procedural_gap_m"])
    lo, hi = conf["default_height_m"]
    out = []
    for e in edge_ids:
        coords = roads[e].coords
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(coords, axis=0).T))])
        at = lambda s: np.array([np.interp(s, cum, coords[:, 0]), np.interp(s, cum, coords[:, 1])])  # noqa: E731
        for side in (1, -1):
            rng = np.random.default_rng([seed, 4, e, side > 0])
            s, j = rng.uniform(0.0, 4.0), 0
            while s < cum[-1] - 5.0:
                end = min(s + rng.uniform(8.0, 24.0), cum[-1])
                a, b = at(s), at(end)
                setback, depth = roads[e].width / 2 + SIDEWALK_M + rng.uniform(0.5, 3.0), rng.uniform(8.0, 14.0)
                height = float(rng.uniform(lo, hi))
                t = (b - a) / max(np.hypot(*(b - a)), 1e-9)
                n = side * np.array([t[1], -t[0]])
                quad = shapely.Polygon([a + n * setback, b + n * setback, b + n * (setback + depth), a + n * (setback + depth)])
                if end - s >= 5.0 and quad.is_valid:
                    near_roads = road_tree.query(quad, predicate="dwithin", distance=float(reach.max()))
                    clear = not np.any(shapely.distance(lines[near_roads], quad) < reach[near_roads])
                    if clear and real_tree is not None:
                        clear = len(real_tree.query(quad, predicate="dwithin", distance=gap_to_real)) == 0
                    if clear:
                        out.append(Building(PROCEDURAL_KEY + (2 * e + (side > 0)) * 1000 + j, quad, height, "procedural"))
                s, j = end + rng.uniform(1.5, 6.0), j + 1
    return out


@dataclass
class Scene:
    """Walls with their facade atlas, the road surface (drawn per cell on demand) and the ground grain."""

    buildings: list[Building]
    roads: list[Road]
    seed: int
    walls: Walls = field(init=False)
    atlas: NDArray[np.uint8] = field(init=False)
    glow: NDArray[np.uint8] = field(init=False)
    grain: NDArray[np.float32] = field(init=False)
    _cells: OrderedDict = field(init=False, default_factory=OrderedDict, repr=False)

    def __post_init__(self) -> None:
        rings = []
        for tile, building in enumerate(self.buildings):
            polygon = shapely.orient_polygons(building.polygon)  # shell counter-clockwise, holes clockwise
            for ring in [polygon.exterior, *polygon.interiors]:
                rings.append((np.asarray(ring.coords), tile, building.height))
        self.walls = Walls.from_rings(rings)
        rows = max(1, -(-len(self.buildings) // ATLAS_COLUMNS))
        self.atlas = np.zeros((rows * TILE_H, ATLAS_COLUMNS * _STRIDE, 3), np.uint8)
        self.glow = np.zeros((rows * TILE_H, ATLAS_COLUMNS * _STRIDE), np.uint8)
        for tile, building in enumerate(tqdm(self.buildings, desc="facades", unit="building", mininterval=2.0,
                                             disable=len(self.buildings) < 200)):
            y0, x0 = self.tile_origin(tile)
            for atlas, texture in zip((self.atlas, self.glow), facade_texture(building.key, self.seed)):
                # One column of padding on each side, copied from the other side: the tile wraps seamlessly.
                atlas[y0:y0 + TILE_H, x0 - 1:x0 + TILE_W + 1] = np.concatenate([texture[:, -1:], texture, texture[:, :1]], axis=1)
        self.grain = grain_tile(self.seed)
        bounds = [(*r.coords.min(axis=0), *r.coords.max(axis=0)) for r in self.roads]
        self._road_bounds = np.array(bounds).reshape(-1, 4)

    @staticmethod
    def tile_origin(tile: int | NDArray[np.int64]) -> tuple[Any, Any]:
        """Atlas (row, column) of the top-left texel of facade tile ``tile``."""
        return (tile // ATLAS_COLUMNS) * TILE_H, (tile % ATLAS_COLUMNS) * _STRIDE + 1

    def ground(self, xy: NDArray[np.float64]) -> tuple[NDArray[np.uint8], float, float]:
        """Road-surface raster around map point ``xy`` and the map (x0, y1) of its top-left corner."""
        cell = (int(np.floor(xy[0] / CELL_M)), int(np.floor(xy[1] / CELL_M)))
        if cell in self._cells:
            self._cells.move_to_end(cell)
            return self._cells[cell]
        x0, y1 = (cell[0] - 1) * CELL_M, (cell[1] + 2) * CELL_M
        size = int(round(3 * CELL_M / TEXEL_M))
        b = self._road_bounds
        margin = 20.0
        hit = (b[:, 0] < x0 + 3 * CELL_M + margin) & (b[:, 2] > x0 - margin) & (b[:, 1] < y1 + margin) \
            & (b[:, 3] > y1 - 3 * CELL_M - margin)
        entry = (draw_ground([r for r, h in zip(self.roads, hit) if h], x0, y1, (size, size)), x0, y1)
        self._cells[cell] = entry
        if len(self._cells) > 6:
            self._cells.popitem(last=False)
        return entry

    def facts(self) -> dict[str, int]:
        """Counts of OSM and procedural buildings and of wall pieces."""
        return {"buildings_osm": sum(b.source == "osm" for b in self.buildings),
                "buildings_procedural": sum(b.source == "procedural" for b in self.buildings),
                "wall_pieces": len(self.walls)}


def scene_for_path(osm_path: str | Path | None, graph: RoadGraph, path_xy: NDArray[np.float64],
                   conf: dict[str, Any], seed: int) -> Scene:
    """The scene around a driven path: OSM buildings (if ``osm_path``), procedural facades, the graph's roads.

    ``conf`` holds the ``render.buildings`` settings and ``render.view_distance_m``.
    """
    path = shapely.LineString(path_xy) if len(path_xy) > 1 else shapely.Point(path_xy[0])
    view = float(conf["view_distance_m"])
    real = read_buildings(osm_path, graph.crs, conf, seed) if osm_path is not None else []
    real = [b for b in real if shapely.dwithin(b.polygon, path, view)]
    roads = graph_roads(graph)
    lines = np.array([shapely.LineString(r.coords) for r in roads], dtype=object)
    near_edges = np.flatnonzero(shapely.dwithin(lines, path, view + 30.0)).tolist()
    procedural = procedural_buildings(roads, near_edges, real, conf, seed) if conf["procedural"] else []
    procedural = [b for b in procedural if shapely.dwithin(b.polygon, path, view)]
    corridor = path.buffer(float(conf["clearance_m"]))
    kept = []
    for building in real + procedural:
        cut = building.polygon.difference(corridor) if building.polygon.intersects(corridor) else building.polygon
        for part in getattr(cut, "geoms", [cut]):
            if isinstance(part, shapely.Polygon) and not part.is_empty and part.area > 1.0:
                kept.append(Building(building.key, part, building.height, building.source))
    return Scene(kept, [roads[e] for e in near_edges], seed)
