import bz2
import math

import pytest

from osm_fixtures import write_cross
from topoloc.errors import InputError
from topoloc.osm.reader import read_road_network


def test_reads_drivable_ways_with_locations(tmp_path):
    network = read_road_network(write_cross(tmp_path / "cross.osm"))
    by_id = {way.osm_id: way for way in network.ways}
    assert set(by_id) == {100, 101, 102, 104, 105, 106, 107}  # footway and area skipped
    assert by_id[104].oneway == 1 and by_id[100].oneway == 0
    assert by_id[107].refs == (7, 30)  # clipped at the node without a location
    assert network.missing_node_refs == 1
    assert network.lonlat[1] == pytest.approx((3.0, 0.0))
    assert network.highway_counts() == {"residential": 5, "service": 1, "tertiary": 1}
    # lanes and width tags: numbers and metres read, lists and other units not
    assert by_id[100].lanes == 2.0 and by_id[101].width_m == 8.5 and by_id[105].lanes == 1.0
    assert math.isnan(by_id[102].lanes) and math.isnan(by_id[104].width_m) and math.isnan(by_id[106].lanes)


def test_private_roads_are_dropped_on_request(tmp_path):
    network = read_road_network(write_cross(tmp_path / "cross.osm"), exclude_private=True)
    assert 105 not in {way.osm_id for way in network.ways}


def test_reads_bz2(tmp_path):
    plain = write_cross(tmp_path / "cross.osm")
    packed = tmp_path / "cross.osm.bz2"
    packed.write_bytes(bz2.compress(plain.read_bytes()))
    assert len(read_road_network(packed).ways) == len(read_road_network(plain).ways)


def test_reads_pbf(helsinki_pbf):
    network = read_road_network(helsinki_pbf)
    assert len(network.ways) > 500
    assert {"primary", "residential", "secondary"} <= set(network.highway_counts())


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (None, "not found"),
        ("", "empty"),
        ('<?xml version="1.0"?>\n<osm version="0.6">\n  <node id="1" lat="0" lon="0"', "cannot read"),
        ('<?xml version="1.0"?>\n<osm version="0.6"></osm>\n', "no drivable roads"),
    ],
)
def test_bad_files_raise_one_line_naming_the_file(tmp_path, content, expected):
    path = tmp_path / "bad.osm"
    if content is not None:
        path.write_text(content)
    with pytest.raises(InputError) as info:
        read_road_network(path)
    message = str(info.value)
    assert message.startswith(str(path)) and expected in message and "\n" not in message


def test_wrong_suffix_is_rejected(tmp_path):
    with pytest.raises(InputError, match="not an OSM file"):
        read_road_network(tmp_path / "roads.geojson")
