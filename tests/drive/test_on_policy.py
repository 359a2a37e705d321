"""The controller at the wheel: in DAgger the expert takes over from a controller heading off the road and labels
every state the controller reached; the closed-loop check tells a controller that drives from one that does not (the
expert from full left; a trained controller from always straight and always left); the train_controller stage runs
both end to end on the town."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.conftest import make_config
from tests.drive.conftest import BASELINES, ConstantSteer, drive_conf, node_at, route_scene, tiny_demos
from topoloc.config import deep_merge
from topoloc.drive import simulate_demonstrations, train_controller
from topoloc.drive.camera import image_shape
from topoloc.drive.config_slices import controller_slice
from topoloc.drive.demonstrations import Demonstrations
from topoloc.drive.drive_route import build_route
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.on_policy import (
    DaggerSettings,
    check_metrics,
    check_route,
    closed_loop_check,
    drive_on_policy,
    offset_ahead,
)
from topoloc.drive.route_planning import plan_route
from topoloc.drive.routes import make_simulator, random_drive_route
from topoloc.drive.simulator import OUTCOMES, SUCCESS, Simulator, VehicleSpec
from topoloc.drive.topo_lp import load_controller
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.render.rig import StereoRig


@pytest.fixture(scope="module")
def road(straight_road):
    graph = straight_road["graph"]
    drive = drive_conf(demonstrations={"record_every": 2})
    edges, froms = plan_route(graph, node_at(graph, 0.0, 60.0), node_at(graph, 400.0, 60.0))
    route = build_route(graph, edges, froms, drive["lane"]["smoothing_m"], drive["lane"]["margin_m"],
                        min_radius_m=drive["lane"]["min_radius_m"]).cut(150.0)
    sim = Simulator(route, route_scene(straight_road["osm"], graph, route), StereoRig.kitti(64, 48, 0.54, 1.65),
                    VehicleSpec.from_conf(drive), 100.0)
    conf = {"drive": drive, "place": {"image": {"color": True}}}
    return conf, sim, Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"]))


def test_the_offset_ahead_sees_a_car_heading_off_the_lane(road):
    _, sim, _ = road
    sim.reset("clear_noon", 0, lateral_m=0.0, yaw_deg=-10.0, speed=5.0)  # turned 10 degrees to the right
    assert abs(sim.lateral) < 0.05
    assert offset_ahead(sim, 1.0) == pytest.approx(5.0 * np.sin(np.radians(10.0)), abs=0.15)  # + is right
    assert offset_ahead(sim, 0.0) == pytest.approx(sim.lateral)


class FullLeft:
    """A controller that steers full left at half throttle, whatever it sees."""

    def act(self, image, speed, command):
        return 1.0, 0.5


class ExpertController:
    """The expert, acting as the controller (the DAgger drive should then never hand over)."""

    def __init__(self, sim, expert):
        self.sim, self.expert = sim, Expert(expert.route, expert.spec, expert.settings)

    def act(self, image, speed, command):
        control = self.expert.control(self.sim.state)
        return control.steer, control.throttle


def test_the_expert_takes_over_from_a_controller_heading_off_the_road(road):
    conf, sim, expert = road
    settings = DaggerSettings(rounds=1, epochs=1, takeover_m=1.0, takeover_s=1.0)
    demo, status, share = drive_on_policy(sim, expert, FullLeft(), "clear_noon", 3, conf, ["clear_noon"], 0, settings)
    assert status == SUCCESS  # the expert kept the car on the road
    assert 0.2 < share < 0.9  # the controller drove in between, and the car went off its lane every time
    assert np.abs(demo.lateral).max() < 2.0
    assert demo.perturbed.all()
    assert demo.steer.max() < 0.9 and demo.steer.min() < 0  # the labels are the expert's way back, never the full lock
    assert len(demo) == pytest.approx(sim.t / 2, abs=1)


def test_a_controller_that_drives_like_the_expert_keeps_the_wheel(road):
    conf, sim, expert = road
    settings = DaggerSettings(rounds=1, epochs=1, takeover_m=1.0, takeover_s=1.0)
    demo, status, share = drive_on_policy(sim, expert, ExpertController(sim, expert), "overcast", 4, conf,
                                          ["clear_noon", "overcast"], 7, settings)
    assert status == SUCCESS and share == 0.0
    assert (demo.route == 7).all() and (demo.condition == 1).all()


@pytest.mark.parametrize("key, value", [("rounds", -1), ("takeover_m", 0.0), ("takeover_s", -1.0)])
def test_bad_dagger_settings_name_their_key(key, value):
    dagger = {"rounds": 1, "epochs": 2, "takeover_m": 1.0, "takeover_s": 1.0} | {key: value}
    with pytest.raises(InputError, match=f"drive.dagger.{key}"):
        DaggerSettings.from_conf(dagger)


class FollowsTheSimulator:
    """The expert of whichever simulator was built last (the closed-loop check builds one per route)."""

    def __init__(self, conf):
        self.conf, self.sim, self.expert = conf, None, None

    def make_simulator(self, osm, graph, route):
        self.sim = make_simulator(osm, graph, route, self.conf)
        self.expert = Expert(route, self.sim.spec, ExpertSettings.from_conf(self.conf["drive"]["expert"]))
        return self.sim

    def act(self, image, speed, command):
        control = self.expert.control(self.sim.state)
        return control.steer, control.throttle


def test_the_closed_loop_check_tells_a_driver_from_a_wreck(town):
    conf = town_conf()
    graph = RoadGraph.load(town["graph"])
    driver = FollowsTheSimulator(conf)
    make_route = lambda rng: random_drive_route(graph, conf, 150.0, rng)
    good = closed_loop_check(driver, conf, None, make_route, lambda route: driver.make_simulator(str(town["osm"]), graph, route))
    assert good["check/routes"] == 3 and good["check/success_rate"] == 1.0 and good["check/share_driven"] == 1.0
    assert {k for k in good if k.startswith("check/success_")} == {"check/success_rate", "check/success_overcast",
                                                                    "check/success_sunset", "check/success_rain"}
    bad = closed_loop_check(FullLeft(), conf, None, make_route,
                            lambda route: make_simulator(str(town["osm"]), graph, route, conf))
    assert bad["check/success_rate"] == 0.0 and bad["check/share_driven"] < 0.5
    assert sum(v for k, v in bad.items() if k in ("check/off_road", "check/wrong_road", "check/reversed")) == 3


#: The closed-loop check's bound on a controller that drives (the straight road's trained Topo-DLM).
CHECK_SUCCESS = 0.75


@pytest.mark.parametrize("driver", ["trained", *BASELINES])
def test_the_closed_loop_check_passes_a_trained_controller_and_no_baseline(straight, trained_dlm, driver):
    """The check of train_controller on four drives of the straight road under a condition its controller never saw,
    each from its own seeded start offset (``drive.follow``: widened to 0.5 m and 3 degrees)."""
    drive, sim = straight
    conf = {"drive": deep_merge(drive, {"check": {"routes": 4}, "follow": {"start_lateral_m": 0.5, "start_yaw_deg": 3.0}}),
            "place": {"image": {"color": True}, "repeat_conditions": ["overcast"]}}
    controller = trained_dlm[0].eval() if driver == "trained" else ConstantSteer(BASELINES[driver], drive)
    metrics = closed_loop_check(controller, conf, None, lambda rng: sim.route, lambda route: sim)
    assert metrics["check/routes"] == 4
    assert (metrics["check/success_rate"] >= CHECK_SUCCESS) == (driver == "trained"), metrics


def town_config() -> dict:
    """The whole config on the town: short routes, small images and networks, three repeat conditions."""
    return make_config(
        render={"length_m": 160.0},
        place={"image": {"width": 64, "height": 48}, "repeat_conditions": ["overcast", "sunset", "rain"]},
        drive={"demonstrations": {"routes": 3, "val_routes": 1, "route_length_m": 150, "min_distance_m": 0, "min_steps": 20,
                                  "side_views": 0},
               "network": {"channels": [8, 16], "hidden": 32},
               "train": {"batch_size": 16, "batches_per_epoch": 4, "max_epochs": 1, "max_time_min": None,
                         "accelerator": "cpu", "log_model": False, "log_every_n_steps": 1},
               "dagger": {"rounds": 2, "epochs": 1}, "check": {"routes": 3}})


def town_conf() -> dict:
    """Drive stages' config on the town (:func:`town_config`) as the stages read it."""
    conf = town_config()
    return {"controller": "dlm", "drive": conf["drive"], "place": conf["place"], "render": conf["render"]}


