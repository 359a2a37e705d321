"""Map errors of the simulated benchmark: each error type makes the map differ from the truth as specified, the
hard-shaped drives have their shape, and the ground truth on the map is right."""

from __future__ import annotations

import dataclasses
import networkx as nx
import numpy as np
import pytest
import shapely

from topoloc.experiments.maps import grid_osm
from topoloc.graph.from_osm import build_road_graph
from topoloc.localization.evaluation import Judge
from topoloc.odometry.map_error_drives import drive, map_truth, walk
from topoloc.odometry.map_errors import DEFAULT_TURN_SMOOTHING_M, LEVELS, dual_carriageway_grid, make_map_pair
from topoloc.odometry.simulate import NOISE_LEVELS

LOW = NOISE_LEVELS["low"]


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    graph, _ = build_road_graph(str(grid_osm(tmp_path_factory.mktemp("grid") / "grid.osm")), ["residential"], 20.0)
    return graph


def _line(coords):
    return shapely.LineString(coords)


def _distance_to(graph, xy, edges=None):
    """Distance of each point to the nearest road of ``graph`` (or of ``edges``)."""
    lines = [_line(graph.geometry[e]) for e in (range(graph.num_edges) if edges is None else edges)]
    points = shapely.points(xy)
    return np.min([shapely.distance(line, points) for line in lines], axis=0)


def _inner(sim, margin_m=15.0):
    """Frames on a straight stretch: the heading within ``margin_m`` on both sides turns by less than a degree, and
    the road stays the same (no corner rounding there)."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(sim.gt_xy, axis=0).T))])
    lo = np.searchsorted(cum, cum - margin_m)
    hi = np.searchsorted(cum, cum + margin_m, side="right")
    yaw = np.unwrap(sim.gt_yaw)
    keep = np.array([np.ptp(yaw[a:b]) < np.radians(1.0) and len(set(sim.edge[a:b].tolist())) == 1
                     for a, b in zip(lo, hi)])
    keep &= (cum >= margin_m) & (cum <= cum[-1] - margin_m)
    return keep


@pytest.mark.parametrize("level", ["none", "medium", "high"])
def test_lateral_offset_every_true_point_at_the_drawn_offset(grid, level):
    pair = make_map_pair(grid, "lateral", level, np.random.default_rng(1))
    low, high = (1.5, 1.5) if level == "none" else LEVELS["lateral"][level]["lane_offset_m"]
    for seed in range(3):
        sim = drive(pair, "random", 800.0, LOW, np.random.default_rng(seed))
        dist = _distance_to(pair.map, sim.gt_xy[_inner(sim)])
        offset = float(np.median(dist))
        assert low - 0.05 <= offset <= high + 0.05
        assert np.abs(dist - offset).max() < 0.1  # one lane for the whole drive, both directions
        # on the right of the direction of travel: the map road lies to the left
        e = sim.edge[_inner(sim)]
        heading = sim.gt_yaw[_inner(sim)]
        left = np.column_stack([-np.sin(heading), np.cos(heading)])
        assert np.all(_distance_to(pair.map, sim.gt_xy[_inner(sim)] + offset * left) < 0.15)
        assert np.all(e >= 0)


def _turn_radius(sim):
    """The smallest radius the drive turns on (metres), its heading smoothed over 5 m."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(sim.gt_xy, axis=0).T))])
    every = np.arange(0.0, cum[-1], 1.0)
    yaw = np.interp(every, cum, np.unwrap(sim.gt_yaw))
    curvature = np.abs(np.convolve(np.gradient(yaw), np.ones(5) / 5, "same"))
    return 1.0 / curvature.max()


