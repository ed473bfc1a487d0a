"""The MOWS node graph for a full ROS 2 Jazzy install: ``ros2 launch mows_bringup mows.launch.py``.

The same nodes and parameter files as ``mows-graph`` (mows_bringup.graph.NODES).
"""

from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription
from mows_bringup.graph import NODES


def generate_launch_description() -> LaunchDescription:
    namespace = LaunchConfiguration("namespace")
    return LaunchDescription(
        [DeclareLaunchArgument("namespace", default_value="", description="namespace of all nodes")]
        + [
            Node(
                package=node.package,
                executable=node.executable,
                name=node.name,
                namespace=namespace,
                parameters=[node.config_path()],
                output="screen",
            )
            for node in NODES
        ]
    )
