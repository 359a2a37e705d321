"""The renderer: stereo geometry, determinism, conditions, routes and scenes (topoloc.render)."""

import dataclasses

import cv2
import numpy as np
import pytest
import shapely

from tests.conftest import make_config
from tests.render.conftest import EMPTY_BLOCK, STREETS_M
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.motion.route import render_route
from topoloc.render.conditions import CONDITIONS, get_condition
from topoloc.render.renderer import Renderer
from topoloc.render.rig import StereoRig
from topoloc.render.scene import Building, Scene, parse_height, read_buildings, scene_for_path
from topoloc.render.textures import Road

RENDER = make_config()["render"]


def kitti_rig(width: int, height: int) -> StereoRig:
    """The KITTI rig scaled to ``width`` x ``height`` with the default render baseline and camera height."""
    return StereoRig.kitti(width, height, RENDER["baseline_m"], RENDER["camera_height_m"])


RIG = kitti_rig(620, 188)
VIEW_M = RENDER["view_distance_m"]
NORTH = np.pi / 2


def wall_scene(depth: float, seed: int = 0) -> Scene:
    """One 60 m wide building whose south wall is fronto-parallel at ``depth`` m north of the origin, and a road."""
    building = Building(7, shapely.box(-30.0, depth, 30.0, depth + 10.0), 15.0)
    road = Road(np.array([[0.0, -50.0], [0.0, 150.0]]), 7.0, True)
    return Scene([building], [road], seed)