@pytest.mark.parametrize("level", ["low", "medium", "high"])
def test_wide_turns_round_the_same_corners_wider_and_shorter(grid, level):
    pair = make_map_pair(grid, "wide_turns", level, np.random.default_rng(1))
    low, high = pair.turn_smoothing_m
    assert pair.map.num_edges == pair.truth.num_edges and (low, high) == LEVELS["wide_turns"][level]["turn_smoothing_m"]
    # the same walk (a smoothing that does not vary draws nothing) with the other types' corners and this level's
    plain = dataclasses.replace(pair, turn_smoothing_m=(DEFAULT_TURN_SMOOTHING_M,) * 2)
    wider = dataclasses.replace(pair, turn_smoothing_m=((low + high) / 2.0,) * 2)
    for seed in range(2):
        a = drive(plain, "circle_block", 1000.0, LOW, np.random.default_rng(seed))
        b = drive(wider, "circle_block", 1000.0, LOW, np.random.default_rng(seed))
        assert b.route == a.route
        # wider corners: a larger smallest radius, and metres less round the same block at every corner
        assert _turn_radius(b) > 1.15 * _turn_radius(a), (_turn_radius(b), _turn_radius(a))
        assert b.length_m < a.length_m - 0.5 * (len(a.route) - 1), (b.length_m, a.length_m)
        edge, _ = map_truth(pair, b.edge, b.gt_xy, b.gt_yaw)
        assert (edge >= 0).all()  # the map is the truth: every frame is on a map road


def test_displacement_moves_nodes_and_bends_roads_within_the_level(grid):
    pair = make_map_pair(grid, "displacement", "medium", np.random.default_rng(2))
    p = LEVELS["displacement"]["medium"]
    moved = np.hypot(*(pair.map.nodes[["x", "y"]] - pair.truth.nodes[["x", "y"]]).to_numpy(float).T)
    assert moved.max() <= p["node_m"] + 1e-9 and np.median(moved) > 0.5
    assert (pair.map.edges[["u", "v", "oneway"]].to_numpy() == pair.truth.edges[["u", "v", "oneway"]].to_numpy()).all()
    deviation = []
    for e in range(pair.map.num_edges):
        m, t = pair.map.geometry[e], pair.truth.geometry[e]
        assert np.allclose(m[0], pair.map.nodes.loc[pair.map.edges.u.iat[e], ["x", "y"]].to_numpy(float))
        assert np.allclose(m[-1], pair.map.nodes.loc[pair.map.edges.v.iat[e], ["x", "y"]].to_numpy(float))
        deviation.append(_line(m).hausdorff_distance(_line(t)))
        assert np.isclose(pair.map.edges.length_m.iat[e], _line(m).length)
    assert max(deviation) <= p["node_m"] + p["curve_m"] + 1e-6
    assert np.median(deviation) > 1.0


def test_simplified_map_has_fewer_points_within_the_tolerance(grid):
    pair = make_map_pair(grid, "simplified", "medium", np.random.default_rng(3))
    tol = LEVELS["simplified"]["medium"]["tolerance_m"]
    fewer = 0
    for e in range(pair.map.num_edges):
        m, t = pair.map.geometry[e], pair.truth.geometry[e]
        assert len(m) <= len(t)
        fewer += len(m) < len(t)
        assert np.allclose(m[[0, -1]], t[[0, -1]])
        assert _line(t).hausdorff_distance(_line(m)) <= tol + 1e-6
    assert fewer >= 0.8 * pair.map.num_edges  # the bent truth roads are simplified
    # the truth is curved: its roads leave the chord between their ends by more than the tolerance
    assert np.median([np.max(shapely.distance(_line(t[[0, -1]]), shapely.points(t))) for t in pair.truth.geometry]) > tol / 2
    assert all(np.allclose(m, b) for m, b in zip(pair.map.geometry, grid.geometry) if len(b) == 2)  # the base's chords


