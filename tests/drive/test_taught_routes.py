"""Teach and repeat on any route: the map of a route's teach drive made in memory, and an aligned Topo-LP repeating
it; the pose tracker keeps up with a chain the teach drive's odometry stretched."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests.conftest import make_config
from tests.drive.conftest import right_turn
from topoloc.drive.agents import LPAgent, TeachImages
from topoloc.drive.camera import drive_rig
from topoloc.drive.episodes import run_episode, speed_limit_ahead
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.ground_alignment import ALONG_GAIN, GroundAligner, PoseTracker
from topoloc.drive.localization_adapters import GroundTruth
from topoloc.drive.simulator import RUNNING, SUCCESS, Simulator, VehicleState
from topoloc.drive.taught_routes import teach_map
from topoloc.place.topometric_map import COMMANDS


class _Embedder:
    """A retrieval network stand-in: keeps the images it embeds; the embedding is each image's mean per channel."""

    def __init__(self) -> None:
        self.seen: list[np.ndarray] = []

    def embed(self, images: np.ndarray) -> np.ndarray:
        self.seen.append(images)
        return images.reshape(len(images), -1, images.shape[-1]).mean(axis=1).astype(np.float32)


class _PathDriver:
    """A Topo-LP stand-in trained on the aligned frame: the expert drives, the path it is told is kept."""

    def __init__(self, expert: Expert, sim: Simulator) -> None:
        self.hparams = {"path_frame": "aligned"}
        self.expert, self.sim, self.told = expert, sim, 0

    def act(self, image, speed, plane):
        self.told += 1
        control = self.expert.control(self.sim.state)
        return control.steer, control.throttle


@pytest.fixture(scope="module")
def turn(town, town_graph):
    """The town's right-turn route, simulated with the controller camera of the full default config."""
    drive, _conf, route, sim, topo, lane_s = right_turn(town, town_graph)
    config = make_config()
    conf = {"drive": drive, "place": config["place"], "render": config["render"]}
    sim = Simulator(route, sim.scene, drive_rig(conf), sim.spec, 100.0)
    return conf, route, sim, topo, lane_s


def test_a_route_is_taught_as_the_pipeline_teaches_its_teach_route(turn):
    conf, route, sim, _topo, _lane_s = turn
    embedder = _Embedder()
    expert = Expert(route, sim.spec, ExpertSettings.from_conf(conf["drive"]["expert"]))
    taught = teach_map(sim, expert, embedder, conf, seed=5)
    topo, image = taught.topo, conf["place"]["image"]
    assert taught.outcome == SUCCESS
    # a vertex every second step of the expert's drive, the place camera's window of each image embedded
    assert embedder.seen[0].shape == (len(topo), int(image["height"]), int(image["width"]), 3)
    assert 150 < len(topo) < 400 and topo.embedding.shape == (len(topo), 3)
    assert np.all(np.diff(taught.lane_s) >= 0) and taught.lane_s[0] < 1.0
    assert taught.lane_s[-1] > route.length_m - 5.0
    assert np.all(np.hypot(*(topo.gt_xy - np.stack([route.point(s) for s in taught.lane_s])).T) < 0.6)
    # positions from the teach drive's noisy odometry; commands the route's at each vertex's progress
    drift = np.hypot(*(topo.xy - topo.gt_xy).T)
    assert drift[0] < 1e-6 and 0.0 < drift.max() < 0.1 * route.length_m
    assert np.array_equal(topo.command, [route.command_at(s) for s in taught.lane_s])
    assert COMMANDS.index("right") in topo.command
    assert np.all(taught.teach_speed > 0) and taught.teach_speed.min() < taught.teach_speed.max() - 1.0  # slow in the turn
    # repeated in closed loop on its own map, with ground truth, by an aligned Topo-LP
    agent = LPAgent(_PathDriver(Expert(route, sim.spec, ExpertSettings.from_conf(conf["drive"]["expert"])), sim), topo,
                    TeachImages(sim, topo, conf["place"]["teach_condition"], 5, True))
    limit = speed_limit_ahead(taught.teach_speed, taught.lane_s, 10.0)
    episode = run_episode(sim, agent, GroundTruth(taught.lane_s), topo, "rain", 7, conf, 0, limit)
    assert episode.outcome == SUCCESS and agent.model.told == episode.steps
    assert np.mean(episode.loc_error_m) < 1.0


@pytest.mark.parametrize("along_gain", [ALONG_GAIN, 0.0])
def test_the_tracker_keeps_up_with_a_chain_the_teach_odometry_stretched(turn, along_gain):
    conf, route, sim, topo, lane_s = turn
    stretched = dataclasses.replace(topo, xy=topo.xy[0] + 1.05 * (topo.xy - topo.xy[0]))  # a 5 % scale error
    tracker = PoseTracker(GroundAligner(sim.rig), stretched.xy, TeachImages(sim, stretched, "clear_noon", 1, True),
                          sim.spec, along_gain=along_gain)
    expert = Expert(route, sim.spec, ExpertSettings.from_conf(conf["drive"]["expert"]))
    obs, status, control, lag = sim.reset("overcast", 3), RUNNING, None, []  # a straight, then the turn
    expert.reset()
    while status == RUNNING:
        vertex = int(np.clip(np.searchsorted(lane_s, sim.s), 0, len(lane_s) - 1))
        tracker.update(obs.image, obs.speed, vertex, control)
        lag.append(vertex - tracker.vertex)
        control = expert.control(sim.state)
        obs, status = sim.step(control)
        if obs is None:
            break
    assert status == SUCCESS
    lag = np.asarray(lag)
    if along_gain > 0:  # the vertex the localizer gives draws it along on the straight; not in the turn (a metre more)
        assert np.abs(lag[:200]).max() <= 1 and np.abs(lag).max() <= 3, lag
    else:  # the model's metres alone: 5 % short of the chain's, 5 m and more behind before the turn puts it right
        assert np.max(lag) >= 5, lag


def test_the_tracker_is_drawn_along_the_chain_only_where_it_runs_straight(turn):
    _conf, _route, sim, _topo, _lane_s = turn
    # a chain of a vertex every metre: 60 m east, then a right angle, 60 m south
    east = np.column_stack([np.arange(0.0, 60.0), np.zeros(60)])
    south = np.column_stack([np.full(60, 60.0), -np.arange(0.0, 60.0)])
    chain = np.vstack([east, south])
    tracker = PoseTracker(GroundAligner(sim.rig), chain, lambda v: None, sim.spec)
    h = 0.5 * sim.spec.wheelbase_m
    for vertex, localized, moved in ((20, 25, 0.5), (58, 63, 0.0)):  # on the straight; at the corner
        tracker.vertex = vertex
        centre = chain[vertex]
        tracker.state = VehicleState(centre[0] - h, centre[1], 0.0, 5.0)
        tracker._pull_along(localized)  # the localizer 5 m further along the chain
        shift = tracker.state.centre(sim.spec) - centre
        assert shift == pytest.approx([moved, 0.0], abs=0.02), (vertex, shift)
