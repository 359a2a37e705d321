"""Synthetic stereo drives rendered from OSM data: an offline image source for odometry and place recognition.

* :mod:`~topoloc.render.rig`: the KITTI-like stereo rig (intrinsics, baseline, ``calib.txt``);
* :mod:`~topoloc.render.scene`: buildings from OSM footprints, procedural facades, road surfaces;
* :mod:`~topoloc.render.textures`: seeded facade, ground and sky textures;
* :mod:`~topoloc.render.raycast`: column ray casting against the vertical walls;
* :mod:`~topoloc.render.conditions`: named appearance conditions (lighting, colour, fog, noise, sky);
* :mod:`~topoloc.render.renderer`: images of a scene under a condition for any list of poses;
* :mod:`~topoloc.render.render_drive`: the ``render_drive`` stage (KITTI layout on disk);
* :mod:`~topoloc.render.plot`: the contact sheet of sample frames per condition.

The motion is planar (no pitch or roll) and the walls are vertical, so every image column is one ray in
the ground plane: a wall slice between a strip of sky and a strip of ground. No GL context is needed.
The camera paths come from :mod:`topoloc.motion.route`.
"""
