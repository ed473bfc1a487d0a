"""The MOWS estimator node: ring-down fits and field estimates on ROS."""
