"""Trajectory learning: DFS training paths on the road graph, their token encoding, the RNN."""
