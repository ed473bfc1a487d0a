"""The MOWS mapper node: rotation sweeps, their decomposition and model reports on ROS."""