def test_train_controller_runs_its_dagger_rounds_and_check_on_the_town(town, tmp_path):
    conf = town_conf()
    inputs = {"osm": str(town["osm"]), "graph": str(town["graph"])}
    demo_out = {k: str(tmp_path / f"demos.{ext}") for k, ext in (("demonstrations", "npz"), ("stats", "json"), ("sheet", "png"))}
    simulate_demonstrations.run(conf, inputs, demo_out)
    outputs = {k: str(tmp_path / name) for k, name in (("model", "controller.ckpt"), ("history", "history.csv"),
                                                      ("metrics", "metrics.json"), ("figure", "training.png"))}
    metrics = train_controller.run(conf, inputs | {"demonstrations": demo_out["demonstrations"]}, outputs)
    history = pd.read_csv(outputs["history"])
    assert sorted(history["round"].unique()) == [0, 1, 2]
    assert history.step.is_monotonic_increasing
    assert metrics["dagger/1/drives"] == 2.0 and metrics["dagger/2/steps"] > 20  # the two training routes, each round
    assert json.loads(Path(outputs["metrics"]).read_text()) == pytest.approx(metrics)
    failures = sum(metrics.get(f"check/{outcome}", 0.0) for outcome in OUTCOMES if outcome != SUCCESS)
    assert metrics["check/routes"] == 3 and metrics["check/success_rate"] * 3 + failures == pytest.approx(3)
    load_controller(outputs["model"], (48, 64, 3))
    wide = deep_merge(conf, {"drive": {"camera": {"hfov_deg": 120.0}}})  # another camera than the demonstrations'
    with pytest.raises(InputError, match=r"demos\.npz.*recorded with 64x48x3 images, but drive\.camera .* give 130x48x3"):
        train_controller.run(wide, inputs | {"demonstrations": demo_out["demonstrations"]}, outputs)
    # The rule's own slice when the controller does not drive (no DAgger round, no check) holds what training reads.
    still = controller_slice(deep_merge(town_config(), {"drive": {"dagger": {"rounds": 0}, "check": {"routes": 0}}}), "lp")
    assert not {"dagger", "check", "episode", "lane"} & set(still["drive"])
    metrics = train_controller.run(still, inputs | {"demonstrations": demo_out["demonstrations"]}, outputs)
    demos = Demonstrations.load(demo_out["demonstrations"])
    assert metrics["train_steps"] == np.sum(demos.route < demos.route.max())  # all but the one validation route
    assert not any(k.startswith(("check/", "dagger/")) for k in metrics)
    assert "round" not in pd.read_csv(outputs["history"]).columns  # written again, by a fit without DAgger rounds