def gray(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def disparities(left: np.ndarray, right: np.ndarray, rows: slice) -> tuple[np.ndarray, np.ndarray]:
    """Rows and disparities of Shi-Tomasi corners of ``left`` within ``rows``, matched into ``right`` by KLT."""
    mask = np.zeros_like(left)
    mask[rows, 20:-20] = 255
    pts = cv2.goodFeaturesToTrack(left, 300, 0.01, 5, mask=mask).reshape(-1, 2)
    matched, status, _ = cv2.calcOpticalFlowPyrLK(left, right, pts, None, winSize=(21, 21), maxLevel=3)
    ok = (status.ravel() == 1) & (np.abs(matched[:, 1] - pts[:, 1]) < 0.5)
    return pts[ok, 1], pts[ok, 0] - matched[ok, 0]


@pytest.mark.parametrize("depth", [6.0, 12.0, 25.0])
def test_wall_disparity_is_f_b_over_z(depth):
    renderer = Renderer(wall_scene(depth), RIG, get_condition("overcast"), 0, VIEW_M)
    left, right = (gray(im) for im in renderer.stereo_pair(np.zeros(2), NORTH))
    # The wall spans the rows between its top (15 m) and its foot; keep clear of both edges.
    top = RIG.cy - (15.0 - RIG.camera_height) * RIG.f / depth
    foot = RIG.cy + RIG.camera_height * RIG.f / depth
    rows, d = disparities(left, right, slice(int(max(top, 0)) + 4, int(foot) - 4))
    assert len(d) >= 20
    assert np.median(np.abs(d - RIG.f * RIG.baseline / depth)) < 0.5
    assert abs(np.median(d) - RIG.f * RIG.baseline / depth) < 0.25


def row_disparity(left_row: np.ndarray, right_row: np.ndarray, d_max: int) -> float:
    """Sub-pixel shift of ``right_row`` against ``left_row`` by SSD over integer shifts and a parabola through the best."""
    a, b = left_row.astype(float), right_row.astype(float)
    x = np.arange(d_max + 20, len(a) - 20)
    ssd = np.array([np.mean((a[x] - b[x - d]) ** 2) for d in range(d_max + 1)])
    d = int(np.clip(np.argmin(ssd), 1, d_max - 1))
    lo, mid, hi = ssd[d - 1], ssd[d], ssd[d + 1]
    return d + 0.5 * (lo - hi) / (lo - 2 * mid + hi)


def test_ground_disparity_follows_rows():
    # Without sensor noise: each ground row is one depth z = h f / (v - cy), so it shifts by f b / z as a whole.
    quiet = dataclasses.replace(get_condition("clear_noon"), noise_std=0.0)
    renderer = Renderer(wall_scene(80.0), RIG, quiet, 0, VIEW_M)
    left, right = (gray(im) for im in renderer.stereo_pair(np.zeros(2), NORTH))
    rows = np.arange(int(RIG.cy) + 20, RIG.height - 2, 8)
    measured = np.array([row_disparity(left[v], right[v], 60) for v in rows])
    expected = RIG.f * RIG.baseline / (RIG.camera_height * RIG.f / (rows - RIG.cy))
    assert np.max(np.abs(measured - expected)) < 0.5


def test_same_seed_same_bytes_other_seed_other_image():
    a = Renderer(wall_scene(12.0, seed=3), RIG, get_condition("rain"), 1, VIEW_M).stereo_pair(np.zeros(2), NORTH, 5)
    b = Renderer(wall_scene(12.0, seed=3), RIG, get_condition("rain"), 1, VIEW_M).stereo_pair(np.zeros(2), NORTH, 5)
    c = Renderer(wall_scene(12.0, seed=4), RIG, get_condition("rain"), 1, VIEW_M).stereo_pair(np.zeros(2), NORTH, 5)
    d = Renderer(wall_scene(12.0, seed=3), RIG, get_condition("rain"), 1, VIEW_M).stereo_pair(np.zeros(2), NORTH, 6)
    assert all(x.tobytes() == y.tobytes() for x, y in zip(a, b))
    assert a[0].tobytes() != c[0].tobytes()  # another facade texture
    assert a[0].tobytes() != d[0].tobytes()  # another frame: other rain and sensor noise


def test_conditions_look_different():
    assert len(CONDITIONS) >= 5
    scene = wall_scene(15.0)
    images = {name: Renderer(scene, RIG, cond, 0, VIEW_M).render(np.zeros(2), NORTH).astype(float) for name, cond in CONDITIONS.items()}
    names = list(images)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            assert np.mean(np.abs(images[a] - images[b])) > 5.0, (a, b)
    brightness = {name: im.mean() for name, im in images.items()}
    assert brightness["night"] < 0.75 * brightness["clear_noon"]
    assert images["fog"][: int(RIG.cy)].std() < images["clear_noon"][: int(RIG.cy)].std()
    for name, cond in CONDITIONS.items():
        assert cond.description and cond.name == name


def test_bad_inputs_name_the_key():
    with pytest.raises(InputError, match=r"^render.conditions: unknown condition 'snow'"):
        get_condition("snow")
    with pytest.raises(InputError, match=r"^render.width: image size 32x188 is too small"):
        kitti_rig(32, 188)
    with pytest.raises(InputError, match=r"^render.height: "):
        kitti_rig(620, 20)


def test_rig_scales_kitti_intrinsics():
    full = kitti_rig(1241, 376)
    assert full.f == pytest.approx(718.856) and full.cx == pytest.approx(607.1928) and full.cy == pytest.approx(185.2157)
    half = kitti_rig(620, 188)
    assert half.f == pytest.approx(718.856 * 620 / 1241)
    assert half.disparity(10.0) == pytest.approx(half.f * 0.54 / 10.0)


def test_route_is_smooth_and_on_the_roads(town):
    graph = RoadGraph.load(town["graph"])
    path = render_route(graph, 400.0, 1.0, np.random.default_rng(0), smoothing_m=4.0, lane_offset_m=1.5, max_turn_deg=3.0)
    assert path.length_m == pytest.approx(400.0, abs=1.5)
    assert np.degrees(np.max(np.abs(np.diff(path.yaw)))) <= 3.0 * 1.05  # the density of frames is integrated numerically
    steps = np.hypot(*np.diff(path.xy, axis=0).T)
    assert steps.max() <= 1.0 + 1e-6 and steps.min() > 0.05
    roads = shapely.MultiLineString([g for g in graph.geometry])
    distance = shapely.distance(shapely.points(path.xy), roads)
    assert np.median(distance) == pytest.approx(1.5, abs=0.1)  # lane offset, right of the centre line
    assert distance.max() < 4.0
    assert set(path.edge_id) <= set(path.route)


def test_parse_height():
    assert parse_height({"height": "12.5"}, 3.0) == 12.5
    assert parse_height({"height": "12,5 m"}, 3.0) == 12.5
    assert parse_height({"building:height": "9m"}, 3.0) == 9.0
    assert parse_height({"building:levels": "4"}, 3.0) == 13.0
    assert parse_height({"height": "tall"}, 3.0) is None and parse_height({}, 3.0) is None


def test_buildings_and_procedural_facades(town):
    graph = RoadGraph.load(town["graph"])
    render = make_config()["render"]
    conf = {**render["buildings"], "view_distance_m": render["view_distance_m"]}
    real = read_buildings(town["osm"], graph.crs, conf, seed=0)
    assert len(real) == len({b.key for b in real}) > 30  # one per footprint (way), no duplicates
    assert all(b.source == "osm" for b in real)
    heights = np.array([b.height for b in real])
    assert np.all((heights >= 9.0) & (heights <= 24.0) | np.isclose(np.mod(heights - 1.0, 3.2), 0.0)
                  | (heights >= 10.0) & (heights <= 20.0))
    assert read_buildings(town["osm"], graph.crs, conf, seed=0)[5].height == real[5].height
    # A path along the street between the empty block and the block east of it.
    x = graph.nodes.x.min() + STREETS_M[1]
    y0 = graph.nodes.y.min()
    path = np.column_stack([np.full(100, x + 1.5), y0 + 160.0 + np.arange(100.0)])
    scene = scene_for_path(town["osm"], graph, path, conf, seed=0)
    facts = scene.facts()
    assert facts["buildings_osm"] > 5 and facts["buildings_procedural"] > 3
    # Procedural blocks fill the empty block (east of the street) and the outside of the grid, never a built block.
    x_min = graph.nodes.x.min()
    blocks = {(i, j): shapely.box(x_min + STREETS_M[j], y0 + STREETS_M[i], x_min + STREETS_M[j + 1], y0 + STREETS_M[i + 1])
              for i in range(2) for j in range(2)}
    proc = [b.polygon.centroid for b in scene.buildings if b.source == "procedural"]
    inside = {key: sum(block.contains(c) for c in proc) for key, block in blocks.items()}
    assert inside[EMPTY_BLOCK] >= 3
    assert sum(inside.values()) == inside[EMPTY_BLOCK]
    corridor = shapely.LineString(path).buffer(2.5 - 1e-6)
    assert not any(b.polygon.intersects(corridor) for b in scene.buildings)
    without = scene_for_path(town["osm"], graph, path, {**conf, "procedural": False}, seed=0)
    assert without.facts()["buildings_procedural"] == 0
