"""The MOWS driver node: the device (simulated, serial or a recorded bag) on ROS."""