def test_the_check_metrics_count_each_condition_and_outcome():
    rows = [("overcast", SUCCESS, 1.0), ("rain", "off_road", 0.25), ("overcast", "off_road", 0.5),
            ("sunset", SUCCESS, 1.0), ("overcast", "reversed", 0.75)]
    assert check_metrics(rows) == pytest.approx({
        "check/routes": 5.0, "check/success_rate": 0.4, "check/share_driven": 0.7, "check/success_overcast": 1 / 3,
        "check/success_rain": 0.0, "check/success_sunset": 1.0, "check/off_road": 2.0, "check/reversed": 1.0})
    assert check_metrics([("rain", SUCCESS, 1.0)]) == {"check/routes": 1.0, "check/success_rate": 1.0,
                                                        "check/share_driven": 1.0, "check/success_rain": 1.0}


def test_routes_checked_one_by_one_in_any_order_give_the_closed_loop_check(straight):
    """check_route depends on the route index and the config alone: the routes checked last to first give
    closed_loop_check's metrics (so they can be checked in parallel)."""
    drive, sim = straight
    follow = {"start_lateral_m": 0.8, "start_yaw_deg": 4.0}
    conf = {"drive": deep_merge(drive, {"check": {"routes": 3}, "follow": follow}),
            "place": {"image": {"color": True}, "repeat_conditions": ["overcast", "rain"]}}
    makers = (lambda rng: sim.route, lambda route: sim)
    controller = ConstantSteer(0.0, drive)  # straight on: off the road from some starts, not from others
    rows = {r: check_route(r, controller, conf, None, *makers) for r in (2, 1, 0)}
    assert [rows[r][0] for r in range(3)] == ["overcast", "rain", "overcast"]
    assert {rows[r][1] for r in range(3)} >= {SUCCESS, "off_road"} and len({rows[r][2] for r in range(3)}) > 1
    assert closed_loop_check(controller, conf, None, *makers) == check_metrics([rows[r] for r in range(3)])


