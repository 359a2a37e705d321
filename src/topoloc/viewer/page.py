"""The viewer's HTML file: a folium (Leaflet) map of the road graph with the drive's data and ``assets/viewer.js``.

The file is self-contained and works offline: Leaflet's script and styles (``assets/leaflet.js``,
``assets/leaflet.css`` with its images as data URIs; Leaflet 1.9.4, BSD-2-Clause, ``assets/LICENSE-leaflet.txt``),
the heat layer (``leaflet_heat.min.js``, shipped by folium) and the viewer's script are inlined; map tiles are an
option (``viewer.tiles``). The data is one JSON block (see :class:`ViewerData`) that ``viewer.js`` reads.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import folium
import numpy as np
import pyproj
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path

ASSETS = Path(__file__).parent / "assets"
#: Inlined in this order: Leaflet, its heat layer, the viewer.
SCRIPTS = ["leaflet.js", "leaflet_heat.min.js"]
PALETTE = ["#1f77b4", "#d62728", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f"]
#: Road geometry is simplified to this tolerance, metres (a pixel at zoom 17).
SIMPLIFY_M = 1.0

LatLon = Callable[[NDArray[np.float64]], list[list[float]]]


def latlon_of(crs: str) -> LatLon:
    """A function from map coordinates ``(n, 2)`` in ``crs`` to ``[[lat, lon], ...]`` rounded to 6 decimals."""
    transformer = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)

    def convert(xy: NDArray[np.float64]) -> list[list[float]]:
        xy = np.asarray(xy, float).reshape(-1, 2)
        lon, lat = transformer.transform(xy[:, 0], xy[:, 1])
        return np.round(np.column_stack([lat, lon]), 6).tolist()

    return convert


@dataclass
class ViewerData:
    """What the viewer shows; every time index is a row of ``time`` (the slider's positions).

    ``time``: ``frame``, ``driven_m`` and ``t_s`` lists, one entry per row. ``truth``: ``[lat, lon]`` per row, or
    None. ``agents``: one dict per localizer (:func:`agent`). ``belief``: ``idx`` (rows), ``roads`` (per moment
    ``[[edge, p], ...]``, the leading roads) and ``heat`` (per moment ``[[lat, lon, w], ...]``), or None.
    ``marks``: points with ``kind`` (start, sure, oracle, fail), ``name``, ``idx``, ``lat``, ``lon``, ``label``.
    ``lines``: static polylines (``name``, ``color``, ``latlngs``). ``images``: ``idx`` and ``src`` (data URIs).
    ``text``: ``idx`` and ``text`` (a status line per moment, e.g. the command). ``time['t_s']`` may be None.
    ``fit_roads``: open on the whole road graph (a city, to see the belief shrink), else on the drive.
    ``drives``: closed-loop drives to replay, one picked at a time (a selector): ``key``, ``label``, ``outcome``,
    ``idx`` (the row of each trace point), ``pos`` (``[lat, lon]`` per point), ``text`` (per point: time, speed,
    command) and ``end`` (``[lat, lon]`` where it stopped).
    """

    title: str
    time: dict[str, list[float] | None]
    truth: list[list[float]] | None = None
    agents: list[dict[str, Any]] = field(default_factory=list)
    belief: dict[str, Any] | None = None
    marks: list[dict[str, Any]] = field(default_factory=list)
    lines: list[dict[str, Any]] = field(default_factory=list)
    images: dict[str, list[Any]] | None = None
    text: dict[str, list[Any]] | None = None
    sure: float = 0.9
    notes: list[str] = field(default_factory=list)
    fit_roads: bool = False
    drives: list[dict[str, Any]] = field(default_factory=list)


def agent(name: str, label: str, index: int, rows: NDArray[np.int64], latlon: list[list[float]] | None,
          edge: NDArray[np.int64], confidence: NDArray[np.float64], unit: str = "road") -> dict[str, Any]:
    """One localizer's answers: at row ``rows[i]`` the road (``unit``: or e.g. the map vertex) ``edge[i]``,
    ``confidence[i]`` and the position ``latlon[i]`` (None where the localizer gives no position). ``index`` picks
    its colour; the answered road is highlighted only when ``unit`` is ``road``."""
    return {"name": name, "label": label, "color": PALETTE[index % len(PALETTE)], "unit": unit,
            "idx": np.asarray(rows, int).tolist(), "edge": np.asarray(edge, int).tolist(),
            "conf": np.round(np.asarray(confidence, float), 3).tolist(), "pos": latlon}


def mark(kind: str, name: str, idx: int, latlon: list[float], label: str) -> dict[str, Any]:
    """A point of the map and the chart: a start, where a localizer or the oracle became sure, a failure."""
    return {"kind": kind, "name": name, "idx": int(idx), "lat": latlon[0], "lon": latlon[1], "label": label}


def rows_of(frames: NDArray[np.int64], row_frames: NDArray[np.int64]) -> NDArray[np.int64]:
    """The slider row of each frame: the last row whose frame is at or before it."""
    return np.maximum(np.searchsorted(np.asarray(row_frames), np.asarray(frames), side="right") - 1, 0)


def thin_rows(count: int, max_rows: int) -> NDArray[np.int64]:
    """At most ``max_rows`` evenly spaced row numbers of ``count`` frames, the first and last included."""
    if count <= max_rows:
        return np.arange(count)
    return np.unique(np.round(np.linspace(0, count - 1, max_rows)).astype(np.int64))


def road_features(graph: RoadGraph, latlon: LatLon) -> dict[str, Any]:
    """The road graph as GeoJSON (WGS84), one LineString per road with its id, name and class."""
    import shapely

    features = []
    for e, coords in enumerate(graph.geometry):
        line = shapely.simplify(shapely.LineString(coords), SIMPLIFY_M)
        ll = latlon(np.asarray(line.coords))
        name = graph.edges["name"].iat[e]
        features.append({"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[b, a] for a, b in ll]},
                         "properties": {"edge_id": e, "name": "" if not isinstance(name, str) else name,
                                        "highway": str(graph.edges["highway"].iat[e])}})
    return {"type": "FeatureCollection", "features": features}


def assets_digest() -> str:
    """sha256 of the inlined assets (Leaflet, the heat layer, the viewer's script and styles): a rule param, so that
    an edit of ``viewer.js`` reruns the viewers like an edit of their Python code."""
    digest = hashlib.sha256()
    for path in sorted(ASSETS.iterdir()):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def _asset(name: str) -> str:
    path = ASSETS / name
    if not path.is_file():
        raise InputError(str(path), "viewer asset missing (a broken install of topoloc?)")
    return path.read_text(encoding="utf-8")


def render_html(graph: RoadGraph | None, data: ViewerData, tiles: str | None = None) -> str:
    """The whole HTML page of ``data`` over ``graph``'s roads (None: no road layer, e.g. teach and repeat)."""
    points = [p for p in (data.truth or [])] + [p for line in data.lines for p in line["latlngs"]]
    roads = road_features(graph, latlon_of(graph.crs)) if graph is not None else None
    if data.fit_roads and roads is not None:
        points = []
    if not points and roads is not None:  # the view opens on the drive, else on the whole map
        points += [[c[1], c[0]] for f in roads["features"] for c in f["geometry"]["coordinates"]]
    if not points:
        points += [p for a in data.agents for p in (a["pos"] or []) if p is not None]
    if not points:
        raise InputError("viewer", f"{data.title}: nothing to draw (no roads, track or answers)")
    pts = np.asarray(points, float)
    fmap = folium.Map(location=pts.mean(axis=0).tolist(), zoom_start=14, tiles=None, prefer_canvas=True,
                      control_scale=True)
    fmap.default_js, fmap.default_css = [], []  # Leaflet is inlined below: no CDN
    if tiles:
        folium.TileLayer(tiles, attr="map tiles", name="tiles").add_to(fmap)
    names = {"map": fmap.get_name(), "roads": None}
    if roads is not None:
        layer = folium.GeoJson(roads, name="roads", style_function=lambda _: {"color": "#9a9a9a", "weight": 2, "opacity": 0.8},
                               tooltip=folium.GeoJsonTooltip(["name", "edge_id"], aliases=["road", "id"]))
        layer.default_js, layer.default_css = [], []
        layer.add_to(fmap)
        names["roads"] = layer.get_name()
    fmap.fit_bounds([pts.min(axis=0).tolist(), pts.max(axis=0).tolist()])
    root = fmap.get_root()
    root.header.add_child(folium.Element(f"<style>{_asset('leaflet.css')}\n{_asset('viewer.css')}</style>"), name="topoloc_css")
    root.header.add_child(folium.Element("".join(f"<script>{_asset(s)}</script>\n" for s in SCRIPTS)), name="topoloc_js")
    root.title = data.title
    html = root.render()
    if "cdn." in html or "https://code.jquery" in html:
        raise RuntimeError("viewer: folium still links a CDN script; list it in page.render_html")
    payload = json.dumps({**asdict(data), **names}, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    tail = (f'<script type="application/json" id="topoloc-data">{payload}</script>\n'
            f"<script>{_asset('viewer.js')}</script>\n")
    return html.replace("</html>", tail + "</html>")


def write_viewer(path: str | Path, graph: RoadGraph | None, data: ViewerData, tiles: str | None = None) -> int:
    """Write the viewer of ``data`` atomically to ``path``; its size in bytes."""
    html = render_html(graph, data, tiles)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(html, encoding="utf-8")
    return len(html.encode("utf-8"))
