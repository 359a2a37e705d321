"""Odometry: KITTI poses, simulated drives, stereo VO, georeferencing, frame labels and turn segmentation."""
