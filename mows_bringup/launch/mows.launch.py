"""The MOWS node graph for a full ROS 2 Jazzy install: ``ros2 launch mows_bringup mows.launch.py``.

The same nodes and parameter files as ``mows-graph`` (mows_bringup.nodes.NODES). The nodes are
managed (lifecycle) nodes; by default each configures and activates itself (``--autostart``);
``autostart:=false`` leaves them unconfigured for a supervisor (``ros2 lifecycle set``,
nav2's lifecycle_manager or mows-graph's order: configure all, activate in data-flow order).
"""

from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription
from mows_bringup.nodes import NODES


def generate_launch_description() -> LaunchDescription:
    namespace = LaunchConfiguration("namespace")
    autostart = LaunchConfiguration("autostart")
    return LaunchDescription(
        [
            DeclareLaunchArgument("namespace", default_value="", description="namespace of all nodes"),
            DeclareLaunchArgument("autostart", default_value="true", description="configure and activate each node"),
        ]
        + [
            Node(
                package=node.package,
                executable=node.executable,
                name=node.name,
                namespace=namespace,
                parameters=[node.config_path()],
                arguments=arguments,
                condition=condition(autostart),
                output="screen",
            )
            for node in NODES
            for arguments, condition in ((["--autostart"], IfCondition), ([], UnlessCondition))
        ]
    )
