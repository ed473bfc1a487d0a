"""What every MOWS node shares; the nodes themselves only translate between ROS and ``mows``."""
