"""Motion below rendering and odometry: poses, georeferencing, routes on the road graph, the odometry noise model.

* :mod:`~topoloc.motion.poses`: KITTI poses, timestamps, calibration, GPS files; planar views of poses;
* :mod:`~topoloc.motion.georef`: placing a local odometry track on the map;
* :mod:`~topoloc.motion.route`: random walks on the road graph and smooth, drivable camera paths along them;
* :mod:`~topoloc.motion.noise`: the one odometry noise model (noisy increments of a true drive, integrated).
"""