def demos_conf() -> dict:
    """The config of train_controller's demonstrations: 64 x 48 place images, the default camera."""
    return make_config(place={"image": {"width": 64, "height": 48}})


def test_one_map_trains_on_its_own_demonstrations_and_several_are_pooled(tmp_path):
    conf = demos_conf()
    shape = image_shape(conf)
    paths = {}
    for name, routes, tag in (("a", [0, 1, 2], 0.0), ("b", [0, 1], 100.0)):
        tiny_demos(routes, shape=shape, tag=tag).save(tmp_path / f"{name}.npz")
        paths[name] = str(tmp_path / f"{name}.npz")
    alone = train_controller.load_demonstrations(conf, {"demonstrations": paths["a"], "osm": "x.osm"})
    np.testing.assert_array_equal(alone.route, [0, 0, 0, 1, 1, 1, 2, 2, 2])  # not renumbered
    np.testing.assert_array_equal(alone.speed, np.arange(9))
    pooled = train_controller.load_demonstrations(conf, {"demonstrations_a": paths["a"], "demonstrations_b": paths["b"],
                                                         "osm": "x.osm", "graph": "x.graph"})
    assert len(pooled) == 15 and len(np.unique(pooled.route)) == 5
    np.testing.assert_array_equal(pooled.speed, [*range(9), *range(100, 106)])
    last = np.unique(pooled.route)[-2:]
    assert set(pooled.speed[np.isin(pooled.route, last)] // 100) == {0, 1}  # validation routes of both maps


def test_demonstrations_of_another_camera_or_other_conditions_are_named(tmp_path):
    conf = demos_conf()
    h, w, c = image_shape(conf)
    good, narrow, other = (str(tmp_path / f"{name}.npz") for name in ("good", "narrow", "other"))
    tiny_demos([0, 1], shape=(h, w, c)).save(good)
    tiny_demos([0, 1], shape=(h, w - 2, c)).save(narrow)
    tiny_demos([0, 1], shape=(h, w, c), conditions=("clear_noon", "night")).save(other)
    for inputs in ({"demonstrations": narrow}, {"demonstrations_a": good, "demonstrations_b": narrow}):
        with pytest.raises(InputError, match=rf"^{narrow}: recorded with {w - 2}x{h}x{c} images, but drive.camera"):
            train_controller.load_demonstrations(conf, inputs)
    with pytest.raises(InputError, match=rf"^{other}: recorded under \['clear_noon', 'night'\], but {good} under"):
        train_controller.load_demonstrations(conf, {"demonstrations_a": good, "demonstrations_b": other})
    with pytest.raises(InputError, match=r"^drive.demonstrations_from"):
        train_controller.load_demonstrations(conf, {"osm": good})