def test_dual_carriageway_mapped_as_one_road(grid):
    pair = make_map_pair(grid, "dual_as_one", "medium", np.random.default_rng(4))
    assert pair.dual and pair.truth.num_edges > pair.map.num_edges
    for right, left, openings in pair.dual:
        for r, l_ in zip(right, left):
            assert pair.truth.edges.oneway.iat[r] == 1 and pair.truth.edges.oneway.iat[l_] == 1
            gap = _line(pair.truth.geometry[r]).distance(_line(pair.truth.geometry[l_]))
            assert 15.0 - 1e-6 <= gap <= 20.0 + 1e-6
            (m,) = pair.truth_to_map[r]
            assert pair.truth_to_map[l_] == [m] and pair.map.edges.oneway.iat[m] == 0
            mid = shapely.points(pair.truth.geometry[r][len(pair.truth.geometry[r]) // 2])
            assert abs(_line(pair.map.geometry[m]).distance(mid) - gap / 2) < 0.5
        assert len(openings) == len(right) + 1
    # the ground truth on the map: the one road, the true position projected onto it (half the gap and the lane away)
    on_dual = 0
    for seed in range(4):
        sim = drive(pair, "random", 1500.0, LOW, np.random.default_rng(seed))
        edge, xy = map_truth(pair, sim.edge, sim.gt_xy, sim.gt_yaw)
        carriageways = {e for r, l_, _ in pair.dual for e in r + l_}
        idx = np.flatnonzero(np.isin(sim.edge, list(carriageways)) & _inner(sim))
        on_dual += len(idx)
        assert all(edge[i] == pair.truth_to_map[sim.edge[i]][0] for i in idx)
        away = np.hypot(*(xy[idx] - sim.gt_xy[idx]).T)
        assert np.all((away > 15.0 / 2 + 1.5 - 0.2) & (away < 20.0 / 2 + 1.5 + 0.2))
        assert all(_line(pair.map.geometry[edge[i]]).distance(shapely.Point(xy[i])) < 1e-6 for i in idx)
    assert on_dual > 100


def test_two_way_road_mapped_as_dual_and_the_truth_on_the_right_carriageway(grid):
    pair = make_map_pair(grid, "two_way_as_dual", "high", np.random.default_rng(5))
    split = {e: ms for e, ms in pair.truth_to_map.items() if len(ms) == 2}
    assert split and all(pair.map.edges.oneway.iat[m] == 1 for ms in split.values() for m in ms)
    checked = 0
    for seed in range(4):
        sim = drive(pair, "random", 1500.0, LOW, np.random.default_rng(seed))
        edge, xy = map_truth(pair, sim.edge, sim.gt_xy, sim.gt_yaw)
        on_split = np.isin(sim.edge, list(split)) & _inner(sim)
        for i in np.flatnonzero(on_split)[::25]:  # the carriageway whose direction is the one driven
            coords = pair.map.geometry[edge[i]]
            along = _line(coords).project(shapely.Point(xy[i]))
            ahead = np.asarray(_line(coords).interpolate(min(along + 1.0, _line(coords).length)).coords[0])
            d = ahead - xy[i]
            assert np.cos(np.arctan2(d[1], d[0]) - sim.gt_yaw[i]) > 0.7
            assert _line(coords).distance(shapely.Point(xy[i])) < 1e-6
            other = [m for m in split[sim.edge[i]] if m != edge[i]][0]
            assert _line(pair.map.geometry[other]).distance(shapely.Point(sim.gt_xy[i])) > \
                _line(coords).distance(shapely.Point(sim.gt_xy[i]))
            checked += 1
    assert checked > 10


def test_missing_road_the_drive_uses_and_the_map_lacks(grid):
    pair = make_map_pair(grid, "missing_road", "medium", np.random.default_rng(6))
    assert pair.detours and all(pair.truth_to_map[e] == [] for e in pair.detours)
    used = 0
    for seed in range(4):
        sim = drive(pair, "random", 1500.0, LOW, np.random.default_rng(seed))
        on = np.isin(sim.edge, list(pair.detours))
        used += on.sum()
        edge, xy = map_truth(pair, sim.edge, sim.gt_xy, sim.gt_yaw)
        assert np.array_equal(edge < 0, on)  # off-map exactly there
        assert np.allclose(xy[on], sim.gt_xy[on])
    assert used > 50
    for e in pair.detours:  # the map has no road along the detour's far side
        far = pair.truth.geometry[e][len(pair.truth.geometry[e]) // 2]
        assert _distance_to(pair.map, far[None])[0] > 20.0


def test_extra_road_in_the_map_not_in_the_truth(grid):
    pair = make_map_pair(grid, "extra_road", "high", np.random.default_rng(7))
    mapped = {m for ms in pair.truth_to_map.values() for m in ms}
    extra = sorted(set(range(pair.map.num_edges)) - mapped)
    assert len(extra) == pair.map.num_edges - pair.truth.num_edges >= 0.1 * pair.map.num_edges
    for e, (m,) in pair.truth_to_map.items():
        assert np.allclose(pair.truth.geometry[e], pair.map.geometry[m])
    assert nx.is_connected(pair.truth.graph)
    sim = drive(pair, "random", 2000.0, LOW, np.random.default_rng(0))
    edge, _ = map_truth(pair, sim.edge, sim.gt_xy, sim.gt_yaw)
    assert not np.isin(edge, extra).any() and (edge >= 0).all()


def test_none_level_is_the_truth_and_its_ground_truth_the_true_roads(grid):
    for error in ("displacement", "dual_as_one", "missing_road"):
        pair = make_map_pair(grid, error, "none", np.random.default_rng(0))
        assert pair.map.num_edges == pair.truth.num_edges
        sim = drive(pair, "random", 1000.0, LOW, np.random.default_rng(1))
        edge, xy = map_truth(pair, sim.edge, sim.gt_xy, sim.gt_yaw)
        assert np.array_equal(edge, sim.edge)
        off = np.hypot(*(xy - sim.gt_xy).T)
        assert abs(np.median(off) - 1.5) < 0.01 and off.max() < 5.0  # the lane; corners rounded


def test_judge_off_map_only_no_road_is_right(grid):
    judge = Judge(grid, 10.0)
    right = judge.right(np.array([-1, 3, 3, 4]), np.array([-1, -1, 3, 5]), np.zeros((4, 2)))
    assert right.tolist()[:3] == [True, False, True]


def test_mirror_walk_on_a_dual_carriageway(grid):
    pair = dual_carriageway_grid(grid)
    right, left, openings = pair.dual[0]
    sim = drive(pair, "out_and_back", 2500.0, LOW, np.random.default_rng(0))
    seen = set(sim.edge.tolist())
    assert set(right) <= seen and set(left) <= seen and {openings[0], openings[-1]} <= seen
    # out on the right carriageway, back on the left: the heading turns by 360 degrees per lap, never reverses on a road
    lap_m = sum(pair.truth.edges.length_m.iat[e] for e in right + left + [openings[0], openings[-1]])
    turned = (sim.gt_yaw[-1] - sim.gt_yaw[0]) / (2 * np.pi)
    assert abs(turned) >= np.floor(sim.length_m / lap_m) - 1e-6
    # the carriageways are 17 m apart and each point of the drive is 1.5 m right of one
    assert np.all(_distance_to(pair.truth, sim.gt_xy[_inner(sim)], right + left) < 1.6)


def test_hard_shapes_out_and_back_circle_and_straight(grid):
    rng = np.random.default_rng(3)
    pair = make_map_pair(grid, "lateral", "none", rng)
    sim = drive(pair, "out_and_back", 1200.0, LOW, rng)
    forward = np.cos(sim.gt_yaw - sim.gt_yaw[0])
    assert forward.min() < -0.9 and forward.max() > 0.9  # turned round and back
    runs = sim.edge[np.concatenate([[True], np.diff(sim.edge) != 0])]
    assert len(runs) >= 3 and runs[0] in runs[len(runs) // 2:]  # back over the roads of the way out
    sim = drive(pair, "circle_block", 1000.0, LOW, rng)
    loop = len(sim.route) // 2
    assert sim.route[:loop] == sim.route[loop:2 * loop] and len(set(sim.route[:loop])) == loop
    assert abs(sim.gt_yaw[-1] - sim.gt_yaw[0]) > 2 * 2 * np.pi - 1.0  # two full turns round the block
    sim = drive(pair, "long_straight", 1000.0, LOW, rng)
    assert sim.length_m > 600.0 and np.abs(sim.gt_yaw - sim.gt_yaw[0]).max() < np.radians(30.0)


def test_walk_respects_one_way_and_prefers_detours(grid):
    pair = make_map_pair(grid, "two_way_as_dual", "high", np.random.default_rng(5))
    for seed in range(5):
        route, froms = walk(pair.map, 2000.0, np.random.default_rng(seed))
        for e, f in zip(route, froms):
            ow = pair.map.edges.oneway.iat[e]
            assert ow == 0 or (ow == 1 and pair.map.edges.u.iat[e] == f)


def test_the_config_schema_lists_every_error_type():
    import yaml

    from topoloc.config import SCHEMA_PATH
    from topoloc.odometry.map_errors import ERROR_TYPES

    errors = yaml.safe_load(SCHEMA_PATH.read_text())["properties"]["experiments"]["properties"]["map_errors"][
        "properties"]["errors"]
    assert errors["items"]["enum"] == list(ERROR_TYPES) and errors["default"] == list(ERROR_TYPES)
