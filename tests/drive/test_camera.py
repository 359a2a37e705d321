"""The controller's camera: the place images' camera extended downwards, whose top rows the localization reads."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests.conftest import make_config
from tests.drive.conftest import drive_conf, route_scene, town_route
from topoloc.drive.camera import drive_rig, hfov_deg, image_shape, place_window
from topoloc.drive.localization_adapters import PlaceLocalization
from topoloc.place.images import make_rig
from topoloc.render.conditions import get_condition
from topoloc.render.renderer import Renderer


def ground_m(rig, row: int) -> float:
    """How far ahead the centre of image row ``row`` sees the ground."""
    return rig.camera_height * rig.f / (row - rig.cy)


def test_the_camera_sees_the_ground_as_close_as_asked():
    conf = make_config()
    place = make_rig(conf["place"]["image"], conf["render"])
    assert ground_m(place, place.height - 1) > 6.0  # the place camera alone misses the expert's aim point (4-5 m)
    rig = drive_rig(conf)
    near = conf["drive"]["camera"]["nearest_ground_m"]
    assert ground_m(rig, rig.height - 1) <= near < ground_m(rig, rig.height - 2)
    assert (rig.width, rig.f, rig.cx, rig.cy) == (place.width, place.f, place.cx, place.cy)
    assert image_shape(conf) == (rig.height, 160, 3) and rig.height == 72
    for far in (None, 30.0):  # the place camera alone, or one that already sees that far
        assert drive_rig(make_config(drive={"camera": {"nearest_ground_m": far}})) == place


def test_a_wider_camera_adds_columns_on_both_sides():
    conf = make_config()
    place, narrow = make_rig(conf["place"]["image"], conf["render"]), drive_rig(conf)
    assert 80.0 < hfov_deg(place) < 83.0  # KITTI's intrinsics
    assert place_window(conf) == (slice(0, 48), slice(0, 160))
    for hfov in (100.0, 120.0):
        wide = drive_rig(make_config(drive={"camera": {"hfov_deg": hfov}}))
        side = (wide.width - place.width) // 2
        assert wide.width == place.width + 2 * side and wide.cx == pytest.approx(place.cx + side)
        assert (wide.height, wide.f, wide.cy) == (narrow.height, place.f, place.cy)
        assert hfov_deg(dataclasses.replace(wide, width=wide.width - 2, cx=wide.cx - 1)) < hfov <= hfov_deg(wide)
    assert drive_rig(make_config(drive={"camera": {"hfov_deg": 60.0}})) == narrow  # already wider than that
    assert drive_rig(make_config(drive={"camera": {"hfov_deg": 120.0}})).width == 322


@pytest.mark.parametrize("hfov", [None, 120.0])
def test_the_place_window_is_the_place_image(town, town_graph, hfov):
    conf = make_config(drive={"camera": {"hfov_deg": hfov}})
    route = town_route(town_graph, "straight", drive_conf())
    scene = route_scene(town["osm"], town_graph, route)
    place, rig = make_rig(conf["place"]["image"], conf["render"]), drive_rig(conf)
    condition = get_condition("overcast")
    noiseless = dataclasses.replace(condition, noise_std=0.0)
    top = Renderer(scene, rig, noiseless, 0, 100.0).render(route.xy[100], float(route.yaw[100]))
    alone = Renderer(scene, place, noiseless, 0, 100.0).render(route.xy[100], float(route.yaw[100]))
    assert top.shape == image_shape(conf)
    assert np.abs(top[place_window(conf)].astype(int) - alone.astype(int)).max() <= 1
    below = top[place.height:].astype(float)
    assert below.std() > 5.0  # the road, not a blank band


class _Recorder:
    """A localizer and retrieval model that record the image shape they were given."""

    name = "recorder"

    def __init__(self) -> None:
        self.shapes: list[tuple[int, ...]] = []
        self.images: list[np.ndarray] = []
        self.hparams = type("H", (), {"embedding_dim": 4})()

    def reset(self, topo, conf) -> None:
        pass

    def embed(self, images):
        self.shapes.append(images.shape[1:])
        self.images.append(images[0])
        return np.zeros((len(images), 4), np.float32)

    def update(self, frame):
        return type("A", (), {"state": 0, "confidence": 1.0})()


def test_the_localization_reads_the_place_cameras_window():
    recorder = _Recorder()
    topo = type("T", (), {"embedding": np.zeros((3, 4), np.float32)})()
    conf = make_config(drive={"camera": {"hfov_deg": 120}})
    loc = PlaceLocalization(recorder, topo, recorder, {}, place_window(conf))
    loc.start(np.random.default_rng(0))
    h, w, c = image_shape(conf)
    columns = np.broadcast_to(np.arange(w, dtype=np.uint16)[None, :, None], (h, w, c))  # each pixel holds its column
    loc.update(columns, 1.0, None)
    assert recorder.shapes == [(48, 160, 3)]
    assert recorder.images[0][0, :, 0].tolist() == list(range(81, 241))  # the middle 160 of 322 columns
