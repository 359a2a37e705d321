"""The topological road graph: building it from OSM, storing, loading and drawing it."""
