"""A node's state on /diagnostics, once a second, in the diagnostic_msgs form that
diagnostic aggregators and ``ros2 topic echo /diagnostics`` read.
They run on wall time (``mows_ros.wall``): under ``use_sim_time`` too, once a second of real time.
Each array is stamped with the node's ROS time, as a diagnostic aggregator beside a simulator
expects: the system clock, or under ``use_sim_time`` the time ``/clock`` gives, once it has given
one (the system clock until then: a stamp of zero says nothing)."""

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from mows_ros.wall import steady_timer, wall_stamp

DIAGNOSTICS_TOPIC = "/diagnostics"
DIAGNOSTICS_DEPTH = 10  # reliable, volatile: the defaults of diagnostic_updater


@dataclass(frozen=True)
class Health:
    """What a node reports about itself: a level (DiagnosticStatus.OK, WARN, ERROR; bytes in
    rclpy), a line of text, and key values."""

    level: bytes
    message: str
    values: Mapping[str, object] = field(default_factory=dict)


def ros_stamp(node: Node):
    """Now on ``node``'s ROS clock (simulated time under ``use_sim_time``), or on the system
    clock while that clock has not started (no ``/clock`` yet)."""
    now = node.get_clock().now()
    return now.to_msg() if now.nanoseconds > 0 else wall_stamp()


class DiagnosticsPublisher:
    """Publishes ``health()`` of ``node`` on /diagnostics every ``period_s`` seconds.

    The status is named after the node's fully qualified name, so that two copies of a
    node in different namespaces stay apart.
    """

    def __init__(self, node: Node, health: Callable[[], Health], period_s: float = 1.0):
        self._node = node
        self._health = health
        self._publisher = node.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_DEPTH)
        self._timer = steady_timer(node, period_s, self.publish)

    def publish(self) -> None:
        health = self._health()
        array = DiagnosticArray()
        array.header.stamp = ros_stamp(self._node)
        array.status = [
            DiagnosticStatus(
                level=health.level,
                name=self._node.get_fully_qualified_name(),
                message=health.message,
                values=[KeyValue(key=k, value=str(v)) for k, v in health.values.items()],
            )
        ]
        self._publisher.publish(array)
