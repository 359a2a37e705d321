"""The closed-loop drives' trace (follow_route's traces.csv.gz): a repeat drive of the town's right turn, decimated,
written and read back."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from tests.drive.conftest import right_turn
from topoloc.drive.agents import ReplayAgent
from topoloc.drive.episodes import run_episode, teach_controls
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.localization_adapters import GroundTruth
from topoloc.drive.traces import TRACE_COLUMNS, episode_trace, read_traces, trace_steps, write_traces
from topoloc.errors import InputError
from topoloc.place.topometric_map import COMMANDS


def test_trace_steps_keep_every_nth_and_the_end():
    assert trace_steps(12, 10.0, 2.0).tolist() == [0, 5, 10, 12]
    assert trace_steps(10, 10.0, 2.0).tolist() == [0, 5, 10]
    assert trace_steps(3, 10.0, 100.0).tolist() == [0, 1, 2, 3]  # never more than one row a step


def test_the_trace_of_a_repeat_drive_follows_the_vehicle_and_its_command(town, town_graph, tmp_path):
    drive, conf, route, sim, topo, lane_s = right_turn(town, town_graph)
    steer, speed = teach_controls(sim, Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"])), "clear_noon",
                                  0, lane_s)
    episode = run_episode(sim, ReplayAgent(steer, speed, 0.5), GroundTruth(lane_s), topo, "night", 1, conf)
    assert episode.outcome == "success" and len(episode.yaw) == len(episode.xy) == episode.steps + 1
    hz = sim.spec.control_hz
    table = episode_trace(episode, topo, hz, 2.0, episode="0/night/0/replay/ground_truth", route=0, condition="night",
                          repeat=0, agent="replay (ground_truth)", localization="ground_truth")
    path = tmp_path / "traces.csv.gz"
    size = write_traces([table, table.assign(episode="other")], path)
    with gzip.open(path, "rt") as f:  # really gzipped
        assert f.readline().strip().split(",") == TRACE_COLUMNS
    back = read_traces(path)
    assert size == path.stat().st_size and len(back) == 2 * len(table)
    one = back[back.episode == "0/night/0/replay/ground_truth"]
    keep = one.step.to_numpy()
    every = int(round(hz / 2.0))
    assert keep[-1] == episode.steps and np.all(np.diff(keep[:-1]) == every)  # a row every 0.5 s, and the end
    assert len(one) == episode.steps // every + 1 + (episode.steps % every != 0)
    assert np.allclose(one[["x", "y"]].to_numpy(), episode.xy[keep], atol=0.01)
    assert np.allclose(one.speed_mps, episode.speed[keep], atol=0.01)
    assert np.allclose(one.t_s, keep / hz) and np.allclose(one.s_m, episode.s[keep], atol=0.01)
    assert abs(one.s_m.iat[-1] - episode.progress_m) < 0.01  # the last row: where the drive ended
    # the localized vertex (ground truth: the nearest), its command and position
    assert one.vertex.tolist() == [int(episode.vertex[min(k, episode.steps - 1)]) for k in keep]
    assert one.command.tolist() == [COMMANDS[int(topo.command[v])] for v in one.vertex]
    assert "right" in set(one.command) and "follow" in set(one.command)
    assert np.median(np.hypot(one.loc_x - one.x, one.loc_y - one.y)) < 1.5
    # the heading turns right by about a right angle over the drive
    turn = np.degrees(one.yaw.iat[-1] - one.yaw.iat[0])
    assert -120 < turn < -60


def test_a_bad_traces_file_names_itself(tmp_path):
    path = tmp_path / "traces.csv.gz"
    path.write_bytes(b"not gzip")
    with pytest.raises(InputError, match="traces.csv.gz"):
        read_traces(path)
    with gzip.open(path, "wt") as f:
        f.write("episode,x,y\n0,1,2\n")
    with pytest.raises(InputError, match="no 'route' column"):
        read_traces(path)
