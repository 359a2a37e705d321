"""The drives of an odometry config: their names (the workflow's ``{drive}`` wildcards) per source.

Kept apart from the ``extract_odometry`` stage so that the workflow can list the drives when it parses the
Snakefile without importing the stereo VO and OpenCV.
"""

from __future__ import annotations

from typing import Any

from topoloc.errors import InputError
from topoloc.render.conditions import rendered_drive_names

SOURCES = ("simulated", "kitti_poses", "kitti_stereo", "rendered")


def simulated_drive_names(conf: dict[str, Any]) -> list[str]:
    """Drive wildcards of the simulated source: ``sim00``, ``sim01``, ..."""
    return [f"sim{i:02d}" for i in range(int(conf["simulated"]["drives"]))]


def drive_names(conf: dict[str, Any], render: dict[str, Any] | None = None) -> list[str]:
    """The drives the workflow builds for the ``odometry`` config slice (and ``render`` for the rendered source)."""
    if conf["source"] == "simulated":
        return simulated_drive_names(conf)
    if conf["source"] == "rendered":
        if render is None:
            raise InputError("render", "odometry.source rendered needs the render config section")
        return rendered_drive_names(render)
    return list(conf["drives"])
