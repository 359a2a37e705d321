"""The config slices the drive stages' rules pass as ``params.conf``: what a stage reads and nothing else, so a change
to another key does not rerun it. Kept here rather than in the workflow so that a test can run a stage on the very
slice its rule gives it."""

from __future__ import annotations

from typing import Any

RENDER_UNUSED = ("routes", "conditions", "sheet", "width", "height", "baseline_m")  # the rendered drives', not a route's


def drive_slice(config: dict[str, Any], drive_keys: tuple[str, ...], place_keys: tuple[str, ...]) -> dict[str, Any]:
    """The config slice of a drive stage: the named drive and place keys (the camera, the teach route, and what
    the stage reads of the place localization), and the render keys of the route and the scene."""
    return {"drive": {k: config["drive"][k] for k in drive_keys},
            "place": {k: config["place"][k] for k in place_keys},
            "render": {k: v for k, v in config["render"].items() if k not in RENDER_UNUSED}}


def controller_slice(config: dict[str, Any], controller: str) -> dict[str, Any]:
    """The config slice of train_controller for ``controller`` (``dlm`` or ``lp``): the training's keys and the camera
    (the demonstrations' images must be its), and with DAgger rounds (``drive.dagger``) or the closed-loop check
    (``drive.check``) those of the simulator, the expert and the routes (so a change to them reruns the training only
    when the controller drives)."""
    drive = config["drive"]
    keys = ("threads", "camera", "vehicle", "expert", "network", "train",
            *(("path_noise",) if controller == "lp" or drive["network"]["dlm_command"] == "move" else ()))
    if drive["dagger"]["rounds"] or drive["check"]["routes"]:
        conf = drive_slice(config, (*keys, "seed", "episode", "lane", "demonstrations", "dagger", "check"),
                           ("route", "image", "command", "repeat_conditions"))
        conf["drive"]["follow"] = {k: drive["follow"][k] for k in ("start_lateral_m", "start_yaw_deg")}
    else:
        conf = {"drive": {k: drive[k] for k in keys} | {"demonstrations": {"val_routes": drive["demonstrations"]["val_routes"]}},
                "place": {"image": config["place"]["image"]},
                "render": {"camera_height_m": config["render"]["camera_height_m"]}}
    return {"controller": controller} | conf
