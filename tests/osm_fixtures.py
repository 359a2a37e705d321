"""A hand-made OSM network with known topology (near the equator in UTM zone 31: 1e-4 deg ~ 11.1 m)."""

from __future__ import annotations

from pathlib import Path

from conftest import write_osm

D = 0.0005  # ~55.7 m

NODES = {
    1: (3.0, 0.0),  # centre: four-way intersection
    2: (3.0 - 2 * D, 0.0),  # west dead end
    3: (3.0 - D, 0.0),  # shape point on the west arm
    4: (3.0 + D, 0.0),  # shape point on the east arm
    5: (3.0 + 2 * D, 0.0),  # east end: two-way meets one-way
    6: (3.0, -2 * D),  # south dead end
    7: (3.0, 2 * D),  # north: the way continues into a clipped way
    30: (3.0, 3 * D),  # north dead end
    9: (3.0 + 3 * D, D),  # shape point of the one-way service road
    10: (3.0 + 4 * D, 2 * D),  # one-way meets two-way again
    11: (3.0 + 5 * D, 2 * D),  # dead end
    8: (3.0 + 2 * D, -D),  # end of a footway
    20: (3.1, 0.1),  # a separate component far away
    21: (3.1 + D, 0.1),
}
WAYS = [
    (100, [2, 3, 1, 4, 5], {"highway": "residential", "name": "West-East", "lanes": "2"}),
    (101, [6, 1, 7], {"highway": "residential", "name": "South-North", "width": "8,5 m"}),
    (102, [6, 1], {"highway": "tertiary", "lanes": "2;3"}),  # mapped over the same stretch as way 101: one road
    (103, [5, 8], {"highway": "footway"}),
    (104, [10, 9, 5], {"highway": "service", "oneway": "yes", "width": "12'"}),  # against the canonical direction
    (105, [10, 11], {"highway": "residential", "access": "private", "lanes": "1"}),
    (106, [20, 21], {"highway": "residential"}),
    (107, [7, 30, 99], {"highway": "residential"}),  # node 99 lies outside the extract
    (108, [2, 6, 30, 2], {"highway": "residential", "area": "yes"}),
]


def write_cross(path: Path) -> Path:
    """Write the network to ``path`` (an .osm file)."""
    return write_osm(path, NODES, WAYS)
