"""Named appearance conditions: the same place under different light, weather and time of day.

A :class:`Condition` is a documented set of parameters that the renderer applies in this order
(colours are BGR in 0..1; the seeded parts draw from the render seed, the frame and the camera):

1. **lighting**: a facade receives ``ambient + sun * max(0, n . s) * cos(elevation)`` (``n`` its outward
   normal, ``s`` the horizontal sun direction from ``sun_azimuth_deg``, clockwise from grid north), the
   ground ``ambient + sun * sin(elevation)``; ``wet`` darkens the road and mixes in the horizon colour;
   ``headlights`` add two low beams (falling off with depth and with the angle off the optical axis);
   ``window_glow`` makes the lit windows of each facade (a seeded mask) emit ``glow_color``;
2. **sky**: a 360-degree panorama from ``sky_zenith`` to ``sky_horizon``, periodic clouds covering a
   share ``clouds`` in ``cloud_color`` (seeded), and a glow around the sun (``sun_glow``);
3. **fog**: transmittance ``exp(-depth / fog_m)`` towards ``fog_color`` (walls also fade out over the
   last quarter of the view distance, so they never pop in);
4. **colour**: ``saturation`` about the luminance, a ``tint`` per channel;
5. **weather on the lens**: ``rain`` seeded streaks per image and a Gaussian ``blur_px``;
6. **sensor**: Gaussian noise of ``noise_std`` grey levels (seeded per frame and camera), then the tone
   curve ``255 (0.5 + contrast ((x / 255) ** (1 / gamma) - 0.5))``.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from typing import Any

from topoloc.errors import InputError

BGR = tuple[float, float, float]
_DRIVE = re.compile(r"^ren(\d+)_([a-z][a-z0-9_]*)$")


@dataclass(frozen=True)
class Condition:
    """Appearance parameters; see the module docstring for how each one is applied."""

    name: str
    description: str
    sun_azimuth_deg: float = 180.0
    sun_elevation_deg: float = 45.0
    sun: BGR = (0.0, 0.0, 0.0)
    ambient: BGR = (0.6, 0.6, 0.6)
    sky_zenith: BGR = (0.8, 0.6, 0.4)
    sky_horizon: BGR = (0.9, 0.85, 0.8)
    clouds: float = 0.0
    cloud_color: BGR = (0.9, 0.9, 0.9)
    sun_glow: float = 0.0
    fog_m: float = 2000.0
    fog_color: BGR = (0.85, 0.85, 0.85)
    wet: float = 0.0
    headlights: float = 0.0
    window_glow: float = 0.0
    glow_color: BGR = (0.45, 0.75, 1.0)
    saturation: float = 1.0
    tint: BGR = (1.0, 1.0, 1.0)
    rain: int = 0
    blur_px: float = 0.0
    noise_std: float = 1.5
    contrast: float = 1.0
    gamma: float = 1.0

    def to_dict(self) -> dict[str, object]:
        """All parameters (for run records)."""
        return asdict(self)


CONDITIONS: dict[str, Condition] = {c.name: c for c in [
    Condition("clear_noon", "High sun from the south, blue sky with a few clouds, light haze, crisp contrast.",
              sun_azimuth_deg=180.0, sun_elevation_deg=50.0, sun=(0.55, 0.6, 0.62), ambient=(0.52, 0.47, 0.42),
              sky_zenith=(0.85, 0.55, 0.3), sky_horizon=(0.95, 0.86, 0.76), clouds=0.15, cloud_color=(0.97, 0.97, 0.97),
              fog_m=900.0, fog_color=(0.92, 0.87, 0.82), noise_std=1.5, contrast=1.05),
    Condition("overcast", "No direct sun, bright grey cloud cover, soft flat light, muted colours.",
              sun_elevation_deg=40.0, sun=(0.0, 0.0, 0.0), ambient=(0.8, 0.8, 0.78), sky_zenith=(0.72, 0.71, 0.7),
              sky_horizon=(0.84, 0.84, 0.83), clouds=0.6, cloud_color=(0.62, 0.62, 0.63), fog_m=400.0,
              fog_color=(0.8, 0.8, 0.8), saturation=0.75, noise_std=2.0, contrast=0.85),
    Condition("sunset", "Low warm sun from the west-north-west, orange horizon with a sun glow, purple shade.",
              sun_azimuth_deg=290.0, sun_elevation_deg=5.0, sun=(0.3, 0.6, 1.0), ambient=(0.36, 0.27, 0.27),
              sky_zenith=(0.55, 0.3, 0.25), sky_horizon=(0.35, 0.6, 0.95), clouds=0.3, cloud_color=(0.45, 0.45, 0.8),
              sun_glow=0.8, fog_m=500.0, fog_color=(0.45, 0.55, 0.8), saturation=1.1, noise_std=3.0, contrast=1.1),
    Condition("rain", "Dark rain clouds, wet reflective road, rain streaks on the lens, blur, haze, sensor noise.",
              sun=(0.0, 0.0, 0.0), ambient=(0.5, 0.5, 0.49), sky_zenith=(0.45, 0.45, 0.46), sky_horizon=(0.6, 0.6, 0.6),
              clouds=0.8, cloud_color=(0.38, 0.38, 0.4), fog_m=180.0, fog_color=(0.6, 0.6, 0.6), wet=0.6,
              saturation=0.6, rain=350, blur_px=0.7, noise_std=3.0, contrast=0.8),
    Condition("fog", "Dense fog: visibility of a few tens of metres, bright grey, low contrast.",
              sun_elevation_deg=30.0, sun=(0.1, 0.1, 0.1), ambient=(0.7, 0.7, 0.7), sky_zenith=(0.8, 0.8, 0.8),
              sky_horizon=(0.8, 0.8, 0.8), fog_m=55.0, fog_color=(0.78, 0.78, 0.78), saturation=0.7, noise_std=2.0,
              contrast=0.9),
    Condition("night", "Night: dark sky with city glow, dim orange street lighting, the car's headlights, lit windows, "
              "high sensor gain.",
              sun=(0.0, 0.0, 0.0), ambient=(0.07, 0.1, 0.14), sky_zenith=(0.07, 0.03, 0.02),
              sky_horizon=(0.12, 0.11, 0.12), clouds=0.3, cloud_color=(0.1, 0.1, 0.12), fog_m=300.0,
              fog_color=(0.08, 0.08, 0.1), headlights=1.0, window_glow=0.9, noise_std=5.0, gamma=1.4),
]}


def get_condition(name: str, where: str = "render.conditions") -> Condition:
    """The condition called ``name``; InputError naming ``where`` and the known names otherwise."""
    if name not in CONDITIONS:
        raise InputError(where, f"unknown condition {name!r}; choose from {sorted(CONDITIONS)}")
    return CONDITIONS[name]


def check_conditions(place: dict[str, Any]) -> dict[str, list[str]]:
    """Teach, repeat, training and held-out condition names of a ``place`` config slice (keys it lacks: empty).

    InputError naming the key when a name is unknown, the teach condition is among the repeat conditions,
    fewer than two conditions are trained on, or none is held out.
    """
    teach = [str(place["teach_condition"])] if "teach_condition" in place else []
    for name in teach:
        get_condition(name, "place.teach_condition")
    repeat = [str(c) for c in place.get("repeat_conditions", [])]
    train = [str(c) for c in place.get("train", {}).get("conditions", [])]
    for key, names in (("place.repeat_conditions", repeat), ("place.train.conditions", train)):
        for i, name in enumerate(names):
            get_condition(name, f"{key}.{i}")
    if "repeat_conditions" in place and not repeat:
        raise InputError("place.repeat_conditions", "at least one repeat condition is needed")
    if set(teach) & set(repeat):
        raise InputError("place.repeat_conditions", f"must not contain the teach condition {teach[0]!r}")
    held_out = [c for c in CONDITIONS if c not in train]
    if "conditions" in place.get("train", {}):
        if len(train) < 2:
            raise InputError("place.train.conditions", "positives are drawn across conditions: give at least two")
        if not held_out:
            raise InputError("place.train.conditions", "keep at least one condition out of training (it is reported separately)")
    return {"teach": teach, "repeat": repeat, "train": train, "held_out": held_out}


def rendered_drive_names(conf: dict[str, Any]) -> list[str]:
    """Drive wildcards of the rendered source: ``ren00_clear_noon``, ... (every route under every condition)."""
    for i, name in enumerate(conf["conditions"]):
        get_condition(name, f"render.conditions.{i}")
    return [f"ren{r:02d}_{name}" for r in range(int(conf["routes"])) for name in conf["conditions"]]


def parse_drive(drive: str) -> tuple[int, str]:
    """Route index and condition name of a rendered drive name."""
    match = _DRIVE.match(drive)
    if not match:
        raise InputError("drive", f"{drive!r} is not a rendered drive name (ren<route>_<condition>)")
    get_condition(match.group(2), "drive")
    return int(match.group(1)), match.group(2)
