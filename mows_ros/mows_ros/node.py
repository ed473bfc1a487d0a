"""The base of every MOWS node: its parameter table declared, its health on /diagnostics."""

from collections.abc import Sequence

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node

import mows
from mows_ros.diagnostics import DiagnosticsPublisher, Health
from mows_ros.params import ParamSpec, declare_parameters, parameter_values


class MowsNode(Node):
    """A node named ``name`` with the parameters of ``table``.

    Subclasses translate between ROS and ``mows`` and override ``health`` to report what
    they are doing; the default reports that the node is up, with its parameters.
    """

    def __init__(self, name: str, table: Sequence[ParamSpec]):
        super().__init__(name)
        self.parameter_table = tuple(table)
        declare_parameters(self, self.parameter_table)
        self.diagnostics = DiagnosticsPublisher(self, self.health)
        self.get_logger().info("up: " + ", ".join(f"{k}={v!r}" for k, v in parameter_values(self, table).items()))

    def health(self) -> Health:
        return Health(
            DiagnosticStatus.OK,
            "up",
            {"mows_version": mows.__version__, **parameter_values(self, self.parameter_table)},
        )
