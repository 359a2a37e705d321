"""The topological road graph: building it from OSM, storing, loading and drawing it."""

from topoloc.graph.road_graph import RoadGraph

__all__ = ["RoadGraph"]
