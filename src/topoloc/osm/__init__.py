"""Raw OpenStreetMap input: where a region's data comes from and how its roads are read."""

from topoloc.osm.reader import DRIVABLE_HIGHWAY_CLASSES, RawNetwork, Way, read_road_network

__all__ = ["DRIVABLE_HIGHWAY_CLASSES", "RawNetwork", "Way", "read_road_network"]
