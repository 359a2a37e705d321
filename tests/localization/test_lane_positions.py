"""Where across its road an answer places the vehicle (``localization.places.lane``): the cells' positions of the
metric filter and the token HMM, and a drive kept right of the centreline answered closer with ``right``."""

from __future__ import annotations

import numpy as np
import pytest
from localization_helpers import corridor_graph, drive_along, make_graph

from topoloc.config import load
from topoloc.errors import InputError
from topoloc.localization.metric.cell_grid import lane_offsets
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.poses import Odometry
from topoloc.registry import make

RESIDENTIAL_M = 7.0  # the carriageway of a residential road without width or lanes tags (render.textures)


def conf_with(lane: str) -> dict:
    conf = {k: load(None)[k] for k in ("localization", "segmentation", "encoding")}
    conf["localization"]["places"]["lane"] = lane
    return conf


def test_lane_offsets_put_two_way_roads_a_quarter_right_or_left_and_one_way_roads_in_the_middle():
    graph = corridor_graph()  # edge 1 is one-way, the others two-way residential roads
    right, left, centre = (lane_offsets(graph, side) for side in ("right", "left", "centre"))
    two_way = np.repeat(graph.edges.oneway.to_numpy() == 0, 2)
    assert np.allclose(right[two_way], RESIDENTIAL_M / 4) and np.allclose(left[two_way], -RESIDENTIAL_M / 4)
    assert np.all(right[~two_way] == 0) and np.all(left[~two_way] == 0) and np.all(centre == 0)
    with pytest.raises(InputError, match="localization.places.lane"):
        lane_offsets(graph, "middle")


@pytest.mark.parametrize("name", ["metric", "hmm"])
def test_cells_lie_right_of_their_direction(name):
    graph = corridor_graph()
    road = RoadMap(graph)
    grids = {}
    for lane in ("right", "centre", "left"):
        localizer = make(name)
        localizer.reset(road, conf_with(lane))
        grids[lane] = localizer.filter.model.grid if name == "metric" else localizer.hmm.grid
    right, centre, left = grids["right"], grids["centre"], grids["left"]
    shift = right.xy - centre.xy
    on = (centre.edge == 0) & (centre.state % 2 == 0)  # road 0 driven east (u -> v)
    back = (centre.edge == 0) & (centre.state % 2 == 1)  # and west
    one_way = centre.edge == 1
    assert on.any() and back.any() and one_way.any()
    assert np.allclose(shift[on], [0.0, -RESIDENTIAL_M / 4], atol=1e-6)  # east: right is south
    assert np.allclose(shift[back], [0.0, RESIDENTIAL_M / 4], atol=1e-6)
    assert np.allclose(shift[one_way], 0.0)
    assert np.allclose(left.xy - centre.xy, -shift)
    assert np.array_equal(right.edge, centre.edge) and np.allclose(right.heading, centre.heading)


def test_a_drive_in_the_right_lane_is_answered_closer_with_right_than_with_centre():
    """A drive 1.75 m right of the centreline, east then left (north) at the only node where a left turn can be
    made: the same roads answered either way; after the turn, sure on the north road, the positions on the true track
    across the road with ``right``, 1.75 m left of it with ``centre``."""
    graph = make_graph({0: (0.0, 0.0), 1: (200.0, 0.0), 2: (200.0, 200.0), 3: (400.0, 0.0)},
                       [(0, 1), (1, 2), (3, 1, 1)])
    xy, yaw, edges, _ = drive_along(graph, [0, 1, 2], start_m=5.0)
    track = xy + RESIDENTIAL_M / 4 * np.column_stack([np.sin(yaw), -np.cos(yaw)])
    odometry = Odometry(track - track[0], yaw)
    road = RoadMap(graph)
    tracks = {}
    for lane in ("right", "centre"):
        localizer = make("metric")
        localizer.reset(road, conf_with(lane))
        observations = localizer.observe(odometry, road, conf_with(lane))
        tracks[lane] = localizer.run(observations.items)
    right, centre, frames = tracks["right"], tracks["centre"], observations.frame
    assert np.array_equal(right.state, centre.state)
    sure = (right.confidence > 0.9) & np.isfinite(right.xy[:, 0]) & (edges[frames] == 1)  # on the two-way road north
    assert sure.sum() >= 20
    across_right = right.xy[sure, 0] - track[frames[sure], 0]  # the north road runs along y: x is across it
    across_centre = centre.xy[sure, 0] - track[frames[sure], 0]
    assert np.allclose(across_right, 0.0, atol=1e-6)
    assert np.allclose(across_centre, -RESIDENTIAL_M / 4, atol=1e-6)
    assert np.allclose(right.xy[sure, 1], centre.xy[sure, 1])  # along the road, the same position
